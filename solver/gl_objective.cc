// SPDX-License-Identifier: MIT
// The gl backend of ChannelObjective: forward and adjoint solves and the gradient on the GPU.
// Per condition the right-hand side b, the forward field phi and the adjoint field psi stay on
// the GPU across evaluations (warm starts); what crosses the bus per evaluation is kappa and mu
// (in), the front face of each phi (out) with the adjoint source on the front face (in), and the
// gradient (out). The conditions solve as batches (GlMultigridSolver::SolveBatch): all forward
// solves of a batch in one lockstep multigrid-PCG, then all adjoint solves, then one gradient
// dispatch per batch.
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
    const int64_t n = shape_.size(), nf = shape_.face_size();
    const int M = int(d.conditions.size());
    const TensorGrid grid = TensorGrid::Uniform(shape_, d.spacing_mm);
    const int64_t k_lit = LitFaceK(d.setup, shape_);
    for (int first = 0; first < M; first += solver_.max_batch()) {
      auto batch = std::make_unique<Batch>();
      batch->first = first;
      batch->count = std::min(solver_.max_batch(), M - first);
      const int64_t values = batch->count * n;
      std::vector<float> b(values);
      for (int f = 0; f < batch->count; ++f)
        LitFaceSource(grid, k_lit, C_, d.conditions[first + f].q[channel].data(), b.data() + f * n);
      batch->b.Alloc(values * 4, b.data());
      batch->rhs.Alloc(values * 4);
      batch->rhs.Zero();
      for (Buffer* field : {&batch->phi, &batch->psi}) {
        field->Alloc(values * 8, nullptr, Elem::kDouble);
        field->Zero();  // all-zero bits are 0.0 in double too
      }
      batches_.push_back(std::move(batch));
    }
    grad_kappa_.Alloc(n * 8, nullptr, Elem::kDouble);
    grad_mu_.Alloc(n * 8, nullptr, Elem::kDouble);
    front_.assign(M, std::vector<double>(nf, 0.0));
  }

  double Evaluate(const double* kappa, const double* mu, double* gk, double* gm) override {
    const int64_t n = shape_.size(), nf = shape_.face_size();
    std::vector<float> kf(kappa, kappa + n), mf(mu, mu + n);
    solver_.SetCoefficients(kf.data(), mf.data(), C_);
    GlMultigridSolver::Impl& I = solver_.impl();
    if (gk) {
      grad_kappa_.Zero();
      grad_mu_.Zero();
    }
    BeginEvaluation();
    double J = 0;
    std::vector<double> source(nf);
    std::vector<float> source_f(nf);
    for (auto& batch : batches_) {
      for (const SolveSummary& s : I.SolveDevice(batch->b, batch->phi, batch->count)) Track(s);
      for (int f = 0; f < batch->count; ++f) {
        const size_t m = size_t(batch->first + f);
        // The front face is k = 0: the first nf nodes of the field.
        batch->phi.Download(front_[m].data(), nf * 8, f * n * 8);
        J += ConditionMisfit(m, source.data());
        if (!gk) continue;
        std::copy(source.begin(), source.end(), source_f.begin());
        batch->rhs.Upload(source_f.data(), nf * 4, f * n * 4);
      }
      if (!gk) continue;
      for (const SolveSummary& s : I.SolveDevice(batch->rhs, batch->psi, batch->count)) Track(s);
      Run("gradient", {&I.levels[0]->geometry, &batch->phi, &batch->psi, &grad_kappa_, &grad_mu_},
          {int(shape_.nx), int(shape_.ny), int(shape_.nz), batch->count}, gl_internal::FlatThreads(n));
    }
    if (gk) {
      grad_kappa_.Download(gk, n * 8);
      grad_mu_.Download(gm, n * 8);
    }
    return J / denom();
  }

 private:
  const double* FrontField(size_t m) const override { return front_[m].data(); }

  // Conditions first .. first + count - 1, each buffer holding their fields back to back:
  // b (float), the adjoint sources rhs (float, zero off the front face), phi and psi (double).
  struct Batch {
    int first = 0, count = 0;
    Buffer b, rhs, phi, psi;
  };

  GridShape shape_;
  double C_;
  GlMultigridSolver solver_;
  std::vector<std::unique_ptr<Batch>> batches_;
  Buffer grad_kappa_, grad_mu_;
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
