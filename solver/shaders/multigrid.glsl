// SPDX-License-Identifier: MIT
// The per-node bodies of the multigrid kernels, written once for the per-level shaders
// (smooth.comp, residual.comp, restrict_axis.comp, prolong_axis.comp, dense_solve.comp: one
// dispatch per step and level) and the coarse tail (tail.comp: every step of every small level
// in one dispatch). A shader pulls this file in with `#include "multigrid.glsl"` (gl_solver.cc's
// CompileProgram splices it in) after declaring the arrays (FLOATS / INTS, common.glsl) that the
// parts it enables read, all named with an mg_ prefix:
//   MG_SMOOTH    mg_cx, mg_cy, mg_cz, mg_inv, mg_luc, mg_b, mg_x   (SmoothColumn, SmoothLine)
//   MG_RESIDUAL  mg_cx, mg_cy, mg_cz, mg_sigma, mg_x, mg_b, mg_y   (ResidualColumn)
//   MG_RESTRICT  mg_src, mg_gstart, mg_gidx, mg_gw                 (RestrictValue)
//   MG_PROLONG   mg_src, mg_lohi, mg_w                             (ProlongValue)
//   MG_DENSE     mg_minv, mg_b                                     (DenseRow)
// Every array is addressed with an offset, so the arrays may be the level's own buffers
// (offsets 0) or a few packed buffers holding several levels (tail.comp aliases the names to
// them with #define; the prefix keeps those macros off other identifiers).

// Where a level's coefficients are: its shape and the offsets of its cx, cy, cz, inv, luc and
// sigma values in their arrays (node p of the level at offset + p).
struct MgLevel {
  int nx, ny, nz, cx, cy, cz, inv, luc, sigma;
};

#ifdef MG_SMOOTH
// Column t of a zebra half-sweep of colour `color`: (i, j) with (i + j) % 2 == color, t running
// over ((nx + 1) / 2) ny columns; false past the last one.
bool SmoothColumn(int t, int nx, int ny, int color, out int i, out int j) {
  int half_nx = (nx + 1) / 2;
  j = Div(t, half_nx);
  i = 2 * (t - j * half_nx) + ((color + j) & 1);
  return j < ny && i < nx;
}

// Z-line Gauss-Seidel on column (i, j): solves its tridiagonal z-system exactly with the
// neighbouring columns held fixed (the line factors inv, luc from factor.comp). b0 and x0: the
// offsets of this field's level values in b and x. x holds d' between the two passes; the
// value of the node below (forward) or above (backward) is carried in a register.
void SmoothLine(MgLevel L, int i, int j, int b0, int x0) {
  int nx = L.nx, ny = L.ny, nz = L.nz, nxy = nx * ny;
  float below = 0.0, cz_below = 0.0;
  int p = i + nx * j;
  for (int k = 0; k < nz; ++k, p += nxy) {
    int q = x0 + p;
    float d = LD(mg_b, b0 + p) + cz_below * below;
    if (i > 0) d += LD(mg_cx, L.cx + p - 1) * LD(mg_x, q - 1);
    if (i + 1 < nx) d += LD(mg_cx, L.cx + p) * LD(mg_x, q + 1);
    if (j > 0) d += LD(mg_cy, L.cy + p - nx) * LD(mg_x, q - nx);
    if (j + 1 < ny) d += LD(mg_cy, L.cy + p) * LD(mg_x, q + nx);
    below = d * LD(mg_inv, L.inv + p);
    ST(mg_x, q, below);
    cz_below = LD(mg_cz, L.cz + p);
  }
  float above = below;
  p -= 2 * nxy;
  for (int k = nz - 2; k >= 0; --k, p -= nxy) {
    above = LD(mg_x, x0 + p) + LD(mg_luc, L.luc + p) * above;
    ST(mg_x, x0 + p, above);
  }
}
#endif

#ifdef MG_RESIDUAL
#ifndef ACC
#define ACC float
#define LDX LD
#endif
// Nodes k0 .. k1 - 1 of column (i, j) (common.glsl's Column): mode 0: y = b - A x (residual),
// mode 1: y = A x, A in the difference form A x_p = sigma_p x_p + sum_q c_pq (x_p - x_q)
// (assemble.comp). x0, b0, y0: this field's level offsets in x, b and y. x and cz of the node
// below are carried in registers. ACC is the accumulator type and LDX loads x (float and LD
// unless the shader defines them: residual.comp's X_DOUBLE).
void ResidualColumn(MgLevel L, int i, int j, int k0, int k1, int mode, int x0, int b0, int y0) {
  int nx = L.nx, ny = L.ny, nz = L.nz, nxy = nx * ny;
  int p = i + nx * j + nxy * k0;
  ACC xm = 0.0, czm = 0.0;  // x and cz of the node below
  if (k0 > 0) {
    xm = LDX(mg_x, x0 + p - nxy);
    czm = ACC(LD(mg_cz, L.cz + p - nxy));
  }
  ACC xc = LDX(mg_x, x0 + p);
  for (int k = k0; k < k1; ++k, p += nxy) {
    int o = x0 + p;  // this node in this field
    ACC xp = k + 1 < nz ? LDX(mg_x, o + nxy) : ACC(0.0);
    ACC czp = ACC(LD(mg_cz, L.cz + p));
    ACC v = ACC(LD(mg_sigma, L.sigma + p)) * xc + czm * (xc - xm) + czp * (xc - xp);
    if (i > 0) v += ACC(LD(mg_cx, L.cx + p - 1)) * (xc - LDX(mg_x, o - 1));
    if (i + 1 < nx) v += ACC(LD(mg_cx, L.cx + p)) * (xc - LDX(mg_x, o + 1));
    if (j > 0) v += ACC(LD(mg_cy, L.cy + p - nx)) * (xc - LDX(mg_x, o - nx));
    if (j + 1 < ny) v += ACC(LD(mg_cy, L.cy + p)) * (xc - LDX(mg_x, o + nx));
    ST(mg_y, y0 + p, float(mode == 0 ? ACC(LD(mg_b, b0 + p)) - v : v));
    xm = xc;
    xc = xp;
    czm = czp;
  }
}
#endif

#ifdef MG_RESTRICT
// Restriction (transpose of linear interpolation) along one axis, `outer` blocks of n_in nodes
// of `inner` contiguous values in, blocks of n_out nodes out: value e of the output. Coarse node
// c gathers fine nodes gidx[gstart[c] .. gstart[c + 1]) with weights gw
// (solver/multigrid_hierarchy.h). in0: this field's offset in src; gs0, gi0, gw0: the axis'
// offsets in gstart, gidx and gw (gstart's entries count from gi0 / gw0).
float RestrictValue(int e, int n_in, int n_out, int inner, int in0, int gs0, int gi0, int gw0) {
  int ec = Div(e, inner), v = e - ec * inner, o = Div(ec, n_out), c = ec - o * n_out;
  int base = in0 + o * n_in * inner + v;
  float s = 0.0;
  for (int g = LD(mg_gstart, gs0 + c); g < LD(mg_gstart, gs0 + c + 1); ++g)
    s += LD(mg_gw, gw0 + g) * LD(mg_src, base + LD(mg_gidx, gi0 + g) * inner);
  return s;
}
#endif

#ifdef MG_PROLONG
// Linear interpolation along one axis from n_in coarse to n_out fine nodes (`outer` blocks of
// `inner` contiguous values): value e of the output, fine node f being
// w[2f] coarse[lohi[2f]] + w[2f+1] coarse[lohi[2f+1]]. in0: this field's offset in src; lh0,
// w0: the axis' offsets in lohi and w.
float ProlongValue(int e, int n_in, int n_out, int inner, int in0, int lh0, int w0) {
  int ef = Div(e, inner), v = e - ef * inner, o = Div(ef, n_out), f = ef - o * n_out;
  int base = in0 + o * n_in * inner + v;
  return LD(mg_w, w0 + 2 * f) * LD(mg_src, base + LD(mg_lohi, lh0 + 2 * f) * inner) +
         LD(mg_w, w0 + 2 * f + 1) * LD(mg_src, base + LD(mg_lohi, lh0 + 2 * f + 1) * inner);
}
#endif

#ifdef MG_DENSE
// Row i of x = M b, M (n x n, row-major at m0 in minv) the explicit inverse of the coarsest
// operator; b0: this field's offset in b. Double sums.
float DenseRow(int i, int n, int m0, int b0) {
  double s = 0.0LF;
  for (int j = 0; j < n; ++j) s += double(LD(mg_minv, m0 + i * n + j)) * double(LD(mg_b, b0 + j));
  return float(s);
}
#endif
