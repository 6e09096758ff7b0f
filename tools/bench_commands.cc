// SPDX-License-Identifier: MIT
// `translume bench`: needs only the solver core (no file IO), so it also builds into the
// self-contained GPU benchmark binary (tools/gpubench.cc).
#include <cstdio>
#include <string>
#include <vector>

#include "solver/bench_forward.h"
#include "solver/forward.h"
#include "solver/gl_context.h"
#include "solver/threads.h"
#include "tools/commands.h"

namespace translume {

namespace {
void PrintProgress(const std::string& line) {
  std::fprintf(stderr, "  %s\n", line.c_str());
}
}  // namespace

int RunBench(int argc, char** argv) {
  CLI::App app{"Benchmarks. Results are medians; ratios compare solvers run side by side in\n"
               "the same process on the same problem.", "translume bench"};
  app.require_subcommand(1);
  auto* fwd = app.add_subcommand("forward", "Forward solve to 1e-6: multigrid-PCG vs Eigen CG "
                                            "(diagonal, IC) and the paper's Jacobi relaxation");
  fwd->fallthrough();  // --threads after the subcommand too
  ForwardBenchOptions o;
  std::vector<std::string> grids;
  bool json = false, no_peers = false;
  std::string precision = "double", backend = "cpu";
  fwd->add_option("--grids", grids, "Grids NXxNYxNZ (default: 33^3, 65^3, 129^3, 130x53x37, 256x256x20)")
      ->delimiter(',');
  fwd->add_option("--repeats", o.repeats, "Solves per grid (median)")->capture_default_str();
  fwd->add_option("--precision", precision, "float or double")->capture_default_str();
  fwd->add_option("--backend", backend, "cpu or gl (gl: float, the cpu solver is the peer, "
                                        "and the stencil's bandwidth is compared to a copy)")
      ->capture_default_str();
  fwd->add_option("--jacobi-cap", o.jacobi_cap_seconds, "Longest Jacobi run per grid, seconds")
      ->capture_default_str();
  fwd->add_flag("--no-peers", no_peers, "Skip the Eigen and Jacobi peers");
  fwd->add_flag("--json", json, "Print JSON instead of a table");
  AddCommonOptions(app);
  if (ParseOrHelp(app, argc, argv)) return 0;
  for (const auto& g : grids) o.grids.push_back(ParseGridShape(g, "--grids"));
  o.precision = ParsePrecision(precision);
  o.backend = ParseBackend(backend);
  if (o.backend == Backend::kGl) {
    const GlInfo& info = GlContext::Get().info();
    std::fprintf(stderr, "gl: %s, %s, %s\n", info.platform.c_str(), info.renderer.c_str(),
                 info.version.c_str());
  }
  o.peers = !no_peers;
  std::fprintf(stderr, "bench forward: backend %s, %d threads, %s\n", backend.c_str(), NumThreads(),
               precision.c_str());
  const auto rows = RunForwardBench(o, PrintProgress);
  std::printf("%s\n", (json ? ForwardBenchJson(rows) : ForwardBenchTable(rows)).c_str());
  return 0;
}

}  // namespace translume
