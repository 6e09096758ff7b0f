// SPDX-License-Identifier: MIT
// LU factors of every z-column's tridiagonal block (Thomas algorithm), one thread per column:
//   inv_k = 1 / (diag_k - cz_{k-1}^2 inv_{k-1}),  luc_k = cz_k inv_k.
layout(std430, binding = 0) readonly buffer Cz { float cz[]; };
layout(std430, binding = 1) readonly buffer Diag { float diag[]; };
layout(std430, binding = 2) writeonly buffer Inv { float inv[]; };
layout(std430, binding = 3) writeonly buffer Luc { float luc[]; };
layout(location = 0) uniform int nx;
layout(location = 1) uniform int ny;
layout(location = 2) uniform int nz;

void main() {
  uint col = ThreadIndex();
  int nxy = nx * ny;
  if (col >= uint(nxy)) return;
  float prev_inv = 0.0, prev_cz = 0.0;
  for (int k = 0; k < nz; ++k) {
    int p = int(col) + nxy * k;
    float d = diag[p] - prev_cz * prev_cz * prev_inv;
    float v = 1.0 / d;
    inv[p] = v;
    luc[p] = cz[p] * v;
    prev_inv = v;
    prev_cz = cz[p];
  }
}
