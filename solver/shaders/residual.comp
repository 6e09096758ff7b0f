// SPDX-License-Identifier: MIT
// mode 0: out = b - A x (residual); mode 1: out = A x (operator application), A in the
// difference form A x_p = sigma_p x_p + sum_q c_pq (x_p - x_q) (assemble.comp). Batched: x, b
// and out hold one field per work-group z (common.glsl); the coefficients are read once per
// node for all of them by the cache. Each invocation walks a z-column of kz nodes (Column),
// carrying x and cz of the node below in registers.
// With X_DOUBLE defined, x is double and the sum accumulates in double: the conjugate-gradient
// iterate is kept in double so that its residual can reach 1e-6 (a float iterate stalls at a
// few 1e-6: A amplifies the rounding of x).
FLOATS(0, Cx, cx, readonly);
FLOATS(1, Cy, cy, readonly);
FLOATS(2, Cz, cz, readonly);
FLOATS(3, Sigma, sigma, readonly);
#ifdef X_DOUBLE
DOUBLES(4, X, x, readonly);
#define ACC double
#define LDX LDD
#else
FLOATS(4, X, x, readonly);
#define ACC float
#define LDX LD
#endif
FLOATS(5, B, b, readonly);
FLOATS(6, Out, y, writeonly);
layout(location = 0) uniform int nx;
layout(location = 1) uniform int ny;
layout(location = 2) uniform int nz;
layout(location = 3) uniform int mode;
layout(location = 4) uniform int kz;

void main() {
  int i, j, k0, k1;
  if (!Column(nx, ny, nz, kz, i, j, k0, k1)) return;
  int nxy = nx * ny, f0 = int(Field()) * nxy * nz;  // offset of this field
  int p = i + nx * j + nxy * k0;
  ACC xm = 0.0, czm = 0.0;  // x and cz of the node below
  if (k0 > 0) {
    xm = LDX(x, f0 + p - nxy);
    czm = ACC(LD(cz, p - nxy));
  }
  ACC xc = LDX(x, f0 + p);
  for (int k = k0; k < k1; ++k, p += nxy) {
    int o = f0 + p;  // this node in this field
    ACC xp = k + 1 < nz ? LDX(x, o + nxy) : ACC(0.0);
    ACC czp = ACC(LD(cz, p));
    ACC v = ACC(LD(sigma, p)) * xc + czm * (xc - xm) + czp * (xc - xp);
    if (i > 0) v += ACC(LD(cx, p - 1)) * (xc - LDX(x, o - 1));
    if (i + 1 < nx) v += ACC(LD(cx, p)) * (xc - LDX(x, o + 1));
    if (j > 0) v += ACC(LD(cy, p - nx)) * (xc - LDX(x, o - nx));
    if (j + 1 < ny) v += ACC(LD(cy, p)) * (xc - LDX(x, o + nx));
    ST(y, o, float(mode == 0 ? ACC(LD(b, o)) - v : v));
    xm = xc;
    xc = xp;
    czm = czp;
  }
}
