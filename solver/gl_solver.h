// SPDX-License-Identifier: MIT
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "solver/multigrid.h"

namespace translume {

// The `gl` backend of MultigridSolver: the same multigrid-preconditioned CG (same hierarchy,
// zebra z-line smoother, separable transfers; see multigrid.h) as OpenGL compute shaders
// (solver/shaders/*.comp) over shader storage buffers (image buffers on llvmpipe:
// GlShaderTuning), float32 storage, dot products reduced in double. Differences from the cpu
// backend: the coarsest level (<= 64 nodes where the grid allows) is solved with a dense
// inverse when it has at most 1024 nodes, else by 8 symmetric sweep pairs, and the
// coefficients are assembled on the GPU, so SetCoefficients uploads only kappa and mu.
// Several right-hand sides of one operator solve as a batch: every dispatch serves all fields
// (kappa, mu and the stencil are read once for all), conjugate gradients run in lockstep with
// each field's scalars kept on the GPU, and the host reads them back only every few iterations
// (docs/gpu.md). Uses the process-wide GlContext; call from the thread that created it.
class GlMultigridSolver {
 public:
  GlMultigridSolver(const GridShape& shape, double h, const MultigridOptions& options = {});
  ~GlMultigridSolver();

  void SetCoefficients(const float* kappa, const float* mu, double C);
  // x: initial guess in, solution out (host arrays of shape.size() floats).
  SolveSummary Solve(const float* b, float* x);
  // Solves A x_f = b_f for `fields` right-hand sides at once. b and x hold the fields back to
  // back: field f is b[f n .. (f + 1) n), n = shape.size(); x: initial guesses in, solutions
  // out. Returns one summary per field (each field converges, stagnates or runs out of
  // iterations on its own); `seconds` is the whole call's time. Batches of more than
  // max_batch() fields run as several batches.
  std::vector<SolveSummary> SolveBatch(int fields, const float* b, float* x);
  // The most fields one batch holds (bounded by the largest shader storage block).
  int max_batch() const;
  void Apply(const float* x, float* y);
  int num_levels() const;
  // The coarse tail (docs/gpu.md): the levels with at most max_nodes nodes (at least two of
  // them, the coarsest included) run their part of every V-cycle as one dispatch, one work
  // group per field, instead of ~13 dispatches per level; the same arithmetic up to float
  // rounding. 0 turns it off. Default: the shader tuning's (TRANSLUME_GL_TAIL_NODES overrides).
  void SetCoarseTail(int64_t max_nodes);
  // Levels the coarse tail covers (0: none).
  int coarse_tail_levels() const;

  // Benchmarks: median seconds of one stencil application on the finest level to `fields`
  // fields at once (one dispatch in the plain layout, as batches apply it on a GPU, whose
  // pack_fields is 1; more than 1 only after a SolveBatch of at least that many, at most
  // max_batch()), and of one device-to-device
  // copy of `bytes` bytes by a compute shader (on llvmpipe: a host memcpy on every thread, see
  // CopyReference), each over `repetitions` runs.
  double TimeApply(int repetitions, int fields = 1);
  double TimeCopy(int64_t bytes, int repetitions);
  // What TimeCopy measured, in words.
  std::string CopyReference() const;
  // Bytes one stencil application to `fields` fields must move at least: cx, cy, cz, sigma
  // read once, each field's x read and y written.
  int64_t ApplyBytes(int fields = 1) const;
  // Median seconds of a dispatch that does nothing (one work group of an empty loop, and its
  // barrier): the fixed cost every dispatch pays (on llvmpipe its thread pool's hand-off).
  double TimeEmptyDispatch(int repetitions);
  // Compute dispatches issued by every gl solver of the process so far.
  static int64_t Dispatches();

  // The device state, for the other gl sources (gl_internal.h).
  struct Impl;
  Impl& impl() { return *impl_; }

 private:
  std::unique_ptr<Impl> impl_;
};

// The shader variant chosen for this device (docs/gpu.md, "Shaders on llvmpipe"), in words.
// Creates the GL context if needed.
std::string GlShaderTuning();

// For tests: compiles `source` as a compute shader the way the backend's shaders are compiled
// (after common.glsl); throws InputError naming `file_name` and the line on a compile error.
void CompileGlShaderForTest(const std::string& file_name, const std::string& source);

}  // namespace translume
