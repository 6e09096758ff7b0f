// SPDX-License-Identifier: MIT
// The per-node bodies of the multigrid kernels, written once for the per-level shaders
// (smooth.comp, residual.comp, transfer.comp, dense_solve.comp: one
// dispatch per step and level) and the coarse tail (tail.comp: every step of every small level
// in one dispatch). A shader pulls this file in with `#include "multigrid.glsl"` (gl_solver.cc's
// CompileProgram splices it in) after declaring the arrays (FLOATS / INTS, common.glsl) that the
// parts it enables read, all named with an mg_ prefix:
//   MG_SMOOTH    mg_cx, mg_cy, mg_cz, mg_inv, mg_luc, mg_b, mg_x   (SmoothColumn, SmoothLine)
//   MG_RESIDUAL  mg_cx, mg_cy, mg_cz, mg_sigma, mg_x, mg_b, mg_y   (ResidualColumn)
//   MG_TRANSFER  mg_src, mg_idx (int), mg_wts                      (Restrict3Value, Prolong3Value)
//   MG_DENSE     mg_minv, mg_b                                     (DenseRow)
// Every array is addressed with an offset, so the arrays may be the level's own buffers
// (offsets 0) or a few packed buffers holding several levels (tail.comp aliases the names to
// them with #define; the prefix keeps those macros off other identifiers).
//
// The field values (mg_b, mg_x, mg_y, mg_src) are MG_VALUE, loaded with MG_LDV: float and LD
// (one field per value), or vec4 and LD4 under FIELDS4 (common.glsl: four fields per node, so
// that the coefficients and transfer weights, read once, serve all four). MG_DVALUE is the
// matching double type.

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
//
// MG_LINE_BLOCK (Tuning::line_block, default 1): with B > 1 each pass walks the column in
// blocks of B nodes, first loading the block's values (none depends on the recurrence, so the
// loads are in flight together), then running the recurrence over them in registers. A column
// is a serial chain of nz nodes, and one invocation per column leaves a GPU mostly idle, so
// one memory round trip per node made the smoother latency-bound (docs/gpu.md); blocks make it
// one per B nodes. The same sums, except that the forward pass adds the node below last
// (B = 1 adds it first).
#ifndef MG_LINE_BLOCK
#define MG_LINE_BLOCK 1
#endif
// d plus the terms of node p's x- and y-neighbours (q: p's offset in x), added in this order.
MG_VALUE AddLineNeighbours(MgLevel L, int i, int j, int p, int q, MG_VALUE d) {
  int nx = L.nx, ny = L.ny;
  if (i > 0) d += LDC(mg_cx, L.cx + p - 1) * MG_LDV(mg_x, q - 1);
#ifdef QUARTERS
  else d += FromLeft(LDC(mg_cx, L.cx + p + nx - 1)) * FromLeft(MG_LDV(mg_x, q + nx - 1));
#endif
  if (i + 1 < nx) d += LDC(mg_cx, L.cx + p) * MG_LDV(mg_x, q + 1);
#ifdef QUARTERS
  else d += LDC(mg_cx, L.cx + p) * FromRight(MG_LDV(mg_x, q - (nx - 1)));
#endif
  if (j > 0) d += LDC(mg_cy, L.cy + p - nx) * MG_LDV(mg_x, q - nx);
  if (j + 1 < ny) d += LDC(mg_cy, L.cy + p) * MG_LDV(mg_x, q + nx);
  return d;
}

#ifndef MG_LINE_PCR  // (smooth.comp binds the diagonal instead of the factors)
void SmoothLine(MgLevel L, int i, int j, int b0, int x0) {
  int nx = L.nx, nz = L.nz, nxy = nx * L.ny;
  MG_VALUE below = MG_VALUE(0.0);
  MG_COEF cz_below = MG_COEF(0.0);
  int p0 = i + nx * j;
#if MG_LINE_BLOCK > 1
  const int kBlock = MG_LINE_BLOCK;
  for (int k0 = 0; k0 < nz; k0 += kBlock) {
    MG_VALUE d[kBlock];
    MG_COEF inv[kBlock], cz[kBlock];
    for (int u = 0; u < kBlock; ++u) {
      int p = p0 + (k0 + u) * nxy;
      if (k0 + u < nz) {
        d[u] = AddLineNeighbours(L, i, j, p, x0 + p, MG_LDV(mg_b, b0 + p));
        inv[u] = LDC(mg_inv, L.inv + p);
        cz[u] = LDC(mg_cz, L.cz + p);
      }
    }
    for (int u = 0; u < kBlock; ++u) {
      if (k0 + u < nz) {
        below = (d[u] + cz_below * below) * inv[u];
        ST(mg_x, x0 + p0 + (k0 + u) * nxy, below);
        cz_below = cz[u];
      }
    }
  }
  MG_VALUE above = below;
  for (int k0 = nz - 2; k0 >= 0; k0 -= kBlock) {
    MG_VALUE xv[kBlock];
    MG_COEF luc[kBlock];
    for (int u = 0; u < kBlock; ++u) {
      int p = p0 + (k0 - u) * nxy;
      if (k0 - u >= 0) {
        xv[u] = MG_LDV(mg_x, x0 + p);
        luc[u] = LDC(mg_luc, L.luc + p);
      }
    }
    for (int u = 0; u < kBlock; ++u) {
      if (k0 - u >= 0) {
        above = xv[u] + luc[u] * above;
        ST(mg_x, x0 + p0 + (k0 - u) * nxy, above);
      }
    }
  }
#else
  int p = p0;
  for (int k = 0; k < nz; ++k, p += nxy) {
    int q = x0 + p;
    MG_VALUE d = AddLineNeighbours(L, i, j, p, q, MG_LDV(mg_b, b0 + p) + cz_below * below);
    below = d * LDC(mg_inv, L.inv + p);
    ST(mg_x, q, below);
    cz_below = LDC(mg_cz, L.cz + p);
  }
  MG_VALUE above = below;
  p -= 2 * nxy;
  for (int k = nz - 2; k >= 0; --k, p -= nxy) {
    above = MG_LDV(mg_x, x0 + p) + LDC(mg_luc, L.luc + p) * above;
    ST(mg_x, x0 + p, above);
  }
#endif
}
#endif  // MG_LINE_PCR
#endif

#ifdef MG_LINE_PCR
// The same z-line solve by parallel cyclic reduction (Tuning::line_pcr, smooth.comp's
// MG_LINE_PCR): one invocation per node, P (a power of two >= nz, dividing TL_GROUP)
// invocations per column, a column's invocations in one work group. Each loads its node's row
// of the column's tridiagonal system
//   a_k x_{k-1} + d_k x_k + c_k x_{k+1} = r_k,  a_k = -cz_{k-1}, c_k = -cz_k, d_k = diag_k,
//   r_k = b_k + the x- and y-neighbours' terms (AddLineNeighbours),
// (rows k >= nz: the identity, 0 = x_k), then log2 P steps each eliminate the rows s = 1, 2,
// 4, ... away: with alpha = -a_k / d_{k-s}, gamma = -c_k / d_{k+s},
//   a_k <- alpha a_{k-s},  c_k <- gamma c_{k+s},
//   d_k <- d_k + alpha c_{k-s} + gamma a_{k+s},  r_k <- r_k + alpha r_{k-s} + gamma r_{k+s},
// after which every row is decoupled: x_k = r_k / d_k. Exact (up to rounding) like the Thomas
// algorithm of SmoothLine, and stable for this diagonally dominant system; the column's loads
// are all issued at once and its serial chain is log2 P steps in shared memory instead of 2 nz
// dependent memory round trips (docs/gpu.md). valid: the invocation's column exists (SmoothColumn).
shared float pcr_a[TL_GROUP], pcr_c[TL_GROUP], pcr_d[TL_GROUP];
shared MG_VALUE pcr_r[TL_GROUP];
void SmoothLinePcr(MgLevel L, bool valid, int i, int j, int k, int P, int b0, int x0) {
  int nxy = L.nx * L.ny, p = i + L.nx * j + nxy * k, lid = int(gl_LocalInvocationID.x), kk = lid % P;
  bool node = valid && k < L.nz;
  float a = 0.0, c = 0.0, d = 1.0;
  MG_VALUE r = MG_VALUE(0.0);
  if (node) {
    r = AddLineNeighbours(L, i, j, p, x0 + p, MG_LDV(mg_b, b0 + p));
    d = LDC(mg_diag, L.inv + p);
    if (k > 0) a = -LDC(mg_cz, L.cz + p - nxy);
    if (k + 1 < L.nz) c = -LDC(mg_cz, L.cz + p);
  }
  for (int s = 1; s < P; s *= 2) {
    pcr_a[lid] = a;
    pcr_c[lid] = c;
    pcr_d[lid] = d;
    pcr_r[lid] = r;
    memoryBarrierShared();
    barrier();
    float a2 = 0.0, c2 = 0.0;
    if (kk >= s) {
      float alpha = -a / pcr_d[lid - s];
      a2 = alpha * pcr_a[lid - s];
      d += alpha * pcr_c[lid - s];
      r += alpha * pcr_r[lid - s];
    }
    if (kk + s < P) {
      float gamma = -c / pcr_d[lid + s];
      c2 = gamma * pcr_c[lid + s];
      d += gamma * pcr_a[lid + s];
      r += gamma * pcr_r[lid + s];
    }
    a = a2;
    c = c2;
    barrier();
  }
  if (node) ST(mg_x, x0 + p, r / d);
}
#endif

#ifdef MG_RESIDUAL
#ifndef ACC
#define ACC MG_VALUE
#define ACC_C MG_COEF
#define LDX MG_LDV
#endif
// Nodes k0 .. k1 - 1 of column (i, j) (common.glsl's Column): mode 0: y = b - A x (residual),
// mode 1: y = A x, A in the difference form A x_p = sigma_p x_p + sum_q c_pq (x_p - x_q)
// (assemble.comp). x0, b0, y0: this field's level offsets in x, b and y. x and cz of the node
// below are carried in registers. ACC is the accumulator type, ACC_C the coefficients' type
// in its sums and LDX loads x (MG_VALUE, MG_COEF and MG_LDV unless the shader defines them:
// residual.comp's X_DOUBLE).
void ResidualColumn(MgLevel L, int i, int j, int k0, int k1, int mode, int x0, int b0, int y0) {
  int nx = L.nx, ny = L.ny, nz = L.nz, nxy = nx * ny;
  int p = i + nx * j + nxy * k0;
  ACC xm = ACC(0.0);  // x and cz of the node below
  ACC_C czm = ACC_C(0.0);
  if (k0 > 0) {
    xm = LDX(mg_x, x0 + p - nxy);
    czm = ACC_C(LDC(mg_cz, L.cz + p - nxy));
  }
  ACC xc = LDX(mg_x, x0 + p);
  for (int k = k0; k < k1; ++k, p += nxy) {
    int o = x0 + p;  // this node in this field
    ACC xp = k + 1 < nz ? LDX(mg_x, o + nxy) : ACC(0.0);
    ACC_C czp = ACC_C(LDC(mg_cz, L.cz + p));
    ACC v = ACC_C(LDC(mg_sigma, L.sigma + p)) * xc + czm * (xc - xm) + czp * (xc - xp);
    if (i > 0) v += ACC_C(LDC(mg_cx, L.cx + p - 1)) * (xc - LDX(mg_x, o - 1));
#ifdef QUARTERS
    else v += ACC_C(FromLeft(LDC(mg_cx, L.cx + p + nx - 1))) * (xc - FromLeft(LDX(mg_x, o + nx - 1)));
#endif
    if (i + 1 < nx) v += ACC_C(LDC(mg_cx, L.cx + p)) * (xc - LDX(mg_x, o + 1));
#ifdef QUARTERS
    else v += ACC_C(LDC(mg_cx, L.cx + p)) * (xc - FromRight(LDX(mg_x, o - (nx - 1))));
#endif
    if (j > 0) v += ACC_C(LDC(mg_cy, L.cy + p - nx)) * (xc - LDX(mg_x, o - nx));
    if (j + 1 < ny) v += ACC_C(LDC(mg_cy, L.cy + p)) * (xc - LDX(mg_x, o + nx));
    ST(mg_y, y0 + p, MG_VALUE(mode == 0 ? ACC(MG_LDV(mg_b, b0 + p)) - v : v));
    xm = xc;
    xc = xp;
    czm = czp;
  }
}
#endif

#ifdef MG_TRANSFER
// The whole transfer between level l and l + 1 (the cpu solver's three separable axis passes,
// multigrid_hierarchy.h, nested in one loop: the same products summed in the same order).
// mg_idx holds a metadata row of kMgMeta ints per level (gl_solver.cc's Impl::PackLevels): nx, ny,
// nz, the tail's offsets (tail.comp), and from kMgAxis on per axis a 7 ints: n_fine, n_coarse,
// the offsets in mg_idx of gstart and gidx, of gw in mg_wts, of lohi in mg_idx and of w in
// mg_wts. Coarse node c of an axis gathers fine nodes gidx[gstart[c] .. gstart[c + 1]) (gstart
// counting from the axis' gidx and gw); fine node f interpolates coarse lohi[2f], lohi[2f+1]
// with weights w[2f], w[2f+1].
const int kMgMeta = 36, kMgAxis = 14;
struct MgAxis {
  int n_fine, n_coarse, gstart, gidx, gw, lohi, w;
};
int MgMeta(int l, int k) { return LD(mg_idx, l * kMgMeta + k); }
MgAxis MgLoadAxis(int l, int a) {
  int m = l * kMgMeta + kMgAxis + 7 * a;
  return MgAxis(LD(mg_idx, m), LD(mg_idx, m + 1), LD(mg_idx, m + 2), LD(mg_idx, m + 3),
                LD(mg_idx, m + 4), LD(mg_idx, m + 5), LD(mg_idx, m + 6));
}

// The fine nodes that coarse node c of axis A gathers, with their weights: loaded once per
// output value and axis, so the nested sums below read only values (at most kMgTaps per axis:
// 3 where the axis is regular, 4 beside a coarse interval of three fine ones; gl_solver.cc's
// PackLevels checks).
const int kMgTaps = 4;
struct MgTaps {
  int n;
  int f[kMgTaps];
  float w[kMgTaps];
};
MgTaps MgGather(MgAxis A, int c) {
  MgTaps t;
  int g0 = LD(mg_idx, A.gstart + c);
  t.n = LD(mg_idx, A.gstart + c + 1) - g0;
  for (int g = 0; g < t.n; ++g) {
    t.f[g] = LD(mg_idx, A.gidx + g0 + g);
    t.w[g] = LD(mg_wts, A.gw + g0 + g);
  }
  return t;
}

// The fine rows' stride, and the fine value of x-tap g of t in the fine row starting at r: the
// level's own layout, or under MG_FINE_QUARTERS (transfer.comp) its quarter rows of mg_qw
// (common.glsl's QUARTERS), where MgQuarterTaps has made each tap an offset in the packed row
// and a component.
#ifdef MG_FINE_QUARTERS
#define MG_FINE_NX(X) mg_qw
#define MG_FINE_VALUE(r, t, q, g) LD4(mg_src, (r) + (t).f[g])[q[g]]
void MgQuarterTaps(inout MgTaps t, out int q[kMgTaps]) {
  for (int g = 0; g < t.n; ++g) {
    q[g] = Div(t.f[g], mg_qw);
    t.f[g] -= q[g] * mg_qw;
  }
}
#else
#define MG_FINE_NX(X) X.n_fine
#define MG_FINE_VALUE(r, t, q, g) MG_LDV(mg_src, (r) + (t).f[g])
#endif

// Restriction R = P^T: coarse node e (of X.n_coarse Y.n_coarse Z.n_coarse) from the fine
// values at in0 (X.n_fine Y.n_fine Z.n_fine of them).
MG_VALUE Restrict3Value(int e, MgAxis X, MgAxis Y, MgAxis Z, int in0) {
  int mxy = X.n_coarse * Y.n_coarse, ck = Div(e, mxy), r = e - ck * mxy, cj = Div(r, X.n_coarse);
  int ci = r - cj * X.n_coarse, nx = MG_FINE_NX(X), nxy = nx * Y.n_fine;
  MgTaps tx = MgGather(X, ci), ty = MgGather(Y, cj), tz = MgGather(Z, ck);
  int tq[kMgTaps];
#ifdef MG_FINE_QUARTERS
  MgQuarterTaps(tx, tq);
#endif
  MG_VALUE s = MG_VALUE(0.0);
  for (int gz = 0; gz < tz.n; ++gz) {
    int kz = in0 + nxy * tz.f[gz];
    MG_VALUE sy = MG_VALUE(0.0);
    for (int gy = 0; gy < ty.n; ++gy) {
      int jy = kz + nx * ty.f[gy];
      MG_VALUE sx = MG_VALUE(0.0);
      for (int gx = 0; gx < tx.n; ++gx) sx += tx.w[gx] * MG_FINE_VALUE(jy, tx, tq, gx);
      sy += ty.w[gy] * sx;
    }
    s += tz.w[gz] * sy;
  }
  return s;
}

#ifndef MG_FINE_QUARTERS  // (there mg_src is the fine level, in quarter rows)
// Prolongation P (trilinear): fine node e (of X.n_fine Y.n_fine Z.n_fine) from the coarse
// values at in0. In two parts, so that the nodes of a row share the y and z part (MgRow: the
// coarse rows' offsets and weights for fine row j, plane k) and only the x part is per node.
struct MgRow {
  int cy[2];
  int z0, z1;
  float wy0, wy1, wz0, wz1;
};
MgRow ProlongRow(int j, int k, MgAxis X, MgAxis Y, MgAxis Z) {
  int mxy = X.n_coarse * Y.n_coarse;
  MgRow row;
  row.cy = int[2](LD(mg_idx, Y.lohi + 2 * j), LD(mg_idx, Y.lohi + 2 * j + 1));
  row.z0 = mxy * LD(mg_idx, Z.lohi + 2 * k);
  row.z1 = mxy * LD(mg_idx, Z.lohi + 2 * k + 1);
  row.wy0 = LD(mg_wts, Y.w + 2 * j);
  row.wy1 = LD(mg_wts, Y.w + 2 * j + 1);
  row.wz0 = LD(mg_wts, Z.w + 2 * k);
  row.wz1 = LD(mg_wts, Z.w + 2 * k + 1);
  return row;
}
MG_VALUE ProlongAt(int i, MgRow row, MgAxis X, int in0) {
  int mx = X.n_coarse;
  int cx[2] = int[2](LD(mg_idx, X.lohi + 2 * i), LD(mg_idx, X.lohi + 2 * i + 1));
  MG_VALUE sy[2];
  for (int a = 0; a < 2; ++a) {
    MG_VALUE sz[2];
    for (int b = 0; b < 2; ++b) {
      int cj = in0 + cx[a] + mx * row.cy[b];
      sz[b] = row.wz0 * MG_LDV(mg_src, cj + row.z0) + row.wz1 * MG_LDV(mg_src, cj + row.z1);
    }
    sy[a] = row.wy0 * sz[0] + row.wy1 * sz[1];
  }
  return LD(mg_wts, X.w + 2 * i) * sy[0] + LD(mg_wts, X.w + 2 * i + 1) * sy[1];
}
MG_VALUE Prolong3Value(int e, MgAxis X, MgAxis Y, MgAxis Z, int in0) {
  int nxy = X.n_fine * Y.n_fine, k = Div(e, nxy), r = e - k * nxy, j = Div(r, X.n_fine);
  return ProlongAt(r - j * X.n_fine, ProlongRow(j, k, X, Y, Z), X, in0);
}
#endif
#endif

#ifdef MG_DENSE
// Row i of x = M b, M (n x n, row-major at m0 in minv) the explicit inverse of the coarsest
// operator; b0: this field's offset in b. Double sums.
MG_VALUE DenseRow(int i, int n, int m0, int b0) {
  MG_DVALUE s = MG_DVALUE(0.0LF);
  for (int j = 0; j < n; ++j) s += double(LD(mg_minv, m0 + i * n + j)) * MG_DVALUE(MG_LDV(mg_b, b0 + j));
  return MG_VALUE(s);
}
#endif
