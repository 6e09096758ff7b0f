// SPDX-License-Identifier: MIT
#include "solver/forward.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>

#include "solver/light.h"
#include "solver/synthetic.h"

namespace translume {
namespace {

// Every forward test body runs on each backend (gl on Mesa llvmpipe where there is no GPU).
class ForwardOnBackend : public ::testing::TestWithParam<Backend> {
 protected:
  ForwardOptions Options() const {
    ForwardOptions o;
    o.backend = GetParam();
    return o;
  }
  // Float backends reach a relative residual of ~1e-6; their radiance agrees to ~1e-5.
  double Tolerance() const { return GetParam() == Backend::kGl ? 2e-5 : 1e-5; }
};

TEST_P(ForwardOnBackend, SymmetricSpotGivesSymmetricRadiance) {
  const Material m = Material::Constant({31, 31, 9}, 0.25, {0.2f, 0.15f, 0.1f}, {0.01f, 0.02f, 0.05f});
  const FacePattern q = GreyPattern(RasterizeLight(LightSpec::Parse("spot:3.75,3.75,1"), m.shape, 0.25));
  const ForwardResult r = SolveForward(m, q, Options());
  for (int c = 0; c < 3; ++c) {
    EXPECT_LE(r.summaries[c].final_residual, 5e-6) << r.summaries[c].BriefReport();
    for (int64_t j = 0; j < 31; ++j)
      for (int64_t i = 0; i < 31; ++i) {
        const double a = r.radiance[c][i + 31 * j], b = r.radiance[c][(30 - i) + 31 * j],
                     t = r.radiance[c][j + 31 * i];
        EXPECT_NEAR(a, b, Tolerance() * r.radiance[c][15 + 31 * 15]);
        EXPECT_NEAR(a, t, Tolerance() * r.radiance[c][15 + 31 * 15]);
        EXPECT_GT(a, 0);
      }
    // More absorption (blue) transmits less.
    if (c > 0) { EXPECT_LT(r.radiance[c][15 + 31 * 15], r.radiance[c - 1][15 + 31 * 15]); }
  }
}

// The side faces' radiance (ForwardOptions::side_faces) is the same field as the front face's:
// where a side face meets the front face they share nodes, and by the spot's symmetry the four
// side faces of a square block carry the same values (x = 0 and x = X, y = 0 and y = Y).
TEST_P(ForwardOnBackend, SideFacesShareTheFrontFacesEdgeAndItsSymmetry) {
  const Material m = Material::Constant({21, 21, 9}, 0.25, {0.2f, 0.15f, 0.1f}, {0.01f, 0.02f, 0.05f});
  const FacePattern q = GreyPattern(RasterizeLight(LightSpec::Parse("spot:2.5,2.5,1"), m.shape, 0.25));
  for (translume::Setup setup : {translume::Setup::kBack, translume::Setup::kFront}) {
    ForwardOptions o = Options();
    o.setup = setup;
    o.side_faces = true;
    const ForwardResult r = SolveForward(m, q, o);
    const int64_t n = 21, nz = 9;
    for (int c = 0; c < 3; ++c) {
      const auto& sides = r.sides[size_t(c)];
      for (const auto& face : sides) ASSERT_EQ(int64_t(face.size()), n * nz);
      double top = 0;  // the largest |L| (front-lit, the lit centre's L is negative)
      for (float v : r.radiance[size_t(c)]) top = std::max(top, double(std::abs(v)));
      for (int64_t t = 0; t < n; ++t) {
        // Row k = 0 of each side face is the front face's edge.
        EXPECT_NEAR(sides[0][size_t(t)], r.radiance[size_t(c)][size_t(n * t)], 1e-6 * top);
        EXPECT_NEAR(sides[1][size_t(t)], r.radiance[size_t(c)][size_t(n - 1 + n * t)], 1e-6 * top);
        EXPECT_NEAR(sides[2][size_t(t)], r.radiance[size_t(c)][size_t(t)], 1e-6 * top);
        EXPECT_NEAR(sides[3][size_t(t)], r.radiance[size_t(c)][size_t(t + n * (n - 1))], 1e-6 * top);
        for (int64_t k = 0; k < nz; ++k)
          for (int f = 1; f < 4; ++f)
            EXPECT_NEAR(sides[size_t(f)][size_t(t + n * k)], sides[0][size_t(t + n * k)], Tolerance() * top);
      }
      // Down the side's middle the radiance is positive and changes with depth (the rows are the
      // side's own, not copies of the front's edge).
      for (int64_t k = 0; k < nz; ++k) EXPECT_GT(sides[0][size_t(10 + n * k)], 0) << "k " << k;
      EXPECT_GT(std::abs(sides[0][size_t(10 + n * 4)] / sides[0][10] - 1), 0.01);
    }
    EXPECT_TRUE(SolveForward(m, q, Options()).sides[0][0].empty());  // only when asked
  }
}

// SPEC section 3's uniformly lit homogeneous slab of thickness T through SolveForward (the lit
// face, the source and L = (phi - q) / (2 pi) as a user gets them): phi(z) = A e^{-s z} +
// B e^{s z} with z from the lit face, so L = (A e^{-sT} + B e^{sT}) / (2 pi) on the front face
// of a back-lit slab and (A + B - q) / (2 pi) on the lit front face of a front-lit one (-0.0549
// for SPEC's slab: more light leaves the lit face than it sends back). Second order: the
// centre node's error falls ~4x from nz = 5 to 9 (back-lit 3.0e-2 -> 7.6e-3, as SPEC says;
// front-lit 2.0e-2 -> 5.1e-3).
TEST_P(ForwardOnBackend, UniformSlabMatchesTheAnalyticSolutionInBothSetups) {
  const double kappa = 0.1, mu = 0.1, T = 2.0, width = 16.0;
  const double s = std::sqrt(mu / kappa);
  for (translume::Setup setup : {translume::Setup::kBack, translume::Setup::kFront}) {
    double err[2];
    for (int r = 0; r < 2; ++r) {
      const int64_t nz = r == 0 ? 5 : 9;
      const double h = T / double(nz - 1);
      const int64_t nx = int64_t(std::llround(width / h)) + 1;
      const Material m = Material::Constant({nx, nx, nz}, h, {float(kappa), float(kappa), float(kappa)},
                                            {float(mu), float(mu), float(mu)});
      const double a = 2 * m.C * kappa * s, e2 = std::exp(-2 * s * T);
      const double A = 1.0 / ((1 + a) - e2 * (1 - a) * (1 - a) / (1 + a)), B = -A * e2 * (1 - a) / (1 + a);
      const double exact = setup == Setup::kBack ? (A * std::exp(-s * T) + B * std::exp(s * T)) / (2 * std::numbers::pi)
                                                 : (A + B - 1.0) / (2 * std::numbers::pi);
      ForwardOptions o = Options();
      o.setup = setup;
      const ForwardResult f = SolveForward(m, GreyPattern(RasterizeLight(LightSpec::Parse("uniform"), m.shape, h)), o);
      const double got = f.radiance[1][nx / 2 + nx * (nx / 2)];
      err[r] = std::abs(got - exact) / std::abs(exact);
      std::printf("%s nz %d: L %.6f, exact %.6f, relative error %.2e\n",
                  setup == Setup::kBack ? "back" : "front", int(nz), got, exact, err[r]);
    }
    EXPECT_LT(err[1], setup == translume::Setup::kBack ? 8e-3 : 6e-3);  // measured 7.6e-3, 5.1e-3
    EXPECT_NEAR(err[0] / err[1], 4.0, 0.4);
  }
}

TEST_P(ForwardOnBackend, FrontSetupSubtractsIncomingLight) {
  const Material m = Material::Constant({21, 21, 8}, 0.5, {0.2f, 0.2f, 0.2f}, {0.02f, 0.02f, 0.02f});
  ForwardOptions o = Options();
  o.setup = Setup::kFront;
  const auto spot = RasterizeLight(LightSpec::Parse("spot:5,5,1.5"), m.shape, 0.5);
  const ForwardResult r = SolveForward(m, GreyPattern(spot), o);
  // Far from the spot the radiance is phi / (2 pi) > 0 and decays with distance.
  EXPECT_GT(r.radiance[0][15 + 21 * 10], r.radiance[0][18 + 21 * 10]);
  EXPECT_GT(r.radiance[0][20 + 21 * 10], 0);
  // Under the spot phi < q (light leaves), so L = (phi - q) / 2pi is negative there.
  EXPECT_LT(r.radiance[0][10 + 21 * 10], 0);
}

// Float solves (cpu float, gl) against the cpu double reference: radiance within 1e-4 relative
// (issue 5's target), measured as a relative L2 error over the face.
TEST_P(ForwardOnBackend, AgreesWithCpuDoubleOnASyntheticMaterial) {
  SynthOptions so;
  so.preset = "marble";
  so.shape = {40, 30, 10};
  const Material m = SynthesizeMaterial(so);
  const FacePattern q = GreyPattern(RasterizeLight(LightSpec::Parse("region:1,2/4"), m.shape, m.spacing_mm));
  ForwardOptions o;
  const ForwardResult d = SolveForward(m, q, o);
  o = Options();
  o.precision = Precision::kFloat;
  const ForwardResult f = SolveForward(m, q, o);
  for (int c = 0; c < 3; ++c) {
    double num = 0, den = 0;
    for (size_t p = 0; p < d.radiance[c].size(); ++p) {
      num += std::pow(d.radiance[c][p] - f.radiance[c][p], 2);
      den += std::pow(d.radiance[c][p], 2);
    }
    EXPECT_LT(std::sqrt(num / den), 1e-5);
    double worst = 0, top = 0;
    for (size_t p = 0; p < d.radiance[c].size(); ++p) top = std::max(top, double(d.radiance[c][p]));
    for (size_t p = 0; p < d.radiance[c].size(); ++p)
      worst = std::max(worst, std::abs(d.radiance[c][p] - f.radiance[c][p]) / top);
    EXPECT_LT(worst, 1e-4);
  }
}

// Several lights at once (on gl one batched solve per channel) give each light's own solve:
// the radiance of every light against the cpu double reference within 1e-4 of its peak.
TEST_P(ForwardOnBackend, BatchOfLightsMatchesSingleSolves) {
  SynthOptions so;
  so.preset = "wax";
  so.shape = {24, 20, 8};
  const Material m = SynthesizeMaterial(so);
  std::vector<FacePattern> lights;
  for (const char* spec : {"region:0,0/2", "spot:2,3,1", "uniform", "region:1,1/2"})
    lights.push_back(GreyPattern(RasterizeLight(LightSpec::Parse(spec), m.shape, m.spacing_mm)));
  const std::vector<ForwardResult> batch = SolveForwardBatch(m, lights, Options());
  ASSERT_EQ(batch.size(), lights.size());
  for (size_t l = 0; l < lights.size(); ++l) {
    const ForwardResult ref = SolveForward(m, lights[l], ForwardOptions{});
    for (int c = 0; c < 3; ++c) {
      EXPECT_TRUE(batch[l].summaries[c].converged) << batch[l].summaries[c].BriefReport();
      EXPECT_LE(batch[l].summaries[c].final_residual, 1e-6);
      double top = 0, worst = 0;
      for (float v : ref.radiance[c]) top = std::max(top, double(std::abs(v)));
      ASSERT_GT(top, 0);
      for (size_t p = 0; p < ref.radiance[c].size(); ++p)
        worst = std::max(worst, std::abs(double(batch[l].radiance[c][p]) - ref.radiance[c][p]) / top);
      EXPECT_LT(worst, 1e-4) << "light " << l << " channel " << c;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Backends, ForwardOnBackend, ::testing::Values(Backend::kCpu, Backend::kGl),
                         [](const auto& info) { return info.param == Backend::kCpu ? "cpu" : "gl"; });

}  // namespace
}  // namespace translume
