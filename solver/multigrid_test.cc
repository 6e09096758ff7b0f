// SPDX-License-Identifier: MIT
#include "solver/multigrid.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "solver/multigrid_split.h"

namespace translume {
namespace {

// SPEC section 3: exact front-face radiance of a uniformly back-lit homogeneous slab.
double SlabFrontRadiance(double kappa, double mu, double C, double T, double q) {
  const double s = std::sqrt(mu / kappa), a = 2 * C * kappa * s;
  const double A = q / ((1 + a) - std::exp(-2 * s * T) * (1 - a) * (1 - a) / (1 + a));
  const double B = -A * std::exp(-2 * s * T) * (1 - a) / (1 + a);
  return (A * std::exp(-s * T) + B * std::exp(s * T)) / (2 * std::numbers::pi);
}

template <typename T>
SolveSummary SolveSlab(int nz, double* rel_err) {
  const double kappa = 0.1, mu = 0.1, C = 2.6021, thick = 2.0, width = 16.0;
  const double h = thick / (nz - 1);
  const int64_t nx = int64_t(std::llround(width / h)) + 1;
  const GridShape s{nx, nx, nz};
  MultigridSolver<T> mg(s, h);
  std::vector<T> K(s.size(), T(kappa)), M(s.size(), T(mu)), b(s.size()), x(s.size(), T(0));
  mg.SetCoefficients(K.data(), M.data(), C);
  std::vector<float> q(s.face_size(), 1.0f);
  LitFaceSource(mg.grid(), nz - 1, C, q.data(), b.data());
  const SolveSummary sum = mg.Solve(b.data(), x.data());
  const double exact = SlabFrontRadiance(kappa, mu, C, thick, 1.0);
  const double got = double(x[s.index(nx / 2, nx / 2, 0)]) / (2 * std::numbers::pi);
  *rel_err = std::abs(got - exact) / exact;
  return sum;
}

TEST(Multigrid, AnalyticSlabConvergesAtSecondOrderWithSpecNumbers) {
  const int nzs[3] = {5, 9, 17};
  const double spec[3] = {3.0e-2, 7.6e-3, 1.9e-3};
  double err[3];
  for (int i = 0; i < 3; ++i) {
    const SolveSummary s = SolveSlab<double>(nzs[i], &err[i]);
    EXPECT_TRUE(s.converged) << s.BriefReport();
    EXPECT_NEAR(err[i], spec[i], 0.05 * spec[i]) << "nz = " << nzs[i];
  }
  EXPECT_NEAR(err[0] / err[1], 4.0, 0.3);
  EXPECT_NEAR(err[1] / err[2], 4.0, 0.3);
}

// Smooth heterogeneous coefficients on an n^3 grid, back-lit.
template <typename T>
SolveSummary SolveHetero(const GridShape& s, std::vector<T>* x, double h = 0.1,
                         double kappa_scale = 1.0, const std::vector<T>* warm = nullptr,
                         const MultigridOptions& options = {}) {
  MultigridSolver<T> mg(s, h, options);
  std::vector<T> K(s.size()), M(s.size()), b(s.size());
  for (int64_t k = 0; k < s.nz; ++k)
    for (int64_t j = 0; j < s.ny; ++j)
      for (int64_t i = 0; i < s.nx; ++i) {
        const double u = double(i) / s.nx, v = double(j) / s.ny, w = double(k) / s.nz;
        K[s.index(i, j, k)] = T(kappa_scale * (0.2 + 0.15 * std::sin(6 * u + 3 * w) * std::cos(5 * v)));
        M[s.index(i, j, k)] = T(0.02 + 0.015 * std::cos(4 * u * v + 2 * w));
      }
  mg.SetCoefficients(K.data(), M.data(), 2.6);
  std::vector<float> q(s.face_size());
  for (int64_t f = 0; f < s.face_size(); ++f) q[f] = float(f % 7 == 0 ? 1.0 : 0.25);
  LitFaceSource(mg.grid(), s.nz - 1, 2.6, q.data(), b.data());
  if (warm) *x = *warm;
  else x->assign(s.size(), T(0));
  return mg.Solve(b.data(), x->data());
}

TEST(Multigrid, IterationsDoNotGrowWithTheGrid) {
  std::vector<int> iters;
  for (int n : {17, 33, 65}) {
    std::vector<double> x;
    const SolveSummary s = SolveHetero<double>({n, n, n}, &x, 1.6 / (n - 1));
    ASSERT_TRUE(s.converged) << s.BriefReport();
    EXPECT_LE(s.final_residual, 1e-6);
    iters.push_back(s.iterations);
  }
  EXPECT_LE(*std::max_element(iters.begin(), iters.end()) -
                *std::min_element(iters.begin(), iters.end()), 2);
  EXPECT_LE(iters.back(), 12);
}

TEST(Multigrid, FlatAndOddGridsConverge) {
  for (GridShape s : {GridShape{128, 128, 10}, GridShape{30, 17, 12}, GridShape{2, 40, 3},
                      GridShape{50, 3, 2}}) {
    std::vector<double> x;
    const SolveSummary sum = SolveHetero<double>(s, &x);
    EXPECT_TRUE(sum.converged) << s.ToString() << ": " << sum.BriefReport();
    EXPECT_LE(sum.iterations, 15) << s.ToString();
  }
}

// The V-cycle is symmetric positive definite (what CG needs), which holds only if every
// half-row of the split-row smoother and residual uses the right couplings at both ends of odd
// and even rows: <M r1, r2> = <r1, M r2> to rounding, and <M r, r> > 0.
TEST(Multigrid, VCycleIsSymmetricOnOddAndEvenRows) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> U(-1, 1);
  for (GridShape s : {GridShape{31, 20, 9}, GridShape{30, 17, 12}, GridShape{2, 9, 5},
                      GridShape{3, 6, 7}, GridShape{44, 21, 30}}) {
    for (ZCoarsening z : {ZCoarsening::kWithXY, ZCoarsening::kLast}) {
      MultigridOptions o;
      o.mixed_precision = false;
      o.coarsest_nodes = 40;
      o.z_coarsening = z;
      MultigridSolver<double> mg(s, 0.1, o);
      std::vector<double> K(s.size()), M(s.size());
      for (auto& v : K) v = 0.2 + 0.15 * U(rng);
      for (auto& v : M) v = 0.02 + 0.015 * U(rng);
      mg.SetCoefficients(K.data(), M.data(), 2.6);
      std::vector<double> r1(s.size()), r2(s.size()), z1(s.size()), z2(s.size());
      for (auto& v : r1) v = U(rng);
      for (auto& v : r2) v = U(rng);
      mg.Precondition(r1.data(), z1.data());
      mg.Precondition(r2.data(), z2.data());
      double z1r2 = 0, r1z2 = 0, z1r1 = 0;
      for (int64_t p = 0; p < s.size(); ++p) {
        z1r2 += z1[p] * r2[p];
        r1z2 += r1[p] * z2[p];
        z1r1 += z1[p] * r1[p];
      }
      EXPECT_GT(z1r1, 0) << s.ToString();
      EXPECT_NEAR(z1r2, r1z2, 1e-11 * z1r1)
          << s.ToString() << " " << (z == ZCoarsening::kLast ? "x-y" : "full") << " coarsening, "
          << mg.num_levels() << " levels";
    }
  }
}

// A grid at or below coarsest_nodes is one level, and the V-cycle is the exact solve (the
// sparse LDL^T factor applied in T): A (M r) = r to T's rounding.
template <typename T>
void ExpectCoarsestSolveIsExact(double tol) {
  const GridShape s{9, 7, 5};
  MultigridOptions o;
  o.mixed_precision = false;
  MultigridSolver<T> mg(s, 0.1, o);
  ASSERT_EQ(mg.num_levels(), 1);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> U(-1, 1);
  std::vector<T> K(s.size()), M(s.size()), r(s.size()), z(s.size()), Az(s.size());
  for (auto& v : K) v = T(0.2 + 0.15 * U(rng));
  for (auto& v : M) v = T(0.02 + 0.015 * U(rng));
  for (auto& v : r) v = T(U(rng));
  mg.SetCoefficients(K.data(), M.data(), 2.6);
  mg.Precondition(r.data(), z.data());
  mg.Apply(z.data(), Az.data());
  double err = 0, norm = 0;
  for (int64_t p = 0; p < s.size(); ++p) {
    err += std::pow(double(Az[p]) - double(r[p]), 2);
    norm += std::pow(double(r[p]), 2);
  }
  EXPECT_LE(std::sqrt(err / norm), tol);
}

TEST(Multigrid, CoarsestSolveIsExact) {
  ExpectCoarsestSolveIsExact<double>(1e-12);
  ExpectCoarsestSolveIsExact<float>(1e-4);
}

TEST(Multigrid, FloatAgreesWithDouble) {
  const GridShape s{33, 25, 17};
  std::vector<double> xd;
  std::vector<float> xf;
  SolveHetero<double>(s, &xd);
  const SolveSummary sf = SolveHetero<float>(s, &xf);
  EXPECT_LE(sf.final_residual, 5e-6) << sf.BriefReport();
  double num = 0, den = 0;
  for (int64_t p = 0; p < s.size(); ++p) {
    num += (xd[p] - xf[p]) * (xd[p] - xf[p]);
    den += xd[p] * xd[p];
  }
  EXPECT_LT(std::sqrt(num / den), 1e-5);
}

TEST(Multigrid, WarmStartNeedsFewerIterations) {
  const GridShape s{40, 30, 20};
  std::vector<double> x0, x1, x2;
  SolveHetero<double>(s, &x0);
  const SolveSummary cold = SolveHetero<double>(s, &x1, 0.1, 1.01);
  const SolveSummary warm = SolveHetero<double>(s, &x2, 0.1, 1.01, &x0);
  EXPECT_TRUE(warm.converged);
  EXPECT_LT(warm.initial_residual, 0.05);
  EXPECT_LT(warm.iterations, cold.iterations);
}

// The full-multigrid start (MultigridOptions::full_multigrid_start) leaves CG a much smaller
// first residual, saves iterations, and does not change the solution.
TEST(Multigrid, FullMultigridStartSavesIterationsAndKeepsTheSolution) {
  for (GridShape s : {GridShape{33, 33, 33}, GridShape{40, 24, 12}, GridShape{30, 17, 12}}) {
    for (ZCoarsening z : {ZCoarsening::kWithXY, ZCoarsening::kLast}) {
      SCOPED_TRACE(s.ToString() + (z == ZCoarsening::kLast ? " xy" : " full"));
      MultigridOptions with, without;
      with.z_coarsening = without.z_coarsening = z;
      without.full_multigrid_start = false;
      std::vector<double> x_with, x_without;
      const SolveSummary a = SolveHetero<double>(s, &x_with, 0.1, 1.0, nullptr, with);
      const SolveSummary b = SolveHetero<double>(s, &x_without, 0.1, 1.0, nullptr, without);
      ASSERT_TRUE(a.converged && b.converged) << a.BriefReport() << " / " << b.BriefReport();
      EXPECT_LE(a.final_residual, 1e-6);
      EXPECT_LE(a.iterations + 1, b.iterations);
      ASSERT_FALSE(a.history.empty());
      EXPECT_LT(a.history[0], 0.1 * b.history[0]);
      // Both solved to 1e-12: the same solution.
      with.tolerance = without.tolerance = 1e-12;
      SolveHetero<double>(s, &x_with, 0.1, 1.0, nullptr, with);
      SolveHetero<double>(s, &x_without, 0.1, 1.0, nullptr, without);
      double num = 0, den = 0;
      for (int64_t p = 0; p < s.size(); ++p) {
        num += (x_with[p] - x_without[p]) * (x_with[p] - x_without[p]);
        den += x_without[p] * x_without[p];
      }
      EXPECT_LT(std::sqrt(num / den), 1e-10);
    }
  }
  // One level (the coarsest is the finest): the pass is the exact solve.
  std::vector<double> x;
  const SolveSummary one = SolveHetero<double>({9, 8, 7}, &x);
  EXPECT_TRUE(one.converged) << one.BriefReport();
  EXPECT_LE(one.iterations, 1);
}

// Every level's intervals along every axis stay within ~[0.6, 1.6] of its first (regular) one,
// whatever the node counts: the irregular end does not grow from level to level.
TEST(MultigridHierarchy, IrregularEndsStayBounded) {
  for (int64_t n : {64, 100, 130, 256, 37, 53, 6, 4}) {
    for (ZCoarsening z : {ZCoarsening::kLast, ZCoarsening::kWithXY}) {
      const auto levels = BuildMultigridHierarchy({n, n, 5}, 0.5, 8, z);
      ASSERT_GE(levels.size(), 2u);
      for (const MultigridLevel& L : levels)
        for (int a = 0; a < 2; ++a) {
          const std::vector<double>& c = L.grid.coord[a];
          if (c.size() < 3) continue;
          for (size_t i = 1; i + 1 < c.size(); ++i) {
            const double ratio = (c[i + 1] - c[i]) / (c[1] - c[0]);
            EXPECT_GE(ratio, 0.6) << "n " << n << " level of " << c.size() << " nodes";
            EXPECT_LE(ratio, 1.62) << "n " << n << " level of " << c.size() << " nodes";
          }
        }
    }
  }
}

// x-y semi-coarsening keeps z until x and y are exhausted; full coarsening coarsens a cube's z
// along with x and y.
TEST(MultigridHierarchy, SemiCoarseningKeepsZ) {
  const auto semi = BuildMultigridHierarchy({33, 33, 33}, 1.0, 1500, ZCoarsening::kLast);
  ASSERT_GE(semi.size(), 3u);
  EXPECT_EQ(semi[1].grid.shape.nz, 33);
  EXPECT_EQ(semi[1].grid.shape.nx, 17);
  const auto full = BuildMultigridHierarchy({33, 33, 33}, 1.0, 1500, ZCoarsening::kWithXY);
  EXPECT_EQ(full[1].grid.shape.nz, 17);
}

// The cpu smoother's split-row transfers along x equal the general separable ones (row by row,
// natural layout) for every fine count, both choices of the irregular end included.
TEST(MultigridHierarchy, SplitTransfersMatchTheGeneralOnes) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  int alone = 0;  // transfers whose last coarse interval is the last fine one
  for (int64_t n = 3; n <= 300; ++n) {
    for (const MultigridLevel& L :
         BuildMultigridHierarchy({n, 3, 2}, 1.0, 1, ZCoarsening::kLast)) {
      const AxisTransfer& t = L.to_coarse[0];
      if (!t.coarsened) continue;
      const int64_t nf = t.n_fine;
      alone += nf % 2 == 0 && t.n_coarse == nf / 2 + 1;
      const SplitTransferX<double> tx(t);
      std::vector<double> fine(nf), split(nf + 1, 0.0), coarse(t.n_coarse + 1, 0.0);
      for (double& v : fine) v = u(rng);
      for (int64_t c = 0; c < t.n_coarse; ++c) coarse[c] = u(rng);
      SplitRow(nf, fine.data(), split.data());
      std::vector<double> got(t.n_coarse), want(t.n_coarse);
      tx.Restrict(split.data(), got.data());
      RestrictAxis(t, fine.data(), want.data(), 1, 1);
      for (int64_t c = 0; c < t.n_coarse; ++c) EXPECT_NEAR(got[c], want[c], 1e-12) << nf << " " << c;
      std::vector<double> pf(fine), ps(split), merged(nf);
      ProlongAxis(t, coarse.data(), pf.data(), 1, 1, true);
      tx.ProlongAdd(coarse.data(), ps.data());
      MergeRow(nf, ps.data(), merged.data());
      for (int64_t f = 0; f < nf; ++f) EXPECT_NEAR(merged[f], pf[f], 1e-12) << nf << " " << f;
    }
  }
  EXPECT_GT(alone, 10);
}

// The cycle each backend fills in, and settings the caller made are kept.
TEST(Multigrid, CycleDefaultsPerBackendAndGridSize) {
  const MultigridOptions unset;
  const MultigridOptions small = unset.WithCycleDefaults(false, 64 * 48 * 16);
  EXPECT_EQ(small.pre_smoothing, 2);
  EXPECT_EQ(*small.z_coarsening, ZCoarsening::kWithXY);
  const MultigridOptions large = unset.WithCycleDefaults(false, 130 * 53 * 37);
  EXPECT_EQ(large.pre_smoothing, 1);
  EXPECT_EQ(large.post_smoothing, 1);
  EXPECT_EQ(large.coarse_smoothing, 2);
  EXPECT_EQ(*large.z_coarsening, ZCoarsening::kLast);
  const MultigridOptions gl = unset.WithCycleDefaults(true, 130 * 53 * 37);
  EXPECT_EQ(gl.pre_smoothing, 2);
  EXPECT_EQ(*gl.z_coarsening, ZCoarsening::kWithXY);
  MultigridOptions set;
  set.pre_smoothing = set.post_smoothing = 3;
  set.z_coarsening = ZCoarsening::kLast;
  const MultigridOptions kept = set.WithCycleDefaults(true, 100);
  EXPECT_EQ(kept.pre_smoothing, 3);
  EXPECT_EQ(*kept.z_coarsening, ZCoarsening::kLast);
  MultigridOptions xy;  // x-y coarsening asked for on a small grid: its V(1,1) finest level
  xy.z_coarsening = ZCoarsening::kLast;
  EXPECT_EQ(xy.WithCycleDefaults(false, 100).pre_smoothing, 1);
}

TEST(Multigrid, OptionsValidationNamesTheConstraint) {
  MultigridOptions o;
  EXPECT_EQ(o.Validate(), "");
  o.tolerance = 0;
  EXPECT_NE(o.Validate().find("tolerance"), std::string::npos);
  o = {};
  o.pre_smoothing = 3;
  EXPECT_NE(o.Validate().find("symmetric"), std::string::npos);
  o = {};
  o.full_multigrid_sweeps = -1;
  EXPECT_NE(o.Validate().find("full_multigrid_sweeps"), std::string::npos);
}

}  // namespace
}  // namespace translume
