// SPDX-License-Identifier: MIT
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "solver/stencil.h"

namespace translume {

// Linear interpolation from a coarse to a fine node list along one axis (prolongation P), and
// its transpose (restriction R = P^T).
struct AxisTransfer {
  bool coarsened = false;
  int64_t n_fine = 0, n_coarse = 0;
  std::vector<int64_t> lo, hi;   // per fine node: the bracketing coarse nodes
  std::vector<double> wlo, whi;  // and their weights (whi = 0 where fine == coarse node)
  // Transpose, flattened: coarse node c gathers fine nodes g_idx[g_start[c] .. g_start[c+1]).
  std::vector<int64_t> g_start, g_idx;
  std::vector<double> g_w;
};

// One level of the geometric hierarchy shared by every backend: the level's tensor grid and
// the per-axis transfers towards the next coarser level (absent on the coarsest).
struct MultigridLevel {
  TensorGrid grid;
  std::array<AxisTransfer, 3> to_coarse;
};

// How the hierarchy coarsens z relative to x and y.
enum class ZCoarsening {
  // z along with x and y while its spacing is no coarser than theirs: full coarsening on cubes.
  kWithXY,
  // z only once x and y cannot coarsen any more: x-y semi-coarsening. With the z-line smoother
  // this is the robust pairing (the smoother must then only damp modes rough in x or y, which
  // zebra line relaxation does well, while modes rough in z stay on every coarse grid). The
  // levels shrink 4x instead of 8x, but a V(1,1) cycle then reduces the error about as much as
  // V(2,2) with full coarsening (docs/benchmarks.md, "Forward solver").
  kLast,
};

// Vertex-centred coarsening of the uniform grid (shape, h): every other node per coarsened
// axis. For an even count the last coarse interval is either the last fine one or the last
// three merged, whichever is nearer the regular coarse interval in length (as a ratio), so
// that the irregular end stays within ~[0.6, 1.6] of the regular interval on every level
// instead of growing towards 2x (which slows the V-cycle down). x and y stay within 1.5x of
// each other; z as `z` says. Stops at <= coarsest_nodes nodes or when no axis can coarsen.
// Finest level first.
std::vector<MultigridLevel> BuildMultigridHierarchy(const GridShape& shape, double h,
                                                    int64_t coarsest_nodes,
                                                    ZCoarsening z = ZCoarsening::kWithXY);

// Separable transfer along one axis. The data is `outer` blocks of n nodes along the axis, each
// node `inner` contiguous values (x: inner = 1; y: inner = nx'; z: inner = nx' ny', where the
// primes are the current sizes of the axes already transferred).
template <typename T>
void RestrictAxis(const AxisTransfer& t, const T* in, T* out, int64_t inner, int64_t outer);
template <typename T>
void ProlongAxis(const AxisTransfer& t, const T* in, T* out, int64_t inner, int64_t outer,
                 bool add);

// One contiguous row along an axis (inner = 1): out[c] = sum of in[g_idx] g_w over the fine
// nodes that coarse node c gathers (n_fine values in, n_coarse out).
template <typename T>
inline void RestrictRow(const AxisTransfer& t, const T* in, T* out) {
  for (int64_t c = 0; c < t.n_coarse; ++c) {
    T s = T(0);
    for (int64_t g = t.g_start[c]; g < t.g_start[c + 1]; ++g) s += T(t.g_w[g]) * in[t.g_idx[g]];
    out[c] = s;
  }
}

// Full 3-D transfers between `fine` and the next coarser level, through two temporaries of
// (coarse nx) * ny * nz and (coarse nx) * (coarse ny) * nz values.
template <typename T>
void Restrict3(const MultigridLevel& fine, const T* f, T* c, T* tmp_a, T* tmp_b);
template <typename T>
void ProlongAdd3(const MultigridLevel& fine, const T* c, T* f, T* tmp_a, T* tmp_b);

}  // namespace translume
