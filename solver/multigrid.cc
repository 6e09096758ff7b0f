// SPDX-License-Identifier: MIT
#include "solver/multigrid.h"

#include <Eigen/Sparse>
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <type_traits>
#include <fmt/format.h>

#include "solver/multigrid_hierarchy.h"
#include "solver/status.h"

namespace translume {
namespace {

template <typename T>
double Dot(const T* a, const T* b, int64_t n) {
  double s = 0;
#pragma omp parallel for reduction(+ : s) schedule(static)
  for (int64_t i = 0; i < n; ++i) s += double(a[i]) * double(b[i]);
  return s;
}

}  // namespace

std::string MultigridOptions::Validate() const {
  if (!(tolerance > 0) || !(tolerance < 1)) return fmt::format("tolerance must be in (0, 1), got {}", tolerance);
  if (max_iterations < 1) return "max_iterations must be >= 1";
  if (pre_smoothing < 1 || post_smoothing < 1) return "pre_smoothing and post_smoothing must be >= 1";
  if (pre_smoothing != post_smoothing) return "pre_smoothing must equal post_smoothing (CG needs a symmetric V-cycle)";
  if (coarsest_nodes < 8) return "coarsest_nodes must be >= 8";
  return "";
}

std::string SolveSummary::BriefReport() const {
  return fmt::format("{} after {} iterations, relative residual {:.2e} -> {:.2e}, {:.3f} s{}{}",
                     converged ? "converged" : "NOT converged", iterations, initial_residual,
                     final_residual, seconds, message.empty() ? "" : ": ", message);
}

template <typename T>
struct MultigridSolver<T>::Level {
  MultigridLevel geo;
  const TensorGrid& grid = geo.grid;
  Stencil<T> A;
  std::vector<T> lu_c, lu_inv;  // factors of every z-column's tridiagonal block
  std::vector<T> b, x, r;
  std::vector<T> kappa, mu;
  std::vector<T> restrict_norm;          // on this level: R applied to ones from the finer one
  mutable std::vector<T> tmp_a, tmp_b;   // intermediate results of separable transfers
  std::vector<T> zeros;                  // one x-row of zeros (missing neighbours)
  std::unique_ptr<Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>>> direct;
};

template <typename T>
void MultigridSolver<T>::Restrict(const Level& L, const T* f, T* c) const {
  Restrict3(L.geo, f, c, L.tmp_a.data(), L.tmp_b.data());
}

template <typename T>
void MultigridSolver<T>::ProlongAdd(const Level& L, const T* c, T* f) const {
  ProlongAdd3(L.geo, c, f, L.tmp_a.data(), L.tmp_b.data());
}

template <typename T>
MultigridSolver<T>::MultigridSolver(const GridShape& shape, double h,
                                    const MultigridOptions& options)
    : options_(options) {
  if (std::string err = options_.Validate(); !err.empty())
    throw InputError("multigrid options: " + err);
  TL_CHECK(shape.nx >= 2 && shape.ny >= 2 && shape.nz >= 2 && h > 0);
  const bool mixed = std::is_same_v<T, double> && options_.mixed_precision;
  if (mixed) {
    MultigridOptions fo = options_;
    fo.mixed_precision = false;
    float_preconditioner_ = std::make_unique<MultigridSolver<float>>(shape, h, fo);
    rf_.resize(shape.size());
    zf_.resize(shape.size());
  }
  // Mixed precision: only the finest level in T (coarsest_nodes = its size stops coarsening).
  for (MultigridLevel& geo :
       BuildMultigridHierarchy(shape, h, mixed ? shape.size() : options_.coarsest_nodes)) {
    auto level = std::make_unique<Level>();
    level->geo = std::move(geo);
    levels_.push_back(std::move(level));
  }
  for (size_t l = 0; l < levels_.size(); ++l) {
    Level& L = *levels_[l];
    const int64_t n = L.grid.shape.size();
    if (l > 0) {
      L.b.resize(n);
      L.x.resize(n);
      L.restrict_norm.resize(n);
      std::vector<T> ones(levels_[l - 1]->grid.shape.size(), T(1));
      Restrict(*levels_[l - 1], ones.data(), L.restrict_norm.data());
    }
    if (l + 1 < levels_.size()) {
      L.r.resize(n);
      const auto& t = L.geo.to_coarse;
      L.tmp_a.resize(t[0].n_coarse * L.grid.shape.ny * L.grid.shape.nz);
      L.tmp_b.resize(t[0].n_coarse * t[1].n_coarse * L.grid.shape.nz);
    }
    L.kappa.resize(n);
    L.mu.resize(n);
    L.zeros.assign(L.grid.shape.nx, T(0));
  }
  const int64_t n0 = shape.size();
  r_.resize(n0);
  z_.resize(n0);
  p_.resize(n0);
  q_.resize(n0);
}

template <typename T>
MultigridSolver<T>::~MultigridSolver() = default;

template <typename T>
void MultigridSolver<T>::SetCoefficients(const T* kappa, const T* mu, double C) {
  for (size_t l = 0; l < levels_.size(); ++l) {
    Level& L = *levels_[l];
    const int64_t n = L.grid.shape.size();
    if (l == 0) {
      std::copy(kappa, kappa + n, L.kappa.begin());
      std::copy(mu, mu + n, L.mu.begin());
    } else {
      const Level& F = *levels_[l - 1];
      Restrict(F, F.kappa.data(), L.kappa.data());
      Restrict(F, F.mu.data(), L.mu.data());
      for (int64_t p = 0; p < n; ++p) {
        L.kappa[p] /= L.restrict_norm[p];
        L.mu[p] /= L.restrict_norm[p];
      }
    }
    AssembleStencil(L.grid, L.kappa.data(), L.mu.data(), C, &L.A);
    if (float_preconditioner_) break;  // the float hierarchy smooths and solves
    const GridShape& s = L.grid.shape;
    const int64_t nxy = s.nx * s.ny;
    if (l + 1 < levels_.size()) {
      L.lu_c.resize(n);
      L.lu_inv.resize(n);
#pragma omp parallel for schedule(static)
      for (int64_t col = 0; col < nxy; ++col) {
        for (int64_t k = 0; k < s.nz; ++k) {
          const int64_t p = col + nxy * k;
          double denom = double(L.A.diag[p]);
          if (k > 0) {
            const double c = double(L.A.cz[p - nxy]);
            denom -= c * c * double(L.lu_inv[p - nxy]);
          }
          L.lu_inv[p] = T(1.0 / denom);
          L.lu_c[p] = T(double(L.A.cz[p]) / denom);
        }
      }
    } else {
      std::vector<Eigen::Triplet<double>> trip;
      trip.reserve(n * 4);
      for (int64_t k = 0; k < s.nz; ++k)
        for (int64_t j = 0; j < s.ny; ++j)
          for (int64_t i = 0; i < s.nx; ++i) {
            const int64_t p = s.index(i, j, k);
            trip.emplace_back(p, p, double(L.A.diag[p]));
            if (i + 1 < s.nx) trip.emplace_back(p + 1, p, -double(L.A.cx[p]));
            if (j + 1 < s.ny) trip.emplace_back(p + s.nx, p, -double(L.A.cy[p]));
            if (k + 1 < s.nz) trip.emplace_back(p + nxy, p, -double(L.A.cz[p]));
          }
      Eigen::SparseMatrix<double> M(n, n);
      M.setFromTriplets(trip.begin(), trip.end());
      L.direct = std::make_unique<Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>>>();
      L.direct->compute(M.template selfadjointView<Eigen::Lower>());
      TL_CHECK_MSG(L.direct->info() == Eigen::Success, "coarsest-level factorisation failed");
    }
  }
  if (float_preconditioner_) {
    const int64_t n = levels_[0]->grid.shape.size();
    std::vector<float> kf(kappa, kappa + n), mf(mu, mu + n);
    float_preconditioner_->SetCoefficients(kf.data(), mf.data(), C);
  }
  has_coefficients_ = true;
}

template <typename T>
void MultigridSolver<T>::Precondition(const T* r, T* z) {
  if (!float_preconditioner_) {
    VCycle(0, r, z);
    return;
  }
  const int64_t n = int64_t(rf_.size());
#pragma omp parallel for schedule(static)
  for (int64_t i = 0; i < n; ++i) rf_[i] = float(r[i]);
  float_preconditioner_->Precondition(rf_.data(), zf_.data());
#pragma omp parallel for schedule(static)
  for (int64_t i = 0; i < n; ++i) z[i] = T(zf_[i]);
}

template <typename T>
void MultigridSolver<T>::Smooth(const Level& L, const T* b, T* x, int color) const {
  const GridShape& s = L.grid.shape;
  const int64_t nx = s.nx, ny = s.ny, nz = s.nz, nxy = nx * ny;
  const T* inv = L.lu_inv.data();
  const T* luc = L.lu_c.data();
  const T* zeros = L.zeros.data();
#pragma omp parallel for schedule(static)
  for (int64_t j = 0; j < ny; ++j) {
    const int64_t i0 = (color + j) & 1;
    // Forward elimination of every column of this colour in row j; x temporarily holds d'.
    // Missing neighbours read a row of zeros instead of branching.
    for (int64_t k = 0; k < nz; ++k) {
      const int64_t row = nx * (j + ny * k);
      const T* cx = L.A.cx.data() + row;
      const T* cym = j > 0 ? L.A.cy.data() + row - nx : zeros;
      const T* xym = j > 0 ? x + row - nx : zeros;
      const T* cyp = j + 1 < ny ? L.A.cy.data() + row : zeros;
      const T* xyp = j + 1 < ny ? x + row + nx : zeros;
      const T* czm = k > 0 ? L.A.cz.data() + row - nxy : zeros;
      const T* xzm = k > 0 ? x + row - nxy : zeros;
      const T* br = b + row;
      T* xr = x + row;
      const T* ir = inv + row;
      for (int64_t i = i0; i < nx; i += 2) {
        T d = br[i] + cym[i] * xym[i] + cyp[i] * xyp[i] + czm[i] * xzm[i];
        if (i > 0) d += cx[i - 1] * xr[i - 1];
        if (i + 1 < nx) d += cx[i] * xr[i + 1];
        xr[i] = d * ir[i];
      }
    }
    for (int64_t k = nz - 2; k >= 0; --k) {
      const int64_t row = nx * (j + ny * k);
      T* xr = x + row;
      const T* xn = x + row + nxy;
      const T* lr = luc + row;
      for (int64_t i = i0; i < nx; i += 2) xr[i] += lr[i] * xn[i];
    }
  }
}

template <typename T>
void MultigridSolver<T>::VCycle(size_t l, const T* b, T* x) {
  Level& L = *levels_[l];
  const int64_t n = L.grid.shape.size();
  if (l + 1 == levels_.size()) {
    Eigen::VectorXd rhs(n);
    for (int64_t p = 0; p < n; ++p) rhs[p] = double(b[p]);
    const Eigen::VectorXd sol = L.direct->solve(rhs);
    for (int64_t p = 0; p < n; ++p) x[p] = T(sol[p]);
    return;
  }
  std::fill(x, x + n, T(0));
  for (int s = 0; s < options_.pre_smoothing; ++s) {
    Smooth(L, b, x, 0);
    Smooth(L, b, x, 1);
  }
  StencilResidual(L.A, b, x, L.r.data());
  Level& Cl = *levels_[l + 1];
  Restrict(L, L.r.data(), Cl.b.data());
  VCycle(l + 1, Cl.b.data(), Cl.x.data());
  ProlongAdd(L, Cl.x.data(), x);
  for (int s = 0; s < options_.post_smoothing; ++s) {
    Smooth(L, b, x, 1);
    Smooth(L, b, x, 0);
  }
}

template <typename T>
SolveSummary MultigridSolver<T>::Solve(const T* b, T* x_out) {
  TL_CHECK_MSG(has_coefficients_, "SetCoefficients() must be called before Solve()");
  const auto t0 = std::chrono::steady_clock::now();
  const Level& L0 = *levels_[0];
  const int64_t n = L0.grid.shape.size();
  // The iterate is kept in double: A amplifies the rounding of a float iterate, whose residual
  // would stall at a few 1e-6. For T = double this is x_out itself.
  std::vector<double> x_store;
  double* x;
  if constexpr (std::is_same_v<T, double>) {
    x = x_out;
  } else {
    x_store.assign(x_out, x_out + n);
    x = x_store.data();
  }
  SolveSummary sum;
  const double bnorm = std::sqrt(Dot(b, b, n));
  // `true_rnorm`: ||b - A x|| if the caller has just computed it, else < 0.
  auto finish = [&](bool converged, std::string message, double true_rnorm = -1) {
    if (true_rnorm < 0) {
      StencilResidual(L0.A, b, x, r_.data());
      true_rnorm = std::sqrt(Dot(r_.data(), r_.data(), n));
    }
    sum.final_residual = bnorm > 0 ? true_rnorm / bnorm : 0.0;
    sum.converged = converged;
    sum.message = std::move(message);
    if constexpr (!std::is_same_v<T, double>)
      for (int64_t i = 0; i < n; ++i) x_out[i] = T(x[i]);
    sum.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return sum;
  };
  if (bnorm == 0) {
    std::fill(x, x + n, 0.0);
    return finish(true, "zero right-hand side", 0.0);
  }
  T* r = r_.data();
  T* z = z_.data();
  T* p = p_.data();
  T* q = q_.data();
  StencilResidual(L0.A, b, x, r);
  double rnorm = std::sqrt(Dot(r, r, n));
  sum.initial_residual = rnorm / bnorm;
  if (sum.initial_residual <= options_.tolerance) return finish(true, "", rnorm);
  const double tol = options_.tolerance * bnorm;
  int restarts = 0;
  bool restart = true;
  double rz = 0;
  while (sum.iterations < options_.max_iterations) {
    if (restart) {
      Precondition(r, z);
      std::copy(z, z + n, p);
      rz = Dot(r, z, n);
      restart = false;
    }
    ApplyStencil(L0.A, p, q);
    const double alpha = rz / Dot(p, q, n);
    double rr = 0;
#pragma omp parallel for reduction(+ : rr) schedule(static)
    for (int64_t i = 0; i < n; ++i) {
      x[i] += alpha * double(p[i]);
      r[i] -= T(alpha) * q[i];
      rr += double(r[i]) * double(r[i]);
    }
    ++sum.iterations;
    rnorm = std::sqrt(rr);
    sum.history.push_back(rnorm / bnorm);
    if (rnorm <= tol) {
      // The recursive residual drifts: confirm with the true one.
      StencilResidual(L0.A, b, x, r);
      rnorm = std::sqrt(Dot(r, r, n));
      if (rnorm <= tol) return finish(true, "", rnorm);
      if (++restarts > 3) return finish(false, "stagnated", rnorm);
      restart = true;
      continue;
    }
    Precondition(r, z);
    const double rz_new = Dot(r, z, n);
    const double beta = rz_new / rz;
    rz = rz_new;
#pragma omp parallel for schedule(static)
    for (int64_t i = 0; i < n; ++i) p[i] = z[i] + T(beta) * p[i];
  }
  return finish(false, fmt::format("reached max_iterations = {}", options_.max_iterations));
}

template <typename T>
void MultigridSolver<T>::Apply(const T* x, T* y) const {
  ApplyStencil(levels_[0]->A, x, y);
}

template <typename T>
const Stencil<T>& MultigridSolver<T>::stencil() const { return levels_[0]->A; }

template <typename T>
const TensorGrid& MultigridSolver<T>::grid() const { return levels_[0]->grid; }

template <typename T>
int MultigridSolver<T>::num_levels() const {
  return float_preconditioner_ ? float_preconditioner_->num_levels() : int(levels_.size());
}

template <typename T>
std::vector<GridShape> MultigridSolver<T>::level_shapes() const {
  if (float_preconditioner_) return float_preconditioner_->level_shapes();
  std::vector<GridShape> out;
  for (const auto& L : levels_) out.push_back(L->grid.shape);
  return out;
}

template class MultigridSolver<float>;
template class MultigridSolver<double>;

}  // namespace translume
