// SPDX-License-Identifier: MIT
#include "solver/recover.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

#include "solver/light.h"
#include "solver/simulate.h"
#include "solver/synthetic.h"

namespace translume {
namespace {

// E = sum (a - b)^2 / sum b^2 over all conditions and channels.
double RelightingError(const std::vector<FacePattern>& a, const std::vector<FacePattern>& b) {
  double num = 0, den = 0;
  for (size_t m = 0; m < a.size(); ++m)
    for (int c = 0; c < 3; ++c)
      for (size_t p = 0; p < a[m][c].size(); ++p) {
        num += std::pow(a[m][c][p] - b[m][c][p], 2);
        den += std::pow(b[m][c][p], 2);
      }
  return num / den;
}

TEST(Recover, HomogeneousVolumeToOnePerMille) {
  const Material truth = Material::Constant({12, 10, 5}, 0.5, {0.25f, 0.15f, 0.08f}, {0.01f, 0.03f, 0.06f});
  SimulateOptions so;
  so.lights = RegionLights("2x2");
  so.oversample = 1;
  const Dataset d = SimulateDataset(truth, so).training;
  RecoveryOptions ro;
  ro.max_iterations = 0;  // the homogeneous fit alone
  RecoveryState st;
  const RecoverySummary s = Recover(d, ro, &st);
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(s.homogeneous_kappa[c] / truth.kappa[c][0], 1.0, 1e-3) << c;
    EXPECT_NEAR(s.homogeneous_mu[c] / truth.mu[c][0], 1.0, 1e-3) << c;
  }
  EXPECT_LT(s.fit_error, 1e-8);
}

// A small heterogeneous recovery from oversampled noise-free data, checked on held-out spots.
TEST(Recover, HeterogeneousVolumeRelightsHeldOutSpots) {
  SynthOptions syn;
  syn.preset = "wax";
  syn.shape = {16, 12, 5};
  syn.spacing_mm = 0.5;
  const Material truth = SynthesizeMaterial(syn);
  SimulateOptions so;
  so.lights = RegionLights("4x4");
  so.holdout = 8;
  const SimulatedData data = SimulateDataset(truth, so);
  RecoveryOptions ro;
  ro.max_iterations = 150;
  RecoveryState st;
  const RecoverySummary s = Recover(data.training, ro, &st);
  std::printf("%s\n", s.BriefReport().c_str());
  const Material rec = MaterialFromState(data.training, st);
  std::vector<FacePattern> q;
  for (const auto& c : data.holdout.conditions) q.push_back(c.q);
  MultigridOptions mg;
  mg.tolerance = 1e-10;
  const double E = RelightingError(RenderFrontFace(rec, Setup::kBack, q, mg),
                                   RenderFrontFace(truth, Setup::kBack, q, mg));
  std::printf("held-out E %.3e, fit E %.3e\n", E, s.fit_error);
  EXPECT_LT(E, 1e-3);
  EXPECT_LT(s.final_objective, s.initial_objective);
}

}  // namespace
}  // namespace translume
