// SPDX-License-Identifier: MIT
#include "render/diffusion.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "render/material_map.h"
#include "render/test_metrics.h"
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
  flat.iterations = {100};
  std::vector<Polygrid> one = {s.levels[0]};
  PolygridDiffusion d1(&one, {s.mats[0]}, C, flat);
  const double e_flat = RelativeL2(d1.Solve({s.q[0]}), exact);
  DiffusionOptions hier;
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

TEST(Diffusion, GlBackendMatchesCpu) {
  SphereCase s(9);
  const double C = ReflectionParameterC(1.3);
  DiffusionOptions o;
  o.iterations = {50, 50, 100};
  PolygridDiffusion cpu(&s.levels, s.mats, C, o);
  const std::vector<float> a = cpu.Solve(s.q);
  o.backend = DiffusionBackend::kGl;
  PolygridDiffusion gl(&s.levels, s.mats, C, o);
  const std::vector<float> b = gl.Solve(s.q);
  const double err = RelativeL2(b, a);
  // Adaptive depth on the finest level, then a frame-coherent second frame (the fluence stays
  // on the device between frames).
  o.depth = {-1, -1, 2};
  o.frame_coherence = true;
  o.coherent_iterations = 30;
  o.backend = DiffusionBackend::kCpu;
  PolygridDiffusion cpu2(&s.levels, s.mats, C, o);
  o.backend = DiffusionBackend::kGl;
  PolygridDiffusion gl2(&s.levels, s.mats, C, o);
  const double err_adaptive = RelativeL2(gl2.Solve(s.q), cpu2.Solve(s.q));
  std::vector<BoundaryLight> dimmer = s.q;
  for (auto& l : dimmer)
    for (auto& c : l)
      for (float& v : c) v *= 0.5f;
  const std::vector<float> cpu_coherent = cpu2.Solve(dimmer);
  const double err_coherent = RelativeL2(gl2.Solve(dimmer), cpu_coherent);
  std::printf("[diffusion] gl vs cpu after the same steps: %.2e; adaptive %.2e; coherent frame "
              "%.2e\n", err, err_adaptive, err_coherent);
  EXPECT_LT(err, 1e-5);
  EXPECT_LT(err_adaptive, 1e-5);
  EXPECT_LT(err_coherent, 1e-5);
  EXPECT_GT(RelativeL2(cpu_coherent, a), 0.1);  // the coherent frame did use the new light
}

}  // namespace
}  // namespace translume
