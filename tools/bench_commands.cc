// SPDX-License-Identifier: MIT
// `translume bench forward`: needs only the solver core (no file IO), so it also builds into
// the self-contained GPU benchmark binary (tools/gpubench.cc).
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "solver/bench_forward.h"
#include "solver/forward.h"
#include "solver/gl_context.h"
#include "solver/status.h"
#include "solver/threads.h"
#include "tools/commands.h"

namespace translume {

void PrintBenchProgress(const std::string& line) { std::fprintf(stderr, "  %s\n", line.c_str()); }

void AddBenchForward(CLI::App& bench) {
  struct Flags {
    ForwardBenchOptions o;
    std::vector<std::string> grids;
    bool json = false, no_peers = false;
    std::string precision = "double", backend = "cpu";
  };
  auto f = std::make_shared<Flags>();
  auto* fwd = bench.add_subcommand("forward", "Forward solve to 1e-6: multigrid-PCG vs Eigen CG "
                                              "(diagonal, IC) and the paper's Jacobi relaxation");
  fwd->fallthrough();  // --threads after the subcommand too
  fwd->add_option("--grids", f->grids, "Grids NXxNYxNZ (default: 33^3, 65^3, 129^3, 130x53x37, 256x256x20)")
      ->delimiter(',');
  fwd->add_option("--repeats", f->o.repeats, "Solves per grid (median)")->capture_default_str();
  fwd->add_option("--precision", f->precision, "float or double")->capture_default_str();
  fwd->add_option("--backend", f->backend, "cpu or gl (gl: float, the cpu solver is the peer, "
                                           "and the stencil's bandwidth is compared to a copy)")
      ->capture_default_str();
  fwd->add_option("--jacobi-cap", f->o.jacobi_cap_seconds, "Longest Jacobi run per grid, seconds")
      ->capture_default_str();
  fwd->add_option("--jacobi-factor", f->o.jacobi_factor,
                  "Jacobi also stops after this many times our solve time (its ratio is then a "
                  "lower bound; raise it to measure the ratio itself)")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  fwd->add_flag("--cpu-time", f->o.cpu_time,
                "Time with the process's CPU clock, not the wall clock (cpu backend, with "
                "--threads 1: unaffected by other jobs on a shared machine)");
  fwd->add_option("--batch", f->o.batch, "gl: also solve this many right-hand sides (4x4 region "
                                         "lights) as one batch; 0 skips")
      ->capture_default_str();
  fwd->add_option("--smoothing", f->o.smoothing, "Our solver's V(N, N) cycle: smoothing sweeps "
                  "before and after each coarse correction")
      ->capture_default_str()->check(CLI::Range(1, 8));
  fwd->add_flag("--no-peers", f->no_peers, "Skip the Eigen and Jacobi peers");
  fwd->add_flag("--json", f->json, "Print JSON instead of a table");
  fwd->callback([f] {
    ForwardBenchOptions o = f->o;
    for (const auto& g : f->grids) o.grids.push_back(ParseGridShape(g, "--grids"));
    o.precision = ParsePrecision(f->precision);
    o.backend = ParseBackend(f->backend);
    if (o.cpu_time && o.backend == Backend::kGl)
      throw InputError("--cpu-time: only with --backend cpu (the gl solver runs on the GPU)");
    if (o.backend == Backend::kGl) {
      const GlInfo& info = GlContext::Get().info();
      std::fprintf(stderr, "gl: %s, %s, %s\n", info.platform.c_str(), info.renderer.c_str(),
                   info.version.c_str());
    }
    o.peers = !f->no_peers;
    std::fprintf(stderr, "bench forward: backend %s, %d threads, %s%s\n", f->backend.c_str(),
                 NumThreads(), f->precision.c_str(), o.cpu_time ? ", CPU time" : "");
    const auto rows = RunForwardBench(o, PrintBenchProgress);
    std::printf("%s\n", (f->json ? ForwardBenchJson(rows) : ForwardBenchTable(rows)).c_str());
  });
}

}  // namespace translume
