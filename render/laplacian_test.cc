// SPDX-License-Identifier: MIT
#include "render/laplacian.h"

#include <Eigen/Geometry>
#include <gtest/gtest.h>
#include <cstdio>
#include <random>
#include <vector>

namespace translume {
namespace {

std::array<Vec3, 6> AxisStencil(const std::array<double, 6>& l) {
  std::array<Vec3, 6> off;
  for (int j = 0; j < 6; ++j) {
    off[j] = Vec3::Zero();
    off[j][j / 2] = j % 2 ? l[j] : -l[j];
  }
  return off;
}

TEST(LaplacianWeights, UndistortedGridGivesSevenPointStencil) {
  const double h[3] = {0.5, 0.25, 1.5};
  std::array<double, 6> w;
  ASSERT_TRUE(LaplacianWeights(AxisStencil({h[0], h[0], h[1], h[1], h[2], h[2]}), &w));
  for (int j = 0; j < 6; ++j) EXPECT_NEAR(w[j], 1 / (h[j / 2] * h[j / 2]), 1e-9 * w[j]) << j;
}

TEST(LaplacianWeights, ExactForQuadraticsOnAxisDistortedStencil) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> len(0.3, 1.7), coef(-2, 2);
  for (int trial = 0; trial < 20; ++trial) {
    std::array<double, 6> l;
    for (double& x : l) x = len(rng);
    const auto off = AxisStencil(l);
    std::array<double, 6> w;
    ASSERT_TRUE(LaplacianWeights(off, &w));
    // f = c0 + b.x + sum_a c_a x_a^2 (the six monomials of Equation (10) without mixed terms).
    const Vec3 b(coef(rng), coef(rng), coef(rng)), c(coef(rng), coef(rng), coef(rng));
    auto f = [&](const Vec3& x) { return 0.3 + b.dot(x) + c.dot(x.cwiseProduct(x)); };
    double lap = 0;
    for (int j = 0; j < 6; ++j) lap += w[j] * (f(off[j]) - f(Vec3::Zero()));
    EXPECT_NEAR(lap, 2 * c.sum(), 1e-9) << trial;
    // Same as the per-axis three-point formula on this stencil.
    const auto axis = AxisLaplacianWeights(off);
    for (int j = 0; j < 6; ++j) EXPECT_NEAR(w[j], axis[j], 1e-9 * axis[j]);
  }
}

TEST(LaplacianWeights, LocalFrameExactForRotatedDistortedStencil) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> len(0.5, 1.5), coef(-2, 2), ang(-3, 3);
  for (int trial = 0; trial < 20; ++trial) {
    std::array<double, 6> l;
    for (double& x : l) x = len(rng);
    const Eigen::Matrix3d R =
        (Eigen::AngleAxisd(ang(rng), Vec3::UnitZ()) * Eigen::AngleAxisd(ang(rng), Vec3::UnitY()) *
         Eigen::AngleAxisd(ang(rng), Vec3::UnitX())).toRotationMatrix();
    auto off = AxisStencil(l);
    for (auto& o : off) o = R * o;
    std::array<double, 6> w;
    ASSERT_TRUE(LaplacianWeights(off, &w));
    // A rotation-invariant quadratic: Laplacian of a + b.x + alpha |x|^2 is 6 alpha.
    const Vec3 b(coef(rng), coef(rng), coef(rng));
    const double alpha = coef(rng);
    auto f = [&](const Vec3& x) { return 1.0 + b.dot(x) + alpha * x.squaredNorm(); };
    double lap = 0;
    for (int j = 0; j < 6; ++j) lap += w[j] * (f(off[j]) - f(Vec3::Zero()));
    EXPECT_NEAR(lap, 6 * alpha, 1e-8) << trial;
  }
}

TEST(LaplacianWeights, SlightlySkewedStencilIsSecondOrderAccurate) {
  // Neighbours perturbed off their axes by 5% of the spacing: the dropped mixed terms make the
  // result approximate; the error on a general quadratic is small and shrinks with the skew.
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  double errs[2];
  for (int s = 0; s < 2; ++s) {
    const double skew = s == 0 ? 0.05 : 0.025;
    std::mt19937 r2(5);
    auto off = AxisStencil({1, 1, 1, 1, 1, 1});
    for (auto& o : off)
      for (int a = 0; a < 3; ++a)
        if (o[a] == 0) o[a] = skew * u(r2);
    std::array<double, 6> w;
    ASSERT_TRUE(LaplacianWeights(off, &w, /*local_frame=*/false));
    auto f = [](const Vec3& x) { return x.x() * x.x() + 2 * x.y() * x.y() + 3 * x.z() * x.z() + x.x() * x.y(); };
    double lap = 0;
    for (int j = 0; j < 6; ++j) lap += w[j] * (f(off[j]) - f(Vec3::Zero()));
    errs[s] = std::abs(lap - 12);
  }
  EXPECT_LT(errs[0], 0.08);
  EXPECT_LT(errs[1], errs[0]);
  (void)rng;
}

TEST(LaplacianWeights, DegenerateStencilIsRejected) {
  auto off = AxisStencil({1, 1, 1, 1, 1, 1});
  off[2] = off[0];  // a y neighbour on the x axis: singular
  off[3] = off[1];
  std::array<double, 6> w;
  EXPECT_FALSE(LaplacianWeights(off, &w));
}

TEST(FirstOrderAxisWeights, KeepsTheAxisWeightsWhereTheyAreConsistent) {
  const auto off = AxisStencil({0.4, 0.9, 0.7, 0.5, 1.2, 0.6});
  const auto axis = AxisLaplacianWeights(off);
  std::array<double, 6> w;
  ASSERT_TRUE(FirstOrderAxisWeights(off, axis, &w));
  for (int j = 0; j < 6; ++j) EXPECT_NEAR(w[j], axis[j], 1e-9 * axis[j]) << j;
}

// Stencils sheared so far that the 6x6 system gives a negative weight (as at the first interior
// nodes along a polycube's edges on a sphere): the weights are exact for every linear function
// and for |x|^2, where the axis weights add a drift (sum_j a_j offsets[j] != 0).
TEST(FirstOrderAxisWeights, ExactForLinearFunctionsAndTheSquaredDistanceWhereThe6x6Fails) {
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> len(0.5, 1.5), shear(-0.6, 0.6), coef(-2, 2);
  int tested = 0;
  for (int trial = 0; trial < 2000 && tested < 20; ++trial) {
    std::array<double, 6> l;
    for (double& x : l) x = len(rng);
    auto off = AxisStencil(l);
    for (auto& o : off)
      for (int a = 0; a < 3; ++a)
        if (o[a] == 0) o[a] = shear(rng) * o.norm();
    std::array<double, 6> w6, w;
    if (LaplacianWeights(off, &w6)) continue;
    const auto axis = AxisLaplacianWeights(off);
    if (!FirstOrderAxisWeights(off, axis, &w)) continue;
    ++tested;
    Vec3 drift_axis = Vec3::Zero(), drift = Vec3::Zero();
    double trace = 0;
    for (int j = 0; j < 6; ++j) {
      EXPECT_GE(w[j], 0.05 * axis[j]);
      drift_axis += axis[j] * off[j];
      drift += w[j] * off[j];
      trace += w[j] * off[j].squaredNorm();
    }
    EXPECT_GT(drift_axis.norm(), 1e-3);
    EXPECT_LT(drift.norm(), 1e-9);
    EXPECT_NEAR(trace, 6, 1e-9);
    const Vec3 b(coef(rng), coef(rng), coef(rng));
    const double alpha = coef(rng);
    auto f = [&](const Vec3& x) { return 0.7 + b.dot(x) + alpha * x.squaredNorm(); };
    double lap = 0;
    for (int j = 0; j < 6; ++j) lap += w[j] * (f(off[j]) - f(Vec3::Zero()));
    EXPECT_NEAR(lap, 6 * alpha, 1e-8) << trial;
  }
  EXPECT_EQ(tested, 20);
}

TEST(FirstOrderAxisWeights, RejectsAStencilWithAllNeighboursOnOneSide) {
  std::array<Vec3, 6> off;
  for (int j = 0; j < 6; ++j) off[j] = Vec3(1.0 + 0.1 * j, 0.2 * (j % 3) - 0.2, 0.3 * (j % 2) - 0.15);
  std::array<double, 6> w;
  EXPECT_FALSE(FirstOrderAxisWeights(off, AxisLaplacianWeights(off), &w));
}

// A sheared cell: the lattice's x, y, z steps mapped by a shear (y picks up 0.4 x, z 0.3 y), so
// the face neighbours' offsets are not orthogonal. Appendix B's six weights cannot give the
// mixed second derivatives there; with the twelve edge-diagonal neighbours, non-negative
// weights meet all nine Taylor conditions, so the Laplacian of every quadratic is exact.
TEST(StencilLaplacianWeights, ShearedCellIsExactForQuadraticsWithTheDiagonals) {
  Eigen::Matrix3d shear;
  shear << 1, 0, 0, 0.4, 1, 0, 0, 0.3, 1;
  const double h = 0.7;
  std::vector<Vec3> face, all;
  for (int j = 0; j < 6; ++j) {
    Vec3 g = Vec3::Zero();
    g[j / 2] = j % 2 ? 1 : -1;
    face.push_back(h * shear * g);
  }
  all = face;
  constexpr int kPairs[3][2] = {{0, 1}, {1, 2}, {0, 2}};
  for (const auto& p : kPairs)
    for (int sa : {1, -1})
      for (int sb : {1, -1}) {
        Vec3 g = Vec3::Zero();
        g[p[0]] = sa, g[p[1]] = sb;
        all.push_back(h * shear * g);
      }
  std::array<Vec3, 6> face6;
  std::copy(face.begin(), face.end(), face6.begin());
  std::array<double, 6> w6;
  ASSERT_TRUE(LaplacianWeights(face6, &w6));
  const double face_residual = TaylorResidual(face, std::vector<double>(w6.begin(), w6.end()), h);
  std::vector<double> w;
  const double residual = StencilLaplacianWeights(all, h, &w);
  std::printf("[laplacian] sheared cell: Taylor residual of the six weights %.3f, of the 18 %.2e\n", face_residual, residual);
  EXPECT_GT(face_residual, 0.3);
  EXPECT_LT(residual, 1e-9);
  EXPECT_NEAR(TaylorResidual(all, w, h), residual, 1e-12);
  ASSERT_EQ(w.size(), 18u);
  for (double x : w) EXPECT_GE(x, 0);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> c(-2, 2);
  for (int trial = 0; trial < 10; ++trial) {
    Eigen::Matrix3d A;
    for (int a = 0; a < 3; ++a)
      for (int b = a; b < 3; ++b) A(a, b) = A(b, a) = c(rng);
    const Vec3 g(c(rng), c(rng), c(rng));
    auto f = [&](const Vec3& x) { return x.dot(A * x) + g.dot(x); };
    double lap = 0, lap6 = 0;
    for (size_t j = 0; j < all.size(); ++j) lap += w[j] * f(all[j]);
    for (int j = 0; j < 6; ++j) lap6 += w6[j] * f(face[j]);
    EXPECT_NEAR(lap, 2 * A.trace(), 1e-9 * (1 + std::abs(A.trace()))) << trial;
    if (trial == 0) std::printf("[laplacian] sheared cell, a quadratic: six weights %.4f, 18 %.4f, exact %.4f\n", lap6, lap, 2 * A.trace());
  }
  // Pulled towards the six weights (as the polygrid builder does) the fit stays nearly exact.
  std::vector<double> toward(w6.begin(), w6.end());
  toward.resize(18, 0.0);
  std::vector<double> pulled;
  EXPECT_LT(StencilLaplacianWeights(all, h, &pulled, 10, toward, 0.03), 0.02);
  for (double x : pulled) EXPECT_GE(x, 0);
}

// On an undistorted (stretched) grid the seven-point weights already meet every condition.
TEST(StencilLaplacianWeights, TaylorResidualOfTheSevenPointStencilIsZero) {
  const double hx = 0.5, hy = 0.25, hz = 1.5;
  std::vector<Vec3> off;
  std::vector<double> w;
  for (int j = 0; j < 6; ++j) {
    Vec3 d = Vec3::Zero();
    const double hj = j / 2 == 0 ? hx : j / 2 == 1 ? hy : hz;
    d[j / 2] = j % 2 ? hj : -hj;
    off.push_back(d);
    w.push_back(1 / (hj * hj));
  }
  EXPECT_LT(TaylorResidual(off, w, 0.7), 1e-12);
}

}  // namespace
}  // namespace translume
