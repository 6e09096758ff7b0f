// SPDX-License-Identifier: MIT
// Sums the m partial sums of each field (dot.comp's layout, `width` sums per group) into
// result[f * stride + slot + k], k < width: one work group per field (work-group z).
DOUBLES(0, Partial, partial, readonly);
DOUBLES(1, Result, result, restrict);
layout(location = 0) uniform int m;
layout(location = 1) uniform int slot;
layout(location = 2) uniform int width;
layout(location = 3) uniform int stride;
shared double sdata[TL_GROUP];

void main() {
  uint l = gl_LocalInvocationID.x;
  int f = int(Field());
  for (int k = 0; k < width; ++k) {
#ifndef TL_INVOCATION_SUMS
    if (m <= 32)  // few partial sums: no barrier tree
#endif
    {  // llvmpipe: one invocation adds them up
      if (l == 0u) {
        double s = 0.0LF;
        for (int q = 0; q < m; ++q) s += LDD(partial, (f * m + q) * width + k);
        STD(result, f * stride + slot + k, s);
      }
      continue;
    }
    double s = 0.0LF;
    for (int q = int(l); q < m; q += TL_GROUP) s += LDD(partial, (f * m + q) * width + k);
    sdata[l] = s;
    barrier();
    for (uint st = uint(TL_GROUP) / 2u; st > 0u; st >>= 1u) {
      if (l < st) sdata[l] += sdata[l + st];
      barrier();
    }
    if (l == 0u) STD(result, f * stride + slot + k, sdata[0]);
    barrier();
  }
}
