// SPDX-License-Identifier: MIT
// One half-sweep of red-black (zebra) z-line Gauss-Seidel: every column (i, j) with
// (i + j) % 2 == color solves its tridiagonal z-system exactly, the neighbouring columns
// (the other colour) held fixed. x holds d' between the two passes; the value of the node
// below (forward) or above (backward) is carried in a register. Batched: b and x hold one
// field per work-group z (common.glsl).
FLOATS(0, Cx, cx, readonly);
FLOATS(1, Cy, cy, readonly);
FLOATS(2, Cz, cz, readonly);
FLOATS(3, Inv, inv, readonly);
FLOATS(4, Luc, luc, readonly);
FLOATS(5, B, b, readonly);
FLOATS(6, X, x, restrict);
layout(location = 0) uniform int nx;
layout(location = 1) uniform int ny;
layout(location = 2) uniform int nz;
layout(location = 3) uniform int color;

void main() {
  uint t = ThreadIndex();
  int half_nx = (nx + 1) / 2;
  int j = Div(int(t), half_nx);
  if (j >= ny) return;
  int i = 2 * (int(t) - j * half_nx) + ((color + j) & 1);
  if (i >= nx) return;
  int nxy = nx * ny;
  int o = int(Field()) * nxy * nz;  // offset of this field
  float below = 0.0, cz_below = 0.0;
  int p = i + nx * j;
  for (int k = 0; k < nz; ++k, p += nxy) {
    int q = o + p;
    float d = LD(b, q) + cz_below * below;
    if (i > 0) d += LD(cx, p - 1) * LD(x, q - 1);
    if (i + 1 < nx) d += LD(cx, p) * LD(x, q + 1);
    if (j > 0) d += LD(cy, p - nx) * LD(x, q - nx);
    if (j + 1 < ny) d += LD(cy, p) * LD(x, q + nx);
    below = d * LD(inv, p);
    ST(x, q, below);
    cz_below = LD(cz, p);
  }
  float above = below;
  p -= 2 * nxy;
  for (int k = nz - 2; k >= 0; --k, p -= nxy) {
    above = LD(x, o + p) + LD(luc, p) * above;
    ST(x, o + p, above);
  }
}
