// SPDX-License-Identifier: MIT
#pragma once

// The CPU multigrid's "split" x-row layout and the row kernels that use it (internal to
// solver/multigrid.cc). Within every x-row the even-i nodes come first, then the odd-i nodes:
// position m holds i = 2m for m < he = (nx + 1) / 2 and i = 2 (m - he) + 1 after. A zebra
// colour's z-lines (the columns with (i + j) % 2 == c) are then one contiguous half of each row,
// their x-neighbours the other half shifted by at most one, and their y- and z-neighbours the
// same positions in the neighbouring rows, so every smoother loop is contiguous and vectorised
// and does no work for the other colour.

#include <algorithm>
#include <cstdlib>
#include <cstdint>
#include <vector>

#include "solver/multigrid_hierarchy.h"
#include "solver/status.h"

namespace translume {

// Natural-order row (nx values) -> split row, and back.
template <typename T, typename U>
inline void SplitRow(int64_t nx, const T* in, U* out) {
  const int64_t he = (nx + 1) / 2;
  for (int64_t m = 0; m < he; ++m) out[m] = U(in[2 * m]);
  for (int64_t m = 0; 2 * m + 1 < nx; ++m) out[he + m] = U(in[2 * m + 1]);
}
template <typename T, typename U>
inline void MergeRow(int64_t nx, const T* in, U* out) {
  const int64_t he = (nx + 1) / 2;
  for (int64_t m = 0; m < he; ++m) out[2 * m] = U(in[m]);
  for (int64_t m = 0; 2 * m + 1 < nx; ++m) out[2 * m + 1] = U(in[he + m]);
}

// One half-row (len nodes of one colour) of either the forward elimination of the z-line solve
// (kResidual false):
//   out = (b + cl xl + cr xr + cym xym + cyp xyp + czm xzm) * inv
// where xzm is the previous plane's eliminated half-row, or the residual (kResidual true):
//   out = b + cl xl + cr xr + cym xym + cyp xyp + czm xzm + czp xzp - dg xs.
// xl[m] and xr[m] are the x-neighbours of node m (in the other half) and cl[m], cr[m] their
// couplings. Every m reads both, so the loop runs vectorised from end to end without peeled
// scalar ends (on short rows these cost as much as the rest): a missing right neighbour has
// coupling 0 (cx is 0 on the last x plane) and reads a finite value past the half (the next
// row's first, or the level's padding element after the last row). The one missing left
// neighbour, that of the even half's first node (i = 0), reads the coupling at the end of the
// row, which is 0 only for odd nx: `fix_first` (even half, even nx) recomputes that node
// without it. Missing y/z rows point at zeros.
// (Inlined, the __restrict qualifiers are lost; `ivdep` keeps the loops vectorised.)
template <typename T, bool kResidual>
inline void HalfRowKernel(int64_t len, bool fix_first,
                          const T* __restrict b, const T* __restrict cl, const T* __restrict xl,
                          const T* __restrict cr, const T* __restrict xr,
                          const T* __restrict cym, const T* __restrict xym,
                          const T* __restrict cyp, const T* __restrict xyp,
                          const T* __restrict czm, const T* __restrict xzm,
                          const T* __restrict czp, const T* __restrict xzp,
                          const T* __restrict dg, const T* __restrict xs,
                          const T* __restrict inv, T* __restrict out) {
  // (Lambdas capture by value: with references the compiler reloads every pointer after each
  // store and does not vectorise.)
  auto core = [=](int64_t m) {
    T v = b[m] + cym[m] * xym[m] + cyp[m] * xyp[m] + czm[m] * xzm[m];
    if constexpr (kResidual) v += czp[m] * xzp[m] - dg[m] * xs[m];
    return v;
  };
  // The residual in two loops (one would need more registers than SSE has, and the compiler
  // would not vectorise it): the y, z and diagonal terms, then the x-neighbours.
  if constexpr (kResidual) {
#pragma GCC ivdep
    for (int64_t m = 0; m < len; ++m) out[m] = core(m);
  }
  auto put = [=](int64_t m, T x_terms) {
    if constexpr (kResidual) out[m] += x_terms;
    else out[m] = (core(m) + x_terms) * inv[m];
  };
#pragma GCC ivdep
  for (int64_t m = 0; m < len; ++m) put(m, cl[m] * xl[m] + cr[m] * xr[m]);
  if (fix_first && len > 0) {
    if constexpr (kResidual) out[0] = core(0) + cr[0] * xr[0];
    else out[0] = (core(0) + cr[0] * xr[0]) * inv[0];
  }
}

// Transfers along x between a fine level's split rows and the next coarser level's split rows
// (vertex-centred coarsening, multigrid_hierarchy.h). Away from the end, fine node 2c is
// coarse node c and odd fine node 2m + 1 lies between coarse nodes m and m + 1 with weights
// wlo[m], whi[m] (an odd fine node that is itself coarse node m or m + 1 has weights 1, 0 or
// 0, 1). Coarse node 0 and the coarse nodes from regular_end on (the irregular end: see
// BuildMultigridHierarchy) restrict from the transfer's general tables, and the even fine nodes
// from even_end on prolong from them.
template <typename T>
struct SplitTransferX {
  bool coarsened = false;
  int64_t nf = 0, nc = 0;
  std::vector<T> wlo, whi;              // per odd fine node m (padded with zeros)
  std::vector<int64_t> irregular;       // coarse nodes restricted from the general tables
  int64_t regular_end = 0;              // coarse nodes [1, regular_end) are regular
  int64_t even_end = 0;                 // even fine nodes [0, even_end) are coarse nodes
  const AxisTransfer* t = nullptr;

  explicit SplitTransferX(const AxisTransfer& at) : coarsened(at.coarsened), nf(at.n_fine),
                                                    nc(at.n_coarse), t(&at) {
    if (!coarsened) return;
    const int64_t ho = nf / 2, he = (nf + 1) / 2;
    wlo.assign(std::max(ho, nc) + 1, T(0));
    whi.assign(std::max(ho, nc) + 1, T(0));
    auto is_coarse = [&](int64_t f, int64_t c) { return at.lo[f] == c && at.whi[f] == 0; };
    for (int64_t m = 0; m < ho; ++m) {
      const int64_t f = 2 * m + 1;
      if (is_coarse(f, m + 1)) {
        whi[m] = T(1);
      } else {
        TL_CHECK(at.lo[f] == m && (at.whi[f] == 0 || at.hi[f] == m + 1));
        wlo[m] = T(at.wlo[f]);
        whi[m] = T(at.whi[f]);
      }
    }
    while (even_end < he && is_coarse(2 * even_end, even_end)) ++even_end;
    // Coarse node c is regular if it is fine node 2c and gathers only fine nodes 2c +- 1 too.
    auto regular = [&](int64_t c) {
      if (2 * c >= nf || !is_coarse(2 * c, c)) return false;
      for (int64_t g = at.g_start[c]; g < at.g_start[c + 1]; ++g)
        if (std::abs(at.g_idx[g] - 2 * c) > 1) return false;
      return true;
    };
    regular_end = 1;
    while (regular_end < nc && regular(regular_end)) ++regular_end;
    irregular.push_back(0);
    for (int64_t c = regular_end; c < nc; ++c) irregular.push_back(c);
  }

  // Fine split row (nf values, then one readable padding value) -> coarse natural row (nc).
  void Restrict(const T* in, T* nat) const {
    const int64_t he = (nf + 1) / 2;
    const T* e = in;
    const T* o = in + he;
    const T* __restrict wl = wlo.data();
    const T* __restrict wh = whi.data();
    for (int64_t c = 1; c < regular_end; ++c) nat[c] = e[c] + wh[c - 1] * o[c - 1] + wl[c] * o[c];
    for (int64_t c : irregular) {
      T s = T(0);
      for (int64_t g = t->g_start[c]; g < t->g_start[c + 1]; ++g) {
        const int64_t f = t->g_idx[g];
        s += T(t->g_w[g]) * in[f % 2 == 0 ? f / 2 : he + f / 2];
      }
      nat[c] = s;
    }
  }

  // Coarse natural row (nc values, then one readable zero) added into the fine split row.
  void ProlongAdd(const T* nat, T* out) const {
    const int64_t he = (nf + 1) / 2, ho = nf / 2;
    T* __restrict e = out;
    T* __restrict o = out + he;
    const T* __restrict wl = wlo.data();
    const T* __restrict wh = whi.data();
    for (int64_t m = 0; m < even_end; ++m) e[m] += nat[m];
    for (int64_t m = 0; m < ho; ++m) o[m] += wl[m] * nat[m] + wh[m] * nat[m + 1];
    for (int64_t m = even_end; m < he; ++m) {
      const int64_t f = 2 * m;
      e[m] += T(t->wlo[f]) * nat[t->lo[f]] + T(t->whi[f]) * nat[t->hi[f]];
    }
  }
};

}  // namespace translume
