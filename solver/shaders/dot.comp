// SPDX-License-Identifier: MIT
// Per-work-group partial sums of a . b (and, with PAIR defined, of a . c too), accumulated in
// double. Batched: a, b, c hold one field of n values per work-group z; the partial sums of
// field f, group g (G groups per field) are at partial[(f G + g) W + k], W = 1 or 2 sums.
layout(std430, binding = 0) readonly buffer A { float a[]; };
layout(std430, binding = 1) readonly buffer B { float b[]; };
layout(std430, binding = 2) writeonly buffer Partial { double partial[]; };
#ifdef PAIR
layout(std430, binding = 3) readonly buffer C { float c[]; };
const uint W = 2u;
shared double sdata1[256];
#else
const uint W = 1u;
#endif
layout(location = 0) uniform int n;
shared double sdata[256];

void main() {
  uint p = ThreadIndex(), l = gl_LocalInvocationID.x;
  bool inside = p < uint(n);
  uint o = inside ? Field() * uint(n) + p : 0u;
  sdata[l] = inside ? double(a[o]) * double(b[o]) : 0.0LF;
#ifdef PAIR
  sdata1[l] = inside ? double(a[o]) * double(c[o]) : 0.0LF;
#endif
  barrier();
  for (uint s = 128u; s > 0u; s >>= 1u) {
    if (l < s) {
      sdata[l] += sdata[l + s];
#ifdef PAIR
      sdata1[l] += sdata1[l + s];
#endif
    }
    barrier();
  }
  if (l == 0u) {
    uint groups = gl_NumWorkGroups.x * gl_NumWorkGroups.y;
    uint g = gl_WorkGroupID.x + gl_WorkGroupID.y * gl_NumWorkGroups.x;
    uint at = (Field() * groups + g) * W;
    partial[at] = sdata[0];
#ifdef PAIR
    partial[at + 1u] = sdata1[0];
#endif
  }
}
