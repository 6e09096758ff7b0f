// SPDX-License-Identifier: MIT
// The coarse tail of a V-cycle in one dispatch: x = B b on levels first .. first + levels - 1
// (the last the coarsest), for one or four (FIELDS4) fields per work group (work-group z = the
// group; its invocations loop over each step's columns or values, a barrier between steps).
// The steps and their per-node math are the per-level path's (gl_solver.cc's VCycle;
// multigrid.glsl): on each level nu smoothing half-sweep pairs (colours 0, 1; nu = nu_fine on
// level 0 of the hierarchy, nu_coarse below, MultigridOptions), the residual, the restriction
// to the next level's b; on the coarsest the dense inverse (dense != 0) or coarse_sweeps sweep
// quadruples (0, 1, 1, 0); back up the prolongation added into x and nu pairs (1, 0).
//
// Memory (gl_solver.cc's Impl::PackLevels and Impl::CopyTailCoefficients, counts in values):
// - coef (float): per tail level cx, cy, cz, inv, luc, sigma, copied from the level's buffers
//   after every coefficient update;
// - mg_idx (int) and mg_wts (float): the packed transfers of every level (multigrid.glsl,
//   MG_TRANSFER); level l's metadata row at mg_idx[l kMgMeta] holds nx, ny, nz, the offsets in
//   coef of cx, cy, cz, inv, luc, sigma (kCoef..) and the offsets in a group's work of b, x, r
//   (kB, kX, kR), then the transfers;
// - work (coherent): `stride` values per group, group g's at g stride: b, x, r of every tail
//   level (and, when the tail starts on the finest level, that level's p and q last:
//   CG_ITERATION);
// - b_in / x_out: the first tail level's b and x, one field of n values at f n (or packed,
//   below).
//
// FIELDS4 (common.glsl; Tuning::pack_fields): a work group solves four fields, g: fields
// 4 g .. 4 g + 3 (those below `fields`), and work holds their values interleaved, one vec4
// per node, so that every load of a coefficient, index or weight serves four fields and one
// load brings a node's four values. b_in and x_out then hold one field per n values (the
// caller's per-field buffers), or with PACKED_IO four (a packed V-cycle's level buffers).
#if defined(FIELDS4) && defined(PACKED_IO)
VALUES(4, BIn, b_in, readonly);
VALUES(5, XOut, x_out, writeonly);
#elif !defined(CG_ITERATION)
FLOATS(4, BIn, b_in, readonly);
FLOATS(5, XOut, x_out, writeonly);
#endif
VALUES(6, Work, work, coherent);
FLOATS(0, Coef, coef, readonly);
INTS(1, Idx, mg_idx, readonly);
FLOATS(2, Wts, mg_wts, readonly);
FLOATS(3, Minv, mg_minv, readonly);
#if defined(CG_ITERATION) && !defined(FIELDS4)
#error CG_ITERATION needs FIELDS4
#endif
#ifdef CG_ITERATION
VALUES(4, R, r_f, restrict);
VALUES(5, P, p_f, restrict);
DOUBLES(7, X, xd, restrict);
DOUBLES(8, Scal, scal, restrict);
DOUBLES(9, Hist, hist, writeonly);
layout(location = 9) uniform int max_iterations;
#endif
layout(location = 0) uniform int first;   // the first tail level
layout(location = 1) uniform int levels;  // tail levels (>= 2), the last the coarsest
layout(location = 2) uniform int nu_fine;
layout(location = 3) uniform int nu_coarse;
layout(location = 4) uniform int dense;
layout(location = 5) uniform int coarse_sweeps;
layout(location = 6) uniform int stride;   // work values per group
layout(location = 7) uniform int columns;  // residual: 1 one z-column per step, 0 one node
layout(location = 8) uniform int fields;   // fields in the batch
#define mg_cx coef
#define mg_cy coef
#define mg_cz coef
#define mg_inv coef
#define mg_luc coef
#define mg_sigma coef
#define mg_b work
#define mg_x work
#define mg_y work
#define mg_src work
#define MG_SMOOTH
#define MG_RESIDUAL
#define MG_TRANSFER
#define MG_DENSE
#include "multigrid.glsl"

const int kCoef = 3, kB = 9, kX = 10, kR = 11;

MgLevel Level(int l) {
  return MgLevel(MgMeta(l, 0), MgMeta(l, 1), MgMeta(l, 2), MgMeta(l, kCoef), MgMeta(l, kCoef + 1),
                 MgMeta(l, kCoef + 2), MgMeta(l, kCoef + 3), MgMeta(l, kCoef + 4), MgMeta(l, kCoef + 5));
}
int Nodes(int l) { return MgMeta(l, 0) * MgMeta(l, 1) * MgMeta(l, 2); }

// Every invocation's writes visible to the whole group before the next step.
void Sync() {
  memoryBarrierBuffer();
  memoryBarrierImage();
  barrier();
}

int lid, group, fw;  // this invocation in the group, the group's size, this group's work

#ifndef CG_ITERATION
// Node e of the first tail level's b (of n0 nodes) for this group's fields, and x_out = v.
MG_VALUE LoadIn(int e, int n0) {
#if defined(PACKED_IO) || !defined(FIELDS4)
  return MG_LDV(b_in, int(Field()) * n0 + e);
#else
  float v[4];
  for (int c = 0; c < 4; ++c) {
    int f = 4 * int(Field()) + c;
    v[c] = f < fields ? LD(b_in, f * n0 + e) : 0.0;
  }
  return vec4(v[0], v[1], v[2], v[3]);
#endif
}
void StoreOut(int e, int n0, MG_VALUE v) {
#if defined(PACKED_IO) || !defined(FIELDS4)
  ST(x_out, int(Field()) * n0 + e, v);
#else
  for (int c = 0; c < 4; ++c) {
    int f = 4 * int(Field()) + c;
    if (f < fields) ST(x_out, f * n0 + e, v[c]);
  }
#endif
}
#endif

void HalfSweep(int l, int color) {
  MgLevel L = Level(l);
  for (int t = lid; t < ((L.nx + 1) / 2) * L.ny; t += group) {
    int i, j;
    if (SmoothColumn(t, L.nx, L.ny, color, i, j)) SmoothLine(L, i, j, fw + MgMeta(l, kB), fw + MgMeta(l, kX));
  }
  Sync();
}

// y = b - A x (mode 0) or y = A x (mode 1) on level l, x, b, y at these offsets in work.
void StencilLevel(int l, int mode, int x0, int b0, int y0) {
  MgLevel L = Level(l);
  int kz = columns != 0 ? L.nz : 1;
  for (int t = lid; t < L.nx * L.ny * ((L.nz + kz - 1) / kz); t += group) {
    int i, j, k0, k1;
    if (ColumnAt(t, L.nx, L.ny, L.nz, kz, i, j, k0, k1)) ResidualColumn(L, i, j, k0, k1, mode, x0, b0, y0);
  }
  Sync();
}

// The V-cycle x = B b on the group's work, b of level `first` already there.
void VCycleWork() {
  int last = first + levels - 1;
  for (int l = first; l <= last; ++l)
    for (int e = lid; e < Nodes(l); e += group) ST(work, fw + MgMeta(l, kX) + e, MG_VALUE(0.0));
  Sync();
  for (int l = first; l < last; ++l) {
    for (int s = 0; s < (l == 0 ? nu_fine : nu_coarse); ++s) {
      HalfSweep(l, 0);
      HalfSweep(l, 1);
    }
    StencilLevel(l, 0, fw + MgMeta(l, kX), fw + MgMeta(l, kB), fw + MgMeta(l, kR));
    MgAxis X = MgLoadAxis(l, 0), Y = MgLoadAxis(l, 1), Z = MgLoadAxis(l, 2);
    for (int e = lid; e < Nodes(l + 1); e += group)
      ST(work, fw + MgMeta(l + 1, kB) + e, Restrict3Value(e, X, Y, Z, fw + MgMeta(l, kR)));
    Sync();
  }
  if (dense != 0) {
    int n = Nodes(last);
    for (int i = lid; i < n; i += group)
      ST(work, fw + MgMeta(last, kX) + i, DenseRow(i, n, 0, fw + MgMeta(last, kB)));
    Sync();
  } else {
    for (int s = 0; s < coarse_sweeps; ++s) {
      HalfSweep(last, 0);
      HalfSweep(last, 1);
      HalfSweep(last, 1);
      HalfSweep(last, 0);
    }
  }
  for (int l = last - 1; l >= first; --l) {
    MgAxis X = MgLoadAxis(l, 0), Y = MgLoadAxis(l, 1), Z = MgLoadAxis(l, 2);
    int x0 = fw + MgMeta(l, kX), c0 = fw + MgMeta(l + 1, kX);
    for (int e = lid; e < Nodes(l); e += group)
      ST(work, x0 + e, MG_LDV(work, x0 + e) + Prolong3Value(e, X, Y, Z, c0));
    Sync();
    for (int s = 0; s < (l == 0 ? nu_fine : nu_coarse); ++s) {
      HalfSweep(l, 1);
      HalfSweep(l, 0);
    }
  }
}

#ifdef CG_ITERATION
// One iteration of SolveDevice's batched conjugate gradients (gl_solver.cc) in one dispatch,
// where the tail is the whole hierarchy (first == 0, FIELDS4): the stencil q = A p, the
// dot p.q, cg_update.comp's x += alpha p and r -= alpha q, the V-cycle z = B r, the dots r.r
// and r.z, the direction p = z + beta p and cg_scalars.comp's bookkeeping, with the same
// per-field arithmetic. p, q and z stay in work (P, Q: the last 2 n0 values of the group's
// work; z: level 0's x); r, p (vec4) and x (four doubles per node) are the caller's packed
// buffers (FIELDS4), and scal and hist the per-field scalars and histories (common.glsl's
// kCg* slots). The dots are summed in double, each invocation's share then the group's
// (GroupSum).
shared dvec4 group_sums[TL_GROUP];

// The sum of s over the group's invocations, the same in every invocation.
dvec4 GroupSum(dvec4 s) {
  group_sums[lid] = s;
  memoryBarrierShared();
  barrier();
  dvec4 t = dvec4(0.0LF);
  for (int q = 0; q < group; ++q) t += group_sums[q];
  barrier();
  return t;
}

bool Live(int c) { return 4 * int(Field()) + c < fields; }
int ScalAt(int c, int slot) { return (4 * int(Field()) + c) * kCgStride + slot; }

void CgIteration() {
  int n0 = Nodes(0), wp = fw + stride - 2 * n0, wq = fw + stride - n0, o = int(Field()) * n0;
  int wb = fw + MgMeta(0, kB), wz = fw + MgMeta(0, kX);
  for (int e = lid; e < n0; e += group) ST(work, wp + e, LD4(p_f, o + e));
  Sync();
  StencilLevel(0, 1, wp, wp, wq);
  dvec4 s = dvec4(0.0LF);
  for (int e = lid; e < n0; e += group) s += dvec4(LD4(work, wp + e)) * dvec4(LD4(work, wq + e));
  dvec4 pq = GroupSum(s);
  double al[4];
  for (int c = 0; c < 4; ++c) {
    al[c] = 0.0LF;
    if (Live(c) && LDD(scal, ScalAt(c, kCgActive)) != 0.0LF && DComp(pq, c) != 0.0LF)
      al[c] = LDD(scal, ScalAt(c, kCgRz)) / DComp(pq, c);
  }
  dvec4 alpha = dvec4(al[0], al[1], al[2], al[3]);
  for (int e = lid; e < n0; e += group) {
    vec4 p = LD4(work, wp + e), r = LD4(r_f, o + e) - vec4(alpha) * LD4(work, wq + e);
    for (int c = 0; c < 4; ++c) {
      int at = 4 * (o + e) + c;
      if (Live(c)) STD(xd, at, LDD(xd, at) + al[c] * double(p[c]));
    }
    ST(r_f, o + e, r);
    ST(work, wb + e, r);
  }
  VCycleWork();
  dvec4 rr = dvec4(0.0LF), rz = dvec4(0.0LF);
  for (int e = lid; e < n0; e += group) {
    dvec4 r = dvec4(LD4(work, wb + e));
    rr += r * r;
    rz += r * dvec4(LD4(work, wz + e));
  }
  rr = GroupSum(rr);
  rz = GroupSum(rz);
  float be[4];
  for (int c = 0; c < 4; ++c) {
    double rz_old = Live(c) ? LDD(scal, ScalAt(c, kCgRz)) : 0.0LF;
    be[c] = rz_old != 0.0LF ? float(DComp(rz, c) / rz_old) : 0.0;
  }
  vec4 beta = vec4(be[0], be[1], be[2], be[3]);
  for (int e = lid; e < n0; e += group) ST(p_f, o + e, LD4(work, wz + e) + beta * LD4(work, wp + e));
  barrier();  // every invocation has read the scalars
  if (lid != 0) return;
  for (int c = 0; c < 4; ++c) {
    if (!Live(c)) continue;
    int f = 4 * int(Field()) + c;
    STD(scal, ScalAt(c, kCgPq), DComp(pq, c));
    STD(scal, ScalAt(c, kCgRr), DComp(rr, c));
    STD(scal, ScalAt(c, kCgRzNew), DComp(rz, c));
    if (LDD(scal, ScalAt(c, kCgActive)) != 0.0LF) {
      int it = int(LDD(scal, ScalAt(c, kCgIter)));
      if (it < max_iterations) STD(hist, f * max_iterations + it, DComp(rr, c));
      STD(scal, ScalAt(c, kCgIter), double(it + 1));
      if (DComp(rr, c) <= LDD(scal, ScalAt(c, kCgTol2))) STD(scal, ScalAt(c, kCgActive), 0.0LF);
    }
    STD(scal, ScalAt(c, kCgRz), DComp(rz, c));
  }
}
#endif

void main() {
  lid = int(gl_LocalInvocationID.x);
  group = int(gl_WorkGroupSize.x);
  fw = int(Field()) * stride;
#ifdef CG_ITERATION
  CgIteration();
#else
  int n0 = Nodes(first);
  for (int e = lid; e < n0; e += group) ST(work, fw + MgMeta(first, kB) + e, LoadIn(e, n0));
  VCycleWork();
  for (int e = lid; e < n0; e += group) StoreOut(e, n0, MG_LDV(work, fw + MgMeta(first, kX) + e));
#endif
}
