// SPDX-License-Identifier: MIT
#include "solver/multigrid.h"

#include <Eigen/Sparse>
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <fmt/format.h>

#include "solver/status.h"

namespace translume {
namespace {

// Linear interpolation from a coarse to a fine node list along one axis, and its transpose.
struct AxisTransfer {
  bool coarsened = false;
  int64_t n_fine = 0, n_coarse = 0;
  std::vector<int64_t> lo, hi;   // per fine node: bracketing coarse nodes
  std::vector<double> wlo, whi;  // and their weights (whi = 0 where fine == coarse node)
  // Transpose, flattened: coarse node c gathers fine nodes g_idx[g_start[c] .. g_start[c+1]).
  std::vector<int64_t> g_start, g_idx;
  std::vector<double> g_w;
};

AxisTransfer MakeAxisTransfer(const std::vector<double>& fine, bool coarsen,
                              std::vector<double>* coarse) {
  const int64_t n = int64_t(fine.size());
  AxisTransfer t;
  t.coarsened = coarsen;
  std::vector<int64_t> keep;
  if (!coarsen) {
    for (int64_t i = 0; i < n; ++i) keep.push_back(i);
  } else {
    // Every other node; for an even count drop node n-2 so the last interval is 3 fine
    // intervals wide instead of 1 (keeps neighbouring intervals within a factor 1.5).
    const int64_t last_even = (n % 2 == 1) ? n - 1 : n - 4;
    for (int64_t i = 0; i <= last_even; i += 2) keep.push_back(i);
    if (keep.back() != n - 1) keep.push_back(n - 1);
  }
  coarse->clear();
  for (int64_t i : keep) coarse->push_back(fine[i]);
  const int64_t nc = int64_t(keep.size());
  t.n_fine = n;
  t.n_coarse = nc;
  t.lo.resize(n);
  t.hi.resize(n);
  t.wlo.resize(n);
  t.whi.resize(n);
  std::vector<std::vector<std::pair<int64_t, double>>> gather(nc);
  int64_t c = 0;
  for (int64_t i = 0; i < n; ++i) {
    while (c + 1 < nc && keep[c + 1] <= i) ++c;
    if (keep[c] == i) {
      t.lo[i] = t.hi[i] = c;
      t.wlo[i] = 1;
      t.whi[i] = 0;
      gather[c].push_back({i, 1.0});
    } else {
      const double x0 = fine[keep[c]], x1 = fine[keep[c + 1]];
      const double w = (fine[i] - x0) / (x1 - x0);
      t.lo[i] = c;
      t.hi[i] = c + 1;
      t.wlo[i] = 1 - w;
      t.whi[i] = w;
      gather[c].push_back({i, 1 - w});
      gather[c + 1].push_back({i, w});
    }
  }
  t.g_start.push_back(0);
  for (int64_t cc = 0; cc < nc; ++cc) {
    for (auto [i, w] : gather[cc]) {
      t.g_idx.push_back(i);
      t.g_w.push_back(w);
    }
    t.g_start.push_back(int64_t(t.g_idx.size()));
  }
  return t;
}

double MeanGap(const std::vector<double>& c) { return (c.back() - c.front()) / double(c.size() - 1); }

// Which axes to coarsen: keep x and y within a factor ~2 of each other (the smoother handles
// strong coupling along z only), and coarsen z only while it is not coarser than x and y.
std::array<bool, 3> ChooseCoarsening(const TensorGrid& g) {
  std::array<double, 3> gap;
  std::array<bool, 3> can;
  for (int a = 0; a < 3; ++a) {
    gap[a] = MeanGap(g.coord[a]);
    can[a] = g.shape.n(a) >= 3;
  }
  std::array<bool, 3> out;
  out[0] = can[0] && (!can[1] || gap[0] <= 1.5 * gap[1]);
  out[1] = can[1] && (!can[0] || gap[1] <= 1.5 * gap[0]);
  out[2] = can[2] && gap[2] <= 1.01 * std::min(gap[0], gap[1]);
  if (!out[0] && !out[1] && can[2] && !can[0] && !can[1]) out[2] = true;
  return out;
}

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
  TensorGrid grid;
  Stencil<T> A;
  std::vector<T> lu_c, lu_inv;  // factors of every z-column's tridiagonal block
  std::vector<T> b, x, r;
  std::vector<T> kappa, mu;
  std::array<AxisTransfer, 3> to_coarse;  // towards the next coarser level
  std::vector<T> restrict_norm;          // on this level: R applied to ones from the finer one
  mutable std::vector<T> tmp_a, tmp_b;   // intermediate results of separable transfers
  std::vector<T> zeros;                  // one x-row of zeros (missing neighbours)
  std::unique_ptr<Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>>> direct;
};

namespace {

// Separable transfers. Along one axis with stride `stride` (1, nx, nx*ny of the source shape),
// `outer` independent lines, each `inner` contiguous values wide, are mapped from n_in to n_out
// nodes. Restriction gathers through the transpose lists; prolongation interpolates.
template <typename T>
void RestrictAxis(const AxisTransfer& t, const T* in, T* out, int64_t inner, int64_t outer) {
  const int64_t n_in = t.n_fine, n_out = t.n_coarse;
#pragma omp parallel for collapse(2) schedule(static)
  for (int64_t o = 0; o < outer; ++o)
    for (int64_t c = 0; c < n_out; ++c) {
      const T* src = in + o * n_in * inner;
      T* dst = out + (o * n_out + c) * inner;
      for (int64_t v = 0; v < inner; ++v) dst[v] = T(0);
      for (int64_t g = t.g_start[c]; g < t.g_start[c + 1]; ++g) {
        const T w = T(t.g_w[g]);
        const T* s = src + t.g_idx[g] * inner;
        for (int64_t v = 0; v < inner; ++v) dst[v] += w * s[v];
      }
    }
}

template <typename T>
void ProlongAxis(const AxisTransfer& t, const T* in, T* out, int64_t inner, int64_t outer,
                 bool add) {
  const int64_t n_in = t.n_coarse, n_out = t.n_fine;
#pragma omp parallel for collapse(2) schedule(static)
  for (int64_t o = 0; o < outer; ++o)
    for (int64_t f = 0; f < n_out; ++f) {
      const T* a = in + (o * n_in + t.lo[f]) * inner;
      const T* b = in + (o * n_in + t.hi[f]) * inner;
      const T wa = T(t.wlo[f]), wb = T(t.whi[f]);
      T* dst = out + (o * n_out + f) * inner;
      if (add)
        for (int64_t v = 0; v < inner; ++v) dst[v] += wa * a[v] + wb * b[v];
      else
        for (int64_t v = 0; v < inner; ++v) dst[v] = wa * a[v] + wb * b[v];
    }
}

// x-axis lines are the contiguous direction: one value per line, handled row by row.
template <typename T>
void RestrictX(const AxisTransfer& t, const T* in, T* out, int64_t rows) {
  const int64_t n_in = t.n_fine, n_out = t.n_coarse;
#pragma omp parallel for schedule(static)
  for (int64_t r = 0; r < rows; ++r) {
    const T* src = in + r * n_in;
    T* dst = out + r * n_out;
    for (int64_t c = 0; c < n_out; ++c) {
      T s = 0;
      for (int64_t g = t.g_start[c]; g < t.g_start[c + 1]; ++g) s += T(t.g_w[g]) * src[t.g_idx[g]];
      dst[c] = s;
    }
  }
}

template <typename T>
void ProlongXAdd(const AxisTransfer& t, const T* in, T* out, int64_t rows) {
  const int64_t n_in = t.n_coarse, n_out = t.n_fine;
#pragma omp parallel for schedule(static)
  for (int64_t r = 0; r < rows; ++r) {
    const T* src = in + r * n_in;
    T* dst = out + r * n_out;
    for (int64_t f = 0; f < n_out; ++f)
      dst[f] += T(t.wlo[f]) * src[t.lo[f]] + T(t.whi[f]) * src[t.hi[f]];
  }
}

}  // namespace

// c = R f = P^T f: x, then y, then z (each pass shrinks the data).
template <typename T>
void MultigridSolver<T>::Restrict(const Level& L, const T* f, T* c) const {
  const auto& t = L.to_coarse;
  const int64_t ny = L.grid.shape.ny, nz = L.grid.shape.nz;
  const int64_t mx = t[0].n_coarse, my = t[1].n_coarse;
  T* a = L.tmp_a.data();
  T* b = L.tmp_b.data();
  RestrictX(t[0], f, a, ny * nz);                 // (mx, ny, nz)
  RestrictAxis(t[1], a, b, mx, nz);               // (mx, my, nz)
  RestrictAxis(t[2], b, c, mx * my, 1);           // (mx, my, mz)
}

// f += P c: z, then y, then x (each pass grows the data).
template <typename T>
void MultigridSolver<T>::ProlongAdd(const Level& L, const T* c, T* f) const {
  const auto& t = L.to_coarse;
  const int64_t ny = L.grid.shape.ny, nz = L.grid.shape.nz;
  const int64_t mx = t[0].n_coarse, my = t[1].n_coarse;
  T* a = L.tmp_a.data();
  T* b = L.tmp_b.data();
  ProlongAxis(t[2], c, b, mx * my, 1, false);     // (mx, my, nz)
  ProlongAxis(t[1], b, a, mx, nz, false);         // (mx, ny, nz)
  ProlongXAdd(t[0], a, f, ny * nz);               // (nx, ny, nz)
}

template <typename T>
MultigridSolver<T>::MultigridSolver(const GridShape& shape, double h,
                                    const MultigridOptions& options)
    : options_(options) {
  if (std::string err = options_.Validate(); !err.empty())
    throw InputError("multigrid options: " + err);
  TL_CHECK(shape.nx >= 2 && shape.ny >= 2 && shape.nz >= 2 && h > 0);
  auto level = std::make_unique<Level>();
  level->grid = TensorGrid::Uniform(shape, h);
  levels_.push_back(std::move(level));
  while (true) {
    Level& L = *levels_.back();
    if (L.grid.shape.size() <= options_.coarsest_nodes) break;
    const std::array<bool, 3> coarsen = ChooseCoarsening(L.grid);
    if (!coarsen[0] && !coarsen[1] && !coarsen[2]) break;
    auto next = std::make_unique<Level>();
    for (int a = 0; a < 3; ++a)
      L.to_coarse[a] = MakeAxisTransfer(L.grid.coord[a], coarsen[a], &next->grid.coord[a]);
    next->grid.shape = {int64_t(next->grid.coord[0].size()), int64_t(next->grid.coord[1].size()),
                        int64_t(next->grid.coord[2].size())};
    levels_.push_back(std::move(next));
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
      const auto& t = L.to_coarse;
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
  has_coefficients_ = true;
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
  if (options_.cycle_index == 2 && l + 2 < levels_.size()) {
    // W-cycle: a second coarse correction from the coarse residual (keeps symmetry).
    std::vector<T> r2(Cl.b.size()), x2(Cl.b.size());
    StencilResidual(Cl.A, Cl.b.data(), Cl.x.data(), r2.data());
    VCycle(l + 1, r2.data(), x2.data());
    for (size_t p = 0; p < x2.size(); ++p) Cl.x[p] += x2[p];
  }
  ProlongAdd(L, Cl.x.data(), x);
  for (int s = 0; s < options_.post_smoothing; ++s) {
    Smooth(L, b, x, 1);
    Smooth(L, b, x, 0);
  }
}

template <typename T>
SolveSummary MultigridSolver<T>::Solve(const T* b, T* x) {
  TL_CHECK_MSG(has_coefficients_, "SetCoefficients() must be called before Solve()");
  const auto t0 = std::chrono::steady_clock::now();
  const Level& L0 = *levels_[0];
  const int64_t n = L0.grid.shape.size();
  SolveSummary sum;
  auto finish = [&](bool converged, std::string message) {
    StencilResidual(L0.A, b, x, r_.data());
    const double bn = std::sqrt(Dot(b, b, n));
    sum.final_residual = bn > 0 ? std::sqrt(Dot(r_.data(), r_.data(), n)) / bn : 0.0;
    sum.converged = converged;
    sum.message = std::move(message);
    sum.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return sum;
  };
  const double bnorm = std::sqrt(Dot(b, b, n));
  if (bnorm == 0) {
    std::fill(x, x + n, T(0));
    return finish(true, "zero right-hand side");
  }
  T* r = r_.data();
  T* z = z_.data();
  T* p = p_.data();
  T* q = q_.data();
  StencilResidual(L0.A, b, x, r);
  double rnorm = std::sqrt(Dot(r, r, n));
  sum.initial_residual = rnorm / bnorm;
  if (sum.initial_residual <= options_.tolerance) return finish(true, "");
  const double tol = options_.tolerance * bnorm;
  int restarts = 0;
  bool restart = true;
  double rz = 0;
  while (sum.iterations < options_.max_iterations) {
    if (restart) {
      VCycle(0, r, z);
      std::copy(z, z + n, p);
      rz = Dot(r, z, n);
      restart = false;
    }
    ApplyStencil(L0.A, p, q);
    const double alpha = rz / Dot(p, q, n);
    double rr = 0;
#pragma omp parallel for reduction(+ : rr) schedule(static)
    for (int64_t i = 0; i < n; ++i) {
      x[i] += T(alpha) * p[i];
      r[i] -= T(alpha) * q[i];
      rr += double(r[i]) * double(r[i]);
    }
    ++sum.iterations;
    rnorm = std::sqrt(rr);
    if (rnorm <= tol) {
      // The recursive residual drifts in float: confirm with the true one.
      StencilResidual(L0.A, b, x, r);
      rnorm = std::sqrt(Dot(r, r, n));
      if (rnorm <= tol) return finish(true, "");
      if (++restarts > 3) {
        return finish(false, fmt::format("stagnated at the precision of {}",
                                         sizeof(T) == 4 ? "float" : "double"));
      }
      restart = true;
      continue;
    }
    VCycle(0, r, z);
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
int MultigridSolver<T>::num_levels() const { return int(levels_.size()); }

template <typename T>
std::vector<GridShape> MultigridSolver<T>::level_shapes() const {
  std::vector<GridShape> out;
  for (const auto& L : levels_) out.push_back(L->grid.shape);
  return out;
}

template class MultigridSolver<float>;
template class MultigridSolver<double>;

}  // namespace translume
