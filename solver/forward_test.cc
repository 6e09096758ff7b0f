// SPDX-License-Identifier: MIT
#include "solver/forward.h"

#include <gtest/gtest.h>

#include <cmath>

#include "solver/light.h"
#include "solver/synthetic.h"

namespace translume {
namespace {

TEST(Forward, SymmetricSpotGivesSymmetricRadiance) {
  const Material m = Material::Constant({31, 31, 9}, 0.25, {0.2f, 0.15f, 0.1f}, {0.01f, 0.02f, 0.05f});
  const FacePattern q = GreyPattern(RasterizeLight(LightSpec::Parse("spot:3.75,3.75,1"), m.shape, 0.25));
  const ForwardResult r = SolveForward(m, q, {});
  for (int c = 0; c < 3; ++c) {
    EXPECT_TRUE(r.summaries[c].converged);
    for (int64_t j = 0; j < 31; ++j)
      for (int64_t i = 0; i < 31; ++i) {
        const double a = r.radiance[c][i + 31 * j], b = r.radiance[c][(30 - i) + 31 * j],
                     t = r.radiance[c][j + 31 * i];
        EXPECT_NEAR(a, b, 1e-5 * r.radiance[c][15 + 31 * 15]);
        EXPECT_NEAR(a, t, 1e-5 * r.radiance[c][15 + 31 * 15]);
        EXPECT_GT(a, 0);
      }
    // More absorption (blue) transmits less.
    if (c > 0) { EXPECT_LT(r.radiance[c][15 + 31 * 15], r.radiance[c - 1][15 + 31 * 15]); }
  }
}

TEST(Forward, FrontSetupSubtractsIncomingLight) {
  const Material m = Material::Constant({21, 21, 8}, 0.5, {0.2f, 0.2f, 0.2f}, {0.02f, 0.02f, 0.02f});
  ForwardOptions o;
  o.setup = Setup::kFront;
  const auto spot = RasterizeLight(LightSpec::Parse("spot:5,5,1.5"), m.shape, 0.5);
  const ForwardResult r = SolveForward(m, GreyPattern(spot), o);
  // Far from the spot the radiance is phi / (2 pi) > 0 and decays with distance.
  EXPECT_GT(r.radiance[0][15 + 21 * 10], r.radiance[0][18 + 21 * 10]);
  EXPECT_GT(r.radiance[0][20 + 21 * 10], 0);
  // Under the spot phi < q (light leaves), so L = (phi - q) / 2pi is negative there.
  EXPECT_LT(r.radiance[0][10 + 21 * 10], 0);
}

TEST(Forward, FloatAndDoubleAgreeOnASyntheticMaterial) {
  SynthOptions so;
  so.preset = "marble";
  so.shape = {40, 30, 10};
  const Material m = SynthesizeMaterial(so);
  const FacePattern q = GreyPattern(RasterizeLight(LightSpec::Parse("region:1,2/4"), m.shape, m.spacing_mm));
  ForwardOptions o;
  const ForwardResult d = SolveForward(m, q, o);
  o.precision = Precision::kFloat;
  const ForwardResult f = SolveForward(m, q, o);
  for (int c = 0; c < 3; ++c) {
    double num = 0, den = 0;
    for (size_t p = 0; p < d.radiance[c].size(); ++p) {
      num += std::pow(d.radiance[c][p] - f.radiance[c][p], 2);
      den += std::pow(d.radiance[c][p], 2);
    }
    EXPECT_LT(std::sqrt(num / den), 1e-5);
  }
}

}  // namespace
}  // namespace translume
