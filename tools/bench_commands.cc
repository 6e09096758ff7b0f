// SPDX-License-Identifier: MIT
// `translume bench forward` and `bench recovery`: they need only the solver and the inverse
// problem in memory (no file IO), so they also build into the self-contained GPU benchmark
// binary (tools/gpubench.cc).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fmt/format.h>
#include <fmt/ranges.h>
#include <memory>
#include <string>
#include <vector>

#include "solver/bench_forward.h"
#include "solver/bench_recovery.h"
#include "solver/forward.h"
#include "solver/gl_context.h"
#include "solver/gl_solver.h"
#include "solver/memory.h"
#include "solver/simulate.h"
#include "solver/status.h"
#include "solver/synthetic.h"
#include "solver/threads.h"
#include "tools/commands.h"
#include "tools/recovery_flags.h"

namespace translume {

void PrintBenchProgress(const std::string& line) { std::fprintf(stderr, "  %s\n", line.c_str()); }

namespace {

void PrintGlInfo() {
  const GlInfo& info = GlContext::Get().info();
  std::fprintf(stderr, "gl: %s, %s, %s\n", info.platform.c_str(), info.renderer.c_str(),
               info.version.c_str());
  // The shader variant too, so that a log of runs under TRANSLUME_GL_* overrides says which ran.
  std::fprintf(stderr, "gl shaders: %s\n", GlShaderTuning().c_str());
}

}  // namespace

void AddBenchForward(CLI::App& bench) {
  struct Flags {
    ForwardBenchOptions o;
    std::vector<std::string> grids;
    bool json = false, no_peers = false, no_full_multigrid = false;
    std::string precision = "double", backend = "cpu", coarsening;
  };
  auto f = std::make_shared<Flags>();
  auto* fwd = bench.add_subcommand("forward", "Forward solve to 1e-6: multigrid-PCG vs Eigen CG "
                                              "(diagonal, IC) and the paper's Jacobi relaxation");
  fwd->fallthrough();  // --threads after the subcommand too
  fwd->add_option("--grids", f->grids, "Grids NXxNYxNZ (default: 33^3, 65^3, 129^3, 130x53x37, 256x256x20)")
      ->delimiter(',');
  fwd->add_option("--repeats", f->o.repeats, "Solves per grid (median)")->capture_default_str()->check(CLI::Range(1, 10000));
  fwd->add_option("--precision", f->precision, "float or double")->capture_default_str();
  fwd->add_option("--backend", f->backend, "cpu or gl (gl: float, the cpu solver is the peer, "
                                           "and the stencil's bandwidth is compared to a copy)")
      ->capture_default_str();
  fwd->add_option("--jacobi-cap", f->o.jacobi_cap_seconds, "Longest Jacobi run per grid, seconds")
      ->capture_default_str()
      ->check(PositiveFinite());
  fwd->add_option("--jacobi-factor", f->o.jacobi_factor,
                  "Jacobi also stops after this many times our solve time (its ratio is then a "
                  "lower bound; raise it to measure the ratio itself)")
      ->capture_default_str()
      ->check(PositiveFinite());
  fwd->add_flag("--cpu-time", f->o.cpu_time,
                "Time with the process's CPU clock, not the wall clock (cpu backend, with "
                "--threads 1: unaffected by other jobs on a shared machine)");
  fwd->add_option("--batch", f->o.batch, "gl: also solve this many right-hand sides (4x4 region "
                                         "lights) as one batch, and time the stencil on them in one "
                                         "dispatch; 0 skips")
      ->capture_default_str()
      ->check(CLI::Range(0, 4096));
  fwd->add_option("--smoothing", f->o.smoothing, "Our solver's V(N, N) cycle on the finest level: "
                  "smoothing sweeps before and after the coarse correction (default: 1 with x-y "
                  "coarsening, else 2)")
      ->check(CLI::Range(1, 8));
  fwd->add_option("--coarse-smoothing", f->o.coarse_smoothing,
                  "The same on every coarser level (default 2)")
      ->check(CLI::Range(1, 8));
  fwd->add_option("--coarsening", f->coarsening, "xy: x-y semi-coarsening, z last; full: z with "
                  "x and y (default: xy for cpu grids of 100000 nodes or more, else full)")
      ->check(CLI::IsMember({"xy", "full"}));
  fwd->add_flag("--no-full-multigrid", f->no_full_multigrid,
                "Start CG from the caller's guess (zero), not from a full-multigrid pass");
  fwd->add_flag("--no-peers", f->no_peers, "Skip the Eigen and Jacobi peers");
  fwd->add_flag("--json", f->json, "Print JSON instead of a table");
  fwd->callback([f] {
    ForwardBenchOptions o = f->o;
    o.precision = ParsePrecision(f->precision);
    for (const auto& g : f->grids) {
      o.grids.push_back(ParseGridShape(g, "--grids"));
      // Checked before any grid runs, as forward does (a grid too large ended in a bare "out of
      // memory" after the smaller ones had run).
      CheckFitsInMemory(EstimateMemory(o.grids.back(), 1, o.precision).forward_bytes,
                        fmt::format("--grids {}: a forward solve on it", g));
    }
    o.backend = ParseBackend(f->backend);
    if (o.cpu_time && o.backend == Backend::kGl)
      throw InputError("--cpu-time: only with --backend cpu (the gl solver runs on the GPU)");
    if (o.backend == Backend::kGl) PrintGlInfo();
    o.peers = !f->no_peers;
    o.full_multigrid_start = !f->no_full_multigrid;
    if (!f->coarsening.empty())
      o.z_coarsening = f->coarsening == "full" ? ZCoarsening::kWithXY : ZCoarsening::kLast;
    std::fprintf(stderr, "bench forward: backend %s, %d threads, %s%s\n", f->backend.c_str(),
                 NumThreads(), f->precision.c_str(), o.cpu_time ? ", CPU time" : "");
    const auto rows = RunForwardBench(o, PrintBenchProgress);
    std::printf("%s\n", (f->json ? ForwardBenchJson(rows) : ForwardBenchTable(rows)).c_str());
  });
}

void AddBenchRecovery(CLI::App& bench) {
  struct Flags {
    RecoveryBenchOptions o;
    bool full = false, json = false, comparison_only = false, no_comparison = false;
    std::string grid, data_backend = "cpu";
    std::vector<std::string> backends = {"cpu"}, setups = {"back", "front"};
  };
  auto f = std::make_shared<Flags>();
  auto* rec = bench.add_subcommand("recovery", "Synthetic recoveries (4 presets x back/front x 0/1 % "
                                               "noise, 16 conditions) and the paper's optimiser vs lbfgs");
  rec->fallthrough();
  RecoveryBenchOptions& ro = f->o;
  rec->add_flag("--json", f->json, "Print JSON instead of a table");
  rec->add_flag("--full", f->full, "64x48x16 grids (slow) instead of the default 24x18x8");
  rec->add_option("--grid", f->grid, "Recovery grid NXxNYxNZ (overrides --full; the paper's: "
                                     "130x53x37 Wax I, 256x256x20 Marble)");
  rec->add_option("--presets", ro.presets, "Presets")->delimiter(',')->capture_default_str();
  rec->add_option("--setups", f->setups, "Lit faces: back, front")->delimiter(',')
      ->capture_default_str();
  rec->add_option("--noises", ro.noises, "Relative noise levels (0.01 = 1 %)")->delimiter(',')
      ->capture_default_str();
  rec->add_option("--backend", f->backends, "cpu or gl: where the recoveries' solves run; a list "
                                            "(gl,cpu) recovers each case on each, the same data")
      ->delimiter(',')->capture_default_str();
  rec->add_option("--data-backend", f->data_backend, "cpu or gl: where the data simulation (on "
                  "the 2x finer grid) and the evaluation run; not part of the recovery's time")
      ->capture_default_str();
  rec->add_option("--spacing", ro.spacing_mm, "Node spacing h in mm")->capture_default_str();
  rec->add_option("--max-iterations", ro.recovery.max_iterations, "Iterations per recovery")
      ->capture_default_str();
  rec->add_option("--max-seconds", ro.max_seconds, "Stop each recovery after this many seconds "
                  "(0: no limit); the row reports the iterations made")
      ->capture_default_str();
  rec->add_option("--validation", ro.validation, "Validation spots simulated per case: the recovery "
                  "stops on them and keeps its best iterate (0: none, all --max-iterations)")
      ->capture_default_str();
  AddValidationFlags(*rec, &ro.recovery);
  AddSolveToleranceFlag(*rec, &ro.recovery);
  rec->add_option("--holdout-every", ro.holdout_every, "Also evaluate the held-out E every this "
                  "many iterations (its solves are not counted in the recovery's time; 0: off)")
      ->capture_default_str();
  rec->add_option("--tolerance", ro.recovery.tolerance, "A channel's optimiser stops when an "
                  "iteration lowers its objective by less than this fraction (tiny: run all --max-iterations)")
      ->capture_default_str();
  rec->add_option("--lbfgs-rank", ro.recovery.lbfgs_rank, "L-BFGS history: pairs of vectors kept "
                  "(memory: 96 bytes per node each)")->capture_default_str();
  rec->add_flag("--joint-optimizer", ro.recovery.joint_optimizer, "One optimiser over all three channels' "
                "unknowns, as the fit was until 2026-12-04, instead of one per channel on three threads (for "
                "comparisons; the row's optimizer reads e.g. lbfgs-joint)");
  rec->add_option("--level-search", ro.recovery.level_search, "Iterations per trial of the absorption level "
                  "search (0: off)")->capture_default_str();
  rec->add_option("--lambda", ro.recovery.lambda, "lambda for noise-free data")->capture_default_str();
  rec->add_option("--noisy-lambda", ro.noisy_lambda, "lambda for 1 % noise")->capture_default_str();
  rec->add_flag("--comparison-only", f->comparison_only, "Only the paper-vs-lbfgs comparison");
  rec->add_flag("--no-comparison", f->no_comparison, "Skip the paper-vs-lbfgs comparison");
  rec->add_option("--paper-iterations", ro.paper_iterations, "Iterations of the paper optimiser")
      ->capture_default_str();
  rec->callback([f, rec] {
    RecoveryBenchOptions o = f->o;
    if (f->full) o.shape = {64, 48, 16};
    if (!f->grid.empty()) o.shape = ParseGridShape(f->grid, "--grid");
    if (f->comparison_only && f->no_comparison)
      throw InputError("bench recovery: --comparison-only and --no-comparison exclude each other");
    o.run_cases = !f->comparison_only;
    o.compare_optimizers = !f->no_comparison;
    // Errors name this command's flags (--setups, not the library's --setup).
    const std::vector<std::string> known = SynthPresetNames();
    for (const auto& p : o.presets)
      if (std::find(known.begin(), known.end(), p) == known.end())
        throw InputError(fmt::format("--presets: unknown preset '{}' (available: {})", p, fmt::join(known, ", ")));
    o.setups.clear();
    for (const auto& s : f->setups) o.setups.push_back(ParseSetup(s, "--setups"));
    o.backends.clear();
    for (const auto& b : f->backends) o.backends.push_back(ParseBackend(b));
    if (o.backends.empty()) throw InputError("bench recovery: --backend needs a backend");
    o.data_backend = ParseBackend(f->data_backend, "--data-backend");
    if (o.paper_iterations < 0) throw InputError("--paper-iterations: must be >= 0");
    if (!(o.noisy_lambda >= 0) || !std::isfinite(o.noisy_lambda)) throw InputError("--noisy-lambda: must be >= 0");
    if (!(o.max_seconds >= 0)) throw InputError("bench recovery: --max-seconds must be >= 0");
    if (o.validation < 0 || o.validation > kMaxHoldout)
      throw InputError(fmt::format("bench recovery: --validation must be within 0..{}", kMaxHoldout));
    if (o.holdout_every < 0) throw InputError("bench recovery: --holdout-every must be >= 0");
    for (double n : o.noises)
      if (!(n >= 0 && n <= 1)) throw InputError(fmt::format("bench recovery: noise {} must be within 0..1", n));
    if (std::string err = o.recovery.Validate(); !err.empty()) throw OptionsError(*rec, "bench recovery", err);
    if (o.data_backend == Backend::kGl ||
        std::find(o.backends.begin(), o.backends.end(), Backend::kGl) != o.backends.end())
      PrintGlInfo();
    std::fprintf(stderr, "bench recovery: grid %s, %d threads\n", o.shape.ToString().c_str(),
                 NumThreads());
    const RecoveryBenchResult r = RunRecoveryBench(o, PrintBenchProgress);
    std::printf("%s\n", (f->json ? RecoveryBenchJson(r) : RecoveryBenchTable(r)).c_str());
  });
}

}  // namespace translume
