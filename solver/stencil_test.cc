// SPDX-License-Identifier: MIT
#include "solver/stencil.h"

#include <gtest/gtest.h>

#include <Eigen/Sparse>
#include <Eigen/SparseCholesky>
#include <random>

namespace translume {
namespace {

// SPEC section 3 written out independently of the stencil code: enumerate every node's box,
// its faces shared with neighbours and its faces on the boundary.
Eigen::SparseMatrix<double> ReferenceMatrix(const GridShape& s, double h, const std::vector<double>& kappa,
                                            const std::vector<double>& mu, double C) {
  std::vector<Eigen::Triplet<double>> t;
  auto extent = [&](int64_t i, int64_t n) { return (i == 0 || i == n - 1) ? h / 2 : h; };
  for (int64_t k = 0; k < s.nz; ++k)
    for (int64_t j = 0; j < s.ny; ++j)
      for (int64_t i = 0; i < s.nx; ++i) {
        const int64_t p = s.index(i, j, k);
        const double ex = extent(i, s.nx), ey = extent(j, s.ny), ez = extent(k, s.nz);
        const double area[3] = {ey * ez, ex * ez, ex * ey};
        const int64_t idx[3] = {i, j, k};
        double diag = ex * ey * ez * mu[p];
        for (int a = 0; a < 3; ++a) {
          for (int dir : {-1, 1}) {
            int64_t q3[3] = {i, j, k};
            q3[a] += dir;
            if (q3[a] < 0 || q3[a] >= s.n(a)) {
              diag += area[a] / (2 * C);  // Robin term on a boundary box face
              continue;
            }
            const int64_t q = s.index(q3[0], q3[1], q3[2]);
            const double c = area[a] * (kappa[p] + kappa[q]) / 2 / h;
            diag += c;
            t.emplace_back(p, q, -c);
          }
          (void)idx;
        }
        t.emplace_back(p, p, diag);
      }
  Eigen::SparseMatrix<double> M(s.size(), s.size());
  M.setFromTriplets(t.begin(), t.end());
  return M;
}

TEST(Stencil, MatchesIndependentAssemblyAndIsSpd) {
  const GridShape s{7, 5, 6};
  const double h = 0.3, C = 2.6021;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> U(0.05, 0.5), V(0.001, 0.1), X(-1, 1);
  std::vector<double> kappa(s.size()), mu(s.size()), x(s.size()), y(s.size()), z(s.size());
  for (int64_t p = 0; p < s.size(); ++p) {
    kappa[p] = U(rng);
    mu[p] = V(rng);
    x[p] = X(rng);
    z[p] = X(rng);
  }
  Stencil<double> A;
  AssembleStencil(TensorGrid::Uniform(s, h), kappa.data(), mu.data(), C, &A);
  const Eigen::SparseMatrix<double> M = ReferenceMatrix(s, h, kappa, mu, C);
  ApplyStencil(A, x.data(), y.data());
  const Eigen::VectorXd ref = M * Eigen::Map<Eigen::VectorXd>(x.data(), s.size());
  const Eigen::VectorXd got = Eigen::Map<Eigen::VectorXd>(y.data(), s.size());
  EXPECT_LT((ref - got).norm(), 1e-13 * ref.norm());

  // Symmetric: the reference matrix equals its transpose, and x^T A z = z^T A x via the stencil.
  EXPECT_LT((Eigen::SparseMatrix<double>(M.transpose()) - M).norm(), 1e-14 * M.norm());
  std::vector<double> az(s.size());
  ApplyStencil(A, z.data(), az.data());
  double xaz = 0, zax = 0, xax = 0;
  for (int64_t p = 0; p < s.size(); ++p) {
    xaz += x[p] * az[p];
    zax += z[p] * y[p];
    xax += x[p] * y[p];
  }
  EXPECT_NEAR(xaz, zax, 1e-12 * std::abs(xaz));
  EXPECT_GT(xax, 0);
  // Positive definite: Cholesky succeeds.
  Eigen::SimplicialLLT<Eigen::SparseMatrix<double>> llt(M);
  EXPECT_EQ(llt.info(), Eigen::Success);
}

TEST(Stencil, ResidualIsBMinusAx) {
  const GridShape s{4, 3, 5};
  std::vector<double> kappa(s.size(), 0.2), mu(s.size(), 0.03), x(s.size()), b(s.size()),
      ax(s.size()), r(s.size());
  for (int64_t p = 0; p < s.size(); ++p) {
    x[p] = std::sin(0.3 * p);
    b[p] = std::cos(0.7 * p);
  }
  Stencil<double> A;
  AssembleStencil(TensorGrid::Uniform(s, 0.5), kappa.data(), mu.data(), 2.0, &A);
  ApplyStencil(A, x.data(), ax.data());
  StencilResidual(A, b.data(), x.data(), r.data());
  for (int64_t p = 0; p < s.size(); ++p) EXPECT_NEAR(r[p], b[p] - ax[p], 1e-14);
}

TEST(Stencil, LitFaceSourceIntegratesLightOverTheFace) {
  const GridShape s{9, 7, 4};
  const double h = 0.25, C = 2.5;
  std::vector<float> q(s.face_size(), 1.0f);
  std::vector<double> b(s.size());
  LitFaceSource(TensorGrid::Uniform(s, h), s.nz - 1, C, q.data(), b.data());
  double sum = 0;
  for (double v : b) sum += v;
  // Face area (nx-1)h x (ny-1)h, times q / (2C).
  EXPECT_NEAR(sum, (8 * h) * (6 * h) / (2 * C), 1e-12);
  for (int64_t p = 0; p < s.size() - s.face_size(); ++p) EXPECT_EQ(b[p], 0.0);
  // Node by node, with q varying along both axes and on the front face: b_p = A_p^z q_p / (2C),
  // A_p^z = h^2 inside the face, h^2 / 2 on its edges and h^2 / 4 at its corners.
  for (int64_t f = 0; f < s.face_size(); ++f) q[f] = float(1 + f % s.nx + 10 * (f / s.nx));
  std::fill(b.begin(), b.end(), 0.0);
  LitFaceSource(TensorGrid::Uniform(s, h), 0, C, q.data(), b.data());
  for (int64_t j = 0; j < s.ny; ++j)
    for (int64_t i = 0; i < s.nx; ++i) {
      const double area = h * h * (i == 0 || i == s.nx - 1 ? 0.5 : 1.0) * (j == 0 || j == s.ny - 1 ? 0.5 : 1.0);
      EXPECT_NEAR(b[s.index(i, j, 0)], area * (1 + i + 10 * j) / (2 * C), 1e-12) << i << "," << j;
    }
  for (int64_t p = s.face_size(); p < s.size(); ++p) EXPECT_EQ(b[p], 0.0);
}

}  // namespace
}  // namespace translume
