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
#include <omp.h>

#include "solver/multigrid_hierarchy.h"
#include "solver/multigrid_split.h"
#include "solver/status.h"
#include "solver/threads.h"

namespace translume {
namespace {

template <typename A, typename B>
double Dot(const A* a, const B* b, int64_t n) {
  constexpr int64_t kBlock = 4096;
  double s = 0;
#pragma omp parallel for reduction(+ : s) schedule(static) if (n >= kParallelNodes)
  for (int64_t i = 0; i < n; i += kBlock) s += RowDot(a + i, b + i, std::min(kBlock, n - i));
  return s;
}

// Per-thread scratch of at least n values (one row of z-lines and one residual row).
template <typename T>
T* Scratch(size_t n) {
  static thread_local std::vector<T> buf;
  if (buf.size() < n) buf.resize(n);
  return buf.data();
}

// CG's vector loops on a grid of shape s, fused with the moves between CG's natural layout and
// the V-cycle's level layout (row (j, k) at nx (k + nz j), split; the V-cycle's input vb and
// output vx, of the precision P of the hierarchy).
// r -= alpha q (q null: r as is) and vb = r (converted), row by row; returns ||r||^2
// (accumulated in double).
template <typename T, typename P>
double UpdateResidualRows(const GridShape& s, double alpha, const T* q, T* r, P* vb) {
  const int64_t nx = s.nx;
  const T a = T(alpha);
  double rr = 0;
#pragma omp parallel for collapse(2) reduction(+ : rr) schedule(static) \
    if (s.size() >= kParallelNodes)
  for (int64_t k = 0; k < s.nz; ++k)
    for (int64_t j = 0; j < s.ny; ++j) {
      const int64_t o = nx * (j + s.ny * k);
      T* __restrict rr_row = r + o;
      if (q) {
        const T* __restrict q_row = q + o;
        for (int64_t i = 0; i < nx; ++i) rr_row[i] -= a * q_row[i];
      }
      rr += RowDot(rr_row, rr_row, nx);
      SplitRow(nx, rr_row, vb + nx * (k + s.nz * j));
    }
  return rr;
}

// x += alpha p (the update CG deferred), then p = vx + beta p, row by row (alpha = beta = 0,
// a restart: p = vx without reading p or x).
template <typename T, typename P>
void UpdateDirectionRows(const GridShape& s, double alpha, double beta, const P* vx, double* x,
                         T* p) {
  const int64_t nx = s.nx;
  const T bt = T(beta);
#pragma omp parallel for collapse(2) schedule(static) if (s.size() >= kParallelNodes)
  for (int64_t k = 0; k < s.nz; ++k)
    for (int64_t j = 0; j < s.ny; ++j) {
      const int64_t o = nx * (j + s.ny * k);
      P* __restrict z = Scratch<P>(size_t(nx));
      MergeRow(nx, vx + nx * (k + s.nz * j), z);
      double* __restrict xr = x + o;
      T* __restrict pr = p + o;
      if (alpha == 0 && beta == 0) {  // a (re)start: p = z only
        for (int64_t i = 0; i < nx; ++i) pr[i] = T(z[i]);
        continue;
      }
      for (int64_t i = 0; i < nx; ++i) {
        xr[i] += alpha * double(pr[i]);
        pr[i] = T(z[i]) + bt * pr[i];
      }
    }
}

// x += vx (moved from the level layout), row by row.
template <typename P>
void AddRows(const GridShape& s, const P* vx, double* x) {
  const int64_t nx = s.nx;
#pragma omp parallel for collapse(2) schedule(static) if (s.size() >= kParallelNodes)
  for (int64_t k = 0; k < s.nz; ++k)
    for (int64_t j = 0; j < s.ny; ++j) {
      P* __restrict z = Scratch<P>(size_t(nx));
      MergeRow(nx, vx + nx * (k + s.nz * j), z);
      double* __restrict xr = x + nx * (j + s.ny * k);
      for (int64_t i = 0; i < nx; ++i) xr[i] += double(z[i]);
    }
}

}  // namespace

std::string MultigridOptions::Validate() const {
  if (!(tolerance > 0) || !(tolerance < 1)) return fmt::format("tolerance must be in (0, 1), got {}", tolerance);
  if (max_iterations < 1) return "max_iterations must be >= 1";
  if (pre_smoothing < 0 || post_smoothing < 0 || coarse_smoothing < 0)
    return "pre_smoothing, post_smoothing and coarse_smoothing must be >= 1 (or 0: the backend's default)";
  if (full_multigrid_sweeps < 0) return "full_multigrid_sweeps must be >= 0";
  if (pre_smoothing != post_smoothing) return "pre_smoothing must equal post_smoothing (CG needs a symmetric V-cycle)";
  if (coarsest_nodes < 8) return "coarsest_nodes must be >= 8";
  return "";
}

MultigridOptions MultigridOptions::WithCycleDefaults(bool gl, int64_t nodes) const {
  // Below this many nodes the cpu solver keeps full coarsening with V(2,2): on small grids the
  // x-y cycle needs a 6th iteration (it has few coarse levels to smooth on) and its larger
  // coarsest level costs more, 5-40 % slower on 24x18x8 .. 64x48x16 (docs/benchmarks.md).
  constexpr int64_t kSemiCoarseningNodes = 100000;
  MultigridOptions o = *this;
  if (!o.z_coarsening)
    o.z_coarsening = !gl && nodes >= kSemiCoarseningNodes ? ZCoarsening::kLast : ZCoarsening::kWithXY;
  // V(1,1) on the finest level with x-y semi-coarsening, V(2,2) with full coarsening.
  if (o.pre_smoothing == 0)
    o.pre_smoothing = o.post_smoothing = *o.z_coarsening == ZCoarsening::kLast ? 1 : 2;
  if (o.coarse_smoothing == 0) o.coarse_smoothing = 2;
  return o;
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
  Stencil<T> A;  // natural layout (the finest level's operator; coarse-level assembly)
  // V-cycle arrays are in the level layout: x-rows split (multigrid_split.h) and ordered
  // plane-fastest, row (j, k) at nx (k + nz j), so that the z-lines of one y-row are contiguous.
  // The smoother's copy of A in it: diagonal, conductance to the x-neighbour on the right (the
  // one on the left is its left neighbour's), to the next row in y and the next plane in z.
  std::vector<T> sdiag, sxr, sy, sz;
  // Every z-line's tridiagonal block factored (level layout): lu_inv[k] = 1 / (sdiag[k] -
  // sz[k-1]^2 lu_inv[k-1]). The back substitution's factor sz[k] lu_inv[k] is formed on the fly
  // from two values the forward pass has just brought into cache, rather than read from a
  // third array (one stream fewer for the smoother, which is bound by its loads).
  std::vector<T> lu_inv;
  // Right-hand side and iterate of the V-cycle on this level, level layout, one padding value.
  std::vector<T> b, x;
  std::vector<T> kappa, mu;
  std::vector<T> restrict_norm;          // on this level: R applied to ones from the finer one
  // Intermediate results of separable transfers (level layout); the last pre-smoothing sweep
  // writes its residual restricted along x into tmp_a ((coarse nx) * nz * ny).
  mutable std::vector<T> tmp_a, tmp_b;
  std::vector<T> zeros;                  // one x-row of zeros (missing neighbours)
  std::unique_ptr<SplitTransferX<T>> tx;  // x transfers towards the next coarser level
  // The coarsest level's exact solve, natural layout: A = P^-1 L D L^T P, factored in double
  // (Eigen's SimplicialLDLT, AMD ordering) and applied in T (a float factor halves the traffic
  // of the triangular solves, which dominate a small grid's coarsest level).
  struct Direct {
    // The factorisation, kept so that new coefficients (same pattern) skip the AMD ordering.
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt;
    Eigen::SparseMatrix<T> L;  // unit lower triangular (diagonal not used)
    Eigen::Matrix<T, Eigen::Dynamic, 1> inv_d;
    Eigen::PermutationMatrix<Eigen::Dynamic, Eigen::Dynamic, int> P;
    mutable Eigen::Matrix<T, Eigen::Dynamic, 1> work;
    void Solve(const T* b, T* x) const {
      const int64_t n = inv_d.size();
      work = P * Eigen::Map<const Eigen::Matrix<T, Eigen::Dynamic, 1>>(b, n);
      L.template triangularView<Eigen::UnitLower>().solveInPlace(work);
      work.array() *= inv_d.array();
      L.transpose().template triangularView<Eigen::UnitUpper>().solveInPlace(work);
      Eigen::Map<Eigen::Matrix<T, Eigen::Dynamic, 1>>(x, n) = P.transpose() * work;
    }
  };
  std::unique_ptr<Direct> direct;
};

template <typename T>
void MultigridSolver<T>::Restrict(const Level& L, const T* f, T* c) const {
  Restrict3(L.geo, f, c, L.tmp_a.data(), L.tmp_b.data());
}

// The y and z passes between the level layouts of a level and the next coarser one, for
// blocks already transferred along x: restriction z then y ((mx, nz, ny) -> (mx, mz, my)),
// prolongation y then z. Axes that are not coarsened are skipped; the last pass writes `out`
// (added to it if `add`, prolongation only), earlier ones `tmp` ((mx, mz, ny) values).
template <typename T>
void TransferYZ(const MultigridLevel& L, bool restrict, const T* in, T* out, bool add, T* tmp) {
  const auto& t = L.to_coarse;
  const int64_t ny = L.grid.shape.ny, nz = L.grid.shape.nz;
  const int64_t mx = t[0].n_coarse, mz = t[2].n_coarse;
  struct Pass {
    const AxisTransfer* t;
    int64_t inner, outer;
  };
  const Pass z{&t[2], mx, ny}, y{&t[1], mx * mz, 1};
  std::vector<Pass> passes;
  for (const Pass& P : restrict ? std::array<Pass, 2>{z, y} : std::array<Pass, 2>{y, z})
    if (P.t->coarsened) passes.push_back(P);
  if (passes.empty()) {
    const int64_t m = mx * nz * ny;
    if (add) for (int64_t i = 0; i < m; ++i) out[i] += in[i];
    else std::copy(in, in + m, out);
    return;
  }
  for (size_t i = 0; i < passes.size(); ++i) {
    const bool last = i + 1 == passes.size();
    T* dst = last ? out : tmp;
    if (restrict) RestrictAxis(*passes[i].t, in, dst, passes[i].inner, passes[i].outer);
    else ProlongAxis(*passes[i].t, in, dst, passes[i].inner, passes[i].outer, last && add);
    in = dst;
  }
}

template <typename T>
void MultigridSolver<T>::ProlongAdd(const Level& L, const T* c, T* f) const {
  const GridShape& s = L.grid.shape;
  if (!L.tx->coarsened) {
    // Along x the transfer is the identity and both levels' rows have the same layout.
    TransferYZ(L.geo, false, c, f, true, L.tmp_b.data());
    return;
  }
  TransferYZ(L.geo, false, c, L.tmp_a.data(), false, L.tmp_b.data());  // (mx, nz, ny)
  const int64_t nx = s.nx, mx = L.tx->nc, rows = s.ny * s.nz;
#pragma omp parallel for schedule(static) if (s.size() >= kParallelNodes)
  for (int64_t row = 0; row < rows; ++row) {
    T* nat = Scratch<T>(size_t(mx + 1));
    MergeRow(mx, L.tmp_a.data() + mx * row, nat);
    nat[mx] = T(0);
    L.tx->ProlongAdd(nat, f + nx * row);
  }
}

template <typename T>
MultigridSolver<T>::MultigridSolver(const GridShape& shape, double h,
                                    const MultigridOptions& options)
    : options_(options.WithCycleDefaults(false, shape.size())) {
  if (std::string err = options_.Validate(); !err.empty())
    throw InputError("multigrid options: " + err);
  TL_CHECK(shape.nx >= 2 && shape.ny >= 2 && shape.nz >= 2 && h > 0);
  const bool mixed = std::is_same_v<T, double> && options_.mixed_precision;
  if (mixed) {
    MultigridOptions fo = options_;
    fo.mixed_precision = false;
    float_preconditioner_ = std::make_unique<MultigridSolver<float>>(shape, h, fo);
  }
  // Mixed precision: only the finest level in T (coarsest_nodes = its size stops coarsening).
  for (MultigridLevel& geo :
       BuildMultigridHierarchy(shape, h, mixed ? shape.size() : options_.coarsest_nodes,
                               *options_.z_coarsening)) {
    auto level = std::make_unique<Level>();
    level->geo = std::move(geo);
    levels_.push_back(std::move(level));
  }
  for (size_t l = 0; l < levels_.size(); ++l) {
    Level& L = *levels_[l];
    const int64_t n = L.grid.shape.size();
    if (!mixed) {  // (with mixed precision the float hierarchy runs the V-cycles)
      L.b.assign(n + 1, T(0));
      L.x.assign(n + 1, T(0));
    }
    if (l > 0) {
      L.restrict_norm.resize(n);
      std::vector<T> ones(levels_[l - 1]->grid.shape.size(), T(1));
      Restrict(*levels_[l - 1], ones.data(), L.restrict_norm.data());
    }
    if (l + 1 < levels_.size()) {
      const auto& t = L.geo.to_coarse;
      L.tmp_a.resize(t[0].n_coarse * L.grid.shape.ny * L.grid.shape.nz);
      L.tmp_b.resize(std::max(t[0].n_coarse * t[1].n_coarse * L.grid.shape.nz,
                              t[0].n_coarse * t[2].n_coarse * L.grid.shape.ny));
      L.tx = std::make_unique<SplitTransferX<T>>(t[0]);
    }
    L.kappa.resize(n);
    L.mu.resize(n);
    L.zeros.assign(L.grid.shape.nx, T(0));
  }
  const int64_t n0 = shape.size();
  r_.resize(n0);
  if (mixed) p_float_.resize(n0);
  else p_.resize(n0);
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
      // The smoother's copy of A in the split layout, then the z-lines' factors from it.
      for (auto* v : {&L.sdiag, &L.sxr, &L.sy, &L.sz, &L.lu_inv}) v->resize(n);
#pragma omp parallel for collapse(2) schedule(static) if (s.size() >= kParallelNodes)
      for (int64_t k = 0; k < s.nz; ++k)
        for (int64_t j = 0; j < s.ny; ++j) {
          const int64_t o = s.nx * (j + s.ny * k), d = s.nx * (k + s.nz * j);
          SplitRow(s.nx, L.A.diag.data() + o, L.sdiag.data() + d);
          SplitRow(s.nx, L.A.cx.data() + o, L.sxr.data() + d);
          SplitRow(s.nx, L.A.cy.data() + o, L.sy.data() + d);
          SplitRow(s.nx, L.A.cz.data() + o, L.sz.data() + d);
        }
#pragma omp parallel for schedule(static) if (s.size() >= kParallelNodes)
      for (int64_t col = 0; col < nxy; ++col) {  // col = (position in the row, j)
        const int64_t base = col % s.nx + s.nx * s.nz * (col / s.nx);
        for (int64_t k = 0; k < s.nz; ++k) {
          const int64_t p = base + s.nx * k;
          double denom = double(L.sdiag[p]);
          if (k > 0) {
            const double c = double(L.sz[p - s.nx]);
            denom -= c * c * double(L.lu_inv[p - s.nx]);
          }
          L.lu_inv[p] = T(1.0 / denom);
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
      if (!L.direct) {
        L.direct = std::make_unique<typename Level::Direct>();
        L.direct->ldlt.analyzePattern(M);  // (M holds the lower triangle: ldlt's UpLo)
      }
      typename Level::Direct& d = *L.direct;
      d.ldlt.factorize(M);
      TL_CHECK_MSG(d.ldlt.info() == Eigen::Success, "coarsest-level factorisation failed");
      d.L = Eigen::SparseMatrix<double>(d.ldlt.matrixL()).template cast<T>();
      d.inv_d = d.ldlt.vectorD().cwiseInverse().template cast<T>();
      d.P = d.ldlt.permutationP();
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
    Level& L = *levels_[0];
    const GridShape& s = L.grid.shape;
    // The V-cycle works in the level layout.
    const int64_t nx = s.nx;
#pragma omp parallel for collapse(2) schedule(static) if (s.size() >= kParallelNodes)
    for (int64_t k = 0; k < s.nz; ++k)
      for (int64_t j = 0; j < s.ny; ++j)
        SplitRow(nx, r + nx * (j + s.ny * k), L.b.data() + nx * (k + s.nz * j));
    VCycle(0, L.b.data(), L.x.data());
#pragma omp parallel for collapse(2) schedule(static) if (s.size() >= kParallelNodes)
    for (int64_t k = 0; k < s.nz; ++k)
      for (int64_t j = 0; j < s.ny; ++j)
        MergeRow(nx, L.x.data() + nx * (k + s.nz * j), z + nx * (j + s.ny * k));
    return;
  }
  const int64_t n = levels_[0]->grid.shape.size();
  rf_.resize(n);  // (Solve does not use these)
  zf_.resize(n);
#pragma omp parallel for schedule(static) if (n >= kParallelNodes)
  for (int64_t i = 0; i < n; ++i) rf_[i] = float(r[i]);
  float_preconditioner_->Precondition(rf_.data(), zf_.data());
#pragma omp parallel for schedule(static) if (n >= kParallelNodes)
  for (int64_t i = 0; i < n; ++i) z[i] = T(zf_[i]);
}

template <typename T>
void MultigridSolver<T>::LineRow(const Level& L, const T* b, T* x, int64_t j, int color,
                                 bool from_zero) const {
  const GridShape& s = L.grid.shape;
  const int64_t nx = s.nx, ny = s.ny, nz = s.nz, dy = nx * nz, he = (nx + 1) / 2;
  // Colour `color`'s columns in row j are the even-i half of the split row if (color + j) is
  // even, else the odd-i half; their x-neighbours are the other half.
  const bool even = ((color + j) & 1) == 0;
  const int64_t off = even ? 0 : he, len = even ? he : nx - he;
  const int64_t left = even ? he - 1 : 0, right = even ? he : 1;  // neighbours, from the row start
  const bool fix_first = even && nx % 2 == 0;
  const T* zeros = L.zeros.data();
  for (int64_t k = 0; k < nz; ++k) {
    const int64_t row = nx * (k + nz * j), p = row + off;
    // The previous plane's half-row already holds its eliminated values.
    const T* czm = k > 0 ? L.sz.data() + p - nx : zeros;
    const T* xzm = k > 0 ? x + p - nx : zeros;
    if (from_zero) {  // no neighbour values to read
      const T* __restrict bp = b + p;
      const T* __restrict inv = L.lu_inv.data() + p;
      T* __restrict xs = x + p;
      for (int64_t m = 0; m < len; ++m) xs[m] = (bp[m] + czm[m] * xzm[m]) * inv[m];
    } else {
      HalfRowKernel<T, false>(len, fix_first, b + p,
                              L.sxr.data() + row + left, x + row + left, L.sxr.data() + p,
                              x + row + right, j > 0 ? L.sy.data() + p - dy : zeros,
                              j > 0 ? x + p - dy : zeros, j + 1 < ny ? L.sy.data() + p : zeros,
                              j + 1 < ny ? x + p + dy : zeros, czm, xzm, nullptr, nullptr,
                              nullptr, nullptr, L.lu_inv.data() + p, x + p);
    }
  }
  for (int64_t k = nz - 2; k >= 0; --k) {
    const int64_t p = nx * (k + nz * j) + off;
    T* __restrict xs = x + p;
    const T* __restrict xn = x + p + nx;
    const T* __restrict cz = L.sz.data() + p;
    const T* __restrict inv = L.lu_inv.data() + p;
    for (int64_t m = 0; m < len; ++m) xs[m] += cz[m] * inv[m] * xn[m];
  }
}

template <typename T>
void MultigridSolver<T>::ResidualRow(const Level& L, const T* b, const T* x, int64_t j,
                                     int solved, T* restricted) const {
  const GridShape& s = L.grid.shape;
  const int64_t nx = s.nx, ny = s.ny, nz = s.nz, dy = nx * nz, he = (nx + 1) / 2;
  const SplitTransferX<T>& tx = *L.tx;
  const int64_t mx = tx.nc;
  const T* zeros = L.zeros.data();
  T* r = Scratch<T>(size_t(nx + 2 * mx + 3));  // residual row, padded; coarse natural row
  T* nat = r + nx + 1;
  for (int64_t k = 0; k < nz; ++k) {
    const int64_t row = nx * (k + nz * j);
    for (int half = 0; half < 2; ++half) {
      const bool even = half == 0;
      const int64_t off = even ? 0 : he, len = even ? he : nx - he, p = row + off;
      if (even == (((solved + j) & 1) == 0)) {  // colour `solved`'s lines: zero
        std::fill(r + off, r + off + len, T(0));
        continue;
      }
      const int64_t left = even ? he - 1 : 0, right = even ? he : 1;
      HalfRowKernel<T, true>(len, even && nx % 2 == 0, b + p,
                             L.sxr.data() + row + left, x + row + left, L.sxr.data() + p,
                             x + row + right, j > 0 ? L.sy.data() + p - dy : zeros,
                             j > 0 ? x + p - dy : zeros, j + 1 < ny ? L.sy.data() + p : zeros,
                             j + 1 < ny ? x + p + dy : zeros, k > 0 ? L.sz.data() + p - nx : zeros,
                             k > 0 ? x + p - nx : zeros, k + 1 < nz ? L.sz.data() + p : zeros,
                             k + 1 < nz ? x + p + nx : zeros,
                             L.sdiag.data() + p, x + p, nullptr, r + off);
    }
    T* out = restricted + mx * (k + nz * j);
    if (!tx.coarsened) {
      std::copy(r, r + nx, out);  // same row on the coarser level
      continue;
    }
    r[nx] = T(0);
    tx.Restrict(r, nat);
    SplitRow(mx, nat, out);
  }
}

template <typename T>
void MultigridSolver<T>::Sweep(const Level& L, const T* b, T* x, int first, bool from_zero,
                               T* restricted, double* bx) const {
  const int64_t ny = L.grid.shape.ny, row_values = L.grid.shape.nx * L.grid.shape.nz;
  // Stages per row j: 0 = colour `first`'s lines, 1 = the other colour's, 2 = the residual.
  // Stage 1 of row j needs stage 0 of rows j-1..j+1 and must precede stage 0 of row j+2, which
  // reads its old values; stage 2 needs stage 1 of rows j-1..j+1. Each thread walks its block
  // of rows with the stages one row apart (the rows it just touched are still in cache), and
  // the rows on block edges, which need a neighbour's rows, wait for a barrier. The result is
  // exactly that of two separate half-sweeps.
#pragma omp parallel if (L.grid.shape.size() >= kParallelNodes)
  {
    const int64_t nt = omp_get_num_threads(), id = omp_get_thread_num();
    const int64_t j0 = ny * id / nt, j1 = ny * (id + 1) / nt;
    double dot = 0;  // b . x over the rows this thread finished
    auto finish_row = [&](int64_t j) {
      LineRow(L, b, x, j, 1 - first, false);
      if (bx) dot += RowDot(b + row_values * j, x + row_values * j, row_values);
    };
    for (int64_t j = j0; j < j1; ++j) {
      LineRow(L, b, x, j, first, from_zero);
      if (j - 1 >= j0 + 1) finish_row(j - 1);
      if (restricted && j - 2 >= j0 + 2) ResidualRow(L, b, x, j - 2, 1 - first, restricted);
    }
#pragma omp barrier
    if (j1 > j0) finish_row(j0);
    if (j1 - 1 > j0) finish_row(j1 - 1);
    if (bx) {
#pragma omp atomic
      *bx += dot;
    }
    if (restricted) {
#pragma omp barrier
      for (int64_t j = j0; j < j1; ++j)
        if (j < j0 + 2 || j > j1 - 3) ResidualRow(L, b, x, j, 1 - first, restricted);
    }
  }
}

template <typename T>
void MultigridSolver<T>::RestrictRhs(const Level& L, const T* fine, T* coarse) const {
  if (!L.tx->coarsened) {
    TransferYZ(L.geo, true, fine, coarse, false, L.tmp_b.data());
    return;
  }
  const GridShape& s = L.grid.shape;
  const int64_t nx = s.nx, mx = L.tx->nc, rows = s.ny * s.nz;
#pragma omp parallel for schedule(static) if (s.size() >= kParallelNodes)
  for (int64_t row = 0; row < rows; ++row) {
    T* nat = Scratch<T>(size_t(mx));
    // (Reads one value past the row, the next row's first or the level's padding, with
    // weight 0.)
    L.tx->Restrict(fine + nx * row, nat);
    SplitRow(mx, nat, L.tmp_a.data() + mx * row);
  }
  TransferYZ(L.geo, true, static_cast<const T*>(L.tmp_a.data()), coarse, false, L.tmp_b.data());
}

template <typename T>
void MultigridSolver<T>::FullMultigrid() {
  const size_t nl = levels_.size();
  for (size_t l = 0; l + 1 < nl; ++l)
    RestrictRhs(*levels_[l], levels_[l]->b.data(), levels_[l + 1]->b.data());
  VCycle(nl - 1, levels_[nl - 1]->b.data(), levels_[nl - 1]->x.data());  // exact
  for (size_t l = nl - 1; l-- > 0;) {
    Level& L = *levels_[l];
    std::fill(L.x.begin(), L.x.end(), T(0));
    ProlongAdd(L, levels_[l + 1]->x.data(), L.x.data());
    if (l > 0) {
      VCycle(l, L.b.data(), L.x.data(), nullptr, false, 1);
    } else {
      for (int s = 0; s < options_.full_multigrid_sweeps; ++s)
        Sweep(L, L.b.data(), L.x.data(), s % 2, false, nullptr);
    }
  }
}

template <typename T>
void MultigridSolver<T>::VCycle(size_t l, const T* b, T* x, double* bx, bool from_zero,
                                int sweeps) {
  Level& L = *levels_[l];
  const int64_t n = L.grid.shape.size();
  if (bx) *bx = 0;
  if (l + 1 == levels_.size()) {
    // Exact solve; the rows are split here too.
    const GridShape& s = L.grid.shape;
    T* rhs = Scratch<T>(size_t(2 * n));
    T* sol = rhs + n;
    for (int64_t k = 0; k < s.nz; ++k)
      for (int64_t j = 0; j < s.ny; ++j)
        MergeRow(s.nx, b + s.nx * (k + s.nz * j), rhs + s.nx * (j + s.ny * k));
    L.direct->Solve(rhs, sol);
    for (int64_t k = 0; k < s.nz; ++k)
      for (int64_t j = 0; j < s.ny; ++j)
        SplitRow(s.nx, sol + s.nx * (j + s.ny * k), x + s.nx * (k + s.nz * j));
    if (bx) *bx = Dot(b, x, n);
    return;
  }
  // Pre-smoothing (from x = 0 unless given a guess), colour 0 first; the last sweep also
  // restricts its residual along x. Post-smoothing colour 1 first, as many sweeps: the cycle is
  // symmetric.
  const int nu = sweeps > 0 ? sweeps : options_.SweepsOnLevel(l);
  for (int s = 0; s < nu; ++s)
    Sweep(L, b, x, 0, from_zero && s == 0, s + 1 == nu ? L.tmp_a.data() : nullptr);
  Level& Cl = *levels_[l + 1];
  TransferYZ(L.geo, true, static_cast<const T*>(L.tmp_a.data()), Cl.b.data(), false,
             L.tmp_b.data());
  VCycle(l + 1, Cl.b.data(), Cl.x.data(), nullptr, true, sweeps);
  ProlongAdd(L, Cl.x.data(), x);
  for (int s = 0; s < nu; ++s) Sweep(L, b, x, 1, false, nullptr, s + 1 == nu ? bx : nullptr);
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
  // The V-cycles run on `V`: the float hierarchy with mixed precision, else this one. CG writes
  // r straight into V's level-0 right-hand side vb (V's precision and layout) as it updates r,
  // and reads V's result vx as it updates p.
  auto cg = [&](auto& V) {
    const GridShape& s = L0.grid.shape;
    auto* vb = V.levels_[0]->b.data();
    auto* vx = V.levels_[0]->x.data();
    T* r = r_.data();
    T* q = q_.data();
    // The search direction p is held in the V-cycle's precision: A p is computed in T from
    // its values as stored and x advances along them, so r stays the residual of x; rounding p
    // to float only perturbs its conjugacy at the 1e-7 level. It saves 12 of CG's ~110 bytes
    // per node and iteration outside the V-cycle.
    using P = std::remove_reference_t<decltype(*vb)>;
    P* p;
    if constexpr (std::is_same_v<P, T>) p = p_.data();
    else p = p_float_.data();
    auto norm_of_r = [&] { return std::sqrt(UpdateResidualRows<T>(s, 0.0, nullptr, r, vb)); };
    // From a zero guess r = b, and A x need not be computed.
    bool zero_guess = true;
    for (int64_t i = 0; i < n && zero_guess; ++i) zero_guess = x[i] == 0;
    if (zero_guess) std::copy(b, b + n, r);
    else StencilResidual(L0.A, b, x, r);
    double rnorm = norm_of_r();
    sum.initial_residual = rnorm / bnorm;
    if (sum.initial_residual <= options_.tolerance) return finish(true, "", rnorm);
    const double tol = options_.tolerance * bnorm;
    if (options_.full_multigrid_start) {
      // vb holds r; x += the full-multigrid approximation of A^-1 r, then the new residual.
      V.FullMultigrid();
      AddRows(s, vx, x);
      StencilResidual(L0.A, b, x, r);
      rnorm = norm_of_r();
      if (rnorm <= tol) return finish(true, "", rnorm);
    }
    // z = M r and r . z (both in the level layout).
    auto precondition = [&] {
      double rz = 0;
      V.VCycle(0, vb, vx, &rz);
      return rz;
    };
    auto update_x = [&](double alpha) {
#pragma omp parallel for schedule(static) if (n >= kParallelNodes)
      for (int64_t i = 0; i < n; ++i) x[i] += alpha * double(p[i]);
    };
    int restarts = 0;
    bool restart = true;
    double rz = 0, alpha = 0;
    while (sum.iterations < options_.max_iterations) {
      if (restart) {
        rz = precondition();
        UpdateDirectionRows(s, 0.0, 0.0, vx, x, p);  // p = z
        restart = false;
      } else {
        const double rz_new = precondition();
        UpdateDirectionRows(s, alpha, rz_new / rz, vx, x, p);
        rz = rz_new;
      }
      alpha = rz / ApplyStencilDot<T, P>(L0.A, p, q);  // q = A p
      rnorm = std::sqrt(UpdateResidualRows(s, alpha, q, r, vb));
      ++sum.iterations;
      sum.history.push_back(rnorm / bnorm);
      if (rnorm <= tol) {
        update_x(alpha);
        alpha = 0;
        // The recursive residual drifts: confirm with the true one.
        StencilResidual(L0.A, b, x, r);
        rnorm = norm_of_r();
        if (rnorm <= tol) return finish(true, "", rnorm);
        if (++restarts > 3) return finish(false, "stagnated", rnorm);
        restart = true;
      }
    }
    update_x(alpha);
    return finish(false, fmt::format("reached max_iterations = {}", options_.max_iterations));
  };
  if (float_preconditioner_) return cg(*float_preconditioner_);
  return cg(*this);
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
