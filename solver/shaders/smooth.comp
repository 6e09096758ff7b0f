// SPDX-License-Identifier: MIT
// One half-sweep of red-black (zebra) z-line Gauss-Seidel: every column (i, j) with
// (i + j) % 2 == color solves its tridiagonal z-system exactly, the neighbouring columns
// (the other colour) held fixed. x holds d' between the two passes. Batched: b and x hold one
// field per work-group z (common.glsl).
layout(std430, binding = 0) readonly buffer Cx { float cx[]; };
layout(std430, binding = 1) readonly buffer Cy { float cy[]; };
layout(std430, binding = 2) readonly buffer Cz { float cz[]; };
layout(std430, binding = 3) readonly buffer Inv { float inv[]; };
layout(std430, binding = 4) readonly buffer Luc { float luc[]; };
layout(std430, binding = 5) readonly buffer B { float b[]; };
layout(std430, binding = 6) buffer X { float x[]; };
layout(location = 0) uniform int nx;
layout(location = 1) uniform int ny;
layout(location = 2) uniform int nz;
layout(location = 3) uniform int color;

void main() {
  uint t = ThreadIndex();
  int half_nx = (nx + 1) / 2;
  int j = int(t) / half_nx;
  if (j >= ny) return;
  int i = 2 * (int(t) % half_nx) + ((color + j) & 1);
  if (i >= nx) return;
  int nxy = nx * ny;
  int o = int(Field()) * nxy * nz;  // offset of this field
  for (int k = 0; k < nz; ++k) {
    int p = i + nx * j + nxy * k, q = o + p;
    float d = b[q];
    if (i > 0) d += cx[p - 1] * x[q - 1];
    if (i + 1 < nx) d += cx[p] * x[q + 1];
    if (j > 0) d += cy[p - nx] * x[q - nx];
    if (j + 1 < ny) d += cy[p] * x[q + nx];
    if (k > 0) d += cz[p - nxy] * x[q - nxy];
    x[q] = d * inv[p];
  }
  for (int k = nz - 2; k >= 0; --k) {
    int p = i + nx * j + nxy * k;
    x[o + p] += luc[p] * x[o + p + nxy];
  }
}
