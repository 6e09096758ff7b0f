// SPDX-License-Identifier: MIT
// The gl backend of ChannelObjective: forward and adjoint solves and the gradient on the GPU.
// Per condition the right-hand side b, the forward field phi and the adjoint field psi stay on
// the GPU across evaluations (warm starts), in the layout the solver runs them in (four fields
// per node on llvmpipe); what crosses the bus per evaluation is kappa and mu (in), the front
// face of each phi (out) with the adjoint source on the front face (in), and the gradient
// (out). The conditions solve as batches (GlMultigridSolver::SolveBatch): all forward
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
    GlMultigridSolver::Impl& I = solver_.impl();
    for (int first = 0; first < M; first += solver_.max_batch()) {
      auto batch = std::make_unique<Batch>();
      batch->first = first;
      batch->count = std::min(solver_.max_batch(), M - first);
      batch->grouped = I.Packed(batch->count);
      // Field slots: whole groups of four when grouped (the padding fields stay 0).
      const int slots = batch->grouped ? I.Slots4(batch->count) : batch->count;
      std::vector<float> b(slots * n, 0.0f);
      std::vector<float> field(n);
      for (int f = 0; f < batch->count; ++f) {
        LitFaceSource(grid, k_lit, C_, d.conditions[first + f].q[channel].data(), field.data());
        for (int64_t e = 0; e < n; ++e) b[batch->At(f, e, n)] = field[e];
      }
      const Elem values = batch->grouped ? Elem::kVec4 : Elem::kFloat;
      batch->b.Alloc(slots * n * 4, b.data(), values);
      batch->rhs.Alloc(slots * n * 4, nullptr, values);
      batch->rhs.Zero();
      for (Buffer* x : {&batch->phi, &batch->psi}) {
        x->Alloc(slots * n * 8, nullptr, Elem::kDouble);
        x->Zero();  // all-zero bits are 0.0 in double too
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
    std::vector<double> source(nf), front;
    std::vector<float> sources;
    for (auto& batch_ptr : batches_) {
      Batch& B = *batch_ptr;
      for (const SolveSummary& s : I.SolveDevice(B.b, B.phi, B.count, B.grouped)) Track(s);
      // The front face is k = 0: the first nf nodes of each field (of each group of four when
      // grouped), read back in one piece per field or group.
      const int64_t face_values = B.grouped ? 4 * nf : nf;
      const int64_t stride = B.grouped ? 4 * n : n;  // values per field or group
      const int pieces = B.grouped ? (B.count + 3) / 4 : B.count;
      front.resize(pieces * face_values);
      for (int g = 0; g < pieces; ++g)
        B.phi.Download(front.data() + g * face_values, face_values * 8, g * stride * 8);
      if (gk) sources.assign(pieces * face_values, 0.0f);
      for (int f = 0; f < B.count; ++f) {
        const size_t m = size_t(B.first + f);
        for (int64_t e = 0; e < nf; ++e) front_[m][e] = front[B.At(f, e, nf)];
        J += ConditionMisfit(m, source.data());
        if (!gk) continue;
        for (int64_t e = 0; e < nf; ++e) sources[B.At(f, e, nf)] = float(source[e]);
      }
      if (!gk) continue;
      // The adjoint sources live on the front face; the rest of rhs stays 0.
      for (int g = 0; g < pieces; ++g)
        B.rhs.Upload(sources.data() + g * face_values, face_values * 4, g * stride * 4);
      for (const SolveSummary& s : I.SolveDevice(B.rhs, B.psi, B.count, B.grouped)) Track(s);
      Run("gradient", {&I.levels[0]->geometry, &B.phi, &B.psi, &grad_kappa_, &grad_mu_},
          {int(shape_.nx), int(shape_.ny), int(shape_.nz), B.count},
          // Per node: the loop over the fields (or groups of four), six neighbours each.
          gl_internal::FlatThreads(n, 8 * (B.grouped ? (B.count + 3) / 4 : B.count) + 1), -1, 0,
          B.grouped ? "#define FIELDS4\n" : "");
    }
    if (gk) {
      grad_kappa_.Download(gk, n * 8);
      grad_mu_.Download(gm, n * 8);
    }
    return J / denom();
  }

 private:
  const double* FrontField(size_t m) const override { return front_[m].data(); }

  // Conditions first .. first + count - 1: b (float), the adjoint sources rhs (float, zero
  // off the front face), phi and psi (double). Each buffer holds the fields back to back, or
  // where the solver runs the batch packed (Impl::Packed) in its packed layout (`grouped`:
  // four fields per node, common.glsl's FIELDS4), so that the solves need no packing.
  struct Batch {
    int first = 0, count = 0;
    bool grouped = false;
    Buffer b, rhs, phi, psi;
    // Where value e of field f is in an array of m values per field (per group of four).
    int64_t At(int f, int64_t e, int64_t m) const {
      return grouped ? 4 * (f / 4 * m + e) + f % 4 : f * m + e;
    }
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
