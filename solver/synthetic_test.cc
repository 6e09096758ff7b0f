// SPDX-License-Identifier: MIT
#include "solver/synthetic.h"

#include <gtest/gtest.h>

#include <algorithm>

#include "solver/status.h"

namespace translume {
namespace {

TEST(Synthetic, EveryPresetIsPlausibleAndDeterministic) {
  for (const std::string& preset : SynthPresetNames()) {
    SynthOptions o;
    o.preset = preset;
    o.shape = {24, 20, 10};
    const Material a = SynthesizeMaterial(o), b = SynthesizeMaterial(o);
    EXPECT_EQ(a.Validate(), "") << preset;
    for (int c = 0; c < 3; ++c) {
      EXPECT_EQ(a.kappa[c], b.kappa[c]) << preset;
      const auto [kmin, kmax] = std::minmax_element(a.kappa[c].begin(), a.kappa[c].end());
      const auto [mmin, mmax] = std::minmax_element(a.mu[c].begin(), a.mu[c].end());
      EXPECT_GE(*kmin, 0.03f) << preset;
      EXPECT_LE(*kmax, 0.6f) << preset;
      EXPECT_GE(*mmin, 0.0009f) << preset;
      EXPECT_LE(*mmax, 0.11f) << preset;
    }
    const bool heterogeneous = preset != "homogeneous";
    const auto [kmin, kmax] = std::minmax_element(a.kappa[1].begin(), a.kappa[1].end());
    EXPECT_EQ(*kmax > *kmin * 1.05f, heterogeneous) << preset;
  }
}

TEST(Synthetic, PaperPresetsHaveThePaperGrids) {
  EXPECT_EQ(DefaultSynthShape("wax1"), (GridShape{130, 53, 37}));
  EXPECT_EQ(DefaultSynthShape("wax2"), (GridShape{140, 75, 48}));
  EXPECT_EQ(DefaultSynthShape("marble"), (GridShape{256, 256, 20}));
  EXPECT_EQ(DefaultSynthShape("stone"), (GridShape{128, 128, 41}));
}

TEST(Synthetic, SeedChangesNoiseAndUnknownPresetIsRejected) {
  SynthOptions o;
  o.preset = "marble";
  o.shape = {16, 16, 6};
  const Material a = SynthesizeMaterial(o);
  o.seed = 2;
  EXPECT_NE(a.kappa[0], SynthesizeMaterial(o).kappa[0]);
  o.preset = "granite";
  try {
    SynthesizeMaterial(o);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("granite"), std::string::npos);
  }
}

}  // namespace
}  // namespace translume
