// SPDX-License-Identifier: MIT
// LU factors of every z-column's tridiagonal block (Thomas algorithm), one thread per column:
//   inv_k = 1 / (diag_k - cz_{k-1}^2 inv_{k-1}),  luc_k = cz_k inv_k.
FLOATS(0, Cz, cz, readonly);
FLOATS(1, Diag, diag, readonly);
FLOATS(2, Inv, inv, writeonly);
FLOATS(3, Luc, luc, writeonly);
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
    float d = LD(diag, p) - prev_cz * prev_cz * prev_inv, v = 1.0 / d, c = LD(cz, p);
    ST(inv, p, v);
    ST(luc, p, c * v);
    prev_inv = v;
    prev_cz = c;
  }
}
