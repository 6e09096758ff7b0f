// SPDX-License-Identifier: MIT
// The coarse tail of a V-cycle in one dispatch: x = B b on every level from the tail's first
// (level 0 of the tail, the finest small level) down to the coarsest, for one field per work
// group (work-group z = the field; one group per field, its invocations looping over each
// step's nodes, a barrier between steps). The steps and their per-node math are the per-level
// path's (gl_solver.cc's VCycle; multigrid.glsl): on each level pre smoothing half-sweep pairs
// (colours 0, 1), the residual, three restrict passes (x, y, z) to the next level's b; on the
// coarsest the dense inverse (dense != 0) or coarse_sweeps sweep quadruples (0, 1, 1, 0); back
// up three prolongation passes added into x, post smoothing pairs (1, 0).
//
// Memory (gl_solver.cc's BuildTail, counts in values):
// - coef (float): per tail level cx, cy, cz, inv, luc, sigma (copied from the level's buffers
//   after every coefficient update), and the transfer weights gw, w of each axis;
// - idx (int): per tail level kMeta ints of metadata (below), then the transfers' gstart, gidx
//   and lohi; gstart's entries count from the axis' own gidx / gw;
// - work (float, coherent): `stride` values per field, field f at f stride: per level b, x, r,
//   tmp_a, tmp_b at the offsets of the metadata;
// - b_in / x_out: the first tail level's b and x, one field of n values at f n.
// Metadata of tail level l at idx[l kMeta]: nx, ny, nz; the offsets in coef of cx, cy, cz,
// inv, luc, sigma; the offsets in a field's work of b, x, r, tmp_a, tmp_b; per axis a (at
// 14 + 7 a) n_fine, n_coarse and the offsets of gstart, gidx (in idx), gw (in coef), lohi (in
// idx), w (in coef).
FLOATS(0, Coef, coef, readonly);
INTS(1, Idx, idx, readonly);
FLOATS(2, Minv, mg_minv, readonly);
FLOATS(3, BIn, b_in, readonly);
FLOATS(4, XOut, x_out, writeonly);
FLOATS(5, Work, work, coherent);
layout(location = 0) uniform int levels;  // tail levels (>= 2), the last the coarsest
layout(location = 1) uniform int pre;
layout(location = 2) uniform int post;
layout(location = 3) uniform int dense;
layout(location = 4) uniform int coarse_sweeps;
layout(location = 5) uniform int stride;   // work values per field
layout(location = 6) uniform int columns;  // residual: 1 one z-column per step, 0 one node
#define mg_cx coef
#define mg_cy coef
#define mg_cz coef
#define mg_inv coef
#define mg_luc coef
#define mg_sigma coef
#define mg_gw coef
#define mg_w coef
#define mg_gstart idx
#define mg_gidx idx
#define mg_lohi idx
#define mg_b work
#define mg_x work
#define mg_y work
#define mg_src work
#define MG_SMOOTH
#define MG_RESIDUAL
#define MG_RESTRICT
#define MG_PROLONG
#define MG_DENSE
#include "multigrid.glsl"

const int kMeta = 36, kB = 9, kX = 10, kR = 11, kTa = 12, kTb = 13, kAxis = 14;

int Meta(int l, int k) { return LD(idx, l * kMeta + k); }
MgLevel Level(int l) {
  int m = l * kMeta;
  return MgLevel(LD(idx, m), LD(idx, m + 1), LD(idx, m + 2), LD(idx, m + 3), LD(idx, m + 4),
                 LD(idx, m + 5), LD(idx, m + 6), LD(idx, m + 7), LD(idx, m + 8));
}

// Every invocation's writes visible to the whole group before the next step.
void Sync() {
  memoryBarrierBuffer();
  memoryBarrierImage();
  barrier();
}

int lid, group, fw;  // this invocation in the group, the group's size, this field's work

void HalfSweep(int l, int color) {
  MgLevel L = Level(l);
  for (int t = lid; t < ((L.nx + 1) / 2) * L.ny; t += group) {
    int i, j;
    if (SmoothColumn(t, L.nx, L.ny, color, i, j)) SmoothLine(L, i, j, fw + Meta(l, kB), fw + Meta(l, kX));
  }
  Sync();
}

// One axis pass of level l's restriction (prolongation) between this field's work values at
// from and at to (Impl::Restrict / ProlongAdd's passes).
void RestrictPass(int l, int a, int from, int to, int inner, int outer) {
  int m = kAxis + 7 * a, n_in = Meta(l, m), n_out = Meta(l, m + 1);
  int gs0 = Meta(l, m + 2), gi0 = Meta(l, m + 3), gw0 = Meta(l, m + 4);
  for (int e = lid; e < outer * n_out * inner; e += group)
    ST(work, fw + to + e, RestrictValue(e, n_in, n_out, inner, fw + from, gs0, gi0, gw0));
  Sync();
}

void ProlongPass(int l, int a, int from, int to, int inner, int outer, bool add) {
  int m = kAxis + 7 * a, n_out = Meta(l, m), n_in = Meta(l, m + 1);
  int lh0 = Meta(l, m + 5), w0 = Meta(l, m + 6);
  for (int e = lid; e < outer * n_out * inner; e += group) {
    float s = ProlongValue(e, n_in, n_out, inner, fw + from, lh0, w0);
    ST(work, fw + to + e, add ? LD(work, fw + to + e) + s : s);
  }
  Sync();
}

void main() {
  lid = int(gl_LocalInvocationID.x);
  group = int(gl_WorkGroupSize.x);
  fw = int(Field()) * stride;
  int last = levels - 1, n0 = Meta(0, 0) * Meta(0, 1) * Meta(0, 2), f0 = int(Field()) * n0;
  for (int e = lid; e < n0; e += group) ST(work, fw + Meta(0, kB) + e, LD(b_in, f0 + e));
  for (int l = 0; l < levels; ++l)
    for (int e = lid, n = Meta(l, 0) * Meta(l, 1) * Meta(l, 2); e < n; e += group)
      ST(work, fw + Meta(l, kX) + e, 0.0);
  Sync();
  for (int l = 0; l < last; ++l) {
    MgLevel L = Level(l);
    for (int s = 0; s < pre; ++s) {
      HalfSweep(l, 0);
      HalfSweep(l, 1);
    }
    int kz = columns != 0 ? L.nz : 1;
    for (int t = lid; t < L.nx * L.ny * ((L.nz + kz - 1) / kz); t += group) {
      int i, j, k0, k1;
      if (ColumnAt(t, L.nx, L.ny, L.nz, kz, i, j, k0, k1))
        ResidualColumn(L, i, j, k0, k1, 0, fw + Meta(l, kX), fw + Meta(l, kB), fw + Meta(l, kR));
    }
    Sync();
    int mx = Meta(l, kAxis + 1), my = Meta(l, kAxis + 8);
    RestrictPass(l, 0, Meta(l, kR), Meta(l, kTa), 1, L.ny * L.nz);
    RestrictPass(l, 1, Meta(l, kTa), Meta(l, kTb), mx, L.nz);
    RestrictPass(l, 2, Meta(l, kTb), Meta(l + 1, kB), mx * my, 1);
  }
  if (dense != 0) {
    int n = Meta(last, 0) * Meta(last, 1) * Meta(last, 2);
    for (int i = lid; i < n; i += group)
      ST(work, fw + Meta(last, kX) + i, DenseRow(i, n, 0, fw + Meta(last, kB)));
    Sync();
  } else {
    for (int s = 0; s < coarse_sweeps; ++s) {
      HalfSweep(last, 0);
      HalfSweep(last, 1);
      HalfSweep(last, 1);
      HalfSweep(last, 0);
    }
  }
  for (int l = last - 1; l >= 0; --l) {
    MgLevel L = Level(l);
    int mx = Meta(l, kAxis + 1), my = Meta(l, kAxis + 8);
    ProlongPass(l, 2, Meta(l + 1, kX), Meta(l, kTb), mx * my, 1, false);
    ProlongPass(l, 1, Meta(l, kTb), Meta(l, kTa), mx, L.nz, false);
    ProlongPass(l, 0, Meta(l, kTa), Meta(l, kX), 1, L.ny * L.nz, true);
    for (int s = 0; s < post; ++s) {
      HalfSweep(l, 1);
      HalfSweep(l, 0);
    }
  }
  for (int e = lid; e < n0; e += group) ST(x_out, f0 + e, LD(work, fw + Meta(0, kX) + e));
}
