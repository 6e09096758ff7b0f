// SPDX-License-Identifier: MIT
#include "solver/evaluate.h"
#include "solver/evaluate_previews.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <limits>

#include "solver/image_io.h"
#include "solver/material.h"
#include "solver/multigrid.h"
#include "solver/status.h"

namespace translume {
namespace {

// A face pattern of nf nodes per channel with values 1 + f + 10 c (distinct in every node and
// channel).
FacePattern Ramp(size_t nf) {
  FacePattern p;
  for (int c = 0; c < 3; ++c)
    for (size_t f = 0; f < nf; ++f) p[c].push_back(float(1 + f + 10 * c));
  return p;
}

FacePattern Scaled(FacePattern p, double s) {
  for (auto& channel : p)
    for (float& v : channel) v = float(v * s);
  return p;
}

// SPEC section 5: E = sum w (a - b)^2 / sum w b^2. a = 1.1 b gives E = 0.1^2 whatever b is;
// a masked node counts in neither sum.
TEST(RelightingError, IsTheSquaredRelativeL2ErrorOverMaskedNodes) {
  const FacePattern b = Ramp(6);
  EXPECT_NEAR(RelightingError({Scaled(b, 1.1), b}, {b, b}), 0.01 / 2, 1e-7);
  EXPECT_NEAR(RelightingError({Scaled(b, 1.1)}, {b}), 0.01, 1e-7);
  EXPECT_EQ(RelightingError({b}, {b}), 0.0);
  // Node 2 wildly off but masked out: only the other nodes count, in both sums.
  FacePattern a = Scaled(b, 1.1);
  for (auto& channel : a) channel[2] = 1e6f;
  std::vector<float> w(6, 1.0f);
  w[2] = 0.0f;
  EXPECT_NEAR(RelightingError({a}, {b}, {w}), 0.01, 1e-7);
  // Half weight on one node: it counts half in both sums (a uniform 1.1 scale: still 0.01).
  w.assign(6, 1.0f);
  w[4] = 0.5f;
  EXPECT_NEAR(RelightingError({Scaled(b, 1.1)}, {b}, {w}), 0.01, 1e-7);
}

// A reference without light has no relative error: 0 where the rendering is dark too, infinite
// where it is not (not 0, which would read as a perfect recovery).
TEST(RelightingError, DarkReferenceIsZeroOnlyForADarkRendering) {
  const FacePattern dark = Scaled(Ramp(4), 0.0);
  EXPECT_EQ(RelightingError({dark}, {dark}), 0.0);
  EXPECT_EQ(RelightingError({Ramp(4)}, {dark}), std::numeric_limits<double>::infinity());
}

// e_k = sqrt(sum (v_rec - v_true)^2 / sum v_true^2) per depth layer k, RGB together.
TEST(LayerErrors, ScalingOneLayerShowsInThatLayerOnly) {
  const GridShape s{4, 3, 5};
  Material truth = Material::Constant(s, 0.5, {0.2f, 0.3f, 0.4f}, {0.01f, 0.02f, 0.03f});
  for (int c = 0; c < 3; ++c)
    for (int64_t p = 0; p < s.size(); ++p) truth.kappa[c][p] *= float(1 + p % 7);  // not constant
  Material rec = truth;
  for (int c = 0; c < 3; ++c)
    for (int64_t f = 0; f < s.face_size(); ++f) {
      rec.kappa[c][f + 2 * s.face_size()] *= 1.02f;  // layer k = 2
      rec.mu[c][f] *= 0.5f;                           // layer k = 0
    }
  std::vector<double> ek, em;
  LayerErrors(rec, truth, &ek, &em);
  ASSERT_EQ(ek.size(), 5u);
  ASSERT_EQ(em.size(), 5u);
  for (int k = 0; k < 5; ++k) {
    EXPECT_NEAR(ek[k], k == 2 ? 0.02 : 0.0, 1e-6) << k;
    EXPECT_NEAR(em[k], k == 0 ? 0.5 : 0.0, 1e-6) << k;
  }
}

Dataset SmallDataset() {
  Dataset d;
  d.shape = {3, 2, 2};
  d.C = 2.6;
  for (const char* name : {"a", "b"}) {
    DatasetCondition c;
    c.name = name;
    c.q = Ramp(6);
    c.L = Scaled(Ramp(6), name[0] == 'a' ? 0.01 : 0.02);
    c.mask.assign(6, 1.0f);
    d.conditions.push_back(c);
  }
  return d;
}

// A measured dataset that is the reference with a gain error: the relative RMS of L is the gain
// error, the least-squares scale recovers the gain, and nothing is left after it; q untouched.
TEST(CompareDatasets, GainErrorShowsAsScaleAndNothingElse) {
  const Dataset reference = SmallDataset();
  Dataset measured = reference;
  for (auto& c : measured.conditions) c.L = Scaled(c.L, 1.01);
  std::swap(measured.conditions[0], measured.conditions[1]);  // matched by name, not order
  const DatasetMismatch m = CompareDatasets(measured, reference);
  EXPECT_NEAR(m.L_rms, 0.01, 1e-6);
  EXPECT_EQ(m.q_rms, 0.0);
  ASSERT_EQ(m.condition_L_rms.size(), 2u);
  for (double e : m.condition_L_rms) EXPECT_NEAR(e, 0.01, 1e-6);
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(m.L_scale[c], 1.01, 1e-6) << c;
    EXPECT_NEAR(m.L_rms_after_scale[c], 0.0, 1e-6) << c;
  }
  // A node masked out in either dataset is left out of L's sums.
  measured.conditions[0].L[1][3] = 1e3f;
  measured.conditions[0].mask[3] = 0.0f;
  EXPECT_NEAR(CompareDatasets(measured, reference).L_rms, 0.01, 1e-6);
}

TEST(CompareDatasets, MissingConditionIsNamed) {
  const Dataset reference = SmallDataset();
  Dataset measured = reference;
  measured.conditions.pop_back();
  try {
    CompareDatasets(measured, reference);
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("condition b"), std::string::npos) << e.what();
  }
}

// A material is evaluated on the dataset's terms: another spacing or C (or a holdout of another
// grid, which aborted on a CHECK) is refused with one line naming what differs.
TEST(EvaluateRecovery, RefusesMaterialsAndHoldoutsOnOtherTerms) {
  Dataset train = SmallDataset();
  train.spacing_mm = 0.5;
  const Material good = Material::Constant(train.shape, 0.5, {1, 1, 1}, {0.01f, 0.01f, 0.01f});
  train.C = good.C;
  MultigridOptions mg;
  auto expect_refused = [&](const Material& rec, const Material* truth, const Dataset& holdout,
                            const std::vector<std::string>& what) {
    try {
      EvaluateRecovery(rec, truth, train, holdout, mg);
      ADD_FAILURE() << "no error";
    } catch (const InputError& e) {
      const std::string msg = e.what();
      EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
      for (const auto& w : what) EXPECT_NE(msg.find(w), std::string::npos) << msg << " lacks " << w;
    }
  };
  EXPECT_NO_THROW(EvaluateRecovery(good, &good, train, Dataset{}, mg));
  Material coarse = good;
  coarse.spacing_mm = 1.0;
  expect_refused(good, &coarse, Dataset{}, {"--truth", "spacing 1 mm", "0.5 mm"});
  expect_refused(coarse, nullptr, Dataset{}, {"recovered", "spacing"});
  Material other_c = Material::Constant(train.shape, 0.5, {1, 1, 1}, {0.01f, 0.01f, 0.01f}, 1.6);
  expect_refused(good, &other_c, Dataset{}, {"--truth", "C", "eta 1.6"});
  Dataset holdout = train;
  holdout.shape = {2, 3, 2};
  expect_refused(good, &good, holdout, {"holdout", "2x3x2", "3x2x2"});
}

// The report keeps the renderings behind its errors, and --previews draws them: one image per
// training condition (measured | recovered | residual) and per held-out one (truth | recovery |
// residual), each three panels of the face side by side.
TEST(EvaluateRecovery, KeepsItsRenderingsAndPreviewsThem) {
  Dataset train = SmallDataset();
  train.spacing_mm = 0.5;
  const Material rec = Material::Constant(train.shape, 0.5, {1, 1, 1}, {0.01f, 0.01f, 0.01f});
  const Material truth = Material::Constant(train.shape, 0.5, {1, 1, 1}, {0.02f, 0.02f, 0.02f});
  train.C = rec.C;
  Dataset holdout = train;
  holdout.conditions.resize(1);
  holdout.conditions[0].name = "h00";
  holdout.conditions[0].mask[5] = 0;  // node (2, 1) masked
  MultigridOptions mg;
  mg.tolerance = 1e-9;
  // Without a truth: the fit, and the held-out error against the held-out data.
  const EvaluationReport no_truth = EvaluateRecovery(rec, nullptr, train, holdout, mg);
  ASSERT_EQ(no_truth.training_recovered.size(), 2u);
  ASSERT_EQ(no_truth.holdout_recovered.size(), 1u);
  EXPECT_TRUE(no_truth.holdout_truth.empty());
  EXPECT_EQ(no_truth.holdout_error, -1);
  EXPECT_NEAR(RelightingError(no_truth.holdout_recovered, {holdout.conditions[0].L}, {holdout.conditions[0].mask}),
              no_truth.holdout_data_error, 1e-12);
  EXPECT_GT(no_truth.holdout_data_error, 0);
  const EvaluationReport r = EvaluateRecovery(rec, &truth, train, holdout, mg);
  EXPECT_EQ(r.holdout_data_error, no_truth.holdout_data_error);
  ASSERT_EQ(r.holdout_recovered.size(), 1u);
  ASSERT_EQ(r.holdout_truth.size(), 1u);
  std::vector<FacePattern> measured;
  std::vector<std::vector<float>> masks;
  for (const auto& c : train.conditions) {
    measured.push_back(c.L);
    masks.push_back(c.mask);
  }
  EXPECT_NEAR(RelightingError(r.training_recovered, measured, masks), r.fit_error, 1e-12);
  EXPECT_NEAR(RelightingError(r.holdout_recovered, r.holdout_truth, {holdout.conditions[0].mask}), r.holdout_error,
              1e-12);
  EXPECT_GT(r.holdout_error, 0);

  const std::string dir = (std::filesystem::temp_directory_path() / "translume_evaluate_previews").string();
  std::filesystem::remove_all(dir);
  const std::vector<std::string> paths = WriteEvaluationPreviews(dir, r, train, holdout);
  ASSERT_EQ(paths, EvaluationPreviewPaths(dir, train, holdout, true));
  ASSERT_EQ(paths.size(), 3u);
  EXPECT_EQ(std::filesystem::path(paths[2]).filename(), "holdout_h00.png");
  const Image img = ReadImage(paths[2]);
  const int z = 86;  // ceil(256 / 3) pixels per node
  EXPECT_EQ(img.width, (3 * 3 + 4) * z);
  EXPECT_EQ(img.height, 2 * z);
  // Less absorption relights brighter: the residual panel is red, not black.
  const size_t residual = size_t((z / 2) * img.width + (2 * 5 + 1) * z + z / 2) * 3;
  EXPECT_GT(img.data[residual], img.data[residual + 2]);
  const size_t masked = size_t((z + z / 2) * img.width + (2 * 5 + 2) * z + z / 2) * 3;
  EXPECT_NEAR(img.data[masked], 0.35f, 1 / 255.0f);  // grey
  EXPECT_NEAR(img.data[masked + 2], 0.35f, 1 / 255.0f);
  EXPECT_EQ(WriteEvaluationPreviews(dir, no_truth, train, holdout).size(), 2u);  // training only
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace translume
