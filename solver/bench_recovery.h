// SPDX-License-Identifier: MIT
#pragma once

#include <cstdint>
#include <array>
#include <string>
#include <vector>

#include "solver/grid.h"
#include "solver/recover.h"

namespace translume {

// Synthetic recoveries end to end: synthesise a preset on the recovery grid, simulate 16
// region conditions (4x4) on a 2x finer grid (+ noise), recover with `options`, evaluate on
// held-out spots (SPEC section 5). One paper-sized case alone: presets {"wax"}, setups {kBack},
// noises {0}, compare_optimizers false, shape {130, 53, 37} (tools/gpu_session.sh).
struct RecoveryBenchOptions {
  std::vector<std::string> presets = {"marble", "layered", "inclusions", "wax"};
  std::vector<Setup> setups = {Setup::kBack, Setup::kFront};
  std::vector<double> noises = {0.0, 0.01};
  // Sized for ~15 minutes on 2 cores (--full: 64x48x16). h = 0.25 mm and 8 layers keep the
  // discretisation floor (the truth's own held-out E) below 1e-3 for every preset: at
  // 24x18x6, h = 0.5 mm it is 1.2e-3 (marble) and 2.4e-3 (layered) in the front-lit setup.
  GridShape shape{24, 18, 8};
  double spacing_mm = 0.25;
  int holdout = 16;
  // Validation spots simulated besides (RecoveryOptions::validation_every stops on them; 0:
  // none, the recovery runs its max_iterations).
  int validation = 4;
  RecoveryOptions recovery;  // its backend is ignored: see backends
  // Each case is simulated once and recovered on each of these in turn (gl with the cpu as
  // its peer: {kGl, kCpu}); the optimiser comparison runs on the first.
  std::vector<Backend> backends = {Backend::kCpu};
  // Where the data simulation and the evaluation's forward solves run (not timed as part of
  // the recovery). gl: faster on a GPU, on the 2x finer grid above all.
  Backend data_backend = Backend::kCpu;
  // > 0: stop each recovery after this many seconds (at the end of the iteration that passes
  // it); the row then reports the iterations it made.
  double max_seconds = 0;
  // > 0: also evaluate the held-out E of the current iterate every this many iterations (the
  // row's `curve`; its solves run on data_backend and are taken out of the recovery's seconds).
  int holdout_every = 0;
  // Noisy cases: lambda 1e-4 on kappa and mu (noise-free ones use `recovery`). Against 1e-5 on
  // kappa alone this lowers the held-out E slightly and the front layer's mu error from 3.3 to
  // 0.2 (wax, back-lit, 1 % noise).
  double noisy_lambda = 1e-4;
  bool noisy_regularize_mu = true;
  // The paper optimiser next to lbfgs on the first preset, back-lit, noise-free.
  bool compare_optimizers = true;
  bool run_cases = true;  // false: only the optimiser comparison
  int paper_iterations = 80;
};

// One point of a recovery's held-out curve (RecoveryBenchOptions::holdout_every).
struct RecoveryCurvePoint {
  int iteration = 0;
  double seconds = 0;  // the recovery's, the curve's evaluations taken out
  double objective = 0, holdout_error = 0;
  std::vector<double> holdout_condition_error;  // per held-out condition
};

struct RecoveryBenchRow {
  std::string preset;
  Setup setup = Setup::kBack;
  double noise = 0;
  GridShape shape;
  std::string optimizer;
  int lbfgs_rank = 0;  // L-BFGS' history pairs; 0 for the optimisers that keep none
  double solve_tolerance = 0;  // RecoveryOptions::solve_tolerance
  Backend backend = Backend::kCpu;
  std::string termination, message;  // why the optimiser stopped (TerminationName; Ceres' words)
  // seconds: the whole recovery (homogeneous fit included); simulate / evaluate: the data and
  // the evaluation, outside the recovery.
  double seconds = 0, homogeneous_seconds = 0, simulate_seconds = 0, evaluate_seconds = 0;
  // Of the heterogeneous phase, the time outside the objective (RecoverySummary).
  double optimizer_seconds = 0;
  // The absorption level search between the two (RecoverySummary): its seconds, solves, trials
  // and the mu factor it chose per channel.
  double level_seconds = 0;
  int64_t level_solves = 0;
  int level_trials = 0;
  std::array<double, 3> level_factor{1, 1, 1};
  int iterations = 0;
  int64_t solves = 0, homogeneous_solves = 0;
  // Conjugate-gradient iterations of all solves and of the homogeneous fit's.
  int64_t cg_iterations = 0, homogeneous_cg_iterations = 0;
  double objective = 0, fit_error = 0, holdout_error = 0, truth_holdout_error = 0;
  std::vector<double> kappa_layer_error, mu_layer_error;
  std::vector<RecoveryCurvePoint> curve;  // holdout_every > 0
  // Validation (RecoverySummary): the result's iteration (-1: none) and error, and the checks' seconds.
  int validation_iteration = -1;
  double validation_error = -1, validation_seconds = 0;
  std::vector<std::pair<int, double>> validation_curve;  // (iteration, validation E) of every check
  // Memory: the peak resident set the recovery added to the process (-1 where /proc does not
  // tell), and EstimateMemory's recovery_bytes for it (memory.h; what `solve` checks).
  int64_t peak_memory_bytes = -1, memory_estimate_bytes = 0;
  // Seconds per iteration of the heterogeneous phase (what scales with the iteration count; the
  // level search's trials not counted).
  double SecondsPerIteration() const;
  // optimizer_seconds as a share of the heterogeneous phase.
  double OptimizerShare() const;
  // Mean conjugate-gradient iterations per solve of the homogeneous fit and of the phase after.
  double HomogeneousIterationsPerSolve() const;
  double IterationsPerSolve() const;
};

struct OptimizerComparison {
  bool ran = false;
  double paper_objective = 0, paper_seconds = 0;
  int64_t paper_solves = 0;  // heterogeneous phase only
  int paper_iterations = 0;
  bool lbfgs_reached = false;
  double lbfgs_seconds = 0;  // to reach paper_objective (heterogeneous phase)
  int64_t lbfgs_solves = 0;
  int lbfgs_iterations = 0;
};

struct RecoveryBenchResult {
  std::vector<RecoveryBenchRow> rows;
  OptimizerComparison comparison;
};

RecoveryBenchResult RunRecoveryBench(const RecoveryBenchOptions& options,
                                     void (*progress)(const std::string&) = nullptr);
std::string RecoveryBenchTable(const RecoveryBenchResult& result);
std::string RecoveryBenchJson(const RecoveryBenchResult& result);

}  // namespace translume
