// SPDX-License-Identifier: MIT
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "solver/multigrid_hierarchy.h"
#include "solver/stencil.h"

namespace translume {

struct MultigridOptions {
  // Stop when ||b - A x|| <= tolerance * ||b|| (2-norms).
  double tolerance = 1e-6;
  int max_iterations = 100;
  // The cycle: z-line Gauss-Seidel sweeps (red + black) before and after the coarse-grid
  // correction on the finest level (pre, post) and on every coarser level (coarse), and how z
  // coarsens (multigrid_hierarchy.h). 0 / unset: the backend's choice (WithCycleDefaults). The
  // cpu solver, bound by memory traffic, takes x-y semi-coarsening with V(1,1) on the finest
  // level and V(2,2) below on grids of 100000 nodes or more: ~5 iterations to 1e-6 (without
  // the full-multigrid start below; 3-4 with it), as full
  // coarsening with V(2,2) needed, for 5-20 % less time; on smaller grids, where that cycle
  // needs a 6th iteration, full coarsening with V(2,2). The gl solver, bound by its number of
  // dispatches, takes full coarsening (fewer levels) with V(2,2) everywhere. An unset
  // smoothing count follows the coarsening: 1 on the finest level with kLast, else 2.
  // docs/benchmarks.md, "Forward solver", has the measurements.
  int pre_smoothing = 0;
  int post_smoothing = 0;
  int coarse_smoothing = 0;
  std::optional<ZCoarsening> z_coarsening;
  // Stop coarsening at this many nodes; the coarsest level is solved exactly (sparse Cholesky).
  int64_t coarsest_nodes = 1500;
  // Double solvers only: precondition with a float V-cycle (half the memory traffic of the
  // hierarchy; CG's residuals and iterate stay in double, so the accuracy is unchanged; only the
  // search direction is float, like the V-cycle's output it is built from).
  bool mixed_precision = true;
  // Before CG, one full-multigrid pass (nested iteration; Brandt 1977, Trottenberg et al. 2001,
  // section 2.6) on the initial residual: restricted to every level, solved exactly on the
  // coarsest, then on each finer level the coarser solution, prolonged, is the initial guess
  // of one V(1,1) cycle; on the finest level full_multigrid_sweeps smoothing sweeps replace
  // the V-cycle (they remove the prolongation's rough error; CG does the rest). From a zero
  // guess CG's first iteration then ends at a relative residual of ~1e-4 .. 6e-4 (5e-2 ..
  // 0.15 without); the pass costs about one iteration and saves one or two of the ~5 to 1e-6
  // (docs/benchmarks.md, "Forward solver"). The gl solver does the same, with one V-cycle
  // over its coarse tail as the coarse solve.
  bool full_multigrid_start = true;
  int full_multigrid_sweeps = 2;

  // Empty if valid, else the broken constraint.
  std::string Validate() const;
  // Sweeps before (and after) the coarse-grid correction on level `level` (0 = finest).
  int SweepsOnLevel(size_t level) const { return level == 0 ? pre_smoothing : coarse_smoothing; }
  // These options with the cycle's unset fields filled in for the cpu or the gl solver on a
  // grid of `nodes` nodes.
  MultigridOptions WithCycleDefaults(bool gl, int64_t nodes) const;
};

struct SolveSummary {
  bool converged = false;
  int iterations = 0;
  double initial_residual = 0;  // relative: ||b - A x0|| / ||b||
  double final_residual = 0;    // relative, recomputed from the returned x
  double seconds = 0;
  std::string message;
  std::vector<double> history;  // relative (recursive) residual after each iteration
  std::string BriefReport() const;
};

// Conjugate gradients preconditioned by one multigrid V-cycle, for the SPD system A x = b of
// one channel (SPEC section 3). The hierarchy coarsens vertex-centred (every other node, each
// axis while it has >= 3 nodes and is not already much coarser than the others: semi-coarsening
// for flat grids such as 256 x 256 x 20), re-discretises kappa and mu averaged by the
// restriction weights, smooths with red-black (zebra) z-line Gauss-Seidel, which stays robust
// when z is strongly coupled, prolongs trilinearly, restricts by the transpose and solves the
// coarsest level exactly. The V-cycle is symmetric, so CG applies. T is float or double; dot
// products accumulate in double.
//
// Usage: construct once per grid, SetCoefficients() whenever kappa/mu change (cheap: O(N)),
// Solve() any number of right-hand sides, each warm-started from the x passed in. The adjoint
// system is the same matrix (A is symmetric), so adjoint solves use Solve() too.
template <typename T>
class MultigridSolver {
 public:
  MultigridSolver(const GridShape& shape, double h, const MultigridOptions& options = {});
  ~MultigridSolver();

  void SetCoefficients(const T* kappa, const T* mu, double C);
  // x holds the initial guess on entry (zeros for a cold start) and the solution on exit.
  SolveSummary Solve(const T* b, T* x);
  // y = A x on the finest level.
  void Apply(const T* x, T* y) const;
  // z = M r: one V-cycle (the preconditioner), from z = 0.
  void Precondition(const T* r, T* z);

  const Stencil<T>& stencil() const;
  const TensorGrid& grid() const;
  int num_levels() const;
  // Shapes of every level, finest first (for reports and tests).
  std::vector<GridShape> level_shapes() const;
  const MultigridOptions& options() const { return options_; }
  MultigridOptions& mutable_options() { return options_; }

 private:
  // A double solver's CG runs its float hierarchy's V-cycles on that hierarchy's own buffers.
  template <typename>
  friend class MultigridSolver;
  struct Level;
  // bx: if not null, receives b . x after the cycle (accumulated in double; conjugate
  // gradients' r . z), summed as the last sweep finishes each row. from_zero: x is zero on
  // entry (the preconditioner), else it holds an initial guess (full multigrid). sweeps > 0:
  // V(sweeps, sweeps) on this level and below instead of the options' cycle.
  void VCycle(size_t l, const T* b, T* x, double* bx = nullptr, bool from_zero = true,
              int sweeps = 0);
  // The full-multigrid pass (MultigridOptions::full_multigrid_start) for the finest level's
  // right-hand side b, leaving its approximate solution in the finest level's x (level layout).
  // Overwrites every level's b and x.
  void FullMultigrid();
  // Values on level L restricted to the next coarser level, both in their level layout (full
  // multigrid's right-hand sides; the V-cycle restricts residuals as its sweeps compute them).
  void RestrictRhs(const Level& L, const T* fine, T* coarse) const;
  // V-cycle internals work on split rows (solver/multigrid_split.h); b and x are the level's.
  // One Gauss-Seidel sweep over both colours of z-lines (colour c: the columns with
  // (i + j) % 2 == c), colour `first` first, fused into one pass over memory. from_zero: x is
  // taken as zero on entry. restricted: if not null, also writes the residual b - A x after the
  // sweep, restricted along x, into it ((coarse nx) * ny * nz values).
  // bx: if not null, receives b . x after the sweep, summed row by row as each row is final.
  void Sweep(const Level& L, const T* b, T* x, int first, bool from_zero, T* restricted,
             double* bx = nullptr) const;
  // The line solves of colour `color`'s columns in row j (all planes).
  void LineRow(const Level& L, const T* b, T* x, int64_t j, int color, bool from_zero) const;
  // Residual of row j (all planes), restricted along x into `restricted`. Colour `solved`'s
  // lines were the last to be solved exactly given all their neighbours, so their residual is
  // zero (to rounding) and is not computed: half the work.
  void ResidualRow(const Level& L, const T* b, const T* x, int64_t j, int solved,
                   T* restricted) const;
  void Restrict(const Level& L, const T* fine, T* coarse) const;
  void ProlongAdd(const Level& L, const T* coarse, T* fine) const;

  MultigridOptions options_;
  std::vector<std::unique_ptr<Level>> levels_;
  // With mixed_precision (T = double): the float hierarchy that preconditions; levels_ then
  // holds only the finest level's double operator.
  std::unique_ptr<MultigridSolver<float>> float_preconditioner_;
  std::vector<float> rf_, zf_;
  std::vector<T> r_, p_, q_;
  std::vector<float> p_float_;  // CG's p instead of p_ with mixed precision (Solve)
  bool has_coefficients_ = false;
};

}  // namespace translume
