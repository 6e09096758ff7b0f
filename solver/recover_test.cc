// SPDX-License-Identifier: MIT
#include "solver/recover.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>

#include "solver/evaluate.h"
#include "solver/light.h"
#include "solver/memory.h"
#include "solver/simulate.h"
#include "solver/status.h"
#include "solver/synthetic.h"

namespace translume {
namespace {

// The recovery tests run on every backend (gl on Mesa llvmpipe where there is no GPU).
class RecoverOnBackend : public ::testing::TestWithParam<Backend> {};

// Training data of 2x2 back-lit regions simulated on the recovery grid itself (exact data).
Dataset DataOnTheRecoveryGrid(const Material& truth) {
  SimulateOptions so;
  so.lights = RegionLights("2x2");
  so.oversample = 1;
  return SimulateDataset(truth, so).training;
}

TEST_P(RecoverOnBackend, HomogeneousVolumeToOnePerMille) {
  const Material truth = Material::Constant({12, 10, 5}, 0.5, {0.25f, 0.15f, 0.08f}, {0.01f, 0.03f, 0.06f});
  const Dataset d = DataOnTheRecoveryGrid(truth);
  RecoveryOptions ro;
  ro.backend = GetParam();
  ro.max_iterations = 0;  // the homogeneous fit alone
  // Tighter than the default 1e-6, which the full-multigrid start alone meets on this small
  // grid: the CG iterations counted below are then more than none.
  ro.solve_tolerance = 1e-8;
  RecoveryState st;
  const RecoverySummary s = Recover(d, ro, &st);
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(s.homogeneous_kappa[c] / truth.kappa[c][0], 1.0, 1e-3) << c;
    EXPECT_NEAR(s.homogeneous_mu[c] / truth.mu[c][0], 1.0, 1e-3) << c;
  }
  EXPECT_LT(s.fit_error, 1e-8);
  // Every solve counted: the fit's, then two evaluations of 4 solves per channel at its result
  // (the objective with no iteration left, the final fit error), warm-started at the fit's
  // solutions: at most one CG iteration each left to do.
  EXPECT_EQ(s.homogeneous_solves, s.solves - 2 * 3 * 4);
  EXPECT_GT(s.homogeneous_cg_iterations, 0);
  EXPECT_GE(s.cg_iterations, s.homogeneous_cg_iterations);
  EXPECT_LE(s.cg_iterations - s.homogeneous_cg_iterations, 2 * 3 * 4);
  EXPECT_LT(s.cg_iterations, 10 * s.solves);
}

// The same fit from data simulated on the 2x finer grid (no inverse crime, SPEC section 5).
// The best homogeneous pair on the recovery grid is then not the truth: it fits the data at
// least as well as the truth does there (the truth is one of the pairs), and kappa stays within
// a few per cent. mu moves further (measured +28 % in the red channel, whose diffusion length
// sqrt(kappa / mu) = 5 mm is twice the slab's thickness: there mu barely changes L, so the
// recovery grid's ~1 % error in L maps into it), so only its direction of influence, the fit,
// is asserted.
TEST_P(RecoverOnBackend, HomogeneousVolumeFromOversampledData) {
  const Material truth = Material::Constant({12, 10, 5}, 0.5, {0.25f, 0.15f, 0.08f}, {0.01f, 0.03f, 0.06f});
  SimulateOptions so;
  so.lights = RegionLights("2x2");
  const Dataset d = SimulateDataset(truth, so).training;
  RecoveryOptions ro;
  ro.backend = GetParam();
  ro.max_iterations = 0;
  RecoveryState st;
  const RecoverySummary s = Recover(d, ro, &st);
  MultigridOptions mg;
  mg.tolerance = 1e-10;
  std::vector<FacePattern> q, L;
  std::vector<std::vector<float>> w;
  for (const auto& c : d.conditions) {
    q.push_back(c.q);
    L.push_back(c.L);
    w.push_back(c.mask);
  }
  const double floor = RelightingError(RenderMeasured(truth, d.setup, q, mg), L, w);
  std::printf("fit E %.3e, the truth's on the recovery grid %.3e\n", s.fit_error, floor);
  EXPECT_GT(floor, 1e-6);  // the data are not the recovery grid's own
  EXPECT_LE(s.fit_error, floor * (1 + 1e-3));
  for (int c = 0; c < 3; ++c) {
    std::printf("channel %d: kappa %.4f (truth %.4f), mu %.4f (truth %.4f)\n", c, s.homogeneous_kappa[c],
                truth.kappa[c][0], s.homogeneous_mu[c], truth.mu[c][0]);
    // Within the recovery grid's discretisation error (the truth's own fit E above): measured
    // 0.7 %, 1.7 % and 5.4 % off, the largest in blue, whose mu decays fastest.
    EXPECT_NEAR(s.homogeneous_kappa[c] / truth.kappa[c][0], 1.0, 0.07) << c;
  }
}

// A small heterogeneous recovery from oversampled noise-free data, checked on held-out spots.
TEST_P(RecoverOnBackend, HeterogeneousVolumeRelightsHeldOutSpots) {
  const SynthOptions syn{.preset = "wax", .shape = {16, 12, 5}};
  const Material truth = SynthesizeMaterial(syn);
  SimulateOptions so;
  so.lights = RegionLights("4x4");
  so.holdout = 8;
  const SimulatedData data = SimulateDataset(truth, so);
  RecoveryOptions ro;
  ro.backend = GetParam();
  ro.max_iterations = 30;
  // The heterogeneous fit itself, from the homogeneous fit (the level search has its own test;
  // on this thin slab it keeps every level, and its trials cost 4x these 30 iterations, ~8 min
  // with the gpu shader tuning on llvmpipe).
  ro.level_search = 0;
  RecoveryState st;
  const RecoverySummary s = Recover(data.training, ro, &st);
  std::printf("%s; level search: %d trials, %.1f s, %lld solves, mu x %.3g %.3g %.3g\n", s.BriefReport().c_str(),
              s.level_trials, s.level_seconds, (long long)s.level_solves, s.level_factor[0], s.level_factor[1],
              s.level_factor[2]);
  // The optimiser's own time is part of the heterogeneous phase, and not all of it.
  EXPECT_GT(s.optimizer_seconds, 0);
  EXPECT_LT(s.optimizer_seconds, s.seconds - s.homogeneous_seconds);
  const Material rec = MaterialFromState(data.training, st);
  ASSERT_EQ(data.holdout.conditions.size(), 8u);
  std::vector<FacePattern> q;
  for (const auto& c : data.holdout.conditions) q.push_back(c.q);
  MultigridOptions mg;
  mg.tolerance = 1e-10;
  const std::vector<FacePattern> reference = RenderFrontFace(truth, Setup::kBack, q, mg);
  const double E = RelightingError(RenderFrontFace(rec, Setup::kBack, q, mg), reference);
  // The control: the homogeneous fit the recovery started from. The held-out spots must see
  // the heterogeneity (else any homogeneous material would pass: measured 28x the recovery's
  // E). The per-node parameters are not asserted: appearance is identifiable, they are not
  // (the paper's Fig. 14); here the front layer's kappa error goes 0.08 -> 0.10 while E falls.
  const Material start = Material::Constant(truth.shape, truth.spacing_mm,
                                            {float(s.homogeneous_kappa[0]), float(s.homogeneous_kappa[1]), float(s.homogeneous_kappa[2])},
                                            {float(s.homogeneous_mu[0]), float(s.homogeneous_mu[1]), float(s.homogeneous_mu[2])});
  const double E_start = RelightingError(RenderFrontFace(start, Setup::kBack, q, mg), reference);
  std::printf("held-out E %.3e (homogeneous start %.3e), fit E %.3e\n", E, E_start, s.fit_error);
  EXPECT_LT(E, 1e-3);
  EXPECT_GT(E_start, 10 * E);
  EXPECT_LT(s.final_objective, s.initial_objective);
}

// On a heterogeneous volume the homogeneous fit's optimum leaves a misfit, which it reaches in
// a few Levenberg-Marquardt iterations; after that the objective's last digits are rounding
// (float on gl), and the fit must stop rather than spend its iterations (3 evaluations of 16
// solves each, more where steps are rejected) wandering among them.
TEST_P(RecoverOnBackend, HomogeneousFitStopsWhereTheObjectiveStalls) {
  const SynthOptions syn{.preset = "wax", .shape = {16, 12, 5}};
  SimulateOptions so;
  so.lights = RegionLights("4x4");
  const Dataset d = SimulateDataset(SynthesizeMaterial(syn), so).training;
  RecoveryOptions ro;
  ro.backend = GetParam();
  ro.max_iterations = 0;
  RecoveryState st;
  const RecoverySummary s = Recover(d, ro, &st);
  const int64_t evaluations = s.homogeneous_solves / (3 * 16);
  std::printf("homogeneous fit: %lld evaluations per channel, objective %.6e\n", (long long)evaluations,
              s.final_objective);
  EXPECT_GT(s.fit_error, 1e-4);
  EXPECT_LE(evaluations, 30);
  // Where it stopped is the optimum: 2 % more or less kappa or mu in every channel fits worse.
  const int64_t n = d.shape.size();
  for (int which = 0; which < 2; ++which)
    for (double step : {-0.02, 0.02}) {
      RecoveryState moved = st;
      for (int c = 0; c < 3; ++c)
        for (int64_t p = 0; p < n; ++p) moved.x[size_t((2 * c + which) * n + p)] += step;
      const RecoverySummary m = Recover(d, ro, &moved);
      EXPECT_GT(m.fit_error, s.fit_error) << (which ? "mu" : "kappa") << " " << step;
    }
}

// A volume whose mu is 0.75, 0 and 0.25 decades above the start's 0.01 (kappa as the start).
Material KnownLevelTruth(const GridShape& shape) {
  return Material::Constant(shape, 0.5, {0.2f, 0.2f, 0.2f},
                            {float(0.01 * std::pow(10.0, 0.75)), 0.01f, float(0.01 * std::pow(10.0, 0.25))});
}

// Options that start the heterogeneous fit at kappa 0.2, mu 0.01 (no homogeneous fit) after the
// level search, and stop after one iteration.
RecoveryOptions KnownLevelOptions(Backend backend) {
  RecoveryOptions ro;
  ro.backend = backend;
  ro.homogeneous_iterations = 0;
  ro.homogeneous_kappa = 0.2;
  ro.homogeneous_mu = 0.01;
  ro.max_iterations = 1;
  return ro;
}

// The search's factors against the truth's.
void ExpectTruthLevel(const Material& truth, const RecoveryOptions& ro, const RecoverySummary& s) {
  std::printf("level search: %d trials, %.1f s, mu x %.3f %.3f %.3f (truth's: 5.62 1 1.78)\n", s.level_trials,
              s.level_seconds, s.level_factor[0], s.level_factor[1], s.level_factor[2]);
  for (int c = 0; c < 3; ++c)
    EXPECT_NEAR(std::log10(s.level_factor[c] / (truth.mu[c][0] / ro.homogeneous_mu)), 0.0, 1e-6) << c;
}

// The absorption level search from a start whose mu is off by a known factor per channel
// (no homogeneous fit: it would find the truth here), 0.75 decades low, right and 0.25 decades
// low: on homogeneous data the heterogeneous fit's objective after a trial is least where the
// level is right; the coarse lattice of 0.5 decades holds neither low factor, its refinement
// by a quarter decade (down for red from 1 or up from 0.5, up for blue from 0) holds both.
// (Offsets of 2x or less the trials' own iterations correct at any level; the search may leave
// them.)
TEST_P(RecoverOnBackend, LevelSearchFindsAKnownAbsorptionLevel) {
  const Material truth = KnownLevelTruth({12, 10, 5});
  const Dataset d = DataOnTheRecoveryGrid(truth);
  RecoveryOptions ro = KnownLevelOptions(GetParam());
  RecoveryState st;
  const RecoverySummary s = Recover(d, ro, &st);
  std::printf("%s\n", s.BriefReport().c_str());
  ExpectTruthLevel(truth, ro, s);
  for (int c = 0; c < 3; ++c) {
    EXPECT_DOUBLE_EQ(st.level_factor[c], s.level_factor[c]);
    EXPECT_DOUBLE_EQ(st.mu_scale[c], ro.homogeneous_mu * s.level_factor[c]);  // the regulariser's reference
  }
  EXPECT_GE(s.level_trials, 3);
  EXPECT_GT(s.level_solves, 0);
  EXPECT_GT(s.level_seconds, 0);
  // Off: the start's level stays, and the heterogeneous fit starts further from the data.
  ro.level_search = 0;
  RecoveryState off;
  const RecoverySummary s0 = Recover(d, ro, &off);
  std::printf("objective at the start: %.3e with the search, %.3e without\n", s.initial_objective,
              s0.initial_objective);
  EXPECT_EQ(s0.level_trials, 0);
  EXPECT_EQ(s0.level_factor, (std::array<double, 3>{1, 1, 1}));
  EXPECT_LT(4 * s.initial_objective, s0.initial_objective);  // measured 5.3x (cpu), 5.7x (gl)
}

// The same search on data with 2 % noise: the trials' few iterations leave most of the noise
// in the residual, a floor common to every level that hides the levels' differences (here,
// scored by the objective itself, the search kept 1, 1, 1; on wax 64x48x16 with 1 % noise no
// level came out 1.5x below another). The trials are scored with the residual low-passed, and
// the search finds the same factors as without noise.
TEST_P(RecoverOnBackend, LevelSearchSeesThroughNoise) {
  const Material truth = KnownLevelTruth({24, 20, 5});
  SimulateOptions so;
  so.lights = RegionLights("2x2");
  so.oversample = 1;
  so.noise = 0.02;
  RecoveryOptions ro = KnownLevelOptions(GetParam());
  ro.lambda = 1e-4;
  ro.regularize_mu = true;
  RecoveryState st;
  ExpectTruthLevel(truth, ro, Recover(SimulateDataset(truth, so).training, ro, &st));
}

// One optimiser per channel, each at most one iteration ahead of the reports (FitChannels): the
// objective reported for iteration k is that of the iterate in the state the callback sees
// with it, and a stop there leaves that iterate in the state.
TEST_P(RecoverOnBackend, EachReportHoldsItsIterate) {
  const Dataset d = DataOnTheRecoveryGrid(SynthesizeMaterial({.preset = "marble", .shape = {12, 10, 5}}));
  RecoveryOptions ro;
  ro.backend = GetParam();
  ro.level_search = 0;
  ro.max_iterations = 50;
  ro.tolerance = 1e-15;
  std::vector<std::vector<double>> xs;
  std::vector<double> fs;
  RecoveryState st;
  const RecoverySummary s = Recover(d, ro, &st, [&](const IterationReport& r, const RecoveryState& state) {
    xs.push_back(state.x);
    fs.push_back(r.objective);
    return r.iteration < 12;
  });
  std::printf("%s\n", s.BriefReport().c_str());
  EXPECT_EQ(s.termination, RecoveryTermination::kStopped);
  ASSERT_EQ(s.iterations, 12);
  ASSERT_EQ(xs.size(), 12u);
  EXPECT_EQ(st.x, xs.back());
  for (const int k : {1, 6, 12}) {
    // No iterations left: the run only evaluates the objective at the state's x.
    RecoveryState at = st;
    at.x = xs[k - 1];
    RecoveryOptions none = ro;
    none.max_iterations = at.iteration = k;
    const RecoverySummary e = Recover(d, none, &at);
    std::printf("iteration %d: reported %.6e, evaluated %.6e\n", k, fs[k - 1], e.final_objective);
    EXPECT_NEAR(e.final_objective / fs[k - 1], 1.0, 1e-3) << k;
  }
  EXPECT_LT(fs[11], 0.5 * fs[0]);  // the iterates do differ
  // Every channel had made the iteration by its report (a report before one had would show
  // that channel's block unchanged since the last).
  const size_t block = st.x.size() / 3;
  for (size_t k = 1; k < xs.size(); ++k)
    for (size_t c = 0; c < 3; ++c)
      EXPECT_FALSE(std::equal(xs[k].begin() + c * block, xs[k].begin() + (c + 1) * block, xs[k - 1].begin() + c * block))
          << "iteration " << k + 1 << ", channel " << c;
}

// Early stopping on validation conditions (RecoveryOptions::validation_every): noisy data from a
// 2x finer grid, where the fit's later iterations fit noise and discretisation error. The fit
// stops validation_patience iterations after the best checked iterate, returns that iterate
// (its validation error, recomputed, is the reported one and the least of the run's), and
// relights independent held-out spots better than the full run does.
TEST_P(RecoverOnBackend, ValidationStopsAtTheBestValidatedIterate) {
  const Material truth = SynthesizeMaterial({.preset = "wax", .shape = {16, 12, 5}});
  SimulateOptions so;
  so.lights = RegionLights("3x3");
  so.noise = 0.01;
  so.holdout = 8;
  so.validation = 4;
  const SimulatedData data = SimulateDataset(truth, so);
  RecoveryOptions ro;
  ro.backend = GetParam();
  ro.lambda = 1e-4;
  ro.regularize_mu = true;
  ro.max_iterations = 100;
  ro.validation_every = 5;
  ro.validation_patience = 25;
  RecoveryState st;
  const RecoverySummary s = Recover(data.training, ro, &st, {}, &data.validation);
  std::printf("%s\n", s.BriefReport().c_str());
  EXPECT_EQ(s.termination, RecoveryTermination::kValidated);
  EXPECT_LT(s.iterations, ro.max_iterations);
  EXPECT_EQ(s.validation_iteration, s.iterations - ro.validation_patience);
  EXPECT_EQ(st.best_iteration, s.validation_iteration);
  // The result is within the margin of the least error, and no later check came within it.
  const double least = st.least_validation_error, within = (1 + ro.validation_margin) * least;
  EXPECT_LE(s.validation_error, within);
  int checked = 0;
  for (const auto& r : s.history)
    if (r.validation_error >= 0) {
      ++checked;
      EXPECT_EQ(r.iteration % ro.validation_every, 0);
      EXPECT_GE(r.validation_error, least) << r.iteration;
      if (r.iteration > s.validation_iteration) {
        EXPECT_GT(r.validation_error, within) << r.iteration;
      }
    }
  EXPECT_EQ(checked + 1, s.validation_checks);  // and the start's
  MultigridOptions mg;
  mg.tolerance = 1e-9;
  std::vector<FacePattern> q, L;
  std::vector<std::vector<float>> w;
  for (const auto& c : data.validation.conditions) {
    q.push_back(c.q);
    L.push_back(c.L);
    w.push_back(c.mask);
  }
  const Material result = MaterialFromState(data.training, st);
  EXPECT_NEAR(RelightingError(RenderMeasured(result, data.training.setup, q, mg), L, w) / s.validation_error,
              1.0, 1e-4);
  // Without validation: all iterations (or the objective's own convergence), worse on held-out light.
  RecoveryOptions full = ro;
  full.validation_every = 0;
  RecoveryState sf;
  const RecoverySummary f = Recover(data.training, full, &sf, {}, &data.validation);
  EXPECT_EQ(f.validation_checks, 0);
  EXPECT_GT(f.iterations, s.iterations);
  const double e_validated =
      EvaluateRecovery(result, &truth, data.training, data.holdout, mg, GetParam()).holdout_error;
  const double e_full =
      EvaluateRecovery(MaterialFromState(data.training, sf), &truth, data.training, data.holdout, mg, GetParam())
          .holdout_error;
  std::printf("held-out E: %.3e validated (iteration %d of %d), %.3e after %d iterations\n", e_validated,
              s.validation_iteration, s.iterations, e_full, f.iterations);
  EXPECT_LT(e_validated, 0.9 * e_full);
  // A checkpoint keeps the best validated iterate, and a resumed fit goes on from it.
  if (GetParam() != Backend::kCpu) return;
  RecoveryState part;
  ro.validation_patience = 1000;
  Recover(data.training, ro, &part, [](const IterationReport& r, const RecoveryState&) { return r.iteration < 12; },
          &data.validation);
  const std::string path = (std::filesystem::temp_directory_path() / "translume_validation_checkpoint.bin").string();
  WriteCheckpoint(path, data.training, part);
  const RecoveryState back = ReadCheckpoint(path, data.training);
  std::filesystem::remove(path);
  EXPECT_EQ(back.best_x, part.best_x);
  EXPECT_EQ(back.best_iteration, part.best_iteration);
  EXPECT_EQ(back.best_validation_error, part.best_validation_error);
  EXPECT_EQ(back.least_validation_error, part.least_validation_error);
  ASSERT_EQ(back.history.size(), part.history.size());
  for (size_t k = 0; k < back.history.size(); ++k)
    EXPECT_EQ(back.history[k].validation_error, part.history[k].validation_error);
}

INSTANTIATE_TEST_SUITE_P(Backends, RecoverOnBackend, ::testing::Values(Backend::kCpu, Backend::kGl),
                         [](const auto& info) { return info.param == Backend::kCpu ? "cpu" : "gl"; });

// Validation conditions on other terms than the training data's are refused with one line
// naming both (DifferentProblem): they would be rendered on the wrong grid or face.
TEST(Recover, RefusesValidationOnOtherTerms) {
  const Material truth = Material::Constant({8, 6, 4}, 0.5, {0.25f, 0.15f, 0.08f}, {0.01f, 0.03f, 0.06f});
  const Dataset d = DataOnTheRecoveryGrid(truth);
  RecoveryOptions ro;
  ro.max_iterations = 2;
  auto expect_refused = [&](const Dataset& v, const std::vector<std::string>& what) {
    RecoveryState st;
    try {
      Recover(d, ro, &st, {}, &v);
      ADD_FAILURE() << "no error";
    } catch (const InputError& e) {
      const std::string msg = e.what();
      EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
      for (const auto& w : what) EXPECT_NE(msg.find(w), std::string::npos) << msg << " lacks " << w;
    }
  };
  Dataset front = d;
  front.setup = Setup::kFront;
  expect_refused(front, {"validation dataset", "front-lit", "back-lit"});
  Dataset coarse = d;
  coarse.spacing_mm = 2 * d.spacing_mm;
  expect_refused(coarse, {"validation dataset", "spacing 1 mm", "0.5 mm"});
}

// Stopping after 15 iterations, writing a checkpoint, reading it back and resuming reaches the
// same result as one uninterrupted run (both to convergence; the resumed L-BFGS starts with an
// empty history, so the iterates differ on the way).
TEST(Recover, CheckpointResumeMatchesUninterruptedRun) {
  const SynthOptions syn{.preset = "layered", .shape = {10, 8, 4}};
  const Material truth = SynthesizeMaterial(syn);
  SimulateOptions so;
  so.lights = RegionLights("2x2");
  so.oversample = 1;
  const Dataset d = SimulateDataset(truth, so).training;
  RecoveryOptions ro;
  ro.lambda = 1e-3;
  ro.regularize_mu = true;
  ro.max_iterations = 600;
  ro.tolerance = 1e-10;
  RecoveryState a;
  const RecoverySummary sa = Recover(d, ro, &a);
  RecoveryState b;
  Recover(d, ro, &b, [](const IterationReport& r, const RecoveryState&) { return r.iteration < 15; });
  EXPECT_EQ(b.iteration, 15);
  const std::string path = (std::filesystem::temp_directory_path() / "translume_checkpoint_test.bin").string();
  WriteCheckpoint(path, d, b);
  RecoveryState c = ReadCheckpoint(path, d);
  std::filesystem::remove(path);
  EXPECT_EQ(c.x, b.x);
  EXPECT_EQ(c.history.size(), 15u);
  const RecoverySummary sc = Recover(d, ro, &c);
  std::printf("uninterrupted: %s\nresumed: %s\n", sa.BriefReport().c_str(), sc.BriefReport().c_str());
  EXPECT_EQ(c.history.front().iteration, 1);
  EXPECT_GT(c.history.back().iteration, 15);
  EXPECT_NEAR(sc.final_objective / sa.final_objective, 1.0, 1e-3);
  const Material ma = MaterialFromState(d, a), mc = MaterialFromState(d, c);
  std::vector<double> ek, em;
  LayerErrors(mc, ma, &ek, &em);
  for (size_t k = 0; k < ek.size(); ++k) {
    EXPECT_LT(ek[k], 2e-2) << k;
    EXPECT_LT(em[k], 2e-2) << k;
  }
  // And they relight the sample the same way.
  std::vector<FacePattern> q;
  for (const auto& cond : d.conditions) q.push_back(cond.q);
  MultigridOptions mg;
  mg.tolerance = 1e-10;
  EXPECT_LT(RelightingError(RenderFrontFace(mc, d.setup, q, mg), RenderFrontFace(ma, d.setup, q, mg)), 1e-6);
  EXPECT_THROW(ReadCheckpoint("/nonexistent/ck.bin", d), InputError);
}

// The wax preset on 24x18x8, h = 0.25 mm, lit by 4x4 back regions (data from the 2x finer grid).
Dataset WaxTraining24x18x8() {
  const SynthOptions syn{.preset = "wax", .shape = {24, 18, 8}, .spacing_mm = 0.25};
  SimulateOptions so;
  so.lights = RegionLights("4x4");
  return SimulateDataset(SynthesizeMaterial(syn), so).training;
}

// A checkpoint written late in a fit resumes with gradients of ~1e-7: L-BFGS' first step, the
// gradient itself, used to change nothing that the warm-started solves could see, and the
// resumed fit stopped at once ("Parameter tolerance reached", zero iterations) on 24x18x8 wax
// as on 64x48x16. It must go on lowering the objective.
TEST(Recover, LateCheckpointResumesDescending) {
  const Dataset d = WaxTraining24x18x8();
  RecoveryOptions ro;
  ro.level_search = 0;
  ro.max_iterations = 60;
  RecoveryState st;
  const RecoverySummary first = Recover(d, ro, &st);
  ASSERT_EQ(first.iterations, 60);
  ro.max_iterations = 80;
  const RecoverySummary resumed = Recover(d, ro, &st);
  std::printf("first: %s\nresumed: %s\n", first.BriefReport().c_str(), resumed.BriefReport().c_str());
  EXPECT_EQ(resumed.iterations, 80);
  EXPECT_LT(resumed.final_objective, 0.8 * first.final_objective);
}

// RecoveryOptions::stop (Ctrl-C in solve and acquire) ends the homogeneous fit and the level
// search where they are, and the fit does not start: the result is the homogeneous fit, at its
// own level. (A first Ctrl-C in the level search used to wait for the whole search.)
TEST(Recover, StopEndsTheHomogeneousFitAndTheLevelSearch) {
  const Dataset d = WaxTraining24x18x8();
  RecoveryOptions ro;
  ro.max_iterations = 50;
  std::atomic<int> polls{0};
  int stop_after = 1 << 30;
  ro.stop = [&] { return polls++ >= stop_after; };
  // The homogeneous fit alone: how many polls it makes.
  ro.level_search = 0;
  ro.max_iterations = 0;
  RecoveryState homogeneous;
  Recover(d, ro, &homogeneous);
  const int homogeneous_polls = polls.load();
  ASSERT_GT(homogeneous_polls, 3);
  // Stopped 5 polls into the level search: some of its trials ran, none of the fit's iterations.
  ro.level_search = 10;
  ro.max_iterations = 50;
  polls = 0;
  stop_after = homogeneous_polls + 5;
  RecoveryState st;
  const RecoverySummary s = Recover(d, ro, &st);
  std::printf("%s\n", s.BriefReport().c_str());
  EXPECT_EQ(s.termination, RecoveryTermination::kStopped);
  EXPECT_NE(s.message.find("in the absorption level search"), std::string::npos) << s.message;
  EXPECT_EQ(s.iterations, 0);
  EXPECT_TRUE(s.level_stopped);
  EXPECT_GE(s.level_trials, 1);
  EXPECT_EQ(s.level_factor, (std::array<double, 3>{1, 1, 1}));
  EXPECT_EQ(st.x, homogeneous.x);  // the homogeneous fit, untouched by the trials
  // Stopped at once: the starting guess, no trial.
  polls = 0;
  stop_after = 0;
  RecoveryState none;
  const RecoverySummary s0 = Recover(d, ro, &none);
  EXPECT_EQ(s0.termination, RecoveryTermination::kStopped);
  EXPECT_EQ(s0.level_trials, 0);
  EXPECT_FALSE(s0.level_stopped);
  for (int c = 0; c < 3; ++c) {
    EXPECT_DOUBLE_EQ(s0.homogeneous_kappa[c], ro.homogeneous_kappa);
    EXPECT_DOUBLE_EQ(s0.homogeneous_mu[c], ro.homogeneous_mu);
  }
  EXPECT_LT(s0.solves, s.solves);
}

// A fresh fit's first step. Ceres' first step is the gradient itself, which from the homogeneous
// start changed the log-parameters by ~3e-6 on 64x48x16 (J is normalised: the gradient per node
// falls as the nodes grow in number); solves to 1e-6 did not register so small a change from
// their warm start, and the fit stopped at once ("Parameter tolerance reached", zero
// iterations). Every fit's first step is now sized (FirstStepScale), so that even solves to
// 1e-5, which do not register it on this grid either, leave a descending fit.
TEST(Recover, FreshFitDescendsWithLooseSolves) {
  const Dataset d = WaxTraining24x18x8();
  RecoveryOptions ro;
  ro.level_search = 0;
  ro.max_iterations = 10;
  ro.solve_tolerance = 1e-5;
  RecoveryState st;
  const RecoverySummary s = Recover(d, ro, &st);
  std::printf("%s\n", s.BriefReport().c_str());
  EXPECT_EQ(s.iterations, 10);
  EXPECT_LT(s.final_objective, 0.5 * s.initial_objective);
}

// A checkpoint is a file a user hands back: damage in it is named, never a crash (an empty
// history row was read past its end, scales of 0 tripped a CHECK, deep nesting overflowed the
// stack, NaN parameters were blamed on the dataset).
TEST(Recover, CorruptCheckpointsAreNamed) {
  const Material m = SynthesizeMaterial({.preset = "wax", .shape = {6, 5, 3}});
  SimulateOptions so;
  so.lights = RegionLights("1x1");
  so.oversample = 1;
  const Dataset d = SimulateDataset(m, so).training;
  RecoveryState st = StateFromMaterial(d, m);
  st.history.push_back({1, 2.0, 3.0, 4, 5.0});
  const std::string path = (std::filesystem::temp_directory_path() / "translume_corrupt_checkpoint.bin").string();
  WriteCheckpoint(path, d, st);
  std::ifstream in(path, std::ios::binary);
  const nlohmann::json good = nlohmann::json::from_cbor(std::vector<uint8_t>((std::istreambuf_iterator<char>(in)), {}));
  EXPECT_EQ(ReadCheckpoint(path, d).history.size(), 1u);
  const auto expect = [&](const std::vector<uint8_t>& bytes, const std::string& what) {
    std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
    try {
      ReadCheckpoint(path, d);
      ADD_FAILURE() << "accepted: " << what;
    } catch (const InputError& e) {
      const std::string msg = e.what();
      EXPECT_EQ(msg.find(path + ": corrupt checkpoint ("), 0u) << msg;
      EXPECT_NE(msg.find(what), std::string::npos) << msg;
    }
  };
  const auto with = [&](const std::function<void(nlohmann::json&)>& change) {
    nlohmann::json j = good;
    change(j);
    return nlohmann::json::to_cbor(j);
  };
  expect(with([](auto& j) { j["history"] = {nlohmann::json::array()}; }), "history row 0 must be 5 or 6 numbers");
  expect(with([](auto& j) { j["history"] = {{1}}; }), "history row 0 must be 5 or 6 numbers");
  expect(with([](auto& j) { j["kappa_scale"] = {0, 0, 0}; }), "kappa_scale must be finite and > 0, got 0");
  expect(with([](auto& j) { j["mu_scale"][1] = -1; }), "mu_scale must be finite and > 0, got -1");
  expect(with([](auto& j) { j["iteration"] = int64_t(1) << 40; }), "iteration must be a whole number within 0..");
  expect(with([](auto& j) { j["x"][7] = 1e300; }), "parameters: node");
  expect(with([](auto& j) { j["x"][7] = NAN; }), "parameters: node");
  const auto validation = [](nlohmann::json& j) {
    j["validation"] = {{"best_iteration", 0}, {"best_error", 1e-3}, {"least_error", 1e-3}, {"best_x", j["x"]}};
  };
  expect(with([&](auto& j) { validation(j); j["validation"]["best_x"][3] = 1e300; }), "validation best_x: node");
  expect(with([&](auto& j) { validation(j); j["validation"]["best_x"].erase(0); }),
         "validation best_x has the wrong number of parameters");
  expect(with([&](auto& j) { validation(j); j["validation"]["best_error"] = -1; }),
         "validation best_error must be finite and >= 0");
  expect(with([&](auto& j) { validation(j); j["validation"]["least_error"] = 2e-3; }),
         "validation least_error must be within 0..best_error");
  expect(with([&](auto& j) { validation(j); j["validation"]["best_iteration"] = 99; }),
         "validation best_iteration must be a whole number within 0..");
  std::vector<uint8_t> deep(200000, 0x81);  // a CBOR array of one element, nested 200000 times
  deep.push_back(0);
  expect(deep, "nested deeper than a checkpoint");
  std::filesystem::remove(path);
}

// --init: a material's state gives the material back (float values), with the dataset's grid,
// and a material on another grid is named as the problem.
TEST(Recover, StateFromMaterialRoundTrips) {
  const SynthOptions syn{.preset = "inclusions", .shape = {9, 7, 4}};
  const Material m = SynthesizeMaterial(syn);
  Dataset d;
  d.shape = m.shape;
  d.spacing_mm = m.spacing_mm;
  d.C = m.C;
  const Material back = MaterialFromState(d, StateFromMaterial(d, m));
  EXPECT_EQ(back.shape, m.shape);
  EXPECT_DOUBLE_EQ(back.spacing_mm, m.spacing_mm);
  for (int c = 0; c < 3; ++c)
    for (int64_t p = 0; p < m.shape.size(); ++p) {
      EXPECT_NEAR(back.kappa[c][p], m.kappa[c][p], 1e-6 * m.kappa[c][p]);
      EXPECT_NEAR(back.mu[c][p], m.mu[c][p], 1e-6 * m.mu[c][p]);
    }
  d.shape.nz += 1;
  EXPECT_THROW(StateFromMaterial(d, m), InputError);
}

TEST(Recover, PaperOptimizerAndNcgLowerTheObjective) {
  const Material truth = Material::Constant({8, 6, 4}, 0.5, {0.2f, 0.15f, 0.1f}, {0.02f, 0.03f, 0.05f});
  SimulateOptions so;
  so.lights = RegionLights("2x2");
  const Dataset d = SimulateDataset(truth, so).training;
  for (OptimizerKind kind : {OptimizerKind::kPaper, OptimizerKind::kNcg}) {
    RecoveryOptions ro;
    ro.optimizer = kind;
    ro.max_iterations = 5;
    ro.homogeneous_iterations = 0;  // start far from the truth
    RecoveryState st;
    const RecoverySummary s = Recover(d, ro, &st);
    EXPECT_LT(s.final_objective, 0.5 * s.initial_objective) << OptimizerName(kind);
    EXPECT_EQ(s.iterations, 5) << s.BriefReport();
  }
  EXPECT_THROW(ParseOptimizer("adam"), InputError);
}

// The recovery's memory estimate (memory.h), which `solve` and `acquire` check against the
// available memory, bounds what a recovery adds to the process: the peak resident set, from
// just before it (the free heap handed back first, so that none serves the recovery), over a
// recovery long enough to fill the L-BFGS history, with freed memory kept as the translume
// binaries keep it; for every optimiser, and L-BFGS at a lower rank. Not loose either: the old
// estimate (half the optimiser's vectors uncounted) was 0.51-0.55 of the peak measured here.
struct MemoryCase {
  const char* name;
  OptimizerKind optimizer;
  int lbfgs_rank;
  // Iterations per trial of the level search's run. L-BFGS: the default, its history's pages
  // are touched as the trial goes. ncg and paper keep no history, so two iterations touch what
  // ten do, in a fifth of the trials' time (the paper's golden sections: 92 s of CI with ten).
  int trial_iterations;
};

class RecoverMemory : public ::testing::TestWithParam<MemoryCase> {};

bool first_recovery_in_process = true;

TEST_P(RecoverMemory, PeakStaysWithinTheEstimate) {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  GTEST_SKIP() << "the sanitizer's allocator and shadow memory change the resident set";
#endif
  KeepFreedMemoryForReuse();
  const SynthOptions syn{.preset = "wax", .shape = {48, 40, 12}};
  SimulateOptions so;
  so.lights = RegionLights("4x4");
  so.oversample = 1;
  so.validation = 4;  // checked every 10 iterations (the default), rendered in parallel
  const SimulatedData data = SimulateDataset(SynthesizeMaterial(syn), so);
  const Dataset& d = data.training;
  RecoveryOptions ro;
  ro.optimizer = GetParam().optimizer;
  ro.lbfgs_rank = GetParam().lbfgs_rank;
  ro.max_iterations = 22;
  ro.tolerance = 1e-15;
  // Without the level search the estimate is also close (the optimiser's vectors are most of
  // it); with it, whose trials run in the channels' threads and arenas, the
  // peak varies more from run to run and only the bound is asserted.
  for (const int level_search : {0, GetParam().trial_iterations}) {
    ro.level_search = level_search;
    // What the data's simulation and the previous run freed must not serve the recovery.
    if (!ResetPeakResidentSet()) GTEST_SKIP() << "cannot reset the peak resident set (/proc/self/clear_refs)";
    const int64_t before = ResidentSetBytes();
    ASSERT_GT(before, 0);
    RecoveryState st;
    const RecoverySummary s = Recover(d, ro, &st, {}, &data.validation);
    const int64_t peak = PeakResidentSetBytes();
    const int64_t estimate = RecoveryMemoryBytes(d.shape, int(d.conditions.size()), ro);
    const double used = double(peak - before);
    std::printf("%s, level search %d, %s, %d conditions, %d iterations: peak %s above the start, estimate %s "
                "(%.2f)\n", GetParam().name, level_search, d.shape.ToString().c_str(), int(d.conditions.size()),
                s.iterations, FormatBytes(peak - before).c_str(), FormatBytes(estimate).c_str(),
                used / double(estimate));
    EXPECT_EQ(s.iterations, 22);
    EXPECT_EQ(s.validation_checks, 4);  // the start, 10, 20 and the end
    EXPECT_LE(used, double(estimate));
    // (The validation checks' solvers are counted in full, but may reuse memory that the fit
    // freed: ncg 0.60 of the estimate with them, 0.68 without.)
    // Only in the process's first recovery (ctest runs each case alone): the channels' optimisers
    // run in their own threads, whose malloc arenas keep their freed tops resident (malloc_trim
    // releases only the main arena's), and a later recovery reuses them unseen (0.36-0.44).
    if (level_search == 0 && first_recovery_in_process) {
      EXPECT_GE(used, 0.55 * double(estimate));
    }
    first_recovery_in_process = false;
  }
}

INSTANTIATE_TEST_SUITE_P(Optimizers, RecoverMemory,
                         ::testing::Values(MemoryCase{"lbfgs_rank20", OptimizerKind::kLbfgs, 20, RecoveryOptions{}.level_search},
                                           MemoryCase{"lbfgs_rank5", OptimizerKind::kLbfgs, 5, RecoveryOptions{}.level_search},
                                           MemoryCase{"ncg", OptimizerKind::kNcg, 20, 2},
                                           MemoryCase{"paper", OptimizerKind::kPaper, 20, 2}),
                         [](const ::testing::TestParamInfo<MemoryCase>& info) { return info.param.name; });

}  // namespace
}  // namespace translume
