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
#include <cstdint>
#include <vector>

#include "solver/multigrid_hierarchy.h"

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
// xl[m] and xr[m] are the x-neighbours of node m (in the other half); the first node has no
// left neighbour unless first_has_left, the last no right one unless last_has_right, and those
// terms are left out (not read). Missing y/z rows point at zeros.
// (Inlined, the __restrict qualifiers are lost; `ivdep` keeps the loops vectorised.)
template <typename T, bool kResidual>
inline void HalfRowKernel(int64_t len, bool first_has_left, bool last_has_right,
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
  const int64_t m0 = first_has_left ? 0 : 1, m1 = last_has_right ? len : len - 1;
  if (!first_has_left) put(0, len > 1 || last_has_right ? cr[0] * xr[0] : T(0));
#pragma GCC ivdep
  for (int64_t m = m0; m < m1; ++m) put(m, cl[m] * xl[m] + cr[m] * xr[m]);
  if (!last_has_right && len - 1 >= m0) put(len - 1, cl[len - 1] * xl[len - 1]);
}

// Transfers along x between a fine level's split rows and the next coarser level's split rows
// (vertex-centred coarsening, multigrid_hierarchy.h). Away from the ends, fine node 2c is
// coarse node c and odd fine node 2m + 1 lies between coarse nodes m and m + 1 with weights
// wlo[m], whi[m]; the few coarse nodes near the ends that gather otherwise use the transfer's
// general tables.
template <typename T>
struct SplitTransferX {
  bool coarsened = false;
  int64_t nf = 0, nc = 0;
  std::vector<T> wlo, whi;              // per odd fine node m (padded with zeros)
  std::vector<int64_t> irregular;       // coarse nodes restricted from the general tables
  int64_t regular_end = 0;              // coarse nodes [1, regular_end) are regular
  bool last_even_irregular = false;     // nf even: fine node nf - 2 lies between nc-2, nc-1
  const AxisTransfer* t = nullptr;

  explicit SplitTransferX(const AxisTransfer& at) : coarsened(at.coarsened), nf(at.n_fine),
                                                    nc(at.n_coarse), t(&at) {
    if (!coarsened) return;
    const int64_t ho = nf / 2;
    wlo.assign(std::max(ho, nc) + 1, T(0));
    whi.assign(std::max(ho, nc) + 1, T(0));
    for (int64_t m = 0; m < ho; ++m) {
      wlo[m] = T(at.wlo[2 * m + 1]);
      whi[m] = T(at.whi[2 * m + 1]);
    }
    const bool even = nf % 2 == 0;
    regular_end = even ? std::max<int64_t>(1, nc - 2) : nc;
    irregular.push_back(0);
    for (int64_t c = std::max<int64_t>(1, regular_end); c < nc; ++c) irregular.push_back(c);
    last_even_irregular = even;
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
    const int64_t e_end = last_even_irregular ? he - 1 : he;
    for (int64_t m = 0; m < e_end; ++m) e[m] += nat[m];
    for (int64_t m = 0; m < ho; ++m) o[m] += wl[m] * nat[m] + wh[m] * nat[m + 1];
    if (last_even_irregular) {
      const int64_t f = nf - 2;
      e[he - 1] += T(t->wlo[f]) * nat[t->lo[f]] + T(t->whi[f]) * nat[t->hi[f]];
    }
  }
};

}  // namespace translume
