// SPDX-License-Identifier: MIT
// The canonical operator of SPEC section 3 as a 7-point stencil (solver/stencil.h): one thread
// per node p computes its face conductances towards +x, +y, +z,
//   c = A_face (kappa_p + kappa_q) / 2 / gap,
// and its diagonal: the six conductances + V_p mu_p + boundary box faces / (2 C).
// geo holds the level's dual-box widths wx[nx] wy[ny] wz[nz], then the gaps gx[nx] gy[ny] gz[nz]
// (gap i is between node i and i + 1; the last is unused).
layout(std430, binding = 0) readonly buffer Kappa { float kappa[]; };
layout(std430, binding = 1) readonly buffer Mu { float mu[]; };
layout(std430, binding = 2) readonly buffer Geo { float geo[]; };
layout(std430, binding = 3) writeonly buffer Cx { float cx[]; };
layout(std430, binding = 4) writeonly buffer Cy { float cy[]; };
layout(std430, binding = 5) writeonly buffer Cz { float cz[]; };
layout(std430, binding = 6) writeonly buffer Diag { float diag[]; };
layout(location = 0) uniform int nx;
layout(location = 1) uniform int ny;
layout(location = 2) uniform int nz;
layout(location = 3) uniform float robin;  // 1 / (2 C)

float Conductance(float area_over_gap, float ka, float kb) { return 0.5 * area_over_gap * (ka + kb); }

void main() {
  uint p = ThreadIndex();
  if (p >= uint(nx * ny * nz)) return;
  int i = int(p) % nx, j = (int(p) / nx) % ny, k = int(p) / (nx * ny);
  int nxy = nx * ny, g0 = nx + ny + nz;
  float wx = geo[i], wy = geo[nx + j], wz = geo[nx + ny + k];
  float kp = kappa[p];
  float sx = 0.0, sy = 0.0, sz = 0.0;
  float cxp = 0.0, cyp = 0.0, czp = 0.0;
  if (i + 1 < nx) { cxp = Conductance(wy * wz / geo[g0 + i], kp, kappa[p + 1]); }
  if (i > 0) sx = Conductance(wy * wz / geo[g0 + i - 1], kappa[p - 1], kp);
  if (j + 1 < ny) { cyp = Conductance(wx * wz / geo[g0 + nx + j], kp, kappa[p + nx]); }
  if (j > 0) sy = Conductance(wx * wz / geo[g0 + nx + j - 1], kappa[p - nx], kp);
  if (k + 1 < nz) { czp = Conductance(wx * wy / geo[g0 + nx + ny + k], kp, kappa[p + nxy]); }
  if (k > 0) sz = Conductance(wx * wy / geo[g0 + nx + ny + k - 1], kappa[p - nxy], kp);
  float bx = float(i == 0) + float(i == nx - 1);
  float by = float(j == 0) + float(j == ny - 1);
  float bz = float(k == 0) + float(k == nz - 1);
  cx[p] = cxp;
  cy[p] = cyp;
  cz[p] = czp;
  diag[p] = wx * wy * wz * mu[p] + robin * (bx * wy * wz + by * wx * wz + bz * wx * wy) +
            cxp + cyp + czp + sx + sy + sz;
}
