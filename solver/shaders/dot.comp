// SPDX-License-Identifier: MIT
// Per-work-group partial sums of a . b, accumulated in double.
layout(std430, binding = 0) readonly buffer A { float a[]; };
layout(std430, binding = 1) readonly buffer B { float b[]; };
layout(std430, binding = 2) writeonly buffer Partial { double partial[]; };
layout(location = 0) uniform int n;
shared double sdata[256];

void main() {
  uint p = ThreadIndex();
  sdata[gl_LocalInvocationID.x] = p < uint(n) ? double(a[p]) * double(b[p]) : 0.0LF;
  barrier();
  for (uint s = 128u; s > 0u; s >>= 1u) {
    if (gl_LocalInvocationID.x < s) sdata[gl_LocalInvocationID.x] += sdata[gl_LocalInvocationID.x + s];
    barrier();
  }
  if (gl_LocalInvocationID.x == 0u)
    partial[gl_WorkGroupID.x + gl_WorkGroupID.y * gl_NumWorkGroups.x] = sdata[0];
}
