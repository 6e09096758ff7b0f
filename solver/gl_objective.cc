// SPDX-License-Identifier: MIT
// The gl backend of ChannelObjective: forward and adjoint solves and the gradient on the GPU.
// Per condition the right-hand side b, the forward field phi and the adjoint field psi stay on
// the GPU across evaluations (warm starts); what crosses the bus per evaluation is kappa and mu
// (in), the front face of each phi (out) with the adjoint source on the front face (in), and the
// gradient (out).
#include <algorithm>
#include <cmath>
#include <fmt/format.h>
#include <numbers>

#include "solver/gl_internal.h"
#include "solver/objective.h"
#include "solver/status.h"
#include "solver/stencil.h"

namespace translume {
namespace {

class GlChannelObjective : public ChannelObjective {
 public:
  GlChannelObjective(const Dataset& d, int channel, const MultigridOptions& mg)
      : shape_(d.shape), C_(d.C), solver_(d.shape, d.spacing_mm, mg) {
    const int64_t n = shape_.size(), nf = shape_.face_size(), M = int64_t(d.conditions.size());
    const TensorGrid grid = TensorGrid::Uniform(shape_, d.spacing_mm);
    const int64_t k_lit = LitFaceK(d.setup, shape_);
    std::vector<float> b(n);
    const std::vector<double> zeros(n, 0.0);
    b_.resize(M);
    phi_.resize(M);
    psi_.resize(M);
    L_.resize(M);
    w_.resize(M);
    q_front_.resize(M);
    misfit_.assign(M, 0.0);
    norm_.assign(M, 0.0);
    for (int64_t m = 0; m < M; ++m) {
      const DatasetCondition& c = d.conditions[m];
      LitFaceSource(grid, k_lit, C_, c.q[channel].data(), b.data());
      b_[m] = std::make_unique<Buffer>();
      b_[m]->Alloc(n * 4, b.data());
      phi_[m] = std::make_unique<Buffer>();
      phi_[m]->Alloc(n * 8, zeros.data());
      psi_[m] = std::make_unique<Buffer>();
      psi_[m]->Alloc(n * 8, zeros.data());
      L_[m].assign(c.L[channel].begin(), c.L[channel].end());
      w_[m].assign(c.mask.begin(), c.mask.end());
      q_front_[m].assign(nf, 0.0);
      if (d.setup == Setup::kFront)
        for (int64_t f = 0; f < nf; ++f) q_front_[m][f] = c.q[channel][f];
      for (int64_t f = 0; f < nf; ++f) norm_[m] += w_[m][f] * L_[m][f] * L_[m][f];
      denom_ += norm_[m];
    }
    if (!(denom_ > 0))
      throw InputError(fmt::format("dataset: channel {} has no light in any measured pixel "
                                   "(sum of mask * L^2 is 0)", "RGB"[channel]));
    rhs_.Alloc(n * 4);
    rhs_.Zero();
    grad_kappa_.Alloc(n * 8);
    grad_mu_.Alloc(n * 8);
    front_.resize(M, std::vector<double>(nf, 0.0));
  }

  double Evaluate(const double* kappa, const double* mu, double* gk, double* gm) override {
    const int64_t n = shape_.size(), nf = shape_.face_size();
    std::vector<float> kf(kappa, kappa + n), mf(mu, mu + n);
    solver_.SetCoefficients(kf.data(), mf.data(), C_);
    GlMultigridSolver::Impl& I = solver_.impl();
    if (gk) {
      grad_kappa_.Zero();  // all-zero bits are 0.0 in double too
      grad_mu_.Zero();
    }
    worst_ = 0;
    double J = 0;
    std::vector<float> rhs(nf);
    for (size_t m = 0; m < b_.size(); ++m) {
      Track(I.SolveDevice(*b_[m], *phi_[m]));
      phi_[m]->Download(front_[m].data(), nf * 8);  // the front face is k = 0: the first nf nodes
      double mis = 0;
      for (int64_t f = 0; f < nf; ++f) {
        const double r = Misfit(m, f);
        mis += w_[m][f] * r * r;
        rhs[f] = float(2 * w_[m][f] * r * kToL / denom_);
      }
      misfit_[m] = mis;
      J += mis;
      if (!gk) continue;
      rhs_.Upload(rhs.data(), nf * 4);
      Track(I.SolveDevice(rhs_, *psi_[m]));
      const GridShape& s = shape_;
      Run("gradient", {&I.levels[0]->geometry, phi_[m].get(), psi_[m].get(), &grad_kappa_, &grad_mu_},
          {int(s.nx), int(s.ny), int(s.nz)}, n);
    }
    if (gk) {
      grad_kappa_.Download(gk, n * 8);
      grad_mu_.Download(gm, n * 8);
    }
    return J / denom_;
  }

  void Residuals(std::vector<double>* out) const override {
    const int64_t nf = shape_.face_size();
    out->resize(b_.size() * nf);
    for (size_t m = 0; m < b_.size(); ++m)
      for (int64_t f = 0; f < nf; ++f) (*out)[m * nf + f] = std::sqrt(w_[m][f] / denom_) * Misfit(m, f);
  }

  int64_t solves() const override { return solves_; }
  const std::vector<double>& condition_misfit() const override { return misfit_; }
  const std::vector<double>& condition_norm() const override { return norm_; }
  double worst_residual() const override { return worst_; }

 private:
  static constexpr double kToL = 1.0 / (2 * std::numbers::pi);
  double Misfit(size_t m, int64_t f) const {
    return (front_[m][f] - q_front_[m][f]) * kToL - L_[m][f];
  }
  void Track(const SolveSummary& s) {
    ++solves_;
    worst_ = std::max(worst_, s.converged ? s.final_residual : std::max(s.final_residual, 1.0));
  }

  GridShape shape_;
  double C_;
  GlMultigridSolver solver_;
  std::vector<std::unique_ptr<Buffer>> b_, phi_, psi_;
  Buffer rhs_, grad_kappa_, grad_mu_;
  std::vector<std::vector<double>> L_, w_, q_front_, front_;
  std::vector<double> misfit_, norm_;
  double denom_ = 0, worst_ = 0;
  int64_t solves_ = 0;
};

}  // namespace

std::unique_ptr<ChannelObjective> MakeGlChannelObjective(const Dataset& dataset, int channel,
                                                         const MultigridOptions& multigrid) {
  TL_CHECK(channel >= 0 && channel < 3);
  if (std::string err = dataset.Validate(); !err.empty()) throw InputError("dataset: " + err);
  return std::make_unique<GlChannelObjective>(dataset, channel, multigrid);
}

}  // namespace translume
