// SPDX-License-Identifier: MIT
#include "solver/bench_recovery.h"

#include <algorithm>
#include <chrono>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "solver/evaluate.h"
#include "solver/light.h"
#include "solver/memory.h"
#include "solver/simulate.h"
#include "solver/status.h"
#include "solver/synthetic.h"

namespace translume {
namespace {

double Since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

struct Case {
  Material truth;
  SimulatedData data;
  double simulate_seconds = 0;
};

Case MakeCase(const RecoveryBenchOptions& o, const std::string& preset, Setup setup, double noise) {
  Case c;
  SynthOptions so;
  so.preset = preset;
  so.shape = o.shape;
  so.spacing_mm = o.spacing_mm;
  c.truth = SynthesizeMaterial(so);
  SimulateOptions sim;
  sim.lights = RegionLights("4x4");
  sim.setup = setup;
  sim.noise = noise;
  sim.holdout = o.holdout;
  sim.validation = o.validation;
  sim.backend = o.data_backend;
  const auto t0 = std::chrono::steady_clock::now();
  c.data = SimulateDataset(c.truth, sim);
  c.simulate_seconds = Since(t0);
  return c;
}

RecoveryBenchRow RunCase(const Case& c, const RecoveryBenchOptions& o, const RecoveryOptions& ro,
                         const std::string& preset, Setup setup, double noise,
                         RecoverySummary* summary_out) {
  MultigridOptions mg;
  mg.tolerance = 1e-9;
  mg.max_iterations = 300;
  RecoveryState st;
  std::vector<RecoveryCurvePoint> curve;
  double curve_seconds = 0;  // the curve's evaluations, inside the recovery's clock
  const RecoveryCallback hook = [&](const IterationReport& rep, const RecoveryState& state) {
    if (o.holdout_every > 0 && rep.iteration % o.holdout_every == 0) {
      const auto t0 = std::chrono::steady_clock::now();
      const EvaluationReport ev = EvaluateRecovery(MaterialFromState(c.data.training, state), &c.truth,
                                                   c.data.training, c.data.holdout, mg, o.data_backend);
      curve.push_back({rep.iteration, rep.seconds - curve_seconds, rep.objective, ev.holdout_error,
                       ev.holdout_condition_error});
      curve_seconds += Since(t0);
    }
    return !(o.max_seconds > 0 && rep.seconds - curve_seconds >= o.max_seconds);
  };
  // The peak from here on is the recovery's (the data's and earlier cases' freed memory handed
  // back first, so that none of it serves this one).
  const bool peak_reset = ResetPeakResidentSet();
  const int64_t resident_before = ResidentSetBytes();
  const RecoverySummary s = Recover(c.data.training, ro, &st, hook, &c.data.validation);
  const int64_t peak = PeakResidentSetBytes();
  const Material rec = MaterialFromState(c.data.training, st);
  const auto t0 = std::chrono::steady_clock::now();
  const EvaluationReport ev =
      EvaluateRecovery(rec, &c.truth, c.data.training, c.data.holdout, mg, o.data_backend);
  RecoveryBenchRow r;
  r.evaluate_seconds = Since(t0);
  r.preset = preset;
  r.setup = setup;
  r.noise = noise;
  r.shape = c.truth.shape;
  r.optimizer = std::string(OptimizerName(ro.optimizer)) + (ro.joint_optimizer ? "-joint" : "");
  r.lbfgs_rank = ro.optimizer == OptimizerKind::kLbfgs ? ro.lbfgs_rank : 0;
  r.solve_tolerance = ro.solve_tolerance;
  r.backend = ro.backend;
  r.termination = TerminationName(s.termination);
  // A bench stops a recovery only at its time cap (stop_after above).
  r.message = s.termination == RecoveryTermination::kStopped && o.max_seconds > 0
                  ? fmt::format("reached the --max-seconds cap of {:g} s", o.max_seconds)
                  : s.message;
  r.seconds = s.seconds - curve_seconds;
  r.homogeneous_seconds = s.homogeneous_seconds;
  // (The curve's evaluations run in Recover's callback, while the channels' optimisers may work
  // on their next iteration: the difference is approximate.)
  r.optimizer_seconds = std::max(0.0, s.optimizer_seconds - curve_seconds);
  r.curve = std::move(curve);
  r.validation_iteration = s.validation_iteration;
  r.validation_error = s.validation_error;
  r.validation_seconds = s.validation_seconds;
  for (const auto& h : s.history)
    if (h.validation_error >= 0) r.validation_curve.push_back({h.iteration, h.validation_error});
  r.level_seconds = s.level_seconds;
  r.level_solves = s.level_solves;
  r.level_trials = s.level_trials;
  r.level_factor = s.level_factor;
  r.simulate_seconds = c.simulate_seconds;
  r.iterations = s.iterations;
  r.solves = s.solves;
  r.homogeneous_solves = s.homogeneous_solves;
  r.cg_iterations = s.cg_iterations;
  r.homogeneous_cg_iterations = s.homogeneous_cg_iterations;
  r.objective = s.final_objective;
  r.fit_error = ev.fit_error;
  r.holdout_error = ev.holdout_error;
  r.truth_holdout_error = ev.truth_holdout_error;
  r.kappa_layer_error = ev.kappa_layer_error;
  r.mu_layer_error = ev.mu_layer_error;
  if (peak_reset && resident_before > 0 && peak >= resident_before) r.peak_memory_bytes = peak - resident_before;
  r.memory_estimate_bytes = RecoveryMemoryBytes(c.data.training.shape, int(c.data.training.conditions.size()), ro);
  if (summary_out) *summary_out = s;
  return r;
}

std::string Layers(const std::vector<double>& v) {
  std::string s;
  for (size_t k = 0; k < v.size(); ++k) s += fmt::format("{}{:.2f}", k ? " " : "", v[k]);
  return s;
}

}  // namespace

double RecoveryBenchRow::SecondsPerIteration() const {
  return iterations > 0 ? (seconds - homogeneous_seconds - level_seconds) / iterations : 0.0;
}

double RecoveryBenchRow::OptimizerShare() const {
  const double t = seconds - homogeneous_seconds - level_seconds;
  return t > 0 ? optimizer_seconds / t : 0.0;
}

double RecoveryBenchRow::HomogeneousIterationsPerSolve() const {
  return homogeneous_solves > 0 ? double(homogeneous_cg_iterations) / homogeneous_solves : 0.0;
}

double RecoveryBenchRow::IterationsPerSolve() const {
  const int64_t n = solves - homogeneous_solves;
  return n > 0 ? double(cg_iterations - homogeneous_cg_iterations) / n : 0.0;
}

RecoveryBenchResult RunRecoveryBench(const RecoveryBenchOptions& o,
                                     void (*progress)(const std::string&)) {
  TL_CHECK(!o.backends.empty());
  RecoveryBenchResult out;
  for (const auto& preset : o.run_cases ? o.presets : std::vector<std::string>{})
    for (Setup setup : o.setups)
      for (double noise : o.noises) {
        const Case c = MakeCase(o, preset, setup, noise);
        if (progress)
          progress(fmt::format("{} {}-lit noise {:g} on {}: data simulated ({}) in {:.1f} s", preset,
                               SetupName(setup), noise, o.shape.ToString(),
                               BackendName(o.data_backend), c.simulate_seconds));
        for (Backend backend : o.backends) {
          RecoveryOptions ro = o.recovery;
          ro.backend = backend;
          if (noise > 0) {
            ro.lambda = o.noisy_lambda;
            ro.regularize_mu = o.noisy_regularize_mu;
          }
          RecoveryBenchRow r = RunCase(c, o, ro, preset, setup, noise, nullptr);
          if (progress)
            progress(fmt::format("{} {}-lit noise {:g} [{}]: held-out E {:.2e} (truth {:.2e}), "
                                 "fit E {:.2e}, {} iterations ({}: {}), {} solves, {:.1f} s "
                                 "(homogeneous {:.1f} s, level search {:.1f} s: {} trials, mu x {:.3g} {:.3g} {:.3g}; "
                                 "{:.3f} s/iteration, {:.0f} % of it in the optimiser; "
                                 "validation: result at iteration {}, E {:.2e}, {:.1f} s; "
                                 "evaluation {:.1f} s); "
                                 "CG iterations per solve {:.2f} in the homogeneous fit, {:.2f} after; "
                                 "peak memory {} (estimate {})",
                                 preset, SetupName(setup), noise, BackendName(backend),
                                 r.holdout_error, r.truth_holdout_error, r.fit_error, r.iterations,
                                 r.termination, r.message, r.solves, r.seconds, r.homogeneous_seconds,
                                 r.level_seconds, r.level_trials, r.level_factor[0], r.level_factor[1],
                                 r.level_factor[2], r.SecondsPerIteration(), 100 * r.OptimizerShare(),
                                 r.validation_iteration, r.validation_error, r.validation_seconds, r.evaluate_seconds,
                                 r.HomogeneousIterationsPerSolve(), r.IterationsPerSolve(),
                                 r.peak_memory_bytes >= 0 ? FormatBytes(r.peak_memory_bytes) : "unknown",
                                 FormatBytes(r.memory_estimate_bytes)));
          out.rows.push_back(std::move(r));
        }
      }
  if (o.compare_optimizers && !o.presets.empty()) {
    // Same data, same homogeneous start (no level search, whose trials would run each
    // optimiser from its own start); compare the heterogeneous phases.
    const Case c = MakeCase(o, o.presets[0], Setup::kBack, 0.0);
    RecoveryOptions paper = o.recovery;
    paper.level_search = 0;
    paper.backend = o.backends.front();
    paper.optimizer = OptimizerKind::kPaper;
    paper.max_iterations = o.paper_iterations;
    RecoverySummary ps, ls;
    RecoveryBenchRow pr = RunCase(c, o, paper, o.presets[0], Setup::kBack, 0.0, &ps);
    RecoveryOptions lbfgs = o.recovery;
    lbfgs.level_search = 0;
    lbfgs.backend = paper.backend;
    lbfgs.optimizer = OptimizerKind::kLbfgs;
    RunCase(c, o, lbfgs, o.presets[0], Setup::kBack, 0.0, &ls);
    OptimizerComparison& cmp = out.comparison;
    cmp.ran = true;
    cmp.paper_objective = ps.final_objective;
    cmp.paper_solves = ps.solves - ps.homogeneous_solves;
    cmp.paper_seconds = ps.seconds - ps.homogeneous_seconds;
    cmp.paper_iterations = ps.iterations;
    for (const auto& h : ls.history)
      if (h.objective <= ps.final_objective) {
        cmp.lbfgs_reached = true;
        cmp.lbfgs_solves = h.solves - ls.homogeneous_solves;
        cmp.lbfgs_seconds = h.seconds - ls.homogeneous_seconds;
        cmp.lbfgs_iterations = h.iteration;
        break;
      }
    if (progress)
      progress(fmt::format("paper optimiser: objective {:.3e} after {} iterations, {} solves; "
                           "lbfgs {} it after {} solves", cmp.paper_objective, cmp.paper_iterations,
                           cmp.paper_solves, cmp.lbfgs_reached ? "reached" : "did NOT reach",
                           cmp.lbfgs_solves));
    pr.optimizer = "paper";
    out.rows.push_back(std::move(pr));
  }
  return out;
}

std::string RecoveryBenchTable(const RecoveryBenchResult& res) {
  // s/iter: the heterogeneous phase per iteration (time s includes the homogeneous fit); opt %:
  // its share outside the objective's evaluations.
  std::string s = fmt::format("| {:<10} | {:<5} | {:>5} | {:<9} | {:<9} | {:<7} | {:>7} | {:>7} | {:>5} | {:>5} | {:>6} | {:>9} | {:>9} | {:>9} | {:<24} | {:<24} |\n",
                              "preset", "setup", "noise", "grid", "optimizer", "backend", "time s", "s/iter",
                              "opt %", "iters", "solves", "fit E", "held-out E", "truth E", "kappa err per layer k",
                              "mu err per layer k");
  s += "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const auto& r : res.rows)
    s += fmt::format("| {:<10} | {:<5} | {:>5g} | {:<9} | {:<9} | {:<7} | {:>7.1f} | {:>7.3f} | {:>5.0f} | {:>5} | {:>6} | {:>9.2e} | {:>9.2e} | {:>9.2e} | {:<24} | {:<24} |\n",
                     r.preset, SetupName(r.setup), r.noise, r.shape.ToString(), r.optimizer,
                     BackendName(r.backend), r.seconds, r.SecondsPerIteration(), 100 * r.OptimizerShare(), r.iterations,
                     r.solves, r.fit_error, r.holdout_error, r.truth_holdout_error,
                     Layers(r.kappa_layer_error), Layers(r.mu_layer_error));
  for (const auto& r : res.rows) {
    if (r.curve.empty()) continue;
    s += fmt::format("\nheld-out E by iteration, {} {}-lit noise {:g} [{}]:", r.preset, SetupName(r.setup),
                     r.noise, BackendName(r.backend));
    for (const auto& p : r.curve) s += fmt::format(" {}: {:.3e}", p.iteration, p.holdout_error);
    s += "\n";
  }
  const auto& c = res.comparison;
  if (c.ran) {
    s += fmt::format("\npaper optimiser (PR-CG + golden section): objective {:.4e} after {} iterations, "
                     "{} solves, {:.1f} s (heterogeneous phase)\n", c.paper_objective, c.paper_iterations,
                     c.paper_solves, c.paper_seconds);
    if (c.lbfgs_reached)
      s += fmt::format("lbfgs reached it at iteration {}: {} solves, {:.1f} s -> {:.3f} of the solves, "
                       "{:.3f} of the time\n", c.lbfgs_iterations, c.lbfgs_solves, c.lbfgs_seconds,
                       double(c.lbfgs_solves) / std::max<int64_t>(1, c.paper_solves),
                       c.lbfgs_seconds / std::max(1e-9, c.paper_seconds));
    else
      s += "lbfgs did NOT reach the paper optimiser's objective\n";
  }
  return s;
}

namespace {

nlohmann::json Curve(const std::vector<RecoveryCurvePoint>& curve) {
  nlohmann::json j = nlohmann::json::array();
  for (const auto& p : curve)
    j.push_back({{"iteration", p.iteration}, {"seconds", p.seconds}, {"objective", p.objective},
                 {"holdout_error", p.holdout_error},
                 {"holdout_condition_error", p.holdout_condition_error}});
  return j;
}

}  // namespace

std::string RecoveryBenchJson(const RecoveryBenchResult& res) {
  nlohmann::json j;
  j["cases"] = nlohmann::json::array();
  for (const auto& r : res.rows)
    j["cases"].push_back({{"preset", r.preset}, {"setup", SetupName(r.setup)}, {"noise", r.noise},
                          {"grid", r.shape.ToString()}, {"optimizer", r.optimizer},
                          {"lbfgs_rank", r.lbfgs_rank}, {"solve_tolerance", r.solve_tolerance},
                          {"backend", BackendName(r.backend)}, {"termination", r.termination},
                          {"message", r.message},
                          {"seconds", r.seconds}, {"homogeneous_seconds", r.homogeneous_seconds},
                          {"seconds_per_iteration", r.SecondsPerIteration()},
                          {"optimizer_seconds", r.optimizer_seconds},
                          {"level_seconds", r.level_seconds}, {"level_solves", r.level_solves},
                          {"level_trials", r.level_trials}, {"level_mu_factor", r.level_factor},
                          {"simulate_seconds", r.simulate_seconds},
                          {"evaluate_seconds", r.evaluate_seconds},
                          {"iterations", r.iterations}, {"solves", r.solves},
                          {"homogeneous_solves", r.homogeneous_solves},
                          {"cg_iterations", r.cg_iterations},
                          {"homogeneous_cg_iterations", r.homogeneous_cg_iterations},
                          {"objective", r.objective}, {"fit_error", r.fit_error},
                          {"holdout_error", r.holdout_error},
                          {"truth_holdout_error", r.truth_holdout_error},
                          {"kappa_layer_error", r.kappa_layer_error},
                          {"mu_layer_error", r.mu_layer_error},
                          {"peak_memory_bytes", r.peak_memory_bytes},
                          {"memory_estimate_bytes", r.memory_estimate_bytes},
                          {"validation_iteration", r.validation_iteration},
                          {"validation_error", r.validation_error},
                          {"validation_seconds", r.validation_seconds},
                          {"validation_curve", r.validation_curve},
                          {"curve", Curve(r.curve)}});
  const auto& c = res.comparison;
  if (c.ran)
    j["optimizer_comparison"] = {{"paper_objective", c.paper_objective},
                                 {"paper_iterations", c.paper_iterations},
                                 {"paper_solves", c.paper_solves},
                                 {"paper_seconds", c.paper_seconds},
                                 {"lbfgs_reached", c.lbfgs_reached},
                                 {"lbfgs_iterations", c.lbfgs_iterations},
                                 {"lbfgs_solves", c.lbfgs_solves},
                                 {"lbfgs_seconds", c.lbfgs_seconds}};
  return j.dump(2);
}

}  // namespace translume
