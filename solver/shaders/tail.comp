// SPDX-License-Identifier: MIT
// The coarse tail of a V-cycle in one dispatch: x = B b on levels first .. first + levels - 1
// (the last the coarsest), for TAIL_FIELDS fields per work group (work-group z = the group;
// its invocations loop over each step's columns or values, a barrier between steps). The steps and their per-node math are the per-level path's (gl_solver.cc's VCycle;
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
//   level;
// - b_in / x_out: the first tail level's b and x, one field of n values at f n.
//
// TAIL_FIELDS (the host's define, 1 or 4, Tuning::tail_fields): the fields one work group
// solves. With 4, group g solves fields 4 g .. 4 g + 3 (those below `fields`) and work holds
// their values interleaved, one vec4 per node (field 4 g + c in component c), so that every
// load of a coefficient, index or weight serves four fields and one load brings a node's four
// values (multigrid.glsl's MG_VALUE).
#ifndef TAIL_FIELDS
#define TAIL_FIELDS 1
#endif
#if TAIL_FIELDS == 4
#define MG_VALUE vec4
#define MG_DVALUE dvec4
#define MG_LDV LD4
VEC4S(6, Work, work, coherent);
#else
FLOATS(6, Work, work, coherent);
#endif
FLOATS(0, Coef, coef, readonly);
INTS(1, Idx, mg_idx, readonly);
FLOATS(2, Wts, mg_wts, readonly);
FLOATS(3, Minv, mg_minv, readonly);
FLOATS(4, BIn, b_in, readonly);
FLOATS(5, XOut, x_out, writeonly);
layout(location = 0) uniform int first;   // the first tail level
layout(location = 1) uniform int levels;  // tail levels (>= 2), the last the coarsest
layout(location = 2) uniform int nu_fine;
layout(location = 3) uniform int nu_coarse;
layout(location = 4) uniform int dense;
layout(location = 5) uniform int coarse_sweeps;
layout(location = 6) uniform int stride;   // work values per field
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

// Node e of the first tail level's b (of n0 nodes) for this group's fields, and x_out = v.
MG_VALUE LoadIn(int e, int n0) {
#if TAIL_FIELDS == 4
  vec4 v = vec4(0.0);
  for (int c = 0; c < 4; ++c) {
    int f = 4 * int(Field()) + c;
    if (f < fields) v[c] = LD(b_in, f * n0 + e);
  }
  return v;
#else
  return LD(b_in, int(Field()) * n0 + e);
#endif
}
void StoreOut(int e, int n0, MG_VALUE v) {
#if TAIL_FIELDS == 4
  for (int c = 0; c < 4; ++c) {
    int f = 4 * int(Field()) + c;
    if (f < fields) ST(x_out, f * n0 + e, v[c]);
  }
#else
  ST(x_out, int(Field()) * n0 + e, v);
#endif
}

void HalfSweep(int l, int color) {
  MgLevel L = Level(l);
  for (int t = lid; t < ((L.nx + 1) / 2) * L.ny; t += group) {
    int i, j;
    if (SmoothColumn(t, L.nx, L.ny, color, i, j)) SmoothLine(L, i, j, fw + MgMeta(l, kB), fw + MgMeta(l, kX));
  }
  Sync();
}

void main() {
  lid = int(gl_LocalInvocationID.x);
  group = int(gl_WorkGroupSize.x);
  fw = int(Field()) * stride;
  int last = first + levels - 1, n0 = Nodes(first);
  for (int e = lid; e < n0; e += group) ST(work, fw + MgMeta(first, kB) + e, LoadIn(e, n0));
  for (int l = first; l <= last; ++l)
    for (int e = lid; e < Nodes(l); e += group) ST(work, fw + MgMeta(l, kX) + e, MG_VALUE(0.0));
  Sync();
  for (int l = first; l < last; ++l) {
    MgLevel L = Level(l);
    for (int s = 0; s < (l == 0 ? nu_fine : nu_coarse); ++s) {
      HalfSweep(l, 0);
      HalfSweep(l, 1);
    }
    int kz = columns != 0 ? L.nz : 1;
    for (int t = lid; t < L.nx * L.ny * ((L.nz + kz - 1) / kz); t += group) {
      int i, j, k0, k1;
      if (ColumnAt(t, L.nx, L.ny, L.nz, kz, i, j, k0, k1))
        ResidualColumn(L, i, j, k0, k1, 0, fw + MgMeta(l, kX), fw + MgMeta(l, kB), fw + MgMeta(l, kR));
    }
    Sync();
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
  for (int e = lid; e < n0; e += group) StoreOut(e, n0, MG_LDV(work, fw + MgMeta(first, kX) + e));
}
