// SPDX-License-Identifier: MIT
// Adds the gradient of the data term of `fields` conditions (discrete adjoint, SPEC section 4)
// to gk (d/dkappa) and gm (d/dmu), one thread per node p, summing over the conditions m:
//   gk_p -= sum_m sum_{faces (p,q)} A_pq / (2 gap) (psi_p - psi_q)(phi_p - phi_q)
//   gm_p -= sum_m V_p psi_p phi_p
// phi: forward fields, psi: adjoint fields (both double, the solver's iterates), condition m at
// [m n, (m + 1) n). geo as in assemble.comp.
layout(std430, binding = 0) readonly buffer Geo { float geo[]; };
layout(std430, binding = 1) readonly buffer Phi { double phi[]; };
layout(std430, binding = 2) readonly buffer Psi { double psi[]; };
layout(std430, binding = 3) buffer GK { double gk[]; };
layout(std430, binding = 4) buffer GM { double gm[]; };
layout(location = 0) uniform int nx;
layout(location = 1) uniform int ny;
layout(location = 2) uniform int nz;
layout(location = 3) uniform int fields;

double Face(uint p, uint q, double area_over_gap) {  // p, q: offsets into the fields
  return 0.5LF * area_over_gap * (psi[p] - psi[q]) * (phi[p] - phi[q]);
}

void main() {
  uint p = ThreadIndex();
  if (p >= uint(nx * ny * nz)) return;
  int i = int(p) % nx, j = (int(p) / nx) % ny, k = int(p) / (nx * ny);
  uint sx = 1u, sy = uint(nx), sz = uint(nx * ny);
  int g0 = nx + ny + nz;
  double wx = double(geo[i]), wy = double(geo[nx + j]), wz = double(geo[nx + ny + k]);
  double g = 0.0LF, v = 0.0LF;
  for (int m = 0; m < fields; ++m) {
    uint o = uint(m * nx * ny * nz) + p;
    if (i > 0) g += Face(o, o - sx, wy * wz / double(geo[g0 + i - 1]));
    if (i + 1 < nx) g += Face(o, o + sx, wy * wz / double(geo[g0 + i]));
    if (j > 0) g += Face(o, o - sy, wx * wz / double(geo[g0 + nx + j - 1]));
    if (j + 1 < ny) g += Face(o, o + sy, wx * wz / double(geo[g0 + nx + j]));
    if (k > 0) g += Face(o, o - sz, wx * wy / double(geo[g0 + nx + ny + k - 1]));
    if (k + 1 < nz) g += Face(o, o + sz, wx * wy / double(geo[g0 + nx + ny + k]));
    v += psi[o] * phi[o];
  }
  gk[p] -= g;
  gm[p] -= wx * wy * wz * v;
}
