// SPDX-License-Identifier: MIT
// Sums m partial sums (double) into result[slot], in one work group.
layout(std430, binding = 0) readonly buffer Partial { double partial[]; };
layout(std430, binding = 1) buffer Result { double result[]; };
layout(location = 0) uniform int m;
layout(location = 1) uniform int slot;
shared double sdata[256];

void main() {
  double s = 0.0LF;
  for (int q = int(gl_LocalInvocationID.x); q < m; q += 256) s += partial[q];
  sdata[gl_LocalInvocationID.x] = s;
  barrier();
  for (uint st = 128u; st > 0u; st >>= 1u) {
    if (gl_LocalInvocationID.x < st) sdata[gl_LocalInvocationID.x] += sdata[gl_LocalInvocationID.x + st];
    barrier();
  }
  if (gl_LocalInvocationID.x == 0u) result[slot] = sdata[0];
}
