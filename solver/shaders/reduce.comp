// SPDX-License-Identifier: MIT
// Sums the m partial sums of each field (dot.comp's layout, `width` sums per group) into
// result[f * stride + slot + k], k < width: one work group per field (work-group z).
DOUBLES(0, Partial, partial, readonly);
DOUBLES(1, Result, result, restrict);
layout(location = 0) uniform int m;
layout(location = 1) uniform int slot;
layout(location = 2) uniform int width;
layout(location = 3) uniform int stride;
shared double sdata[256];

void main() {
  uint l = gl_LocalInvocationID.x;
  int f = int(Field());
  for (int k = 0; k < width; ++k) {
    if (m <= 32) {  // few partial sums (llvmpipe's grid-stride dots): no barrier tree
      if (l == 0u) {
        double s = 0.0LF;
        for (int q = 0; q < m; ++q) s += LDD(partial, (f * m + q) * width + k);
        STD(result, f * stride + slot + k, s);
      }
      continue;
    }
    double s = 0.0LF;
    for (int q = int(l); q < m; q += 256) s += LDD(partial, (f * m + q) * width + k);
    sdata[l] = s;
    barrier();
    for (uint st = 128u; st > 0u; st >>= 1u) {
      if (l < st) sdata[l] += sdata[l + st];
      barrier();
    }
    if (l == 0u) STD(result, f * stride + slot + k, sdata[0]);
    barrier();
  }
}
