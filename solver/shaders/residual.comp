// SPDX-License-Identifier: MIT
// mode 0: out = b - A x (residual); mode 1: out = A x (operator application). Batched: x, b
// and out hold one field per work-group z (common.glsl); the coefficients are read once per
// node for all of them by the cache.
// With X_DOUBLE defined, x is double and the sum accumulates in double: the conjugate-gradient
// iterate is kept in double so that its residual can reach 1e-6 (a float iterate stalls at a
// few 1e-6: A amplifies the rounding of x).
layout(std430, binding = 0) readonly buffer Cx { float cx[]; };
layout(std430, binding = 1) readonly buffer Cy { float cy[]; };
layout(std430, binding = 2) readonly buffer Cz { float cz[]; };
layout(std430, binding = 3) readonly buffer Diag { float diag[]; };
#ifdef X_DOUBLE
layout(std430, binding = 4) readonly buffer X { double x[]; };
#define ACC double
#else
layout(std430, binding = 4) readonly buffer X { float x[]; };
#define ACC float
#endif
layout(std430, binding = 5) readonly buffer B { float b[]; };
layout(std430, binding = 6) writeonly buffer Out { float y[]; };
layout(location = 0) uniform int nx;
layout(location = 1) uniform int ny;
layout(location = 2) uniform int nz;
layout(location = 3) uniform int mode;

void main() {
  uint p = ThreadIndex();
  int nxy = nx * ny;
  if (p >= uint(nxy * nz)) return;
  int ip = int(p);
  int i = ip % nx, j = (ip / nx) % ny, k = ip / nxy;
  int o = int(Field()) * nxy * nz + ip;  // this node in this field
  ACC v = ACC(diag[p]) * x[o];
  if (i > 0) v -= ACC(cx[p - 1]) * x[o - 1];
  if (i + 1 < nx) v -= ACC(cx[p]) * x[o + 1];
  if (j > 0) v -= ACC(cy[p - nx]) * x[o - nx];
  if (j + 1 < ny) v -= ACC(cy[p]) * x[o + nx];
  if (k > 0) v -= ACC(cz[p - nxy]) * x[o - nxy];
  if (k + 1 < nz) v -= ACC(cz[p]) * x[o + nxy];
  y[o] = float(mode == 0 ? ACC(b[o]) - v : v);
}
