// SPDX-License-Identifier: MIT
#include "render/polygrid.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <map>
#include <random>

#include "render/diffusion.h"
#include "render/material_map.h"
#include "render/mesh_io.h"
#include "render/test_metrics.h"
#include "solver/forward.h"
#include "solver/status.h"

namespace translume {
namespace {

void ExpectWellFormed(const Polygrid& pg) {
  ASSERT_GT(pg.num_interior, 0);
  std::vector<int> boundary_links(pg.size(), 0);
  for (int64_t i = 0; i < pg.num_interior; ++i)
    for (int j = 0; j < 6; ++j) {
      const int32_t k = pg.neighbours[i][j];
      ASSERT_GE(k, 0);
      ASSERT_LT(k, pg.size());
      if (pg.is_boundary(k)) {
        ++boundary_links[k];
        EXPECT_EQ(pg.neighbours[k][0], i);
      }
      EXPECT_TRUE(std::isfinite(pg.weights[i][j]));
      EXPECT_GT(pg.weights[i][j], 0);
    }
  // The wide stencil's rows, where there are any: finite, non-negative, no weight on a missing
  // neighbour, every neighbour a node.
  if (!pg.stencil_weights.empty()) {
    ASSERT_EQ(int64_t(pg.stencil_weights.size()), pg.num_interior);
    ASSERT_EQ(int64_t(pg.diagonal_neighbours.size()), pg.num_interior);
    for (int64_t i = 0; i < pg.num_interior; ++i)
      for (int k = 0; k < 18; ++k) {
        const float w = pg.stencil_weights[i][k];
        EXPECT_TRUE(std::isfinite(w) && w >= 0) << i << " " << k;
        if (k < 6) continue;
        const int32_t n = pg.diagonal_neighbours[i][k - 6];
        EXPECT_LT(n, pg.size());
        if (n < 0) {
          EXPECT_EQ(w, 0.f) << i << " " << k;
        }
      }
  } else {
    EXPECT_EQ(pg.diagonal_stencil_nodes, 0);
  }
  for (int64_t b = pg.num_interior; b < pg.size(); ++b) {
    EXPECT_EQ(boundary_links[b], 1) << "boundary node " << b;
    for (int j = 1; j < 6; ++j) EXPECT_EQ(pg.neighbours[b][j], -1);
    // The first interior node sits at d along the inward normal when it has this one boundary
    // link; with two or three (polycube edges and corners on a smooth surface) it takes the mean
    // of the d-offset points, somewhat closer.
    const int32_t i = pg.neighbours[b][0];
    int links = 0;
    for (int j = 0; j < 6; ++j) links += pg.is_boundary(pg.neighbours[i][j]);
    const double len = pg.link_length[b - pg.num_interior];
    if (links == 1) {
      EXPECT_NEAR(len, pg.first_layer_distance, 1e-6 * pg.first_layer_distance);
    } else {
      EXPECT_GT(len, 0.2 * pg.first_layer_distance);
      EXPECT_LT(len, pg.mean_boundary_spacing);
    }
    EXPECT_EQ(pg.layer[b], 0);
  }
}

// The exact boundary radiance phi(R) / (2 pi) of a homogeneous sphere of radius R (mm) under
// uniform light q = 1: by symmetry phi(r) = A sinh(r / l) / r with l = sqrt(kappa / mu), and A
// from the Robin condition phi + 2 C kappa dphi/dr = 1 at r = R.
double RadialSphereRadiance(double kappa, double mu, double R, double C) {
  const double l = std::sqrt(kappa / mu), phi_R = std::sinh(R / l) / R;
  const double dphi_R = std::cosh(R / l) / (l * R) - std::sinh(R / l) / (R * R);
  return phi_R / (phi_R + 2 * C * kappa * dphi_R) / (2 * M_PI);
}

// The boundary radiance (red) of a homogeneous polygrid under uniform light q = 1, from the
// reference solve; L = phi / (2 pi), as the renderer shades (renderer.cc).
std::vector<float> UniformlyLitRadiance(const Polygrid& pg, float kappa, float mu, double C) {
  const NodeMaterial m = ConstantNodeMaterial(pg, {kappa, kappa, kappa}, {mu, mu, mu});
  BoundaryLight q, none;
  for (int c = 0; c < 3; ++c) {
    q[c].assign(pg.num_boundary(), 1.f);
    none[c].assign(pg.num_boundary(), 0.f);
  }
  return BoundaryRadiance(pg, m, none, SolveReference(BuildJacobiSystem(pg, m, C, q), 1))[0];
}

struct Spread {
  double mean = 0, sd = 0, range = 0;  // sd and max - min relative to the mean
};
Spread SpreadOf(const std::vector<float>& v) {
  double sum = 0, sq = 0, lo = 1e300, hi = -1e300;
  for (float x : v) {
    sum += x;
    sq += double(x) * x;
    lo = std::min(lo, double(x));
    hi = std::max(hi, double(x));
  }
  Spread s;
  s.mean = sum / double(v.size());
  s.sd = std::sqrt(std::max(0.0, sq / double(v.size()) - s.mean * s.mean)) / s.mean;
  s.range = (hi - lo) / s.mean;
  return s;
}

TEST(Polygrid, SingleCubeBoxCountsAndGeometry) {
  const auto box = MakeBoxShape(Vec3(4, 4, 4));
  PolygridOptions o;
  o.resolution = 9;
  const Polygrid pg = BuildPolygrid(BuiltinPolycube("box"), *box, o);
  EXPECT_EQ(pg.num_interior, 7 * 7 * 7);
  EXPECT_EQ(pg.num_boundary(), 6 * 7 * 7);  // convex edge and corner nodes removed
  ExpectWellFormed(pg);
  EXPECT_NEAR(pg.first_layer_distance, 0.1 * pg.mean_boundary_spacing, 1e-12);
  // A box gives a tensor-product grid: boundary nodes on the faces, every link along the face
  // normal with length d, the grid lines continued to the surface, every 6x6 system regular.
  EXPECT_EQ(pg.fallback_weights, 0);
  for (int64_t b = pg.num_interior; b < pg.size(); ++b) {
    const int dir = pg.link_dir[b - pg.num_interior], axis = dir / 2;
    EXPECT_NEAR(std::abs(pg.position[b][axis]), 2.0, 1e-9);
    const Vec3 link = pg.position[b] - pg.position[pg.neighbours[b][0]];
    EXPECT_NEAR(link[axis], dir % 2 ? pg.first_layer_distance : -pg.first_layer_distance, 1e-6);
    EXPECT_NEAR(link.norm(), pg.first_layer_distance, 1e-6);
  }
  for (int64_t i = 0; i < pg.num_interior; ++i)
    for (int a = 0; a < 3; ++a) {
      // Nodes that share a lattice coordinate share the world coordinate: straight grid lines.
      const int64_t k = pg.neighbours[i][2 * ((a + 1) % 3) + 1];
      if (k < pg.num_interior) {
        EXPECT_NEAR(pg.position[i][a], pg.position[k][a], 1e-9) << i;
      }
    }
}

// Winslow's placement leaves a box's tensor-product grid where it is (it solves the same
// equations there: straight, evenly spaced grid lines).
TEST(Polygrid, WinslowPlacementKeepsTheBoxGrid) {
  const auto box = MakeBoxShape(Vec3(4, 4, 4));
  PolygridOptions o;
  o.resolution = 9;
  const Polygrid a = BuildPolygrid(BuiltinPolycube("box"), *box, o);
  o.placement = InteriorPlacement::kWinslow;
  const Polygrid b = BuildPolygrid(BuiltinPolycube("box"), *box, o);
  ASSERT_EQ(a.size(), b.size());
  EXPECT_EQ(b.fallback_weights, 0);
  double worst = 0;
  for (int64_t n = 0; n < a.size(); ++n) worst = std::max(worst, (a.position[n] - b.position[n]).norm());
  EXPECT_LT(worst, 1e-6);
  EXPECT_THROW(ParseInteriorPlacement("conformal"), InputError);
}

// A 12-triangle cube read as a mesh is the same box as the built-in one, so its polygrid must
// be the same: boundary nodes, normals, links along the face normals. The mesh's normals used
// to be interpolated from the vertex normals (the cube's diagonals at every corner), which
// tilted the boundary normals by up to 55 degrees, so the incident light's cosine and the
// first layer's placement were wrong on every flat-faced mesh.
TEST(Polygrid, CubeMeshMatchesBuiltinBox) {
  const auto box = MakeBoxShape(Vec3(4, 4, 4));
  const auto cube = MakeMeshShape(MakeBoxShape(Vec3(4, 4, 4), 1)->mesh(), "cube.obj", 0);
  ASSERT_EQ(cube->mesh().triangles.size(), 12u);
  PolygridOptions o;
  o.resolution = 9;
  const Polygrid a = BuildPolygrid(BuiltinPolycube("box"), *box, o);
  const Polygrid b = BuildPolygrid(BuiltinPolycube("box"), *cube, o);
  ExpectWellFormed(b);
  ASSERT_EQ(a.size(), b.size());
  ASSERT_EQ(a.num_interior, b.num_interior);
  double pos = 0, nrm = 0;
  for (int64_t n = 0; n < a.size(); ++n) pos = std::max(pos, (a.position[n] - b.position[n]).norm());
  for (int64_t k = 0; k < a.num_boundary(); ++k) nrm = std::max(nrm, (a.normal[k] - b.normal[k]).norm());
  EXPECT_LT(pos, 1e-6);
  EXPECT_LT(nrm, 1e-9);
}

TEST(Polygrid, BuiltinShapesAreWellFormed) {
  for (const std::string name : {"sphere", "blob", "torus", "slab"}) {
    SCOPED_TRACE(name);
    const auto shape = MakeBuiltinShape(name, 20);
    PolygridOptions o;
    o.resolution = 9;
    const Polygrid pg = BuildPolygrid(BuiltinPolycube(name), *shape, o);
    ExpectWellFormed(pg);
    // Boundary nodes are on the surface.
    for (int64_t b = pg.num_interior; b < pg.size(); b += 7) {
      Vec3 s, n;
      shape->Project(pg.position[b], &s, &n);
      EXPECT_NEAR((s - pg.position[b]).norm(), 0, 1e-6 * 20);
    }
    std::printf("[polygrid] %s: %lld interior + %lld boundary nodes, spacing %.3f mm, d %.4f mm, "
                "%lld nodes with fallback weights\n",
                name.c_str(), (long long)pg.num_interior, (long long)pg.num_boundary(),
                pg.mean_boundary_spacing, pg.first_layer_distance, (long long)pg.fallback_weights);
  }
}

// The same shapes as faceted meshes (latitude-longitude triangles, ~2.5 mm apart, coarser
// than the polygrid's ~1.7 mm): the closest point on such a mesh takes every node of a convex
// vertex's region to that vertex, which put polycube-edge nodes of two faces on one point
// (infinite Laplacian weights, NaN diffusion, a black render). The nodes must stay apart, and
// under uniform light the mesh's boundary radiance must match the analytic shape's (within 3 %;
// 0.1 % for the sphere, 2.4 % for the torus).
TEST(Polygrid, FacetedMeshesAreWellFormed) {
  for (const std::string name : {"sphere", "torus"}) {
    SCOPED_TRACE(name);
    const auto analytic = MakeBuiltinShape(name, 20);
    const auto mesh = MakeMeshShape(MakeBuiltinShape(name, 20, 12)->mesh(), name + ".obj", 20);
    PolygridOptions o;
    o.resolution = 13;
    double mean_radiance[2];
    // The mesh first: where Winslow's placement diverged on it and the smoothed nodes were
    // kept, the analytic shape is placed the same way, so that the comparison is of the
    // surfaces alone (the placements differ by 1.8 % in the torus's mean: smoothed 0.1185,
    // Winslow 0.1164). The faceted torus diverged while its boundary was folded at the hole's
    // corners (TorusMeshBoundaryIsNotFolded); it converges now, 2.7 % from the analytic torus.
    for (int s = 1; s >= 0; --s) {
      const Polygrid pg = BuildPolygrid(BuiltinPolycube(name), s ? *mesh : *analytic, o);
      if (s == 1 && pg.placement_note.find("diverged") != std::string::npos) {
        o.placement = InteriorPlacement::kVariance;
        o.variance_iterations = 0;
      }
      if (!pg.placement_note.empty())
        std::printf("[polygrid] %s (%s): %s\n", name.c_str(), s ? "mesh" : "analytic", pg.placement_note.c_str());
      ExpectWellFormed(pg);
      double nearest = 1e300;  // between boundary nodes of nearby lattice points (split concave
      // nodes, one lattice point, share their surface point by design)
      for (int64_t b = pg.num_interior; b < pg.size(); ++b)
        for (int64_t c = b + 1; c < pg.size(); ++c) {
          int lattice_gap = 0;
          for (int a = 0; a < 3; ++a) lattice_gap += std::abs(pg.lattice[b][a] - pg.lattice[c][a]);
          if (lattice_gap >= 1 && lattice_gap <= 2) nearest = std::min(nearest, (pg.position[b] - pg.position[c]).norm());
        }
      EXPECT_GT(nearest, 1e-3 * pg.mean_boundary_spacing);
      std::printf("[polygrid] %s (%s): nearest boundary nodes %.3g spacings apart\n", name.c_str(),
                  s ? "mesh" : "analytic", nearest / pg.mean_boundary_spacing);
      mean_radiance[s] = SpreadOf(UniformlyLitRadiance(pg, 0.5f, 0.05f, ReflectionParameterC(1.3))).mean;
    }
    std::printf("[polygrid] %s under uniform light: mean boundary radiance %.5f (analytic) %.5f "
                "(mesh)\n", name.c_str(), mean_radiance[0], mean_radiance[1]);
    EXPECT_GT(mean_radiance[0], 0);
    EXPECT_NEAR(mean_radiance[1] / mean_radiance[0], 1.0, 0.03);
  }
}

// Cells whose det J (J's columns: the central differences of the node's lattice neighbours)
// is below 0.02 of |J_1| |J_2| |J_3|: near flat or inverted. *worst: the smallest such ratio.
int64_t PoorCells(const Polygrid& pg, double* worst) {
  int64_t poor = 0;
  *worst = 1;
  for (int64_t i = 0; i < pg.num_interior; ++i) {
    Eigen::Matrix3d J;
    for (int a = 0; a < 3; ++a)
      J.col(a) = (pg.position[pg.neighbours[i][2 * a + 1]] - pg.position[pg.neighbours[i][2 * a]]) / 2;
    const double quality = J.determinant() / (J.col(0).norm() * J.col(1).norm() * J.col(2).norm());
    *worst = std::min(*worst, quality);
    poor += quality < 0.02;
  }
  return poor;
}

// Near the polycube's hole corners the line from the one cube's centre through a torus mesh's
// boundary node runs past the inner wall and meets the surface beyond the cube; those nodes
// landed far from their neighbours and the smoothed grid had 296 cells with det J below 0.02
// of |J_1| |J_2| |J_3| (most inverted, down to -0.96) where the analytic torus has none. Such
// nodes now take a nearer line (worst cell 0.05).
TEST(Polygrid, TorusMeshBoundaryIsNotFolded) {
  const auto mesh = MakeMeshShape(MakeBuiltinShape("torus", 20, 48)->mesh(), "torus.obj", 20);
  PolygridOptions o;
  o.resolution = 13;
  o.placement = InteriorPlacement::kVariance;
  o.variance_iterations = 0;  // the smoothed grid, before any placement
  const Polygrid pg = BuildPolygrid(BuiltinPolycube("torus"), *mesh, o);
  ExpectWellFormed(pg);
  double worst;
  const int64_t poor = PoorCells(pg, &worst);
  std::printf("[polygrid] torus mesh 13^3, smoothed grid: %lld cells of quality below 0.02, worst %.3f\n",
              (long long)poor, worst);
  EXPECT_EQ(poor, 0);
}

// The boundary nodes stay evenly spread on smooth shapes: neighbouring boundary nodes of one
// polycube face (lattice neighbours with the same link direction) are at most 2.5x as far
// apart at one place as at another (sphere 1.78x, blob 1.93x; the cube's own distortion). The
// alignment passes, when they ran on smooth sides too, pulled the nodes towards the cube's
// edges (sphere 0.35 to 2.05 mm, 5.8x; blob 0.10 to 3.33 mm, 33x), which showed as streaks and
// blotches in renders. (The torus is left out: its inner equator is shorter
// than its outer one, 4.1x.)
TEST(Polygrid, BoundaryNodesStayEvenOnSmoothShapes) {
  for (const char* name : {"sphere", "blob"}) {
    const auto shape = MakeBuiltinShape(name, 20);
    PolygridOptions o;
    o.resolution = 17;
    const Polygrid pg = BuildPolygrid(BuiltinPolycube(name), *shape, o);
    std::map<std::array<int, 4>, int64_t> at;
    for (int64_t b = pg.num_interior; b < pg.size(); ++b) {
      const auto& g = pg.lattice[b];
      at[{g[0], g[1], g[2], pg.link_dir[b - pg.num_interior]}] = b;
    }
    double lo = 1e300, hi = 0;
    for (const auto& [key, b] : at)
      for (int a = 0; a < 3; ++a) {
        if (a == key[3] / 2) continue;
        std::array<int, 4> next = key;
        ++next[a];
        const auto it = at.find(next);
        if (it == at.end()) continue;
        const double l = (pg.position[it->second] - pg.position[b]).norm();
        lo = std::min(lo, l);
        hi = std::max(hi, l);
      }
    std::printf("[polygrid] %s 17^3: neighbouring boundary nodes %.3f to %.3f mm apart (%.2fx)\n", name, lo, hi, hi / lo);
    EXPECT_LT(hi / lo, 2.5) << name;
  }
}

// A homogeneous sphere (radius R = 10 mm) under uniform light q = 1 (RadialSphereRadiance): by
// symmetry the exact boundary radiance is uniform. At 13^3 and 17^3 the polygrid's mean is
// within 2 % of it (-0.7 %, -0.6 %), its sd under 1.05 % of the mean (0.95 %, 0.52 %; with the
// six weights, Polygrid::stencil_weights off, -4.2 %, -3.4 % and 0.96 %, 1.01 %; 1.13 %, 1.21 %
// before the leaning links read phi at their foot). Before links
// off the normal counted their normal extent, the sd was 8 % and the mean 9 % high; with the
// paper's variance steps instead of Winslow's placement it is 1.6 %, 3.3 %. What is left comes
// from the first interior nodes along the cube's edges, where the 6x6 weights fail
// (docs/render.md, "Accuracy on curved shapes"): with the axis weights there the mean was
// -3.2 %, -0.7 % but the sd 1.0 %, 1.4 % and growing with the resolution (2.6 % at 25^3, 3.0 %
// at 33^3); FirstOrderAxisWeights keep it at 1.1-1.2 % and the mean converging (-2.9 %, -2.3 %
// at 25^3, 33^3). At 9^3 the coarse grid adds its own error (h = 2.5 mm against a diffusion
// length of 3.2 mm).
TEST(Polygrid, UniformlyLitSphereMatchesTheRadialSolution) {
  const double R = 10, C = ReflectionParameterC(1.3), exact = RadialSphereRadiance(0.5, 0.05, R, C);
  const auto shape = MakeBuiltinShape("sphere", 2 * R);
  for (int resolution : {13, 17}) {
    PolygridOptions o;
    o.resolution = resolution;
    const Polygrid pg = BuildPolygrid(BuiltinPolycube("sphere"), *shape, o);
    const Spread L = SpreadOf(UniformlyLitRadiance(pg, 0.5f, 0.05f, C));
    std::printf("[polygrid] uniformly lit sphere %d^3: mean radiance %.5f (exact %.5f), sd %.4f, max - min %.4f of "
                "the mean (%lld fallback nodes of %lld interior)\n", resolution, L.mean, exact, L.sd, L.range,
                (long long)pg.fallback_weights, (long long)pg.num_interior);
    EXPECT_NEAR(L.mean / exact, 1.0, 0.02) << resolution;
    EXPECT_LT(L.sd, 0.0105) << resolution;
    EXPECT_LT(L.range, 0.03) << resolution;
  }
}

struct LitSphereError {
  double rms = 0, far_rms = 0, worst = 0;  // relative; far: cos theta < -0.3
};

// The polygrid's boundary radiance (the reference solve) against LitSphereRadiance, over eight
// light directions: along a face's normal (+z), towards a corner (1, 1, 1), and six random ones.
LitSphereError DirectionallyLitSphereError(const Polygrid& pg, float kappa, float mu, double R, double C) {
  const LitSphereRadiance exact(kappa, mu, R, C, [](double c) { return std::max(0.0, c); });
  const NodeMaterial m = ConstantNodeMaterial(pg, {kappa, kappa, kappa}, {mu, mu, mu});
  std::mt19937 rng(7);
  std::normal_distribution<double> g;
  double sq = 0, far_sq = 0;
  int64_t n = 0, far_n = 0;
  LitSphereError e;
  for (int dir = 0; dir < 8; ++dir) {
    const Vec3 d = dir == 0 ? Vec3(0, 0, 1)
                   : dir == 1 ? Vec3(1, 1, 1).normalized()
                              : Vec3(g(rng), g(rng), g(rng)).normalized();
    std::vector<double> cos_theta(pg.num_boundary());
    BoundaryLight q;
    for (int64_t b = 0; b < pg.num_boundary(); ++b)
      cos_theta[b] = pg.position[pg.num_interior + b].normalized().dot(d);
    q[0].resize(pg.num_boundary());
    for (int64_t b = 0; b < pg.num_boundary(); ++b) q[0][b] = float(std::max(0.0, cos_theta[b]));
    q[1] = q[2] = q[0];
    const std::vector<float> L = ShadedRadiance(pg, m, SolveReference(BuildJacobiSystem(pg, m, C, q), 1))[0];
    for (int64_t b = 0; b < pg.num_boundary(); ++b) {
      const double r = L[b] / exact(cos_theta[b]) - 1;
      sq += r * r;
      ++n;
      e.worst = std::max(e.worst, std::abs(r));
      if (cos_theta[b] < -0.3) {
        far_sq += r * r;
        ++far_n;
      }
    }
  }
  e.rms = std::sqrt(sq / double(n));
  e.far_rms = std::sqrt(far_sq / double(far_n));
  return e;
}

// The boundary links of the sphere's first interior nodes along the single cube's edges lean
// far off the normal; the Robin condition reads phi at each link's foot v_b - d n_b, interpolated
// from the interior node and the nodes beside it (Polygrid::foot_weights). Interpolating the
// positions themselves checks it for every linear field at once: the interpolated point lies
// within a small fraction of a spacing of the foot, where the interior node itself (what the
// condition read before) lies 0.66 spacings from it on average.
TEST(Polygrid, LeaningLinksReadTheirFootBesideTheInteriorNode) {
  const auto shape = MakeBuiltinShape("sphere", 20);
  for (int resolution : {9, 17}) {
    PolygridOptions o;
    o.resolution = resolution;
    const Polygrid pg = BuildPolygrid(BuiltinPolycube("sphere"), *shape, o);
    double before_sum = 0, after_sum = 0, after_max = 0;
    int leaning = 0, capped = 0, capped_corner_full = 0;
    for (int64_t b = pg.num_interior; b < pg.size(); ++b) {
      const std::array<float, 6>& w = pg.foot_weights[b - pg.num_interior];
      const int32_t j = pg.neighbours[b][0];
      int links = 0;
      for (int k = 0; k < 6; ++k) links += pg.is_boundary(pg.neighbours[j][k]);
      double sum = 0;
      for (int k = 0; k < 6; ++k) {
        EXPECT_GE(w[k], 0.f);
        EXPECT_TRUE(w[k] == 0 || !pg.is_boundary(pg.neighbours[j][k])) << "a weight on a boundary node";
        sum += w[k];
      }
      EXPECT_LE(sum, 1 + 1e-6);
      if (links == 1) {
        EXPECT_EQ(sum, 0) << "a normal link has its foot on the interior node";
        continue;
      }
      const Vec3 foot = pg.position[b] - pg.link_length[b - pg.num_interior] * pg.normal[b - pg.num_interior];
      Vec3 at = (1 - sum) * pg.position[j];
      for (int k = 0; k < 6; ++k) at += double(w[k]) * pg.position[pg.neighbours[j][k]];
      const double before = (pg.position[j] - foot).norm() / pg.mean_boundary_spacing;
      const double after = (at - foot).norm() / pg.mean_boundary_spacing;
      before_sum += before;
      after_sum += after;
      after_max = std::max(after_max, after);
      ++leaning;
      // Homogeneous rows whose lateral slab term the cap d^2 W <= 2 (1 - sum) scales down.
      const int axis = pg.link_dir[b - pg.num_interior] / 2;
      double W = 0;
      for (int k = 0; k < 6; ++k)
        if (k / 2 != axis) W += pg.weights[j][k];
      const double d = pg.link_length[b - pg.num_interior];
      capped += d * d * W > 2 * (1 - sum);
      capped_corner_full += d * d * W > 2 * (1 - sum) && links == 3 && sum > 0.999;
    }
    std::printf("[polygrid] sphere %d^3: %d leaning links; their foot read %.3f spacings off on average (at most "
                "%.3f), against %.3f at the interior node; %d rows with the lateral term capped (%d at corner "
                "nodes, their foot at the neighbours)\n", resolution, leaning, after_sum / leaning, after_max,
                before_sum / leaning, capped, capped_corner_full);
    EXPECT_GT(leaning, 0);
    EXPECT_LT(after_sum, 0.25 * before_sum) << resolution;
    EXPECT_LT(after_max, 0.2) << resolution;
  }
}

// Light through the sphere: kappa 1 mm, mu 0.02/mm (diffusion length 7.1 mm) in a 20 mm sphere,
// so the far side gets ~6 % of the lit pole's radiance. The error sits along the single cube's
// edges, where the 6x6 weights fail (first interior nodes): with the axis weights there, their
// drift made dark lines on the far side (far-side rms 15.5 % at 17^3, 14.2 % at 25^3: not
// converging); FirstOrderAxisWeights: 10.2 %, 8.2 %; reading the leaning links' feet
// (Polygrid::foot_weights): 9.5 %, 8.0 %, the worst node 46 -> 34.5 % at 17^3. Under light
// oblique to the cube's axes the six weights, which have no mixed terms, missed most on the dark
// side next to the terminator, where the sheared cells meet large mixed derivatives; the wide
// stencil (Polygrid::stencil_weights) meets them: rms 8.3 -> 2.6 % (17^3), 6.9 -> 1.4 % (25^3),
// far side 9.5 -> 2.3 %, 8.0 -> 1.1 %, worst node 34.5 -> 17 %.
TEST(Polygrid, DirectionallyLitSphereMatchesTheLegendreSolution) {
  const double R = 10, C = ReflectionParameterC(1.3);
  {
    // The exact solution's own check: q = 1 is the radial solution; q = cos theta is the l = 1
    // mode alone, with i_1(x) = cosh x / x - sinh x / x^2 and i_1' = i_0 - 2 i_1 / x (to the
    // quadrature's 1e-6 over 160 modes).
    const LitSphereRadiance uniform(0.5, 0.05, R, C, [](double) { return 1.0; });
    EXPECT_NEAR(uniform(0.3) / RadialSphereRadiance(0.5, 0.05, R, C), 1.0, 1e-5);
    const double l0 = std::sqrt(1.0 / 0.02), x = R / l0;
    const double i0 = std::sinh(x) / x, i1 = std::cosh(x) / x - std::sinh(x) / (x * x);
    const double mode1 = 1 / (1 + 2 * C * 1.0 * (i0 - 2 * i1 / x) / (l0 * i1)) / (2 * M_PI);
    const LitSphereRadiance dipolar(1.0, 0.02, R, C, [](double t) { return t; });
    EXPECT_NEAR(dipolar(-0.6) / (-0.6 * mode1), 1.0, 1e-5);
  }
  const auto shape = MakeBuiltinShape("sphere", 2 * R);
  std::array<LitSphereError, 3> e;  // 17^3, 25^3, 17^3 with the six weights
  for (int k = 0; k < 3; ++k) {
    PolygridOptions o;
    o.resolution = k == 1 ? 25 : 17;
    o.diagonal_stencil = k < 2;
    const Polygrid pg = BuildPolygrid(BuiltinPolycube("sphere"), *shape, o);
    if (k < 2) {
      EXPECT_GT(pg.diagonal_stencil_nodes, pg.num_interior / 2);
    }
    e[k] = DirectionallyLitSphereError(pg, 1.0f, 0.02f, R, C);
    std::printf("[polygrid] directionally lit sphere %d^3%s, 8 directions: radiance rms %.2f %% off the exact value, "
                "far side (cos < -0.3) %.2f %%, worst node %.1f %%\n", o.resolution,
                k == 2 ? " (the six weights)" : "", 100 * e[k].rms, 100 * e[k].far_rms, 100 * e[k].worst);
  }
  EXPECT_LT(e[0].rms, 0.035);
  EXPECT_LT(e[0].far_rms, 0.035);
  EXPECT_LT(e[1].rms, 0.02);
  EXPECT_LT(e[1].far_rms, 0.015);
  EXPECT_LT(e[1].far_rms, 0.7 * e[0].far_rms);  // converging
  EXPECT_LT(std::max(e[0].worst, e[1].worst), 0.22);
  EXPECT_GT(e[2].rms, 2 * e[0].rms);  // the wide stencil's share
}

// With Winslow's placement the sphere's cells stay nearer orthogonal: about a third as many
// nodes need fallback weights (the 6x6 system failing), and the radiance follows the radial
// solution more closely (sd 0.52 %, 0.23 % at 17^3, 25^3 against 4.5 %, 2.2 % with the variance
// steps; mean -0.6 %, -0.4 % against -8.3 %, -3.8 %; with the six weights only, sd 1.0 %, 1.0 %
// against 4.8 %, 2.4 %, mean -3.4 %, -2.8 % against -14.2 %, -6.2 %).
TEST(Polygrid, WinslowPlacementFollowsTheRadialSolutionMoreClosely) {
  const double R = 10, C = ReflectionParameterC(1.3), exact = RadialSphereRadiance(0.5, 0.05, R, C);
  const auto shape = MakeBuiltinShape("sphere", 2 * R);
  for (int resolution : {17, 25}) {
    std::array<Spread, 2> L;
    std::array<int64_t, 2> fallback;
    for (int k = 0; k < 2; ++k) {
      PolygridOptions o;
      o.resolution = resolution;
      o.placement = k ? InteriorPlacement::kWinslow : InteriorPlacement::kVariance;
      const Polygrid pg = BuildPolygrid(BuiltinPolycube("sphere"), *shape, o);
      L[k] = SpreadOf(UniformlyLitRadiance(pg, 0.5f, 0.05f, C));
      fallback[k] = pg.fallback_weights;
      std::printf("[polygrid] sphere %d^3, %s placement: mean radiance %+.2f %% off the exact value, sd %.4f, %lld "
                  "fallback nodes\n", resolution, k ? "winslow" : "variance", 100 * (L[k].mean / exact - 1), L[k].sd,
                  (long long)fallback[k]);
    }
    EXPECT_NEAR(L[1].mean / exact, 1.0, 0.04) << resolution;
    EXPECT_LT(L[1].sd, 0.015) << resolution;
    EXPECT_LT(L[1].sd, 0.6 * L[0].sd) << resolution;
    EXPECT_LT(fallback[1], fallback[0] / 2) << resolution;
  }
}

// Taubin's lambda|mu smoothing (lambda 0.5, mu -0.53) of a mesh with uniform one-ring
// weights: rounds creases without shrinking the solid much.
TriangleMesh TaubinSmoothed(TriangleMesh mesh, int iterations) {
  std::vector<std::vector<int>> ring(mesh.vertices.size());
  for (const auto& t : mesh.triangles)
    for (int k = 0; k < 3; ++k)
      for (int e : {1, 2}) ring[t[k]].push_back(t[(k + e) % 3]);
  for (auto& r : ring) {
    std::sort(r.begin(), r.end());
    r.erase(std::unique(r.begin(), r.end()), r.end());
  }
  for (int it = 0; it < 2 * iterations; ++it) {
    const double f = it % 2 ? -0.53 : 0.5;
    std::vector<Vec3> next = mesh.vertices;
    for (size_t v = 0; v < next.size(); ++v) {
      Vec3 mean = Vec3::Zero();
      for (int j : ring[v]) mean += mesh.vertices[j];
      next[v] += f * (mean / double(ring[v].size()) - mesh.vertices[v]);
    }
    mesh.vertices.swap(next);
  }
  return mesh;
}

// The bunny's polycube under a rounded mesh of its solid (Taubin-smoothed: a user's mesh with
// its polycube).
// tessellation: quads per cube face side before the rounding.
std::unique_ptr<Shape> RoundedBunny(int tessellation = 4) {
  const auto blocky = MakePolycubeSolidShape(BuiltinPolycube("bunny"), 20, tessellation, "bunny");
  return MakeMeshShape(TaubinSmoothed(blocky->mesh(), 30), "rounded_bunny.obj", 20);
}

// Its Laplacian-smoothed grid at `resolution`^3 (before any placement), checked well formed;
// prints and returns the cells of quality below 0.02 (PoorCells).
int64_t PoorCellsOfSmoothedRoundedBunny(int resolution, Polygrid* pg) {
  PolygridOptions o;
  o.resolution = resolution;
  o.placement = InteriorPlacement::kVariance;
  o.variance_iterations = 0;
  *pg = BuildPolygrid(BuiltinPolycube("bunny"), *RoundedBunny(), o);
  ExpectWellFormed(*pg);
  double worst;
  const int64_t poor = PoorCells(*pg, &worst);
  std::printf("[polygrid] rounded bunny %d^3, smoothed grid: %lld of %lld cells of quality below 0.02, worst %.3f\n",
              resolution, (long long)poor, (long long)pg->num_interior, worst);
  return poor;
}

// Along a concave edge of the polycube that the rounded mesh fills in, the line from the
// centre of the node's cubes meets the surface at a glancing angle, more so towards the cube's
// corners, and near the corners it ran through the solid to the far side: neighbouring nodes
// along the edge landed out of order (up to 1.8 mm from nodes 0.15 mm apart), and the first
// interior layer behind them folded. The rounded bunny's smoothed grid had 775 cells of
// quality below 0.02 at 13^3. Where a line's hit lies further than twice the nearest surface
// point plus half a lattice step, the nearer of the lines along the face's normal and along
// the nearest point's normal is taken instead: 75 such cells, and 51 since the fix of the crease
// rules (RoundedEdgesAreNoCreases), nearly all at split nodes where a concave edge ends, out
// of line with their neighbours along the edge. Since the nodes along concave edges are evened
// out along the edge too (as those inside a face are within it), none.
TEST(Polygrid, RoundedMeshBoundaryIsNotFoldedAlongConcaveEdges) {
  Polygrid pg;
  EXPECT_EQ(PoorCellsOfSmoothedRoundedBunny(13, &pg), 0);
}

// Boundary nodes of different lattice points that share their position (to 1e-6 of the
// boundary spacing; split concave nodes, one lattice point, share theirs by design).
int64_t MergedBoundaryNodes(const Polygrid& pg) {
  std::map<std::array<int64_t, 3>, std::array<int, 3>> at;
  int64_t merged = 0;
  for (int64_t b = pg.num_interior; b < pg.size(); ++b) {
    std::array<int64_t, 3> key;
    for (int a = 0; a < 3; ++a) key[a] = std::llround(pg.position[b][a] / (1e-6 * pg.mean_boundary_spacing));
    const auto [it, fresh] = at.emplace(key, pg.lattice[b]);
    merged += !fresh && it->second != pg.lattice[b];
  }
  return merged;
}

// A polycube edge under a rounded edge of the mesh is no crease, however far apart the normals
// of the nodes beside it are. At 9^3 those of the rounded bunny are mostly more than 30
// degrees apart (at 13^3 mostly less), and the crease rules took every side of the polycube
// for a crease side: the edge rule slid the two boundary nodes of an edge's interior node
// onto one point, and the alignment passes then gathered the nodes of two faces behind them too (792 cells of quality below 0.02, 357 merged boundary nodes). A
// crease now also needs the normals to turn less than half as much to the next node along
// each face, and a slide that gathers the nodes is undone (6 cells, no merged nodes; none
// since the evening out along concave edges).
TEST(Polygrid, RoundedEdgesAreNoCreases) {
  Polygrid pg;
  EXPECT_LT(PoorCellsOfSmoothedRoundedBunny(9, &pg), 10);
  const int64_t merged = MergedBoundaryNodes(pg);
  std::printf("[polygrid] rounded bunny 9^3: %lld merged boundary nodes\n", (long long)merged);
  EXPECT_EQ(merged, 0);
}

// Winslow's sweeps need not converge (its equations are nonlinear). On the rounded bunny's 13^3
// grid, before the fixes above, run on to their cap of 2000, they diverged: 401654 of 460553
// nodes on fallback weights in a 53 s build, where the Laplacian smoothing they start from had
// 21252. With those fixes they converge on it (tried: 5^3 to 10^3, 13^3, 17^3); they still
// stall on a low-poly rounded bunny (one quad per cube face before the rounding) at 9^3. Stopped where their steps
// stall, the grid keeps to the smoothed one's quality.
TEST(Polygrid, WinslowPlacementStopsWhereItsSweepsStall) {
  const Polycube pc = BuiltinPolycube("bunny");
  const auto rounded = RoundedBunny(1);
  PolygridOptions o;
  o.resolution = 9;
  o.placement = InteriorPlacement::kVariance;
  o.variance_iterations = 0;  // the Laplacian smoothing alone
  const Polygrid smoothed = BuildPolygrid(pc, *rounded, o);
  o.placement = InteriorPlacement::kWinslow;
  const Polygrid winslow = BuildPolygrid(pc, *rounded, o);
  ExpectWellFormed(winslow);
  std::printf("[polygrid] low-poly rounded bunny, 9^3: %lld of %lld nodes on fallback weights after smoothing, %lld "
              "with winslow placement (%s)\n", (long long)smoothed.fallback_weights, (long long)smoothed.num_interior,
              (long long)winslow.fallback_weights, winslow.placement_note.c_str());
  EXPECT_NE(winslow.placement_note.find("stalled"), std::string::npos) << winslow.placement_note;
  EXPECT_GT(smoothed.fallback_weights, 0);
  EXPECT_LT(winslow.fallback_weights, 1.6 * smoothed.fallback_weights);
}

// A polycube that does not fit the shape folds the grid, here onto itself: under one cube the
// bunny's 9^3 grid has nodes whose neighbour coincides with them (4 inverted cells). Their axis
// weights were infinite (12) and the render's diffusion went to zero everywhere; a link counts
// as at least 1e-3 boundary spacings now.
TEST(Polygrid, FoldedGridKeepsFiniteWeights) {
  Polycube one;
  one.cubes.push_back({0, 0, 0});
  PolygridOptions o;
  o.resolution = 9;
  const Polygrid pg = BuildPolygrid(one, *MakeBuiltinShape("bunny", 20), o);
  EXPECT_GT(pg.inverted_cells, 0);
  for (int64_t i = 0; i < pg.num_interior; ++i)
    for (int j = 0; j < 6; ++j) ASSERT_TRUE(std::isfinite(pg.weights[i][j]) && pg.weights[i][j] > 0) << i << " " << j;
}

// The sample bar (samples/bar.obj, a superellipsoid, with its 3 cubes) at 9^3: its sides count
// as crease sides there, and the alignment passes took the bottom's nodes near the rounded
// ends along grid lines that converge onto the end caps, past their neighbours (44 of 1127
// cells folded; 8 of 99 at 5^3). An alignment move now stops short of half-way to a face
// neighbour: none folded.
TEST(Polygrid, AlignmentKeepsTheSampleBarUnfolded) {
  const std::string samples = std::string(TRANSLUME_SOURCE_DIR) + "/samples/";
  const auto bar = MakeMeshShape(ReadMesh(samples + "bar.obj"), "bar.obj", 20);
  for (int resolution : {5, 9}) {
    PolygridOptions o;
    o.resolution = resolution;
    const Polygrid pg = BuildPolygrid(ReadPolycube(samples + "bar.cubes"), *bar, o);
    ExpectWellFormed(pg);
    EXPECT_EQ(pg.inverted_cells, 0) << resolution;
  }
}

// --polycube auto:N: the cells inside the mesh. The rounded bunny at N = 11 (its box is 11 x 7
// x 10 cubes of the bunny's polycube) gives back the 253 cubes it was rounded from.
TEST(Polygrid, VoxelPolycubeOfTheRoundedBunnyIsItsPolycube) {
  std::string note;
  Polycube want = BuiltinPolycube("bunny");
  std::sort(want.cubes.begin(), want.cubes.end());
  // And the blocky bunny too, whose vertices and edges lie on the cells' grid lines (the rays
  // are moved off them).
  for (const auto& shape : {RoundedBunny(), MakeBuiltinShape("bunny", 20)}) {
    Polycube pc = VoxelPolycube(*shape, 11, &note);
    EXPECT_TRUE(note.empty()) << note;
    std::sort(pc.cubes.begin(), pc.cubes.end());
    EXPECT_EQ(pc.cubes, want.cubes) << shape->name();
  }
  // A torus has no cell inside at N = 1 (its centre is the hole): a clear error.
  const auto torus = MakeMeshShape(MakeBuiltinShape("torus", 20, 24)->mesh(), "torus.obj", 20);
  try {
    VoxelPolycube(*torus, 1, &note);
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("raise N in --polycube auto:N"), std::string::npos) << e.what();
  }
}

// The notes translume render prints: none for a sphere at 9^3 (3 levels); a resolution that
// allows fewer levels than asked is named; a mesh of two separate pieces and a polycube of
// another genus are named.
TEST(Polygrid, NotesNameWhatTheUserShouldKnow) {
  const auto sphere = MakeBuiltinShape("sphere", 20, 24);
  PolygridOptions o;
  o.resolution = 9;
  EXPECT_TRUE(PolygridNotes(BuildPolygridHierarchy(BuiltinPolycube("sphere"), *sphere, o, 3), 3, "x", "s").empty());
  EXPECT_TRUE(PolycubeNotes(*sphere, BuiltinPolycube("sphere"), "x").empty());
  o.resolution = 6;
  const auto notes = PolygridNotes(BuildPolygridHierarchy(BuiltinPolycube("sphere"), *sphere, o, 3), 3, "x", "s");
  ASSERT_EQ(notes.size(), 1u);
  EXPECT_NE(notes[0].find("--resolution 6 allows 1 level, not the 3"), std::string::npos) << notes[0];
  TriangleMesh two = sphere->mesh();
  const int n = int(two.vertices.size());
  for (int v = 0; v < n; ++v) two.vertices.push_back(two.vertices[size_t(v)] + Vec3(30, 0, 0));
  for (int t = 0, m = int(two.triangles.size()); t < m; ++t)
    two.triangles.push_back({two.triangles[size_t(t)][0] + n, two.triangles[size_t(t)][1] + n, two.triangles[size_t(t)][2] + n});
  const auto pair = MakeMeshShape(two, "two.obj", 0);
  const auto pn = PolycubeNotes(*pair, BuiltinPolycube("torus"), "ring");
  ASSERT_EQ(pn.size(), 2u);
  EXPECT_NE(pn[0].find("two.obj has 2 separate surface pieces"), std::string::npos) << pn[0];
  EXPECT_NE(pn[1].find("two.obj has genus 0 but the polycube ring has genus 1"), std::string::npos) << pn[1];
}

// `shape`'s mesh turned by q (a shape of its own).
std::unique_ptr<Shape> Turned(const Shape& shape, const Eigen::Matrix3d& q) {
  TriangleMesh mesh = shape.mesh();
  for (Vec3& v : mesh.vertices) v = q * v;
  return MakeMeshShape(mesh, "turned_" + shape.name(), 0);
}

// 30 degrees about z, then 20 about x.
Eigen::Matrix3d TestTurn() {
  return (Eigen::AngleAxisd(20 * M_PI / 180, Vec3::UnitX()) * Eigen::AngleAxisd(30 * M_PI / 180, Vec3::UnitZ()))
      .toRotationMatrix();
}

// --polycube auto: the smallest N whose voxel polycube has the mesh's genus and does not fold:
// one cube for a sphere mesh, the ring of 8 for a torus mesh (N = 2 gives 4 cubes without the
// hole), and the bunny's 253 cubes for the rounded bunny (N = 1 to 10 fold 1.5-11 % of their
// 5^3 cells).
TEST(Polygrid, AutoPolycubeFollowsTheShape) {
  std::string report;
  const ReportLine add = [&](const std::string& line) { report += line; };
  const auto sphere = MakeMeshShape(MakeBuiltinShape("sphere", 20, 24)->mesh(), "sphere.obj", 20);
  EXPECT_EQ(AutoPolycube(*sphere, AutoPolycubeOptions(), add).cubes.size(), 1u) << report;
  report.clear();
  const auto torus = MakeMeshShape(MakeBuiltinShape("torus", 20, 24)->mesh(), "torus.obj", 20);
  Polycube ring = AutoPolycube(*torus, AutoPolycubeOptions(), add), want = BuiltinPolycube("torus");
  std::sort(ring.cubes.begin(), ring.cubes.end());
  std::sort(want.cubes.begin(), want.cubes.end());
  EXPECT_EQ(ring.cubes, want.cubes) << report;
  report.clear();
  const auto rounded = RoundedBunny();
  const Polycube bunny = AutoPolycube(*rounded, AutoPolycubeOptions(), add);
  std::printf("[polygrid] --polycube auto on the rounded bunny:\n%s", report.c_str());
  EXPECT_EQ(bunny.cubes.size(), 253u) << report;
  EXPECT_EQ(bunny.axes, Eigen::Matrix3d::Identity());
  // Turned, the same 253 cubes along the turned axes (in their own order: the frame nearest
  // the mesh's axes may swap the lattice's); along the mesh's own axes N = 10 passed with 220
  // cubes, and its grid at 17^3 folded 1.3 % of the cells.
  report.clear();
  const Polycube turned = AutoPolycube(*Turned(*rounded, TestTurn()), AutoPolycubeOptions(), add);
  std::printf("[polygrid] --polycube auto on the rounded bunny turned:\n%s", report.c_str());
  EXPECT_EQ(turned.cubes.size(), 253u) << report;
  EXPECT_NE(report.find("turned by"), std::string::npos);
}

// A polycube with axes is laid over the shape in its frame: the polygrid of the torus mesh
// turned by q under the ring with axes q^T (its lattice axes turned as the mesh) is the
// polygrid of the unturned mesh turned by q: the same nodes, cells and weights, each node where
// the turned one is to 0.008 spacings RMS (0.11 at most, at a few boundary nodes: on this
// symmetric mesh the placement meets ties that round-off breaks either way). Without the axes
// the turned mesh's polygrid folds 12 cells and has 40 % more fallback weights.
TEST(Polygrid, PolycubeAxesTurnThePolygridWithTheShape) {
  const auto torus = MakeMeshShape(MakeBuiltinShape("torus", 20, 24)->mesh(), "torus.obj", 20);
  const Eigen::Matrix3d q = TestTurn();
  const auto turned_torus = Turned(*torus, q);
  Polycube ring = BuiltinPolycube("torus");
  PolygridOptions o;
  o.resolution = 9;
  const Polygrid pg = BuildPolygrid(ring, *torus, o);
  const Polygrid unaligned = BuildPolygrid(ring, *turned_torus, o);
  ring.axes = q.transpose();
  const Polygrid turned = BuildPolygrid(ring, *turned_torus, o);
  ASSERT_EQ(turned.size(), pg.size());
  ASSERT_EQ(turned.num_interior, pg.num_interior);
  double most = 0, sum2 = 0, normals = 0;
  for (int64_t n = 0; n < pg.size(); ++n) {
    const double d = (turned.position[n] - q * pg.position[n]).norm();
    most = std::max(most, d);
    sum2 += d * d;
    if (n >= pg.num_interior)
      normals += (turned.normal[n - pg.num_interior] - q * pg.normal[n - pg.num_interior]).norm();
  }
  const double h = pg.mean_boundary_spacing, rms = std::sqrt(sum2 / double(pg.size()));
  std::printf("[polygrid] torus turned with its polycube's axes: nodes %.1e spacings apart RMS, %.2f at most; "
              "%lld and %lld folded cells, %lld and %lld fallback weights; without the axes %lld and %lld\n",
              rms / h, most / h, (long long)pg.inverted_cells, (long long)turned.inverted_cells,
              (long long)pg.fallback_weights, (long long)turned.fallback_weights, (long long)unaligned.inverted_cells,
              (long long)unaligned.fallback_weights);
  EXPECT_LT(rms, 0.02 * h);
  EXPECT_LT(most, 0.25 * h);
  EXPECT_LT(normals / double(pg.num_boundary()), 0.01);
  EXPECT_NEAR(turned.mean_boundary_spacing, h, 1e-4 * h);
  EXPECT_EQ(turned.inverted_cells, pg.inverted_cells);
  EXPECT_NEAR(double(turned.fallback_weights), double(pg.fallback_weights), 0.02 * double(pg.fallback_weights));
  EXPECT_GT(unaligned.inverted_cells, pg.inverted_cells);
  EXPECT_GT(unaligned.fallback_weights, pg.fallback_weights + pg.fallback_weights / 5);
}

// FitPolycubeFrame finds the turn of a turned mesh whose faces lie along axes (the rounded
// bunny: its frame times the turn is one of the cube's 24 rotations, within 0.5 degrees), and
// keeps the mesh's own axes where they serve as well: the unturned bunny, a sphere, a torus
// and the blob, alike in every frame about their axes.
TEST(Polygrid, PolycubeFrameFindsTheMeshsAxes) {
  const auto bunny = RoundedBunny();
  const Eigen::Matrix3d q = TestTurn();
  const PolycubeFrameFit fit = FitPolycubeFrame(Turned(*bunny, q)->mesh());
  const Eigen::Matrix3d r = fit.axes * q;  // a signed permutation where the turn is undone
  const Eigen::Matrix3d p = r.array().round().matrix();
  const double off = Eigen::AngleAxisd(Eigen::Matrix3d(r * p.transpose())).angle() * 180 / M_PI;
  std::printf("[polygrid] rounded bunny turned by %.1f degrees: frame turned by %.1f, %.2f degrees off its axes; "
              "alignment %.3f against %.3f\n", Eigen::AngleAxisd(q).angle() * 180 / M_PI, fit.turn_deg, off,
              fit.alignment, fit.identity_alignment);
  EXPECT_EQ(std::abs(p.determinant()), 1.0);
  EXPECT_LT(off, 0.5);
  EXPECT_LT(fit.alignment, fit.identity_alignment - 0.1);
  EXPECT_EQ(FitPolycubeFrame(bunny->mesh()).axes, Eigen::Matrix3d::Identity());
  for (const char* name : {"sphere", "torus", "blob"})
    EXPECT_EQ(FitPolycubeFrame(MakeBuiltinShape(name, 20)->mesh()).axes, Eigen::Matrix3d::Identity()) << name;
}

// A homogeneous torus under uniform light is symmetric about its axis, so the boundary radiance
// depends on the angle around the tube only. Within bins of that angle it varies around the axis
// by sd 1.1 % of the bin's mean at 13^3 (2.2 % with the paper's variance steps, 3.4 % while the
// alignment passes still ran on smooth sides; what is left is the polycube's corners,
// docs/render.md "Accuracy on curved shapes").
TEST(Polygrid, UniformlyLitTorusIsRotationallySymmetric) {
  const auto shape = MakeBuiltinShape("torus", 20);
  const double r = shape->hi.z(), R = shape->hi.x() - r;  // tube and ring radii
  PolygridOptions o;
  o.resolution = 13;
  const Polygrid pg = BuildPolygrid(BuiltinPolycube("torus"), *shape, o);
  const std::vector<float> L = UniformlyLitRadiance(pg, 0.5f, 0.05f, ReflectionParameterC(1.3));
  const int bins = 24;
  std::vector<double> sum(bins), sq(bins);
  std::vector<int> count(bins);
  for (int64_t b = 0; b < pg.num_boundary(); ++b) {
    const Vec3& p = pg.position[pg.num_interior + b];
    const double tube = std::atan2(p.z(), std::hypot(p.x(), p.y()) - R);
    const int k = std::clamp(int((tube + M_PI) / (2 * M_PI) * bins), 0, bins - 1);
    sum[k] += L[b];
    sq[k] += double(L[b]) * L[b];
    ++count[k];
  }
  double weighted = 0;
  int n = 0;
  for (int k = 0; k < bins; ++k) {
    ASSERT_GT(count[k], 3);
    const double mean = sum[k] / count[k];
    weighted += count[k] * std::sqrt(std::max(0.0, sq[k] / count[k] - mean * mean)) / mean;
    n += count[k];
  }
  std::printf("[polygrid] uniformly lit torus (R %.2f mm, r %.2f mm) 13^3: radiance sd around the axis %.4f of the "
              "mean at its tube angle\n", R, r, weighted / n);
  EXPECT_LT(weighted / n, 0.015);
}

// The built-in bunny (the benchmark's 253-cube polycube): its solid's surface holds the
// boundary nodes, and the polygrid is well-formed.
TEST(Polygrid, BunnyPolycube) {
  const Polycube pc = BuiltinPolycube("bunny");
  EXPECT_EQ(pc.cubes.size(), 253u);
  EXPECT_EQ(pc.Validate(), "");
  const auto shape = MakeBuiltinShape("bunny", 40, 24);
  PolygridOptions o;
  o.resolution = 5;
  const Polygrid pg = BuildPolygrid(pc, *shape, o);
  ExpectWellFormed(pg);
  EXPECT_GT(pg.num_interior, 253 * 27);
  for (int64_t b = pg.num_interior; b < pg.size(); b += 5) {
    Vec3 s, n;
    shape->Project(pg.position[b], &s, &n);
    EXPECT_NEAR((s - pg.position[b]).norm(), 0, 1e-9);
  }
  std::printf("[polygrid] bunny 253 x 5^3: %lld interior + %lld boundary nodes, %lld nodes with "
              "fallback weights\n", (long long)pg.num_interior, (long long)pg.num_boundary(),
              (long long)pg.fallback_weights);
}

TEST(Polygrid, TorusSplitsConcaveNodes) {
  const auto shape = MakeBuiltinShape("torus", 30);
  PolygridOptions o;
  o.resolution = 5;
  const Polygrid pg = BuildPolygrid(BuiltinPolycube("torus"), *shape, o);
  std::map<std::array<int, 3>, int> per_lattice;
  for (int64_t b = pg.num_interior; b < pg.size(); ++b) ++per_lattice[pg.lattice[b]];
  int split = 0;
  for (const auto& [g, n] : per_lattice) split += n > 1;
  EXPECT_GT(split, 0);  // the four concave edges around the hole
  ExpectWellFormed(pg);
}

TEST(Polygrid, HierarchyProlongsConstants) {
  const auto shape = MakeBuiltinShape("sphere", 10);
  PolygridOptions o;
  o.resolution = 9;
  const auto levels = BuildPolygridHierarchy(BuiltinPolycube("sphere"), *shape, o, 3);
  ASSERT_EQ(levels.size(), 3u);
  EXPECT_EQ(levels[1].resolution, 5);
  EXPECT_EQ(levels[2].resolution, 3);
  std::vector<float> coarse(levels[1].size(), 2.5f), fine;
  ProlongPolygrid(levels[1], coarse, levels[0], &fine);
  for (float v : fine) EXPECT_FLOAT_EQ(v, 2.5f);
  // Restriction averages children of the same kind: constants stay, and a field that is 1 on
  // the boundary and 0 inside stays so on the coarse level.
  std::vector<float> kind(levels[0].size()), coarse_kind;
  for (int64_t n = 0; n < levels[0].size(); ++n) kind[n] = levels[0].is_boundary(n) ? 1.f : 0.f;
  RestrictPolygrid(levels[0], kind, levels[1], &coarse_kind);
  for (int64_t n = 0; n < levels[1].size(); ++n)
    EXPECT_FLOAT_EQ(coarse_kind[n], levels[1].is_boundary(n) ? 1.f : 0.f) << n;
}

// The polygrid of a box (one cube, undistorted) against the regular-grid forward solver of
// SPEC section 3 on the same box, same material, back face lit uniformly: the front-face
// radiance agrees (relative L2 over the face nodes away from the rim). The material may vary
// with depth z below the front face (mm; SPEC: z = 0 is the front face, the polygrid's -z
// face, lattice k = 0): kappa(z) and mu(z), evaluated at every node's own depth on both grids.
using DepthProfile = std::function<float(double)>;

double BoxEquivalenceError(int n, double h, const DepthProfile& kappa, const DepthProfile& mu,
                           double fraction = 0.1) {
  const double L = (n - 1) * h;
  const auto box = MakeBoxShape(Vec3(L, L, L));
  PolygridOptions o;
  o.resolution = n;
  o.first_layer_fraction = fraction;
  const Polygrid pg = BuildPolygrid(BuiltinPolycube("box"), *box, o);
  NodeMaterial m;
  for (int c = 0; c < 3; ++c)
    for (int64_t i = 0; i < pg.size(); ++i) {
      const double z = pg.position[i].z() + L / 2;
      m.kappa[c].push_back(kappa(z));
      m.mu[c].push_back(mu(z));
    }
  const double C = ReflectionParameterC(1.3);
  BoundaryLight q;
  for (int c = 0; c < 3; ++c) {
    q[c].assign(pg.num_boundary(), 0.f);
    for (int64_t b = 0; b < pg.num_boundary(); ++b)
      if (pg.link_dir[b] == 5) q[c][b] = 1.f;  // the +z (back) face
  }
  const JacobiSystem S = BuildJacobiSystem(pg, m, C, q);
  const BoundaryLight Lpg = BoundaryRadiance(pg, m, q, SolveReference(S, 1));

  Material mat = Material::Constant({n, n, n}, h, {1, 1, 1}, {1, 1, 1});
  for (int c = 0; c < 3; ++c)
    for (int k = 0; k < n; ++k)
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
          mat.kappa[c][mat.shape.index(i, j, k)] = kappa(k * h);
          mat.mu[c][mat.shape.index(i, j, k)] = mu(k * h);
        }
  ForwardOptions fo;
  fo.multigrid.tolerance = 1e-10;
  fo.multigrid.max_iterations = 400;
  const ForwardResult r = SolveForward(mat, GreyPattern(std::vector<float>(n * n, 1.f)), fo);
  double num = 0, den = 0;
  for (int64_t b = 0; b < pg.num_boundary(); ++b) {
    if (pg.link_dir[b] != 4) continue;  // the -z (front) face, lattice k = 0
    const auto& g = pg.lattice[pg.num_interior + b];
    if (g[0] < 2 || g[1] < 2 || g[0] > n - 3 || g[1] > n - 3) continue;
    // The regular solver's radiance, bilinear at the polygrid node's (x, y).
    const Vec3& p = pg.position[pg.num_interior + b];
    const double fx = (p.x() + L / 2) / h, fy = (p.y() + L / 2) / h;
    const int i0 = std::min(n - 2, int(fx)), j0 = std::min(n - 2, int(fy));
    const double tx = fx - i0, ty = fy - j0;
    auto R = [&](int i, int j) { return double(r.radiance[0][i + n * j]); };
    const double ref = (1 - ty) * ((1 - tx) * R(i0, j0) + tx * R(i0 + 1, j0)) +
                       ty * ((1 - tx) * R(i0, j0 + 1) + tx * R(i0 + 1, j0 + 1));
    num += (Lpg[0][b] - ref) * (Lpg[0][b] - ref);
    den += ref * ref;
  }
  return std::sqrt(num / den);
}

double BoxEquivalenceError(int n, double h, float kappa, float mu, double fraction = 0.1) {
  return BoxEquivalenceError(n, h, [=](double) { return kappa; }, [=](double) { return mu; },
                             fraction);
}

TEST(Polygrid, SingleCubeBoxMatchesRegularGridSolver) {
  const double e9 = BoxEquivalenceError(9, 0.5, 0.4f, 0.05f);
  const double e17 = BoxEquivalenceError(17, 0.25, 0.4f, 0.05f);
  const double e33 = BoxEquivalenceError(33, 0.125, 0.4f, 0.05f);
  std::printf("[box equivalence] 4 mm cube, kappa 0.4 mm, mu 0.05/mm: relative L2 difference "
              "%.3e (9^3), %.3e (17^3), %.3e (33^3)\n", e9, e17, e33);
  EXPECT_LT(e33, e17);
  EXPECT_LT(e17, e9);
  // Issue 7's target. Measured (docs/benchmarks.md): second-order convergence, 6.2e-4 at 33^3
  // (with the paper's first-order boundary link and bent grid lines it was 2.6e-3).
  EXPECT_LT(e33, 1e-3);
}

// The same box with a material layered in depth: kappa 0.2 -> 0.6 mm and mu 0.02 -> 0.1/mm
// linearly from the front face (z = 0) to the back (z = 4 mm), so that the flux between nodes
// at different depths depends on how kappa is averaged. SPEC section 3 takes the face average
// (kappa_p + kappa_q) / 2; the paper's interior form Laplacian(kappa phi) (kappa_p phi_q - ...)
// solves a different equation here, 0.61 off at every resolution (measured: 6.2e-1, 6.1e-1,
// 6.1e-1 at 9^3, 17^3, 33^3), and reading a neighbour's kappa or mu from the wrong node shows
// likewise. Measured with the face average: 2.2e-2 (9^3), 3.9e-3 (17^3), 8.4e-4 (33^3), second
// order as in the homogeneous case (6.2e-4 at 33^3); the same 1e-3 target holds.
TEST(Polygrid, SingleCubeBoxMatchesRegularGridSolverLayered) {
  const auto kappa = [](double z) { return float(0.2 + 0.4 * z / 4); };
  const auto mu = [](double z) { return float(0.02 + 0.08 * z / 4); };
  const double e9 = BoxEquivalenceError(9, 0.5, kappa, mu);
  const double e33 = BoxEquivalenceError(33, 0.125, kappa, mu);
  std::printf("[box equivalence] 4 mm cube, kappa 0.2 -> 0.6 mm, mu 0.02 -> 0.1/mm with depth: "
              "relative L2 difference %.3e (9^3), %.3e (33^3)\n", e9, e33);
  EXPECT_LT(e33, e9 / 8);  // converging (second order: about 1/16 per two halvings of h)
  EXPECT_LT(e33, 1e-3);
}

}  // namespace
}  // namespace translume
