// SPDX-License-Identifier: MIT
// The optimisers of a recovery (RecoveryOptions::optimizer: Ceres' L-BFGS and nonlinear CG, the
// paper's Polak-Ribiere CG) over an objective given as a function, and FitChannels, which runs
// one per channel on threads of its own.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <span>
#include <string>

#include "solver/recover.h"

namespace translume {

// What an optimiser reports after each iteration; returns false to stop.
using IterationHook = std::function<bool(int iteration, double f, double gnorm)>;

struct OptimizerResult {
  RecoveryTermination termination = RecoveryTermination::kFailed;
  std::string message;
  int iterations = 0;
  double initial = 0, final = 0;
};

// What the optimisers minimise: f(x) and, where g is non-null, df/dx into g; ok: whether the
// last evaluation's solves converged (the optimisers treat a point where they did not as failed).
struct Objective {
  std::function<double(const double* x, double* g)> evaluate;
  std::function<bool()> ok;
};

// The run's optimiser (o.optimizer) on f from x, in place; each iteration goes to `hook`
// (optional; its false stops the run). The objective is scaled for Ceres so that its first step
// changes the largest log-parameter by 0.1 (FirstStepScale, optimizer.cc). Ceres' first step
// is the gradient itself (no curvature known yet), whose size is the objective's and not the
// problem's: from a homogeneous start on 64x48x16 it changed the
// log-parameters by ~3e-6 (35000x short of FirstStepScale's 0.1: J is normalised, so the
// gradient per node falls as the nodes grow in number), and late in a fit (a resumed
// checkpoint, --init) by ~1e-7. Warm-started solves register so small a change only where their
// tolerance is far below it: with solves to 1e-6 instead of 1e-8 a fresh 64x48x16 fit stopped
// at once ("Parameter tolerance reached", zero step; docs/benchmarks.md, "The first step of
// every fit"), and before the scaling a resumed checkpoint did so with 1e-8 too. From some level
// search trials it changed them by ~1e-4 and the trial crept (wax 64x48x16's blue at +0.25
// decades: 0.404 -> 0.402 in 10 iterations, against 1.7e-3 at +0.5). The later steps and Ceres'
// relative tolerances do not depend on the scale. RunPaper sizes its first trial the same way.
OptimizerResult RunOptimizer(const Objective& f, const RecoveryOptions& o, int max_iterations,
                             std::span<double> x, const IterationHook& hook);

// Three independent objectives, one per channel, each over its own 2 n unknowns (FitChannels).
struct ChannelObjectives {
  // f_c at x and, where g is non-null, its gradient into g.
  std::function<double(int c, const double* x, double* g)> evaluate;
  // Whether channel c's last evaluation can be trusted (Objective::ok).
  std::function<bool(int c)> ok;
  // OpenMP threads for each channel's own thread.
  int threads_per_channel = 1;
  // Evaluate on the calling thread, one channel at a time (the gl backend: its context is
  // current there), rather than on each channel's thread.
  bool serve_here = false;
};

// The run's optimiser on each channel's block of x (2 n values from x + 2 c n) at once, each
// channel on its own thread, minimising f_c / 3 (recover.h: the channels' terms of the joint
// objective). Channels whose `fit` is false are left alone. The channels are independent
// problems; run as one, Ceres' L-BFGS does its vector work over all of them on one thread, and
// that was 50-64 % of a Wax I iteration on the H200's gl backend (docs/benchmarks.md, "GPU
// session 2026-12-04"). Here each channel's vector work runs on its own thread, and on gl it
// overlaps the GPU's work: with `serve_here` the evaluations run on the calling thread (gl:
// the context is current there), one at a time, in turn, while the other channels' optimisers
// work. Each channel takes its own line-search steps (in one joint run the channel furthest
// from its optimum set them for all).
//
// With a `hook`, the channels report their iterations in step: the hook runs once per
// iteration k, on the calling thread, when every channel still running has reported k, with
// k, the channels' summed objective (of the last iteration each reported) and the norm of the joint gradient,
// while x holds every channel's iterate of k (or of its last report); its false stops them
// all. A channel may meanwhile work on iteration k + 1 (its optimiser works on its own copy of
// its block) but not finish it before the hook of k has run, so the GPU need not idle while
// the host's optimisers work. After a false, each channel stops at the end of the iteration it
// is in. x ends with each channel's last reported iterate: a channel that converges does so in
// an iteration that its optimiser does not report (Ceres), whose change is below the tolerance.
// A channel's error stops the others too and is rethrown here. Without a hook, the channels run
// on to their own ends (RecoveryOptions::stop still stops them) and x gets their final iterates.
OptimizerResult FitChannels(const ChannelObjectives& problem, const RecoveryOptions& o, int64_t n,
                            int max_iterations, const std::array<bool, 3>& fit, double* x,
                            const IterationHook& hook);

}  // namespace translume
