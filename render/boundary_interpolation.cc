// SPDX-License-Identifier: MIT
#include "render/boundary_interpolation.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <utility>

#include "render/shape.h"

namespace translume {
namespace {

using Lattice = std::array<int, 3>;

Lattice Add(Lattice a, const Lattice& b, int sign = 1) {
  for (int k = 0; k < 3; ++k) a[k] += sign * b[k];
  return a;
}

// The point of the bilinear patch P(s, t) = p00 (1-s)(1-t) + p10 s (1-t) + p01 (1-s) t + p11 s t,
// (s, t) in [0, 1]^2, nearest to x: Gauss-Newton from the centre; where that leaves the square,
// the nearest point on the clamped edge (Newton in the free parameter), so that two patches
// sharing an edge give the same point for x beyond it.
std::pair<double, double> NearestOnBilinearPatch(const Vec3& x, const Vec3& p00, const Vec3& p10, const Vec3& p01,
                                                 const Vec3& p11) {
  auto at = [&](double s, double t) { return Vec3(p00 * (1 - s) * (1 - t) + p10 * s * (1 - t) + p01 * (1 - s) * t + p11 * s * t); };
  auto ds = [&](double t) { return Vec3((p10 - p00) * (1 - t) + (p11 - p01) * t); };
  auto dt = [&](double s) { return Vec3((p01 - p00) * (1 - s) + (p11 - p10) * s); };
  double s = 0.5, t = 0.5;
  for (int it = 0; it < 12; ++it) {
    Eigen::Matrix<double, 3, 2> J;
    J << ds(t), dt(s);
    const Eigen::Vector2d step = (J.transpose() * J).ldlt().solve(J.transpose() * (x - at(s, t)));
    if (!step.allFinite()) break;
    s += step[0];
    t += step[1];
    if (step.squaredNorm() < 1e-20) break;
  }
  if (s >= 0 && s <= 1 && t >= 0 && t <= 1) return {s, t};
  // On an edge: hold the parameter that left [0, 1] (the one further out), move the other.
  const bool hold_s = std::max(-s, s - 1) >= std::max(-t, t - 1);
  s = std::clamp(s, 0.0, 1.0);
  t = std::clamp(t, 0.0, 1.0);
  for (int it = 0; it < 12; ++it) {
    const Vec3 d = hold_s ? dt(s) : ds(t);
    const double step = d.dot(x - at(s, t)) / d.squaredNorm();
    if (!std::isfinite(step)) break;
    double& free = hold_s ? t : s;
    free = std::clamp(free + step, 0.0, 1.0);
    if (step * step < 1e-20) break;
  }
  return {s, t};
}

}  // namespace

BoundaryElements::BoundaryElements(const Polygrid& pg) : pg_(pg) {
  const int64_t nb = pg.num_boundary();
  // The boundary node (index b - num_interior) at lattice g linked along dir, or -1.
  const BoundaryNodeIndex index(pg);
  auto find = [&](const Lattice& g, int dir) {
    const int64_t k = index.Find(g, dir);
    return int32_t(k < 0 ? -1 : k - pg.num_interior);
  };
  for (int64_t b = 0; b < nb; ++b) {
    const int dir = pg.link_dir[b];
    const Lattice g = pg.lattice[pg.num_interior + b], n = LatticeStep(dir);
    const int a = dir / 2, u = (a + 1) % 3, v = (a + 2) % 3;
    // A face's quad, from its lowest corner.
    const int32_t bu = find(Add(g, LatticeStep(2 * u + 1)), dir), bv = find(Add(g, LatticeStep(2 * v + 1)), dir);
    const int32_t buv = find(Add(Add(g, LatticeStep(2 * u + 1)), LatticeStep(2 * v + 1)), dir);
    if (bu >= 0 && bv >= 0 && buv >= 0) elements_.push_back({{int32_t(b), bu, bv, buv}});
    // Across a convex edge: towards the edge (direction s in the face) no node of this face,
    // the other face's counterpart at g + s - n. Each quad from the lower-indexed rim node, and
    // along the edge from the lower lattice end.
    for (int k = 0; k < 4; ++k) {
      const int sdir = k < 2 ? 2 * u + k : 2 * v + k - 2;
      const Lattice s = LatticeStep(sdir);
      if (find(Add(g, s), dir) >= 0) continue;
      const int32_t p = find(Add(Add(g, s), n, -1), sdir);
      if (p < 0 || p < b) continue;
      const int t = k < 2 ? v : u;  // along the edge
      const int32_t bt = find(Add(g, LatticeStep(2 * t + 1)), dir);
      const int32_t pt = find(Add(pg.lattice[pg.num_interior + p], LatticeStep(2 * t + 1)), sdir);
      if (bt >= 0 && pt >= 0) elements_.push_back({{int32_t(b), bt, int32_t(p), pt}});
    }
  }
  num_quads_ = int64_t(elements_.size());
  // Convex corners: a node with counterparts across both of its face's rims at the corner.
  for (int64_t b = 0; b < nb; ++b) {
    const int dir = pg.link_dir[b];
    const Lattice g = pg.lattice[pg.num_interior + b], n = LatticeStep(dir);
    const int a = dir / 2, u = (a + 1) % 3, v = (a + 2) % 3;
    for (int su : {2 * u, 2 * u + 1})
      for (int sv : {2 * v, 2 * v + 1}) {
        if (find(Add(g, LatticeStep(su)), dir) >= 0 || find(Add(g, LatticeStep(sv)), dir) >= 0) continue;
        const int32_t p = find(Add(Add(g, LatticeStep(su)), n, -1), su), q = find(Add(Add(g, LatticeStep(sv)), n, -1), sv);
        if (p < 0 || q < 0 || p < b || q < b) continue;
        elements_.push_back({{int32_t(b), p, q, -1}});
      }
  }
  of_node_.assign(size_t(nb), {});
  for (size_t e = 0; e < elements_.size(); ++e)
    for (int32_t node : elements_[e].node)
      if (node >= 0) of_node_[size_t(node)].push_back(int32_t(e));
}

bool BoundaryElements::Weights(const Vec3& x, const std::array<int32_t, 4>& near, std::array<int32_t, 4>* idx,
                               std::array<float, 4>* w) const {
  double best = pg_.mean_boundary_spacing * pg_.mean_boundary_spacing;
  bool found = false;
  auto position = [&](int32_t b) -> const Vec3& { return pg_.position[pg_.num_interior + b]; };
  std::array<int32_t, 16> seen;
  int num_seen = 0;
  for (int32_t nb : near) {
    if (nb < 0) continue;
    for (int32_t e : of_node_[size_t(nb)]) {
      if (std::find(seen.begin(), seen.begin() + num_seen, e) != seen.begin() + num_seen) continue;
      if (num_seen < int(seen.size())) seen[size_t(num_seen++)] = e;
      const auto& c = elements_[size_t(e)].node;
      std::array<double, 4> weight;
      Vec3 at;
      if (c[3] < 0) {
        at = ClosestPointOnTriangle(x, position(c[0]), position(c[1]), position(c[2]), &weight[0], &weight[1],
                                    &weight[2]);
        weight[3] = 0;
      } else {
        const auto [s, t] = NearestOnBilinearPatch(x, position(c[0]), position(c[1]), position(c[2]), position(c[3]));
        weight = {(1 - s) * (1 - t), s * (1 - t), (1 - s) * t, s * t};
        at = weight[0] * position(c[0]) + weight[1] * position(c[1]) + weight[2] * position(c[2]) +
             weight[3] * position(c[3]);
      }
      const double d2 = (at - x).squaredNorm();
      if (!(d2 < best)) continue;
      best = d2;
      found = true;
      *idx = {c[0], c[1], c[2], c[3] < 0 ? c[0] : c[3]};
      for (int k = 0; k < 4; ++k) (*w)[size_t(k)] = float(weight[size_t(k)]);
    }
  }
  return found;
}

}  // namespace translume
