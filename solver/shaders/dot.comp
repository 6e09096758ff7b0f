// SPDX-License-Identifier: MIT
// Partial sums of a . b (and, with PAIR defined, of a . c too), accumulated in double, each
// invocation first summing its elements of a grid-stride loop (common.glsl), then one sum per
// work group from a shared-memory tree; with TL_INVOCATION_SUMS (llvmpipe, where barriers are
// coroutine switches) one sum per invocation instead. Batched: a, b, c hold one field of n
// values per work-group z; partial sum g of field f (G per field) is at partial[(f G + g) W + k],
// W = 1 or 2 sums.
FLOATS(0, A, a, readonly);
FLOATS(1, B, b, readonly);
DOUBLES(2, Partial, partial, writeonly);
#ifdef PAIR
FLOATS(3, C, c, readonly);
const uint W = 2u;
shared double sdata1[TL_GROUP];
#else
const uint W = 1u;
#endif
layout(location = 0) uniform int n;
shared double sdata[TL_GROUP];

void main() {
  uint l = gl_LocalInvocationID.x, f0 = Field() * uint(n);
  double s0 = 0.0LF, s1 = 0.0LF;
  for (uint e = ThreadIndex(); e < uint(n); e += Stride()) {
    double ae = double(LD(a, f0 + e));
    s0 += ae * double(LD(b, f0 + e));
#ifdef PAIR
    s1 += ae * double(LD(c, f0 + e));
#endif
  }
#ifdef TL_INVOCATION_SUMS
  uint at = (Field() * Stride() + ThreadIndex()) * W;
  STD(partial, at, s0);
#ifdef PAIR
  STD(partial, at + 1u, s1);
#endif
  return;
#endif
  sdata[l] = s0;
#ifdef PAIR
  sdata1[l] = s1;
#endif
  barrier();
  for (uint s = uint(TL_GROUP) / 2u; s > 0u; s >>= 1u) {
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
    STD(partial, at, sdata[0]);
#ifdef PAIR
    STD(partial, at + 1u, sdata1[0]);
#endif
  }
}
