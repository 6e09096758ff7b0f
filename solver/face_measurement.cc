// SPDX-License-Identifier: MIT
#include "solver/face_measurement.h"

#include <algorithm>

#include "solver/status.h"

namespace translume {
namespace {

struct Tap {
  int64_t index;
  double weight;
};
using Rule = std::vector<std::vector<Tap>>;  // per output node along one axis

// MeasureFace's 1-D rule over n nodes (face_measurement.h).
Rule NodeRule(int64_t n) {
  TL_CHECK(n >= 2);
  Rule r(n);
  auto border = [&](int64_t i, int64_t inward) {
    if (n == 2) r[i] = {{i, 0.75}, {i + inward, 0.25}};
    else r[i] = {{i, 8.0 / 12}, {i + inward, 5.0 / 12}, {i + 2 * inward, -1.0 / 12}};
  };
  border(0, 1);
  border(n - 1, -1);
  for (int64_t i = 1; i + 1 < n; ++i) r[i] = {{i - 1, 1.0 / 24}, {i, 22.0 / 24}, {i + 1, 1.0 / 24}};
  return r;
}

// BoxMeansOfFineFace's 1-D rule: coarse node i of n over the fine nodes of its box.
Rule FineRule(int64_t n, int K) {
  TL_CHECK(K >= 2 && K % 2 == 0);
  const int64_t nf = (n - 1) * K + 1;
  Rule r(n);
  for (int64_t i = 0; i < n; ++i) {
    const int64_t lo = std::max<int64_t>(0, i * K - K / 2), hi = std::min(nf - 1, i * K + K / 2);
    const int64_t m = hi - lo;  // fine intervals in the box
    std::vector<Tap>& t = r[i];
    if (m == 1) {
      // One interval [lo, hi]: the quadratic through it and the next node inwards.
      const int64_t in = lo == 0 ? 1 : -1, a = lo == 0 ? lo : hi, b = a + in, c = b + in;
      t = {{a, 5.0 / 12}, {b, 8.0 / 12}, {c, -1.0 / 12}};
    } else if (m == 3) {
      t = {{lo, 1.0 / 8}, {lo + 1, 3.0 / 8}, {lo + 2, 3.0 / 8}, {lo + 3, 1.0 / 8}};
    } else {
      TL_CHECK(m % 2 == 0);
      for (int64_t d = 0; d <= m; ++d) {
        const double w = d == 0 || d == m ? 1 : d % 2 ? 4 : 2;
        t.push_back({lo + d, w / (3.0 * m)});
      }
    }
  }
  return r;
}

// out(i, j) = sum_a sum_b rx[i][a].w ry[j][b].w in(rx[i][a].index, ry[j][b].index), or its
// transpose (scattering out's values back to in's nodes).
template <typename In, typename Out>
void ApplySeparable(const Rule& rx, const Rule& ry, const In* in, int64_t in_nx, Out* out,
                    bool transpose) {
  const int64_t nx = int64_t(rx.size()), ny = int64_t(ry.size());
  for (int64_t j = 0; j < ny; ++j)
    for (int64_t i = 0; i < nx; ++i) {
      double v = 0;
      for (const Tap& b : ry[j])
        for (const Tap& a : rx[i]) {
          if (transpose)
            out[a.index + in_nx * b.index] += Out(a.weight * b.weight * double(in[i + nx * j]));
          else
            v += a.weight * b.weight * double(in[a.index + in_nx * b.index]);
        }
      if (!transpose) out[i + nx * j] = Out(v);
    }
}

}  // namespace

void MeasureFace(int64_t nx, int64_t ny, const double* L, double* out) {
  TL_CHECK(L != out);
  ApplySeparable(NodeRule(nx), NodeRule(ny), L, nx, out, false);
}

void MeasureFaceTranspose(int64_t nx, int64_t ny, const double* v, double* out) {
  TL_CHECK(v != out);
  std::fill(out, out + nx * ny, 0.0);
  ApplySeparable(NodeRule(nx), NodeRule(ny), v, nx, out, true);
}

std::vector<float> MeasureFace(const GridShape& s, const std::vector<float>& L) {
  TL_CHECK(int64_t(L.size()) == s.face_size());
  std::vector<float> out(L.size());
  ApplySeparable(NodeRule(s.nx), NodeRule(s.ny), L.data(), s.nx, out.data(), false);
  return out;
}

std::vector<float> BoxMeansOfFineFace(const GridShape& coarse, int K, const std::vector<float>& fine_L) {
  if (K == 1) return MeasureFace(coarse, fine_L);
  const int64_t fnx = (coarse.nx - 1) * K + 1, fny = (coarse.ny - 1) * K + 1;
  TL_CHECK(int64_t(fine_L.size()) == fnx * fny);
  std::vector<float> out(coarse.face_size());
  ApplySeparable(FineRule(coarse.nx, K), FineRule(coarse.ny, K), fine_L.data(), fnx, out.data(), false);
  return out;
}

}  // namespace translume
