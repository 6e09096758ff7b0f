// SPDX-License-Identifier: MIT
#include "render/diffusion.h"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "render/material_map.h"
#include "render/mesh_io.h"
#include "render/test_metrics.h"
#include "solver/evaluate.h"
#include "solver/material.h"

namespace translume {
namespace {

// A sphere lit from +x: q = cos(theta) on the lit half.
struct SphereCase {
  std::unique_ptr<Shape> shape = MakeBuiltinShape("sphere", 10);
  std::vector<Polygrid> levels;
  std::vector<NodeMaterial> mats;
  std::vector<BoundaryLight> q;
  explicit SphereCase(int resolution, int nlevels = 3) {
    PolygridOptions o;
    o.resolution = resolution;
    levels = BuildPolygridHierarchy(BuiltinPolycube("sphere"), *shape, o, nlevels);
    for (const Polygrid& pg : levels) {
      mats.push_back(ProceduralNodeMaterial(pg, "marble"));
      BoundaryLight l;
      for (int c = 0; c < 3; ++c) {
        l[c].resize(pg.num_boundary());
        for (int64_t b = 0; b < pg.num_boundary(); ++b)
          l[c][b] = float(std::max(0.0, pg.normal[b].x()));
      }
      q.push_back(l);
    }
  }
};

// The built-in bunny (253 cubes, 20 mm) under a homogeneous grey material, lit from (1, 0.3, 0.6).
struct BunnyCase {
  std::unique_ptr<Shape> shape = MakeBuiltinShape("bunny", 20);
  std::vector<Polygrid> levels;
  std::vector<NodeMaterial> mats;
  std::vector<BoundaryLight> q;
  BunnyCase(int resolution, float kappa, float mu) {
    PolygridOptions po;
    po.resolution = resolution;
    levels = BuildPolygridHierarchy(BuiltinPolycube("bunny"), *shape, po, 3);
    const Vec3 l = Vec3(1, 0.3, 0.6).normalized();
    for (const Polygrid& pg : levels) {
      mats.push_back(ConstantNodeMaterial(pg, {kappa, kappa, kappa}, {mu, mu, mu}));
      BoundaryLight b;
      for (int c = 0; c < 3; ++c) {
        b[c].resize(pg.num_boundary());
        for (int64_t k = 0; k < pg.num_boundary(); ++k) b[c][k] = float(std::max(0.0, pg.normal[k].dot(l)));
      }
      q.push_back(b);
    }
  }
};

TEST(Diffusion, HierarchicalRelaxationConvergesToDirectSolve) {
  SphereCase s(9);
  const double C = ReflectionParameterC(1.3);
  const std::vector<float> exact = SolveReference(BuildJacobiSystem(s.levels[0], s.mats[0], C, s.q[0]));
  DiffusionOptions o;
  o.iterations = {400, 400, 2000};
  PolygridDiffusion d(&s.levels, s.mats, C, o);
  const double err = RelativeL2(d.Solve(s.q), exact);
  std::printf("[diffusion] sphere 9^3: hierarchical relaxation vs direct: %.2e\n", err);
  EXPECT_LT(err, 1e-3);
}

TEST(Diffusion, HierarchyAndCoherenceReduceTheError) {
  SphereCase s(9);
  const double C = ReflectionParameterC(1.3);
  const std::vector<float> exact = SolveReference(BuildJacobiSystem(s.levels[0], s.mats[0], C, s.q[0]));
  DiffusionOptions flat;
  flat.relaxation = Relaxation::kJacobi;  // the paper's steps (Chebyshev's converge in 100 anyway)
  flat.iterations = {100};
  std::vector<Polygrid> one = {s.levels[0]};
  PolygridDiffusion d1(&one, {s.mats[0]}, C, flat);
  const double e_flat = RelativeL2(d1.Solve({s.q[0]}), exact);
  DiffusionOptions hier;
  hier.relaxation = Relaxation::kJacobi;
  hier.iterations = {50, 50, 100};
  PolygridDiffusion d3(&s.levels, s.mats, C, hier);
  const double e_hier = RelativeL2(d3.Solve(s.q), exact);
  // Adaptive: the finest level updates only the outer 1 or 3 layers (the rest keeps the
  // prolonged coarse solution): cheaper, less accurate, better with more layers.
  hier.depth = {-1, -1, 1};
  PolygridDiffusion da1(&s.levels, s.mats, C, hier);
  const double e_adapt1 = RelativeL2(da1.Solve(s.q), exact);
  hier.depth = {-1, -1, 3};
  PolygridDiffusion da3(&s.levels, s.mats, C, hier);
  const double e_adapt3 = RelativeL2(da3.Solve(s.q), exact);
  // Frame coherence: a second frame with the same light starts from the first's solution.
  hier.depth = {};
  hier.frame_coherence = true;
  hier.coherent_iterations = 100;
  PolygridDiffusion dc(&s.levels, s.mats, C, hier);
  dc.Solve(s.q);
  const double e_coh = RelativeL2(dc.Solve(s.q), exact);
  std::printf("[diffusion] 100 finest steps: flat %.2e, hierarchical %.2e, adaptive 1 layer %.2e, "
              "3 layers %.2e, second coherent frame %.2e\n", e_flat, e_hier, e_adapt1, e_adapt3, e_coh);
  EXPECT_LT(e_hier, e_flat);
  EXPECT_LT(e_coh, e_hier);
  EXPECT_LT(e_adapt3, e_adapt1);
}

class DiffusionRelaxation : public ::testing::TestWithParam<Relaxation> {};

TEST_P(DiffusionRelaxation, GlBackendMatchesCpu) {
  SphereCase s(9);
  const double C = ReflectionParameterC(1.3);
  DiffusionOptions o;
  o.relaxation = GetParam();
  // Chebyshev's steps converge to float rounding in ~60 finest steps, where both backends
  // would agree whatever their arithmetic; fewer steps compare the steps themselves.
  o.iterations = GetParam() == Relaxation::kJacobi ? std::vector<int>{50, 50, 100} : std::vector<int>{8, 8, 13};
  PolygridDiffusion cpu(&s.levels, s.mats, C, o);
  const std::vector<float> a = cpu.Solve(s.q);
  // Adaptive depth on the finest level, then a frame-coherent second frame (the fluence stays
  // on the device between frames).
  DiffusionOptions o2 = o;
  o2.depth = {-1, -1, 2};
  o2.frame_coherence = true;
  // (Step counts that are no multiple of 3, so the gl backend's current buffer is not the first.)
  o2.coherent_iterations = GetParam() == Relaxation::kJacobi ? 31 : 7;
  PolygridDiffusion cpu2(&s.levels, s.mats, C, o2);
  const std::vector<float> cpu_adaptive = cpu2.Solve(s.q);
  std::vector<BoundaryLight> dimmer = s.q;
  for (auto& l : dimmer)
    for (auto& c : l)
      for (float& v : c) v *= 0.5f;
  const std::vector<float> cpu_coherent = cpu2.Solve(dimmer);
  EXPECT_GT(RelativeL2(cpu_coherent, a), 0.1);  // the coherent frame did use the new light
  const JacobiSystem system = BuildJacobiSystem(s.levels[0], s.mats[0], C, s.q[0]);
  EXPECT_GT(RelativeL2(a, SolveReference(system)), 1e-5);  // not converged: the comparison is of the steps
  // The sphere has wide rows (extra entries after the six), which the gl rows carry too.
  ASSERT_FALSE(system.extra_nb.empty());
  o.backend = o2.backend = DiffusionBackend::kGl;
  PolygridDiffusion gl(&s.levels, s.mats, C, o), gl2(&s.levels, s.mats, C, o2);
  const double err = RelativeL2(gl.Solve(s.q), a);
  const double err_adaptive = RelativeL2(gl2.Solve(s.q), cpu_adaptive);
  const double err_coherent = RelativeL2(gl2.Solve(dimmer), cpu_coherent);
  std::printf("[diffusion] gl vs cpu after the same steps: %.2e; adaptive %.2e; coherent frame %.2e\n", err,
              err_adaptive, err_coherent);
  EXPECT_LT(err, 1e-5);
  EXPECT_LT(err_adaptive, 1e-5);
  EXPECT_LT(err_coherent, 1e-5);
}

INSTANTIATE_TEST_SUITE_P(Diffusion, DiffusionRelaxation,
                         ::testing::Values(Relaxation::kJacobi, Relaxation::kChebyshev),
                         [](const auto& info) {
                           return info.param == Relaxation::kJacobi ? "Jacobi" : "Chebyshev";
                         });

// The estimate against the spectral radius of the dense iteration matrix: from below, and
// close enough that Chebyshev's steps gain (a small sphere, every channel).
TEST(Diffusion, SpectralRadiusEstimateIsCloseFromBelow) {
  for (int resolution : {5, 9}) {
    SphereCase s(resolution, 1);
    const double C = ReflectionParameterC(1.3);
    const HierarchyRelaxer::Level v = RelaxationRows(s.levels[0], s.mats[0], C);
    const std::array<double, 3> e10 = JacobiSpectralRadii(v, 10), e50 = JacobiSpectralRadii(v);
    for (int c = 0; c < 3; ++c) {
      Eigen::MatrixXd a = Eigen::MatrixXd::Zero(v.size, v.size);
      for (int64_t n = 0; n < v.size; ++n) {
        for (int k = 0; k < 6; ++k) {
          ASSERT_GE(v.a[(n * 3 + c) * 6 + k], 0.f);  // what the estimate's bound needs
          a(n, v.nb[n * 6 + k]) += v.a[(n * 3 + c) * 6 + k];
        }
        if (v.extra_start.empty()) continue;
        for (int32_t e = v.extra_start[n]; e < v.extra_start[n + 1]; ++e) {  // the wide stencil's
          ASSERT_GE(v.extra_a[e * 3 + c], 0.f);
          a(n, v.extra_nb[e]) += v.extra_a[e * 3 + c];
        }
      }
      const Eigen::VectorXcd ev = Eigen::EigenSolver<Eigen::MatrixXd>(a, false).eigenvalues();
      double rho = 0, imag = 0;
      for (int i = 0; i < ev.size(); ++i) {
        rho = std::max(rho, std::abs(ev[i]));
        imag = std::max(imag, std::abs(ev[i].imag()));
      }
      std::printf("[diffusion] sphere %d^3 (%lld nodes), channel %d: rho %.6f (largest |Im| %.1e), "
                  "estimate after 10 / 50 power steps %.6f / %.6f\n", resolution, (long long)v.size,
                  c, rho, imag, e10[c], e50[c]);
      EXPECT_LE(e10[c], e50[c] + 1e-12);
      EXPECT_LE(e50[c], rho * (1 + 1e-9));
      EXPECT_GT(e50[c], rho - 0.25 * (1 - rho));  // within a quarter of the gap to 1
    }
  }
}

// Chebyshev's steps reach the solution of the same equations (the direct solve's) far sooner
// than Jacobi's, on both backends, with and without the hierarchy.
TEST(Diffusion, ChebyshevConvergesFasterToTheSameSolution) {
  SphereCase s(9);
  const double C = ReflectionParameterC(1.3);
  const std::vector<float> exact = SolveReference(BuildJacobiSystem(s.levels[0], s.mats[0], C, s.q[0]));
  const std::vector<Polygrid> one = {s.levels[0]};
  for (DiffusionBackend backend : {DiffusionBackend::kCpu, DiffusionBackend::kGl})
    for (bool hierarchy : {false, true}) {
      double err[2][2];  // [relaxation][few, many steps]
      for (Relaxation r : {Relaxation::kJacobi, Relaxation::kChebyshev})
        for (int many = 0; many < 2; ++many) {
          DiffusionOptions o;
          o.backend = backend;
          o.relaxation = r;
          const int finest = many ? 400 : 30;
          o.iterations = hierarchy ? std::vector<int>{30, 30, finest} : std::vector<int>{finest};
          PolygridDiffusion d(hierarchy ? &s.levels : &one,
                              hierarchy ? s.mats : std::vector<NodeMaterial>{s.mats[0]}, C, o);
          err[int(r)][many] = RelativeL2(d.Solve(hierarchy ? s.q : std::vector<BoundaryLight>{s.q[0]}), exact);
        }
      std::printf("[diffusion] %s, %s: 30 finest steps, Jacobi %.2e, Chebyshev %.2e; 400 steps %.2e, %.2e\n",
                  backend == DiffusionBackend::kGl ? "gl" : "cpu", hierarchy ? "3 levels" : "one level",
                  err[0][0], err[1][0], err[0][1], err[1][1]);
      EXPECT_LT(err[1][0], 0.1 * err[0][0]);
      EXPECT_LT(err[1][1], 1e-5);  // float rounding: the same fixed point
    }
}

TEST(Diffusion, ChebyshevScheduleWeights) {
  ChebyshevSchedule jacobi({0, 0, 0}, 100, false);
  for (int k = 0; k < 100; ++k) EXPECT_TRUE(ChebyshevSchedule::IsJacobi(jacobi.Next()));
  // rho 0.5 by hand: omega 1, 1 / (1 - 1 / 8) = 8 / 7, 1 / (1 - (8 / 7) / 16) = 14 / 13.
  ChebyshevSchedule half({0.5, 0.5, 0.5}, 3, false);
  EXPECT_FLOAT_EQ(half.Next()[0], 1.0f);
  EXPECT_FLOAT_EQ(half.Next()[1], 8.0f / 7);
  EXPECT_FLOAT_EQ(half.Next()[2], 14.0f / 13);
  const std::array<double, 3> rho = {0.5, 0.9, 0.999};
  // 30 steps: the sequence only, or repeated one cycle, 26 of the sequence and 4 of Jacobi's;
  // 150 steps: three cycles of 50, 43 and 7 each; 101 steps: cycles of 51 and 50
  // (ceil(101 / 60) = 2 cycles).
  struct Case {
    int steps;
    bool repeated;
    std::vector<int> cycles, tails;  // each cycle's length and its Jacobi steps (ceil(L / 8))
  };
  for (const Case& t : {Case{30, false, {30}, {0}}, Case{30, true, {30}, {4}},
                        Case{150, false, {50, 50, 50}, {7, 7, 7}}, Case{101, true, {51, 50}, {7, 7}}}) {
    const int steps = t.steps;
    ChebyshevSchedule s(rho, steps, t.repeated);
    for (size_t cycle = 0; cycle < t.cycles.size(); ++cycle) {
      const int length = t.cycles[cycle], tail = t.tails[cycle];
      std::array<double, 3> omega = {1, 1, 1};
      for (int k = 0; k < length - tail; ++k) {
        const std::array<float, 3> w = s.Next();
        for (int c = 0; c < 3; ++c) {
          const double r2 = rho[c] * rho[c];
          omega[c] = k == 0 ? 1 : k == 1 ? 1 / (1 - r2 / 2) : 1 / (1 - r2 * omega[c] / 4);
          EXPECT_NEAR(w[c], omega[c], 1e-6) << steps << " steps, step " << k << " of a cycle, channel " << c;
        }
      }
      // rho 0.5 has reached omega's limit 2 / (1 + sqrt(1 - rho^2)) within the run.
      EXPECT_NEAR(omega[0], 2 / (1 + std::sqrt(1 - 0.25)), 1e-6);
      for (int k = 0; k < tail; ++k) EXPECT_TRUE(ChebyshevSchedule::IsJacobi(s.Next())) << steps << " steps";
    }
  }
}

// The bunny under a homogeneous material: its rows' matrix has complex eigenvalues outside
// Chebyshev's ellipse (ChebyshevSchedule). Without the Jacobi tails, 300 steps per level ended
// at a relative error of 8.7 here (the coarsest level's error grew ~10 % per step); with them
// they converge, on either backend. The coherent frames converge with or without the tails at
// 5^3; at 9^3 (too slow for this test: ~100 s) `translume render homogeneous:1,0.01 --shape
// bunny --resolution 9 --turntable 24 --coherence` grew without them (docs/benchmarks.md).
TEST(Diffusion, ChebyshevConvergesOnTheBunnyUnderAHomogeneousMaterial) {
  const BunnyCase bunny(5, 1.f, 0.1f);
  const std::vector<Polygrid>& levels = bunny.levels;
  const std::vector<NodeMaterial>& mats = bunny.mats;
  const std::vector<BoundaryLight>& q = bunny.q;
  const double C = ReflectionParameterC(1.3);
  const std::vector<float> exact = SolveReference(BuildJacobiSystem(levels[0], mats[0], C, q[0]));
  for (DiffusionBackend backend : {DiffusionBackend::kCpu, DiffusionBackend::kGl}) {
    const char* name = backend == DiffusionBackend::kGl ? "gl" : "cpu";
    DiffusionOptions o;
    o.backend = backend;
    o.iterations = {300, 300, 300};
    PolygridDiffusion d(&levels, mats, C, o);
    EXPECT_EQ(d.reduced_radii(), 0) << name;
    const double long_run = RelativeL2(d.Solve(q), exact);
    // A frame of the default steps, then 24 coherent frames of 50 finest steps each.
    o.iterations = {60, 30, 30};
    o.frame_coherence = true;
    PolygridDiffusion coherent(&levels, mats, C, o);
    const double first = RelativeL2(coherent.Solve(q), exact);
    std::vector<float> phi;
    for (int f = 0; f < 24; ++f) phi = coherent.Solve(q);
    const double last = RelativeL2(phi, exact);
    std::printf("[diffusion] %s, bunny 5^3, kappa 1 mm, mu 0.1 / mm: 300 steps per level %.2e; a frame %.2e, "
                "then 24 coherent frames %.2e\n", name, long_run, first, last);
    EXPECT_LT(long_run, 1e-5) << name;
    EXPECT_LT(first, 0.1) << name;  // 0.047; 0.22 before a frame's calls took the tails here
    EXPECT_LT(last, 1e-5) << name;
  }
}

// The bunny with the wide stencil under a homogeneous material: a frame's plain 30 steps on the
// finest level grew modes off the real axis 36-139-fold (from ChebyshevRemainder's random
// start), so PolygridDiffusion ran 6 of the 9 level channels with a smaller radius and a frame
// ended at E 1.8e-3 against the converged solution (1.0e-2 at 17^3, above the paper's 5e-3).
// Where plain calls grow and the Jacobi tails shrink them, a frame's calls end in the tails
// (Level::tails): here 2 of 3 levels, no smaller radius, and E 2.5e-4 against 2.2e-3 without
// the tails (this light; the same steps with the frame's first relative L2 error in the test
// above, at 5^3: 0.047 against 0.22). The sphere keeps the plain sequence.
TEST(Diffusion, AFrameEndsInJacobiTailsWherePlainStepsWouldGrow) {
  const BunnyCase bunny(9, 0.5f, 0.05f);
  const double C = ReflectionParameterC(1.3);
  const Polygrid& pg = bunny.levels[0];
  const BoundaryLight exact = ShadedRadiance(pg, bunny.mats[0], SolveReference(BuildJacobiSystem(pg, bunny.mats[0], C, bunny.q[0]), 3, true));
  for (DiffusionBackend backend : {DiffusionBackend::kCpu, DiffusionBackend::kGl}) {
    const char* name = backend == DiffusionBackend::kGl ? "gl" : "cpu";
    DiffusionOptions o;  // render's 60 / 30 / 30 steps
    o.backend = backend;
    PolygridDiffusion d(&bunny.levels, bunny.mats, C, o);
    const double E = RelightingError({ShadedRadiance(pg, bunny.mats[0], d.Solve(bunny.q))}, {exact});
    std::printf("[diffusion] %s, bunny 9^3, kappa 0.5 mm, mu 0.05 / mm, 60 / 30 / 30 steps: %d of 3 levels end "
                "their calls in Jacobi tails, %d of 9 level channels with a smaller radius; a frame's E %.2e\n",
                name, d.tailed_levels(), d.reduced_radii(), E);
    EXPECT_EQ(d.tailed_levels(), 2) << name;
    EXPECT_EQ(d.reduced_radii(), 0) << name;
    EXPECT_LT(E, 5e-4) << name;
  }
  SphereCase sphere(17);
  const PolygridDiffusion plain(&sphere.levels, sphere.mats, C, DiffusionOptions{});
  EXPECT_EQ(plain.tailed_levels(), 0);
  EXPECT_EQ(plain.reduced_radii(), 0);
}

// The guard's three checks in one run give the same numbers as three runs, on a level whose
// plain call is the coherent run's first steps (30) and on one where it is not (60: the
// coherent run's first cycle has 52 sequence steps, then its tail), with a radius and without.
TEST(Diffusion, OneRunServesTheGuardsThreeChecks) {
  const BunnyCase bunny(5, 0.5f, 0.05f);
  HierarchyRelaxer::Level v = RelaxationRows(bunny.levels[0], bunny.mats[0], ReflectionParameterC(1.3));
  for (const std::array<double, 3>& rho : {JacobiSpectralRadii(v), std::array<double, 3>{0, 0, 0}}) {
    v.rho = rho;
    for (int call : {30, 60}) {
      SCOPED_TRACE(call);
      const ChebyshevRemainders r = ChebyshevCallRemainders(v, call, 120);
      EXPECT_EQ(r.coherent, ChebyshevRemainder(v, 120, true));
      EXPECT_EQ(r.plain, ChebyshevRemainder(v, call, false));
      EXPECT_EQ(r.tailed, ChebyshevRemainder(v, call, true));
    }
  }
}

// Chebyshev's steps assume a real spectrum. A tetrahedron's voxel polycube at 9^3 leaves cells
// so distorted that the rows (with the wide stencil) have eigenvalues far off the real axis, and
// Chebyshev's steps grew the error by 1e4 in 100 steps, where Jacobi's converge (error against the
// converged solution 0.46 after 100 steps, 0.12 after 400): ChebyshevRemainder says so, and
// PolygridDiffusion runs them with a smaller radius there, with which they shrink
// (Render.SharpEdgedMeshStaysBounded renders the tetrahedron). On the sphere it keeps the radius.
TEST(Diffusion, ChebyshevTakesASmallerRadiusWhereItWouldGrow) {
  const auto shape = MakeMeshShape(TetrahedronMesh(), "tet.obj", 20);
  const Polycube pc = AutoPolycube(*shape, AutoPolycubeOptions(), [](const std::string&) {});
  PolygridOptions po;
  po.resolution = 9;
  const std::vector<Polygrid> levels = {BuildPolygrid(pc, *shape, po)};
  const Polygrid& pg = levels[0];
  const std::vector<NodeMaterial> mats = {ConstantNodeMaterial(pg, {0.2f, 0.2f, 0.2f}, {0.01f, 0.01f, 0.01f})};
  const double C = ReflectionParameterC(1.3);
  HierarchyRelaxer::Level v = RelaxationRows(pg, mats[0], C);
  v.rho = JacobiSpectralRadii(v);
  const std::array<double, 3> remainder = ChebyshevRemainder(v);
  EXPECT_GT(*std::min_element(remainder.begin(), remainder.end()), 1);
  DiffusionOptions o;
  o.iterations = {100};
  const PolygridDiffusion d(&levels, mats, C, o);
  EXPECT_GT(pg.diagonal_stencil_nodes, pg.num_interior / 2);
  EXPECT_EQ(d.reduced_radii(), 3);
  EXPECT_EQ(d.jacobi_fallbacks(), 0);  // a smaller radius suffices here
  std::printf("[diffusion] tetrahedron 9^3 (%lld of %lld interior rows on the wide stencil): Chebyshev's steps "
              "would grow the error; %d channels with a smaller radius, %d of them on Jacobi's steps\n",
              (long long)pg.diagonal_stencil_nodes, (long long)pg.num_interior, d.reduced_radii(), d.jacobi_fallbacks());
  SphereCase sphere(9, 1);
  HierarchyRelaxer::Level w = RelaxationRows(sphere.levels[0], sphere.mats[0], C);
  w.rho = JacobiSpectralRadii(w);
  const std::array<double, 3> sphere_remainder = ChebyshevRemainder(w);
  EXPECT_LT(*std::max_element(sphere_remainder.begin(), sphere_remainder.end()), 1);
}

}  // namespace
}  // namespace translume
