// SPDX-License-Identifier: MIT
// One half-sweep of red-black (zebra) z-line Gauss-Seidel on one level: every column (i, j)
// with (i + j) % 2 == color solves its tridiagonal z-system exactly, the neighbouring columns
// (the other colour) held fixed (multigrid.glsl's SmoothLine). One column per invocation.
// Batched: b and x hold one field per work-group z, or four under FIELDS4 (common.glsl); under
// QUARTERS one field's quarter rows (common.glsl), nx the packed width.
COEFS(0, Cx, mg_cx, readonly);
COEFS(1, Cy, mg_cy, readonly);
COEFS(2, Cz, mg_cz, readonly);
#ifdef MG_LINE_PCR
COEFS(3, Diag, mg_diag, readonly);  // the full diagonal (MgLevel's inv offset)
#else
COEFS(3, Inv, mg_inv, readonly);
#endif
COEFS(4, Luc, mg_luc, readonly);
VALUES(5, B, mg_b, readonly);
VALUES(6, X, mg_x, restrict);
layout(location = 0) uniform int nx;
layout(location = 1) uniform int ny;
layout(location = 2) uniform int nz;
layout(location = 3) uniform int color;
layout(location = 4) uniform int pcr_p;  // MG_LINE_PCR: invocations per column
#define MG_SMOOTH
#include "multigrid.glsl"

void main() {
#ifdef MG_LINE_PCR
  int t = int(ThreadIndex()), col = Div(t, pcr_p), i, j;
  bool valid = SmoothColumn(col, nx, ny, color, i, j);
  int o = int(Field()) * nx * ny * nz;
  SmoothLinePcr(MgLevel(nx, ny, nz, 0, 0, 0, 0, 0, 0), valid, i, j, t - col * pcr_p, pcr_p, o, o);
#else
  int i, j;
  if (!SmoothColumn(int(ThreadIndex()), nx, ny, color, i, j)) return;
  int o = int(Field()) * nx * ny * nz;  // offset of this field
  SmoothLine(MgLevel(nx, ny, nz, 0, 0, 0, 0, 0, 0), i, j, o, o);
#endif
}
