// SPDX-License-Identifier: MIT
// Adds the gradient of the data term of `fields` conditions (discrete adjoint, SPEC section 4)
// to gk (d/dkappa) and gm (d/dmu), one thread per node p, summing over the conditions m:
//   gk_p -= sum_m sum_{faces (p,q)} A_pq / (2 gap) (psi_p - psi_q)(phi_p - phi_q)
//   gm_p -= sum_m V_p psi_p phi_p
// phi: forward fields, psi: adjoint fields (both double, the solver's iterates), condition m at
// [m n, (m + 1) n), or under FIELDS4 in the solver's packed layout (common.glsl: condition
// 4 g + c is component c of group g's four consecutive doubles per node; padding fields are 0
// and add nothing). geo as in assemble.comp.
FLOATS(0, Geo, geo, readonly);
DOUBLES(1, Phi, phi, readonly);
DOUBLES(2, Psi, psi, readonly);
DOUBLES(3, GK, gk, restrict);
DOUBLES(4, GM, gm, restrict);
layout(location = 0) uniform int nx;
layout(location = 1) uniform int ny;
layout(location = 2) uniform int nz;
layout(location = 3) uniform int fields;

void Node(uint p) {
  int r = Div(int(p), nx), i = int(p) - r * nx, k = Div(r, ny), j = r - k * ny;
  int n = nx * ny * nz, g0 = nx + ny + nz;
  double wx = double(LD(geo, i)), wy = double(LD(geo, nx + j)), wz = double(LD(geo, nx + ny + k));
  // Half the area over the gap of each face (0 on the boundary), with the neighbour's offset.
  double a[6] = double[6](0.0LF, 0.0LF, 0.0LF, 0.0LF, 0.0LF, 0.0LF);
  const int d[6] = int[6](-1, 1, -nx, nx, -nx * ny, nx * ny);
  if (i > 0) a[0] = wy * wz / double(LD(geo, g0 + i - 1));
  if (i + 1 < nx) a[1] = wy * wz / double(LD(geo, g0 + i));
  if (j > 0) a[2] = wx * wz / double(LD(geo, g0 + nx + j - 1));
  if (j + 1 < ny) a[3] = wx * wz / double(LD(geo, g0 + nx + j));
  if (k > 0) a[4] = wx * wy / double(LD(geo, g0 + nx + ny + k - 1));
  if (k + 1 < nz) a[5] = wx * wy / double(LD(geo, g0 + nx + ny + k));
  double g = 0.0LF, v = 0.0LF;
#ifdef FIELDS4
  for (int m = 0; m < (fields + 3) / 4; ++m) {
    int o = m * n + int(p);
    dvec4 sp = LDD4(psi, o), fp = LDD4(phi, o);
    for (int f = 0; f < 6; ++f)
      if (a[f] != 0.0LF) g += a[f] * dot(sp - LDD4(psi, o + d[f]), fp - LDD4(phi, o + d[f]));
    v += dot(sp, fp);
  }
#else
  for (int m = 0; m < fields; ++m) {
    int o = m * n + int(p);
    double sp = LDD(psi, o), fp = LDD(phi, o);
    for (int f = 0; f < 6; ++f)
      if (a[f] != 0.0LF) g += a[f] * (sp - LDD(psi, o + d[f])) * (fp - LDD(phi, o + d[f]));
    v += sp * fp;
  }
#endif
  STD(gk, p, LDD(gk, p) - 0.5LF * g);
  STD(gm, p, LDD(gm, p) - wx * wy * wz * v);
}

void main() {
  for (uint p = ThreadIndex(); p < uint(nx * ny * nz); p += Stride()) Node(p);
}
