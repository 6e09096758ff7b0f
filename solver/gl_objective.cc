// SPDX-License-Identifier: MIT
// The gl backend of ChannelObjective: forward and adjoint solves and the gradient on the GPU.
// Per condition the right-hand side b, the forward field phi and the adjoint field psi stay on
// the GPU across evaluations (warm starts); what crosses the bus per evaluation is kappa and mu
// (in), the front face of each phi (out) with the adjoint source on the front face (in), and the
// gradient (out).
#include <algorithm>
#include <cmath>
#include <fmt/format.h>

#include "solver/gl_internal.h"
#include "solver/objective.h"
#include "solver/status.h"
#include "solver/stencil.h"

namespace translume {
namespace {

class GlChannelObjective : public FrontFaceObjective {
 public:
  GlChannelObjective(const Dataset& d, int channel, const MultigridOptions& mg)
      : FrontFaceObjective(d, channel), shape_(d.shape), C_(d.C),
        solver_(d.shape, d.spacing_mm, mg) {
    const int64_t n = shape_.size(), nf = shape_.face_size(), M = int64_t(d.conditions.size());
    const TensorGrid grid = TensorGrid::Uniform(shape_, d.spacing_mm);
    const int64_t k_lit = LitFaceK(d.setup, shape_);
    std::vector<float> b(n);
    const std::vector<double> zeros(n, 0.0);
    for (int64_t m = 0; m < M; ++m) {
      LitFaceSource(grid, k_lit, C_, d.conditions[m].q[channel].data(), b.data());
      b_.push_back(std::make_unique<Buffer>());
      b_.back()->Alloc(n * 4, b.data());
      phi_.push_back(std::make_unique<Buffer>());
      phi_.back()->Alloc(n * 8, zeros.data());
      psi_.push_back(std::make_unique<Buffer>());
      psi_.back()->Alloc(n * 8, zeros.data());
    }
    rhs_.Alloc(n * 4);
    rhs_.Zero();
    grad_kappa_.Alloc(n * 8);
    grad_mu_.Alloc(n * 8);
    front_.assign(M, std::vector<double>(nf, 0.0));
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
    BeginEvaluation();
    double J = 0;
    std::vector<double> source(nf);
    std::vector<float> source_f(nf);
    for (size_t m = 0; m < b_.size(); ++m) {
      Track(I.SolveDevice(*b_[m], *phi_[m]));
      phi_[m]->Download(front_[m].data(), nf * 8);  // the front face is k = 0: the first nf nodes
      J += ConditionMisfit(m, source.data());
      if (!gk) continue;
      std::copy(source.begin(), source.end(), source_f.begin());
      rhs_.Upload(source_f.data(), nf * 4);
      Track(I.SolveDevice(rhs_, *psi_[m]));
      Run("gradient", {&I.levels[0]->geometry, phi_[m].get(), psi_[m].get(), &grad_kappa_, &grad_mu_},
          {int(shape_.nx), int(shape_.ny), int(shape_.nz)}, n);
    }
    if (gk) {
      grad_kappa_.Download(gk, n * 8);
      grad_mu_.Download(gm, n * 8);
    }
    return J / denom();
  }

 private:
  const double* FrontField(size_t m) const override { return front_[m].data(); }

  GridShape shape_;
  double C_;
  GlMultigridSolver solver_;
  std::vector<std::unique_ptr<Buffer>> b_, phi_, psi_;
  Buffer rhs_, grad_kappa_, grad_mu_;
  std::vector<std::vector<double>> front_;  // front faces of phi, read back per evaluation
};

}  // namespace

std::unique_ptr<ChannelObjective> MakeGlChannelObjective(const Dataset& dataset, int channel,
                                                         const MultigridOptions& multigrid) {
  TL_CHECK(channel >= 0 && channel < 3);
  if (std::string err = dataset.Validate(); !err.empty()) throw InputError("dataset: " + err);
  return std::make_unique<GlChannelObjective>(dataset, channel, multigrid);
}

}  // namespace translume
