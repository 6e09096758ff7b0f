// SPDX-License-Identifier: MIT
// mode 0: out = b - A x (residual); mode 1: out = A x (operator application), A in the
// difference form A x_p = sigma_p x_p + sum_q c_pq (x_p - x_q) (assemble.comp; the per-node
// body is multigrid.glsl's ResidualColumn). Batched: x, b and out hold one field per work-group
// z, or four under FIELDS4 (common.glsl); the coefficients are read once per node for all of
// them by the cache. Each
// invocation walks a z-column of kz nodes (Column).
// With X_DOUBLE defined, x is double and the sum accumulates in double: the conjugate-gradient
// iterate is kept in double so that its residual can reach 1e-6 (a float iterate stalls at a
// few 1e-6: A amplifies the rounding of x). Under FIELDS4 its four fields' values are four
// consecutive doubles per node (common.glsl's LDD4). Under QUARTERS (common.glsl) x, b, out and
// the coefficients hold one field's quarter rows, nx the packed width.
COEFS(0, Cx, mg_cx, readonly);
COEFS(1, Cy, mg_cy, readonly);
COEFS(2, Cz, mg_cz, readonly);
COEFS(3, Sigma, mg_sigma, readonly);
#if defined(X_DOUBLE) && defined(FIELDS4)
DOUBLES(4, X, mg_x, readonly);
#define ACC dvec4
#ifdef QUARTERS
#define ACC_C dvec4
#else
#define ACC_C double
#endif
#define LDX LDD4
#elif defined(X_DOUBLE)
DOUBLES(4, X, mg_x, readonly);
#define ACC double
#define ACC_C double
#define LDX LDD
#else
VALUES(4, X, mg_x, readonly);
#endif
VALUES(5, B, mg_b, readonly);
VALUES(6, Out, mg_y, writeonly);
layout(location = 0) uniform int nx;
layout(location = 1) uniform int ny;
layout(location = 2) uniform int nz;
layout(location = 3) uniform int mode;
layout(location = 4) uniform int kz;
#define MG_RESIDUAL
#include "multigrid.glsl"

void main() {
  int i, j, k0, k1;
  if (!Column(nx, ny, nz, kz, i, j, k0, k1)) return;
  int o = int(Field()) * nx * ny * nz;  // offset of this field
  ResidualColumn(MgLevel(nx, ny, nz, 0, 0, 0, 0, 0, 0), i, j, k0, k1, mode, o, o, o);
}
