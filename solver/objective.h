// SPDX-License-Identifier: MIT
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "solver/dataset.h"
#include "solver/multigrid.h"

namespace translume {

// The data term of one RGB channel of a dataset (SPEC section 4), evaluated by a backend:
//   J(kappa, mu) = sum_m sum_p w_mp (L^R_mp - L_mp)^2 / D,   D = sum_m sum_p w_mp L_mp^2
// over conditions m and front-face nodes p (w = mask), with L^R = (phi - q_front) / (2 pi)
// (paper Eq. (3); q_front = q in the front-lit setup, else 0) and A(kappa, mu) phi_m = b_m the
// canonical forward model (paper Eqs. (1), (2), (8); SPEC section 3).
// The gradient is the discrete adjoint (discretise-then-differentiate): per condition one
// adjoint solve A psi_m = dJ/dphi_m = 2 w (L^R - L) / (2 pi D) on the front face, then
//   dJ/dkappa_p = -sum_{faces (p,q)} A_pq / (2 gap) (psi_p - psi_q)(phi_p - phi_q)
//   dJ/dmu_p    = -V_p psi_p phi_p                         (AccumulateOperatorGradient)
// A backend keeps phi_m and psi_m between calls and warm-starts every solve from them.
// kappa (mm) and mu (1/mm) hold shape.size() values in the grid's linear order.
class ChannelObjective {
 public:
  virtual ~ChannelObjective() = default;
  // Returns J. With non-null gradients (each shape.size()), overwrites them with dJ/dkappa and
  // dJ/dmu (2M solves); with null ones only the M forward solves run.
  virtual double Evaluate(const double* kappa, const double* mu, double* grad_kappa,
                          double* grad_mu) = 0;
  // Linear solves so far (forward and adjoint), and their conjugate-gradient iterations.
  virtual int64_t solves() const = 0;
  virtual int64_t cg_iterations() const = 0;
  // From the last Evaluate: per condition sum_p w (L^R - L)^2 and sum_p w L^2.
  virtual const std::vector<double>& condition_misfit() const = 0;
  virtual const std::vector<double>& condition_norm() const = 0;
  // From the last Evaluate: the weighted residuals r = sqrt(w / D) (L^R - L), all conditions'
  // front faces concatenated (M nx ny values), so that J = |r|^2.
  virtual void Residuals(std::vector<double>* r) const = 0;
  // The worst relative residual of the last Evaluate's solves, and whether all converged.
  virtual double worst_residual() const = 0;
};

// What the backends share: one channel's measured data and the data term's math on the front
// face (paper Eq. (3)); a backend supplies the solves and FrontField.
class FrontFaceObjective : public ChannelObjective {
 public:
  int64_t solves() const override { return solves_; }
  int64_t cg_iterations() const override { return cg_iterations_; }
  const std::vector<double>& condition_misfit() const override { return misfit_; }
  const std::vector<double>& condition_norm() const override { return norm_; }
  double worst_residual() const override { return worst_; }
  void Residuals(std::vector<double>* r) const override;

 protected:
  // Throws InputError if the channel has no light in any measured pixel.
  FrontFaceObjective(const Dataset& dataset, int channel);
  // The front face (k = 0, the first nx*ny values) of condition m's current forward field.
  virtual const double* FrontField(size_t m) const = 0;
  // Stores and returns condition m's misfit sum_p w (L^R - L)^2 (not yet divided by D), L^R =
  // M (phi - q_front) / (2 pi) with M the camera's box means (MeasureFace); writes the adjoint
  // source dJ/dphi = M^T (2 w (L^R - L)) / (2 pi D) at the nx*ny front-face nodes.
  double ConditionMisfit(size_t m, double* adjoint_source);
  // Counts a solve and keeps the worst residual of this evaluation (reset by BeginEvaluation).
  void Track(const SolveSummary& s);
  void BeginEvaluation() { worst_ = 0; }
  size_t num_conditions() const { return L_.size(); }
  double denom() const { return denom_; }

 private:
  // L^R of condition m at the nx*ny front-face nodes: M (phi - q_front) / (2 pi).
  void Measured(size_t m, double* out) const;
  int64_t nf_ = 0, nx_ = 0;
  std::vector<std::vector<double>> L_, w_, q_front_;
  std::vector<double> misfit_, norm_;
  double denom_ = 0, worst_ = 0;
  // Atomic: a recovery's progress report reads them while the channel's optimiser may be
  // evaluating its next iteration (FitChannels, solver/optimizer.h).
  std::atomic<int64_t> solves_ = 0, cg_iterations_ = 0;
};

// The CPU backend: one MultigridSolver<double> per channel. The solver's OpenMP loops use the
// calling thread's OpenMP thread count (set it per channel thread).
std::unique_ptr<ChannelObjective> MakeCpuChannelObjective(const Dataset& dataset, int channel,
                                                          const MultigridOptions& multigrid);

// The gl backend (gl_objective.cc): the same objective with forward and adjoint solves and the
// gradient accumulation as compute shaders; b, phi and psi of every condition stay on the GPU.
// Float storage, double iterates and reductions. Call from the thread that uses the GL context.
std::unique_ptr<ChannelObjective> MakeGlChannelObjective(const Dataset& dataset, int channel,
                                                         const MultigridOptions& multigrid);

// Smoothness regularisers on a node field v (kappa or mu), edges e = (p, q) of the grid:
//   R(v) = (1 / |E|) sum_e rho((v_p - v_q) / s)
//   tk1:   rho(d) = d^2                                  (the paper's |grad kappa|^2, SPEC 4)
//   tv:    rho(d) = sqrt(d^2 + eps^2) - eps              (smoothed total variation)
//   huber: rho(d) = d^2 for |d| <= delta, else 2 delta |d| - delta^2
// s is a fixed reference value of v (the homogeneous fit), so R is dimensionless and
// independent of the grid size: lambda = 1e-4 means a mean relative jump of 1 % between
// neighbours costs as much as a relative data misfit of 1e-8.
enum class RegularizerKind { kTikhonov, kTotalVariation, kHuber };
RegularizerKind ParseRegularizer(const std::string& text);  // tk1 | tv | huber
const char* RegularizerName(RegularizerKind kind);

struct RegularizerOptions {
  RegularizerKind kind = RegularizerKind::kTikhonov;
  double tv_epsilon = 1e-3;
  double huber_delta = 0.02;
  std::string Validate() const;
};

// Returns R(v) and adds weight * dR/dv to grad (if non-null).
double Regularize(const GridShape& shape, const double* v, double scale,
                  const RegularizerOptions& options, double weight, double* grad);

}  // namespace translume
