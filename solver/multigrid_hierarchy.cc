// SPDX-License-Identifier: MIT
#include "solver/multigrid_hierarchy.h"

#include <algorithm>
#include <cmath>

#include "solver/status.h"
#include "solver/threads.h"

namespace translume {
namespace {

AxisTransfer MakeAxisTransfer(const std::vector<double>& fine, bool coarsen,
                              std::vector<double>* coarse) {
  const int64_t n = int64_t(fine.size());
  AxisTransfer t;
  t.coarsened = coarsen;
  std::vector<int64_t> keep;
  if (!coarsen) {
    for (int64_t i = 0; i < n; ++i) keep.push_back(i);
  } else if (n % 2 == 1 || n < 4) {
    for (int64_t i = 0; i < n; i += 2) keep.push_back(i);
    if (keep.back() != n - 1) keep.push_back(n - 1);
  } else {
    // An odd number of intervals: all but the last one or three pair up. Of the two coarse
    // end intervals (the fine one alone, or three merged) take the one nearer in length to
    // the regular coarse interval.
    const double regular = fine[2] - fine[0];
    const double alone = fine[n - 1] - fine[n - 2], merged = fine[n - 1] - fine[n - 4];
    const bool merge = std::abs(std::log(merged / regular)) < std::abs(std::log(alone / regular));
    for (int64_t i = 0; i <= (merge ? n - 4 : n - 2); i += 2) keep.push_back(i);
    keep.push_back(n - 1);
  }
  coarse->clear();
  for (int64_t i : keep) coarse->push_back(fine[i]);
  const int64_t nc = int64_t(keep.size());
  t.n_fine = n;
  t.n_coarse = nc;
  t.lo.resize(n);
  t.hi.resize(n);
  t.wlo.resize(n);
  t.whi.resize(n);
  std::vector<std::vector<std::pair<int64_t, double>>> gather(nc);
  int64_t c = 0;
  for (int64_t i = 0; i < n; ++i) {
    while (c + 1 < nc && keep[c + 1] <= i) ++c;
    if (keep[c] == i) {
      t.lo[i] = t.hi[i] = c;
      t.wlo[i] = 1;
      t.whi[i] = 0;
      gather[c].push_back({i, 1.0});
    } else {
      const double w = (fine[i] - fine[keep[c]]) / (fine[keep[c + 1]] - fine[keep[c]]);
      t.lo[i] = c;
      t.hi[i] = c + 1;
      t.wlo[i] = 1 - w;
      t.whi[i] = w;
      gather[c].push_back({i, 1 - w});
      gather[c + 1].push_back({i, w});
    }
  }
  t.g_start.push_back(0);
  for (int64_t cc = 0; cc < nc; ++cc) {
    for (auto [i, w] : gather[cc]) {
      t.g_idx.push_back(i);
      t.g_w.push_back(w);
    }
    t.g_start.push_back(int64_t(t.g_idx.size()));
  }
  return t;
}

double MeanGap(const std::vector<double>& c) { return (c.back() - c.front()) / double(c.size() - 1); }

std::array<bool, 3> ChooseCoarsening(const TensorGrid& g, ZCoarsening z) {
  std::array<double, 3> gap;
  std::array<bool, 3> can;
  for (int a = 0; a < 3; ++a) {
    gap[a] = MeanGap(g.coord[a]);
    can[a] = g.shape.n(a) >= 3;
  }
  std::array<bool, 3> out;
  out[0] = can[0] && (!can[1] || gap[0] <= 1.5 * gap[1]);
  out[1] = can[1] && (!can[0] || gap[1] <= 1.5 * gap[0]);
  out[2] = z == ZCoarsening::kWithXY && can[2] && gap[2] <= 1.01 * std::min(gap[0], gap[1]);
  if (!out[0] && !out[1] && can[2] && !can[0] && !can[1]) out[2] = true;
  return out;
}

}  // namespace

std::vector<MultigridLevel> BuildMultigridHierarchy(const GridShape& shape, double h,
                                                    int64_t coarsest_nodes, ZCoarsening z) {
  TL_CHECK(shape.nx >= 2 && shape.ny >= 2 && shape.nz >= 2 && h > 0);
  std::vector<MultigridLevel> levels(1);
  levels[0].grid = TensorGrid::Uniform(shape, h);
  while (levels.back().grid.shape.size() > coarsest_nodes) {
    const std::array<bool, 3> coarsen = ChooseCoarsening(levels.back().grid, z);
    if (!coarsen[0] && !coarsen[1] && !coarsen[2]) break;
    MultigridLevel next;
    for (int a = 0; a < 3; ++a)
      levels.back().to_coarse[a] =
          MakeAxisTransfer(levels.back().grid.coord[a], coarsen[a], &next.grid.coord[a]);
    next.grid.shape = {int64_t(next.grid.coord[0].size()), int64_t(next.grid.coord[1].size()),
                       int64_t(next.grid.coord[2].size())};
    levels.push_back(std::move(next));
  }
  return levels;
}

template <typename T>
void RestrictAxis(const AxisTransfer& t, const T* in, T* out, int64_t inner, int64_t outer) {
  const int64_t n_in = t.n_fine, n_out = t.n_coarse;
  if (inner == 1) {  // along x: one contiguous row per block
#pragma omp parallel for schedule(static) if (outer * n_in >= kParallelNodes)
    for (int64_t o = 0; o < outer; ++o) RestrictRow(t, in + o * n_in, out + o * n_out);
    return;
  }
#pragma omp parallel for collapse(2) schedule(static) if (outer * n_in * inner >= kParallelNodes)
  for (int64_t o = 0; o < outer; ++o)
    for (int64_t c = 0; c < n_out; ++c) {
      const T* src = in + o * n_in * inner;
      T* dst = out + (o * n_out + c) * inner;
      for (int64_t v = 0; v < inner; ++v) dst[v] = T(0);
      for (int64_t g = t.g_start[c]; g < t.g_start[c + 1]; ++g) {
        const T w = T(t.g_w[g]);
        const T* s = src + t.g_idx[g] * inner;
        for (int64_t v = 0; v < inner; ++v) dst[v] += w * s[v];
      }
    }
}

template <typename T>
void ProlongAxis(const AxisTransfer& t, const T* in, T* out, int64_t inner, int64_t outer,
                 bool add) {
  const int64_t n_in = t.n_coarse, n_out = t.n_fine;
  if (inner == 1) {  // along x: one contiguous row per block
#pragma omp parallel for schedule(static) if (outer * n_out >= kParallelNodes)
    for (int64_t o = 0; o < outer; ++o) {
      const T* src = in + o * n_in;
      T* dst = out + o * n_out;
      for (int64_t f = 0; f < n_out; ++f) {
        const T v = T(t.wlo[f]) * src[t.lo[f]] + T(t.whi[f]) * src[t.hi[f]];
        dst[f] = add ? dst[f] + v : v;
      }
    }
    return;
  }
#pragma omp parallel for collapse(2) schedule(static) if (outer * n_out * inner >= kParallelNodes)
  for (int64_t o = 0; o < outer; ++o)
    for (int64_t f = 0; f < n_out; ++f) {
      const T* a = in + (o * n_in + t.lo[f]) * inner;
      const T* b = in + (o * n_in + t.hi[f]) * inner;
      const T wa = T(t.wlo[f]), wb = T(t.whi[f]);
      T* dst = out + (o * n_out + f) * inner;
      if (add)
        for (int64_t v = 0; v < inner; ++v) dst[v] += wa * a[v] + wb * b[v];
      else
        for (int64_t v = 0; v < inner; ++v) dst[v] = wa * a[v] + wb * b[v];
    }
}

// Axes that are not coarsened are identities and skipped.
template <typename T>
void Restrict3(const MultigridLevel& L, const T* f, T* c, T* a, T* b) {
  const auto& t = L.to_coarse;
  const int64_t ny = L.grid.shape.ny, nz = L.grid.shape.nz;
  const int64_t mx = t[0].n_coarse, my = t[1].n_coarse;
  const T* in = f;
  if (t[0].coarsened) {
    T* out = t[1].coarsened || t[2].coarsened ? a : c;
    RestrictAxis(t[0], in, out, 1, ny * nz);  // -> (mx, ny, nz)
    in = out;
  }
  if (t[1].coarsened) {
    T* out = t[2].coarsened ? b : c;
    RestrictAxis(t[1], in, out, mx, nz);  // -> (mx, my, nz)
    in = out;
  }
  if (t[2].coarsened) RestrictAxis(t[2], in, c, mx * my, 1);  // -> (mx, my, mz)
  if (!t[0].coarsened && !t[1].coarsened && !t[2].coarsened)
    std::copy(f, f + L.grid.shape.size(), c);
}

template <typename T>
void ProlongAdd3(const MultigridLevel& L, const T* c, T* f, T* a, T* b) {
  const auto& t = L.to_coarse;
  const int64_t ny = L.grid.shape.ny, nz = L.grid.shape.nz;
  const int64_t mx = t[0].n_coarse, my = t[1].n_coarse;
  const T* in = c;
  if (t[2].coarsened) {
    const bool last = !t[1].coarsened && !t[0].coarsened;
    T* out = last ? f : b;
    ProlongAxis(t[2], in, out, mx * my, 1, last);  // -> (mx, my, nz)
    in = out;
  }
  if (t[1].coarsened) {
    const bool last = !t[0].coarsened;
    T* out = last ? f : a;
    ProlongAxis(t[1], in, out, mx, nz, last);  // -> (mx, ny, nz)
    in = out;
  }
  if (t[0].coarsened) ProlongAxis(t[0], in, f, 1, ny * nz, true);  // -> (nx, ny, nz), added
}

#define TL_INSTANTIATE(T)                                                                    \
  template void RestrictAxis<T>(const AxisTransfer&, const T*, T*, int64_t, int64_t);        \
  template void ProlongAxis<T>(const AxisTransfer&, const T*, T*, int64_t, int64_t, bool);   \
  template void Restrict3<T>(const MultigridLevel&, const T*, T*, T*, T*);                   \
  template void ProlongAdd3<T>(const MultigridLevel&, const T*, T*, T*, T*);
TL_INSTANTIATE(float)
TL_INSTANTIATE(double)
#undef TL_INSTANTIATE

}  // namespace translume
