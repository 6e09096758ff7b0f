// SPDX-License-Identifier: MIT
#include "render/boundary_interpolation.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

#include "render/polycube.h"
#include "render/shape.h"

namespace translume {
namespace {

// The 4 boundary nodes nearest to x (boundary indices), by brute force.
std::array<int32_t, 4> Nearest4(const Polygrid& pg, const Vec3& x) {
  std::vector<std::pair<double, int32_t>> d;
  for (int64_t b = 0; b < pg.num_boundary(); ++b)
    d.push_back({(pg.position[pg.num_interior + b] - x).squaredNorm(), int32_t(b)});
  std::partial_sort(d.begin(), d.begin() + 4, d.end());
  return {d[0].second, d[1].second, d[2].second, d[3].second};
}

// The renderer's fallback: inverse squared distance over the 4 nearest.
double InverseDistance(const Polygrid& pg, const Vec3& x, const std::vector<double>& value) {
  double sum = 0, wsum = 0;
  for (int32_t b : Nearest4(pg, x)) {
    const double w = 1 / ((pg.position[pg.num_interior + b] - x).squaredNorm() + 1e-12);
    sum += w * value[size_t(b)];
    wsum += w;
  }
  return sum / wsum;
}

struct Interpolated {
  double value = 0;
  bool found = false;
};
Interpolated Interpolate(const BoundaryElements& e, const Polygrid& pg, const Vec3& x,
                         const std::vector<double>& value) {
  std::array<int32_t, 4> idx;
  std::array<float, 4> w;
  Interpolated r;
  r.found = e.Weights(x, Nearest4(pg, x), &idx, &w);
  if (r.found)
    for (int k = 0; k < 4; ++k) r.value += w[k] * value[size_t(idx[k])];
  return r;
}

// On a box's flat faces the elements reproduce a linear field exactly; the inverse-distance
// weights used before do not (they pull towards the nearest node's value).
TEST(BoundaryInterpolation, LinearFieldOnABoxIsExactOnItsFaces) {
  const Vec3 extent(6, 4, 3);
  const auto box = MakeBoxShape(extent);
  PolygridOptions o;
  o.resolution = 9;
  const Polygrid pg = BuildPolygrid(BuiltinPolycube("box"), *box, o);
  const BoundaryElements elements(pg);
  auto f = [](const Vec3& x) { return 0.3 * x.x() - 0.2 * x.y() + 0.5 * x.z() + 1; };
  std::vector<double> value(size_t(pg.num_boundary()));
  for (int64_t b = 0; b < pg.num_boundary(); ++b) value[size_t(b)] = f(pg.position[pg.num_interior + b]);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> unit(-0.5, 0.5);
  double worst_face = 0, worst_idw = 0, worst_all = 0;
  int found = 0, total = 0;
  for (int i = 0; i < 3000; ++i) {
    // A random point on a random face of the box (centred at the origin).
    Vec3 x(unit(rng) * extent.x(), unit(rng) * extent.y(), unit(rng) * extent.z());
    const int a = i % 3;
    x[a] = (i / 3) % 2 ? extent[a] / 2 : -extent[a] / 2;
    const Interpolated r = Interpolate(elements, pg, x, value);
    ++total;
    if (!r.found) continue;
    ++found;
    // Away from the box's edges, the face's quads are planar.
    bool inner = true;
    for (int k = 0; k < 3; ++k)
      if (k != a && std::abs(x[k]) > extent[k] / 2 - 1.5 * pg.mean_boundary_spacing) inner = false;
    const double err = std::abs(r.value - f(x));
    worst_all = std::max(worst_all, err);
    if (inner) {
      worst_face = std::max(worst_face, err);
      worst_idw = std::max(worst_idw, std::abs(InverseDistance(pg, x, value) - f(x)));
    }
  }
  std::printf("[interpolation] box: %d of %d points in an element (%lld quads, %lld triangles); linear field: "
              "worst error %.2e inside the faces (inverse distance %.2e), %.2e anywhere\n", found, total,
              (long long)elements.num_quads(), (long long)elements.num_triangles(), worst_face, worst_idw, worst_all);
  EXPECT_EQ(found, total);
  EXPECT_EQ(elements.num_triangles(), 8);  // one per corner of the box
  EXPECT_LT(worst_face, 1e-5);
  EXPECT_GT(worst_idw, 100 * worst_face);
  // Across the edges the quads cut the corner by at most ~d / 2 (d = 0.1 spacing): small.
  EXPECT_LT(worst_all, 0.6 * 0.1 * pg.mean_boundary_spacing);
}

// Along a path over the sphere the interpolated value of a smooth field changes smoothly: no
// jumps where the set of nearest nodes changes, as inverse-distance weights have.
TEST(BoundaryInterpolation, ContinuousAlongAPathOnTheSphere) {
  const auto sphere = MakeBuiltinShape("sphere", 20);
  PolygridOptions o;
  o.resolution = 9;
  const Polygrid pg = BuildPolygrid(BuiltinPolycube("sphere"), *sphere, o);
  const BoundaryElements elements(pg);
  std::vector<double> value(size_t(pg.num_boundary()));
  for (int64_t b = 0; b < pg.num_boundary(); ++b) value[size_t(b)] = pg.position[pg.num_interior + b].z();
  // A tilted great circle (it crosses faces, edges and the corners' regions), 4000 steps.
  const int steps = 4000;
  const double step_mm = 2 * M_PI * 10 / steps;
  double prev = 0, prev_idw = 0, worst = 0, worst_idw = 0;
  int found = 0;
  for (int i = 0; i <= steps; ++i) {
    const double phi = 2 * M_PI * i / steps;
    Vec3 x = 10 * Vec3(std::cos(phi), 0.6 * std::sin(phi), 0.8 * std::sin(phi)), n;
    sphere->Project(x, &x, &n);
    const Interpolated r = Interpolate(elements, pg, x, value);
    const double idw = InverseDistance(pg, x, value);
    found += r.found;
    const double v = r.found ? r.value : idw;
    if (i > 0) {
      worst = std::max(worst, std::abs(v - prev));
      worst_idw = std::max(worst_idw, std::abs(idw - prev_idw));
    }
    prev = v;
    prev_idw = idw;
  }
  std::printf("[interpolation] sphere: %d of %d path points in an element; largest change per %.4f mm step: %.2e "
              "(inverse distance %.2e; the field's gradient is at most 1)\n", found, steps + 1, step_mm, worst,
              worst_idw);
  EXPECT_EQ(found, steps + 1);
  EXPECT_LT(worst, 3 * step_mm);
  EXPECT_GT(worst_idw, 5 * worst);
}

}  // namespace
}  // namespace translume
