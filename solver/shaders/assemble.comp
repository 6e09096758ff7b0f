// SPDX-License-Identifier: MIT
// The canonical operator of SPEC section 3 as a 7-point stencil (solver/stencil.h): one thread
// per node p computes its face conductances towards +x, +y, +z,
//   c = A_face (kappa_p + kappa_q) / 2 / gap,
// and its diagonal: the six conductances + V_p mu_p + boundary box faces / (2 C) (the
// smoother's line factors and the coarsest level's inverse use it), and sigma = V_p mu_p +
// boundary box faces / (2 C) alone: residual.comp applies A in the difference form
// sigma_p x_p + sum_q c_pq (x_p - x_q), where the float rounding of each coefficient stays
// relative to its own term (the diagonal's rounding, ~1e-7 of it, is ~1e-3 of the absorption
// term where mu h^2 / kappa ~ 1e-4).
// geo holds the level's dual-box widths wx[nx] wy[ny] wz[nz], then the gaps gx[nx] gy[ny] gz[nz]
// (gap i is between node i and i + 1; the last is unused).
FLOATS(0, Kappa, kappa, readonly);
FLOATS(1, Mu, mu, readonly);
FLOATS(2, Geo, geo, readonly);
FLOATS(3, Cx, cx, writeonly);
FLOATS(4, Cy, cy, writeonly);
FLOATS(5, Cz, cz, writeonly);
FLOATS(6, Diag, diag, writeonly);
FLOATS(7, Sigma, sigma, writeonly);
layout(location = 0) uniform int nx;
layout(location = 1) uniform int ny;
layout(location = 2) uniform int nz;
layout(location = 3) uniform float robin;  // 1 / (2 C)

float Conductance(float area_over_gap, float ka, float kb) { return 0.5 * area_over_gap * (ka + kb); }

void Node(uint p) {
  int r = Div(int(p), nx), i = int(p) - r * nx, k = Div(r, ny), j = r - k * ny;
  int nxy = nx * ny, g0 = nx + ny + nz;
  float wx = LD(geo, i), wy = LD(geo, nx + j), wz = LD(geo, nx + ny + k);
  float kp = LD(kappa, p);
  float sx = 0.0, sy = 0.0, sz = 0.0;
  float cxp = 0.0, cyp = 0.0, czp = 0.0;
  if (i + 1 < nx) { cxp = Conductance(wy * wz / LD(geo, g0 + i), kp, LD(kappa, p + 1)); }
  if (i > 0) sx = Conductance(wy * wz / LD(geo, g0 + i - 1), LD(kappa, p - 1), kp);
  if (j + 1 < ny) { cyp = Conductance(wx * wz / LD(geo, g0 + nx + j), kp, LD(kappa, p + nx)); }
  if (j > 0) sy = Conductance(wx * wz / LD(geo, g0 + nx + j - 1), LD(kappa, p - nx), kp);
  if (k + 1 < nz) { czp = Conductance(wx * wy / LD(geo, g0 + nx + ny + k), kp, LD(kappa, p + nxy)); }
  if (k > 0) sz = Conductance(wx * wy / LD(geo, g0 + nx + ny + k - 1), LD(kappa, p - nxy), kp);
  float bx = float(i == 0) + float(i == nx - 1);
  float by = float(j == 0) + float(j == ny - 1);
  float bz = float(k == 0) + float(k == nz - 1);
  ST(cx, p, cxp);
  ST(cy, p, cyp);
  ST(cz, p, czp);
  float self = wx * wy * wz * LD(mu, p) + robin * (bx * wy * wz + by * wx * wz + bz * wx * wy);
  ST(sigma, p, self);
  ST(diag, p, self + cxp + cyp + czp + sx + sy + sz);
}

void main() {
  for (uint p = ThreadIndex(); p < uint(nx * ny * nz); p += Stride()) Node(p);
}
