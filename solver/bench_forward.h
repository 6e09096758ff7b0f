// SPDX-License-Identifier: MIT
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "solver/forward.h"
#include "solver/grid.h"
#include "solver/multigrid.h"

namespace translume {

struct ForwardBenchOptions {
  std::vector<GridShape> grids;  // empty: the default list (small to the paper's grids)
  int repeats = 5;               // our solver: median of this many cold solves
  Precision precision = Precision::kDouble;
  Backend backend = Backend::kCpu;  // gl: float, with the cpu solver as the peer
  bool peers = true;             // also run Eigen CG (diagonal, IC) and Jacobi relaxation
  // The paper's relaxation runs at most min(jacobi_factor * our time, jacobi_cap_seconds).
  double jacobi_factor = 100;
  double jacobi_cap_seconds = 60;
  double tolerance = 1e-6;
  // Our solver's cycle: V(smoothing, smoothing) on the finest level, V(coarse_smoothing,
  // coarse_smoothing) below, and how z coarsens; 0 / unset: the backend's default
  // (MultigridOptions).
  int smoothing = 0;
  int coarse_smoothing = 0;
  std::optional<ZCoarsening> z_coarsening;
  // Start CG from the full-multigrid pass (MultigridOptions::full_multigrid_start).
  bool full_multigrid_start = true;
  // Time with the process's CPU clock instead of the wall clock (cpu backend; meaningful with
  // one thread, where it is the solve's own time however busy the machine is).
  bool cpu_time = false;
  // gl: also solve `batch` right-hand sides (the 4x4 region lights on the lit face, cycled) as
  // one batched solve; the table sets its time per right-hand side against one gl solve and
  // the cpu peer's. 0 skips it.
  int batch = 16;
};

struct PeerResult {
  std::string name;
  bool ran = false, converged = false;
  int64_t iterations = 0;
  double seconds = 0, residual = 0;
  // Our solver's advantage: peer time / our time. When the peer did not converge within its
  // budget this is a lower bound (`lower_bound` = true).
  double ratio = 0;
  bool lower_bound = false;
};

struct ForwardBenchRow {
  GridShape shape;
  int levels = 0, iterations = 0;
  double seconds = 0;          // median solve to `tolerance`
  double apply_seconds = 0;    // median operator application
  double work_units = 0;       // seconds / apply_seconds
  double nodes_per_second = 0;
  double residual = 0;
  // gl only: effective bandwidth of the stencil (ApplyBytes / apply_seconds) and of a plain
  // copy kernel measured in the same run (the device's practical peak), bytes per second.
  double apply_bandwidth = 0, copy_bandwidth = 0;
  std::string copy_reference;  // what the copy was (GlMultigridSolver::CopyReference)
  // gl only: the gl solution against the cpu solver's in double solved to 1e-12 on the same
  // problem: relative L2 error over every node, and the largest error on the front face (the
  // radiance there) relative to the face's largest value.
  double gl_error_l2 = 0, gl_error_front = 0;
  // gl only: dispatches of one solve, and the median seconds of an empty dispatch (their
  // fixed cost) measured in the same run.
  int64_t dispatches = 0;
  double dispatch_seconds = 0;
  // gl only: the batched solve of batch_fields right-hand sides (median seconds for all of
  // them, the most iterations of any field).
  int batch_fields = 0, batch_iterations = 0;
  double batch_seconds = 0;
  // gl only: the stencil applied to batch_apply_fields fields in one dispatch (the batch's, or
  // the most one dispatch takes: GlMultigridSolver::max_batch), as a GPU's batched solves and
  // the recovery's evaluations apply it: its effective bandwidth, ApplyBytes(fields) / median
  // seconds (the coefficients read once for every field).
  int batch_apply_fields = 0;
  double batch_apply_bandwidth = 0;
  std::vector<PeerResult> peers;
};

std::vector<GridShape> DefaultForwardBenchGrids();
// Runs the benchmark; `progress` (may be null) receives one line per finished measurement.
std::vector<ForwardBenchRow> RunForwardBench(const ForwardBenchOptions& options,
                                             void (*progress)(const std::string&) = nullptr);
std::string ForwardBenchTable(const std::vector<ForwardBenchRow>& rows);
std::string ForwardBenchJson(const std::vector<ForwardBenchRow>& rows);

}  // namespace translume
