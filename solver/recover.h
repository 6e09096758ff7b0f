// SPDX-License-Identifier: MIT
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "solver/dataset.h"
#include "solver/forward.h"
#include "solver/material.h"
#include "solver/objective.h"

namespace translume {

// The inverse problem of SPEC section 4, all three channels at once. The unknowns are the
// log-parameters x (so kappa, mu > 0 at every iterate), laid out channel by channel:
//   x[(2 c) n + p] = log kappa_c[p],  x[(2 c + 1) n + p] = log mu_c[p],  n = nodes, c = R, G, B.
// The objective is the mean over channels of the per-channel objectives
//   f_c = J_c(kappa_c, mu_c) + lambda R(kappa_c; s_kappa_c) [+ lambda R(mu_c; s_mu_c)]
// (J_c: ChannelObjective, R: Regularize with reference scales s = the starting material's
// geometric means). Channels are independent problems: each has its own optimiser, on its own
// thread, over its block of x, and the three iterate in lockstep (Recover's callback sees
// iteration k when every channel still running has made it).

enum class OptimizerKind { kLbfgs, kNcg, kPaper };
OptimizerKind ParseOptimizer(const std::string& text);  // lbfgs | ncg | paper
const char* OptimizerName(OptimizerKind kind);

struct RecoveryOptions {
  // lbfgs / ncg: Ceres GradientProblemSolver (Wolfe line search; ncg = Polak-Ribiere).
  // paper: Polak-Ribiere CG with golden-section line search (Wang et al. 2008, Table I).
  OptimizerKind optimizer = OptimizerKind::kLbfgs;
  Backend backend = Backend::kCpu;
  double lambda = 1e-6;
  RegularizerOptions regularizer;
  bool regularize_mu = false;
  int max_iterations = 300;
  // lbfgs: how many past steps' pairs of vectors (2N doubles per channel, 6N in all: 96 bytes
  // per node per pair)
  // shape the search direction (Ceres' max_lbfgs_rank; 20, Ceres' default, is ~40 % of a
  // recovery's memory). A lower rank trades little for memory here (docs/inverse.md, "Memory").
  int lbfgs_rank = 20;
  // A channel's optimiser stops when an iteration lowers its objective by less than
  // tolerance * objective (the fit ends when all three have, or on max_iterations; with
  // joint_optimizer, the one optimiser on the mean objective).
  double tolerance = 1e-7;
  // First fit one (kappa, mu) per channel (Levenberg-Marquardt on 2 unknowns per channel, at
  // most this many iterations, stopping as above, or where its model promises less; 0 skips
  // it), then the heterogeneous problem.
  int homogeneous_iterations = 40;
  double homogeneous_kappa = 0.1, homogeneous_mu = 0.01;  // its starting point (mm, 1/mm)
  // Then search each channel's absorption level: a homogeneous fit to a heterogeneous volume
  // misjudges mu (wax's red 13x low), and the heterogeneous fit keeps the level it starts
  // from. Trials scale mu by 10^t (t on a lattice of 0.5 decades up from 0, walking while the
  // score falls, up to 2), each running this many iterations of the heterogeneous fit per
  // channel, scored by the objective with the residual images low-passed (noise is rough, a
  // wrong level's residual smooth); per channel the lowest score wins if it is 1.5x below the
  // homogeneous level's, then a quarter decade either side of it wins if 1.2x below, and the
  // fit starts from the homogeneous fit with that channel's mu scaled by it (docs/inverse.md,
  // "The absorption level"). 0 skips it. Only after a homogeneous fit (not --init, not resumed)
  // and before a heterogeneous one (max_iterations > 0).
  int level_search = 10;
  // Early stopping on validation conditions (Recover's `validation`: lights that the fit does
  // not use, e.g. a few spots). Every validation_every iterations the current iterate is
  // rendered under them and its relighting error against their measured L is taken (SPEC
  // section 5's E). The result is the latest checked iterate whose error is within
  // validation_margin of the least so far (differences below it are not told apart; the later
  // iterate fits the training light better), and the fit stops once validation_patience
  // iterations have passed without such an iterate: past a point the iterations fit the
  // training light's noise and the discretisation's error, and relight other light worse
  // (docs/inverse.md, "Validation"). validation_every 0: off.
  int validation_every = 10;
  int validation_patience = 80;
  double validation_margin = 0.02;
  // Relative residual of every forward and adjoint solve. 1e-6: on 64x48x16 13-38 % less time
  // per iteration than 1e-7, and 1e-7 7-13 % less than 1e-8 (the default until 2026-12-02), at
  // the same fit and held-out E (docs/benchmarks.md, "The first step of every fit, and the
  // solves' tolerance"); it relies on every fit's first step being sized (RunOptimizer).
  double solve_tolerance = 1e-6;
  // One optimiser over all 6 N unknowns (the fit until 2026-12-04) instead of one per channel:
  // for side-by-side benchmarks only (`bench recovery --joint-optimizer`, tools/gpu_session.sh).
  // The absorption level search runs per channel either way.
  bool joint_optimizer = false;
  // OpenMP threads inside each channel's solver; 0: max(1, NumThreads() / 3).
  int threads_per_channel = 0;
  // Polled (from the channels' threads too) during the homogeneous fit, per iteration, and the
  // absorption level search, per iteration of its trials: true ends them there (the search's
  // level stays the homogeneous fit's) and skips the heterogeneous fit, whose iterations Recover's
  // callback stops instead; the result is then the homogeneous fit (termination kStopped). A
  // first Ctrl-C during the level search of a large grid used to wait for the whole search.
  std::function<bool()> stop;
  bool StopRequested() const { return stop && stop(); }

  std::string Validate() const;
};

struct IterationReport {
  int iteration = 0;
  double objective = 0, gradient_norm = 0;
  int64_t solves = 0;    // cumulative, forward + adjoint, all channels
  double seconds = 0;    // cumulative
  double validation_error = -1;  // E on the validation conditions where checked, else -1
};

// kValidated: stopped early by the validation conditions (RecoveryOptions::validation_every).
enum class RecoveryTermination { kConverged, kMaxIterations, kStopped, kFailed, kValidated };
const char* TerminationName(RecoveryTermination t);

// The memory a recovery with these options adds to the process (EstimateMemory's recovery_bytes,
// with the L-BFGS history these options keep; none for ncg and paper).
int64_t RecoveryMemoryBytes(const GridShape& shape, int conditions, const RecoveryOptions& options);

// Where a recovery starts: empty x -> homogeneous fit first. Filled from a material (--init) or
// a checkpoint (resume: counters and history continue).
struct RecoveryState {
  std::vector<double> x;
  std::array<double, 3> kappa_scale{}, mu_scale{};  // regulariser reference scales
  std::array<double, 3> homogeneous_kappa{}, homogeneous_mu{};
  std::array<double, 3> level_factor{1, 1, 1};  // the level search's choice (RecoverySummary)
  int iteration = 0;
  int64_t solves = 0;
  double seconds = 0;
  std::vector<IterationReport> history;
  // The result so far of the validation (RecoveryOptions::validation_margin; empty until an
  // iterate is checked), its iteration and validation error, and the least error checked.
  std::vector<double> best_x;
  int best_iteration = -1;
  double best_validation_error = -1, least_validation_error = -1;
};

struct RecoverySummary {
  RecoveryTermination termination = RecoveryTermination::kFailed;
  std::string message;
  OptimizerKind optimizer = OptimizerKind::kLbfgs;
  int iterations = 0;
  int64_t solves = 0;
  double seconds = 0, homogeneous_seconds = 0;
  // Of this run's seconds after the homogeneous fit, those in which neither a channel's
  // evaluation of the objective nor a validation check ran: the optimisers' own vector work and
  // line search where nothing overlapped it, and the callback.
  double optimizer_seconds = 0;
  int64_t homogeneous_solves = 0;  // of `solves`, spent in the homogeneous fit
  // The absorption level search (RecoveryOptions::level_search): its seconds and solves (of
  // `seconds` and `solves`), its trials, and the factor it chose per channel (1: the
  // homogeneous fit's level; all 1 when it did not run).
  double level_seconds = 0;
  int64_t level_solves = 0;
  int level_trials = 0;
  bool level_stopped = false;  // abandoned by RecoveryOptions::stop
  std::array<double, 3> level_factor{1, 1, 1};
  // Conjugate-gradient iterations of this run's solves (not of a resumed run's earlier ones),
  // and of them the homogeneous fit's.
  int64_t cg_iterations = 0, homogeneous_cg_iterations = 0;
  double initial_objective = 0, final_objective = 0;
  std::array<double, 3> homogeneous_kappa{}, homogeneous_mu{};
  std::vector<IterationReport> history;
  // Validation (RecoveryOptions::validation_every; all -1 / 0 without validation conditions):
  // the result's validation error and iteration, the checks made and their seconds (of
  // `seconds`; their solves are not counted in `solves`).
  double validation_error = -1;
  int validation_iteration = -1;
  int validation_checks = 0;
  double validation_seconds = 0;
  // Fit error on the training conditions at the result: E over everything and per condition,
  // E = sum w (L^R - L)^2 / sum w L^2 (RGB together).
  double fit_error = 0;
  std::vector<double> condition_fit_error;
  std::string BriefReport() const;
};

// Progress hook: called after every iteration with the report and the current state (x is
// the current, best, iterate). Return false to stop (the result is then that iterate).
using RecoveryCallback = std::function<bool(const IterationReport&, const RecoveryState&)>;

// Starting state from a material on the dataset's grid (--init). Throws InputError on a
// grid mismatch.
RecoveryState StateFromMaterial(const Dataset& dataset, const Material& material);
// The material of a state (values rounded to float).
Material MaterialFromState(const Dataset& dataset, const RecoveryState& state, double eta = 1.3);

// Runs the recovery from `state` (updated in place to the result: the final iterate, or with
// validation conditions the best validated one). `validation` (may be null or have no
// conditions: no validation) must share the dataset's grid, spacing, C and setup. Throws
// InputError on invalid options or data.
RecoverySummary Recover(const Dataset& dataset, const RecoveryOptions& options,
                        RecoveryState* state, const RecoveryCallback& callback = {},
                        const Dataset* validation = nullptr);

// Checkpoint file: CBOR (nlohmann) of {"format": "translume-checkpoint/1", grid, x (doubles,
// exact), scales, counters, history}. Written atomically. Reading throws InputError naming the
// file on a wrong format or a grid different from `dataset`'s.
void WriteCheckpoint(const std::string& path, const Dataset& dataset, const RecoveryState& state);
RecoveryState ReadCheckpoint(const std::string& path, const Dataset& dataset);

}  // namespace translume
