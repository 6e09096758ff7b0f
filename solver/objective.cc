// SPDX-License-Identifier: MIT
#include "solver/objective.h"

#include <algorithm>
#include <cmath>
#include <fmt/format.h>
#include <numbers>

#include "solver/face_measurement.h"
#include "solver/stencil.h"
#include "solver/status.h"

namespace translume {
namespace {

class CpuChannelObjective : public FrontFaceObjective {
 public:
  CpuChannelObjective(const Dataset& d, int channel, const MultigridOptions& mg)
      : FrontFaceObjective(d, channel), shape_(d.shape), C_(d.C),
        solver_(d.shape, d.spacing_mm, mg), k_lit_(LitFaceK(d.setup, d.shape)) {
    const int64_t n = shape_.size(), M = int64_t(d.conditions.size());
    q_.resize(M);
    for (int64_t m = 0; m < M; ++m) q_[m] = d.conditions[m].q[channel];
    b_.assign(n, 0.0);
    rhs_.assign(n, 0.0);
    phi_.assign(M, std::vector<double>(n, 0.0));
    psi_.assign(M, std::vector<double>(n, 0.0));
  }

  double Evaluate(const double* kappa, const double* mu, double* gk, double* gm) override {
    const int64_t n = shape_.size();
    solver_.SetCoefficients(kappa, mu, C_);
    if (gk) {
      std::fill(gk, gk + n, 0.0);
      std::fill(gm, gm + n, 0.0);
    }
    BeginEvaluation();
    double J = 0;
    for (size_t m = 0; m < q_.size(); ++m) {
      // b is O(face) to rebuild; keeping one per condition would cost M volumes.
      LitFaceSource(solver_.grid(), k_lit_, C_, q_[m].data(), b_.data());
      Track(solver_.Solve(b_.data(), phi_[m].data()));
      J += ConditionMisfit(m, rhs_.data());  // the adjoint source on the front face (k = 0)
      if (!gk) continue;
      Track(solver_.Solve(rhs_.data(), psi_[m].data()));
      AccumulateOperatorGradient(solver_.grid(), phi_[m].data(), psi_[m].data(), -1.0, gk, gm);
    }
    return J / denom();
  }

 private:
  const double* FrontField(size_t m) const override { return phi_[m].data(); }

  GridShape shape_;
  double C_;
  MultigridSolver<double> solver_;
  int64_t k_lit_ = 0;
  std::vector<std::vector<float>> q_;                 // lit-face light per condition
  std::vector<std::vector<double>> phi_, psi_;        // kept between evaluations
  std::vector<double> b_, rhs_;
};

// rho(d) and rho'(d) of the regulariser kinds.
inline double Rho(const RegularizerOptions& o, double d, double* dr) {
  switch (o.kind) {
    case RegularizerKind::kTikhonov:
      *dr = 2 * d;
      return d * d;
    case RegularizerKind::kTotalVariation: {
      const double s = std::sqrt(d * d + o.tv_epsilon * o.tv_epsilon);
      *dr = d / s;
      return s - o.tv_epsilon;
    }
    case RegularizerKind::kHuber:
      if (std::abs(d) <= o.huber_delta) {
        *dr = 2 * d;
        return d * d;
      }
      *dr = 2 * o.huber_delta * (d > 0 ? 1 : -1);
      return 2 * o.huber_delta * std::abs(d) - o.huber_delta * o.huber_delta;
  }
  return 0;
}

}  // namespace

FrontFaceObjective::FrontFaceObjective(const Dataset& d, int channel)
    : nf_(d.shape.face_size()), nx_(d.shape.nx) {
  const size_t M = d.conditions.size();
  L_.resize(M);
  w_.resize(M);
  q_front_.resize(M);
  misfit_.assign(M, 0.0);
  norm_.assign(M, 0.0);
  for (size_t m = 0; m < M; ++m) {
    const DatasetCondition& c = d.conditions[m];
    L_[m].assign(c.L[channel].begin(), c.L[channel].end());
    w_[m].assign(c.mask.begin(), c.mask.end());
    q_front_[m].assign(nf_, 0.0);
    if (d.setup == Setup::kFront)
      for (int64_t f = 0; f < nf_; ++f) q_front_[m][f] = c.q[channel][f];
    for (int64_t f = 0; f < nf_; ++f) norm_[m] += w_[m][f] * L_[m][f] * L_[m][f];
    denom_ += norm_[m];
  }
  if (!(denom_ > 0))
    throw InputError(fmt::format("dataset: channel {} has no light in any measured pixel "
                                 "(sum of mask * L^2 is 0)", "RGB"[channel]));
}

// What the camera would measure of condition m's current phi (paper Eq. (3), MeasureFace).
void FrontFaceObjective::Measured(size_t m, double* out) const {
  constexpr double kToL = 1.0 / (2 * std::numbers::pi);
  std::vector<double> L(nf_);
  const double* phi = FrontField(m);
  for (int64_t f = 0; f < nf_; ++f) L[f] = (phi[f] - q_front_[m][f]) * kToL;
  MeasureFace(nx_, nf_ / nx_, L.data(), out);
}

double FrontFaceObjective::ConditionMisfit(size_t m, double* adjoint_source) {
  constexpr double kToL = 1.0 / (2 * std::numbers::pi);
  std::vector<double> model(nf_), dJ(nf_);
  Measured(m, model.data());
  double mis = 0;
  for (int64_t f = 0; f < nf_; ++f) {
    const double r = model[f] - L_[m][f];
    mis += w_[m][f] * r * r;
    dJ[f] = 2 * w_[m][f] * r * kToL / denom_;
  }
  MeasureFaceTranspose(nx_, nf_ / nx_, dJ.data(), adjoint_source);
  misfit_[m] = mis;
  return mis;
}

void FrontFaceObjective::Residuals(std::vector<double>* out) const {
  out->resize(L_.size() * nf_);
  std::vector<double> model(nf_);
  for (size_t m = 0; m < L_.size(); ++m) {
    Measured(m, model.data());
    for (int64_t f = 0; f < nf_; ++f)
      (*out)[m * nf_ + f] = std::sqrt(w_[m][f] / denom_) * (model[f] - L_[m][f]);
  }
}

void FrontFaceObjective::Track(const SolveSummary& s) {
  ++solves_;
  cg_iterations_ += s.iterations;
  worst_ = std::max(worst_, s.converged ? s.final_residual : std::max(s.final_residual, 1.0));
}

std::unique_ptr<ChannelObjective> MakeCpuChannelObjective(const Dataset& dataset, int channel,
                                                          const MultigridOptions& multigrid) {
  TL_CHECK(channel >= 0 && channel < 3);
  if (std::string err = dataset.Validate(); !err.empty()) throw InputError("dataset: " + err);
  return std::make_unique<CpuChannelObjective>(dataset, channel, multigrid);
}

RegularizerKind ParseRegularizer(const std::string& text) {
  if (text == "tk1") return RegularizerKind::kTikhonov;
  if (text == "tv") return RegularizerKind::kTotalVariation;
  if (text == "huber") return RegularizerKind::kHuber;
  throw InputError(fmt::format("--regularizer: unknown regulariser '{}' (tk1, tv, huber)", text));
}

const char* RegularizerName(RegularizerKind kind) {
  switch (kind) {
    case RegularizerKind::kTikhonov: return "tk1";
    case RegularizerKind::kTotalVariation: return "tv";
    case RegularizerKind::kHuber: return "huber";
  }
  return "?";
}

std::string RegularizerOptions::Validate() const {
  if (!(tv_epsilon > 0)) return "tv_epsilon must be > 0";
  if (!(huber_delta > 0)) return "huber_delta must be > 0";
  return "";
}

double Regularize(const GridShape& s, const double* v, double scale, const RegularizerOptions& o,
                  double weight, double* grad) {
  TL_CHECK(scale > 0);
  const int64_t nx = s.nx, ny = s.ny, nz = s.nz, nxy = nx * ny;
  const double edges = double((nx - 1) * ny * nz + nx * (ny - 1) * nz + nx * ny * (nz - 1));
  const double inv = 1.0 / scale, w = weight / edges;
  double R = 0;
  // Gather form: each node sums rho'(d) over its edges; each edge's value is counted once, by
  // its lower node.
#pragma omp parallel for reduction(+ : R) schedule(static)
  for (int64_t k = 0; k < nz; ++k)
    for (int64_t j = 0; j < ny; ++j)
      for (int64_t i = 0; i < nx; ++i) {
        const int64_t p = i + nx * (j + ny * k);
        double g = 0, dr = 0;
        auto edge = [&](int64_t q, bool lower) {
          const double val = Rho(o, (v[p] - v[q]) * inv, &dr);
          if (lower) R += val;
          g += dr * inv;
        };
        if (i > 0) edge(p - 1, false);
        if (i + 1 < nx) edge(p + 1, true);
        if (j > 0) edge(p - nx, false);
        if (j + 1 < ny) edge(p + nx, true);
        if (k > 0) edge(p - nxy, false);
        if (k + 1 < nz) edge(p + nxy, true);
        if (grad) grad[p] += w * g;
      }
  return R / edges;
}

}  // namespace translume
