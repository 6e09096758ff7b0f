// SPDX-License-Identifier: MIT
#include "render/laplacian.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

#include "solver/status.h"

namespace translume {

bool LaplacianWeights(const std::array<Vec3, 6>& offsets, std::array<double, 6>* weights,
                      bool local_frame) {
  Eigen::Matrix3d frame = Eigen::Matrix3d::Identity();  // rows: x', y', z'
  if (local_frame) {
    const Vec3 ex = offsets[1] - offsets[0], ey = offsets[3] - offsets[2];
    if (ex.norm() == 0 || ey.norm() == 0) return false;
    const Vec3 x = ex.normalized();
    Vec3 y = ey - ey.dot(x) * x;
    if (y.norm() < 1e-12 * ey.norm()) return false;
    y.normalize();
    frame.row(0) = x;
    frame.row(1) = y;
    frame.row(2) = x.cross(y);
  }
  Eigen::Matrix<double, 6, 6> M;
  for (int j = 0; j < 6; ++j) {
    const Vec3 d = frame * offsets[j];
    for (int a = 0; a < 3; ++a) {
      M(j, 2 * a) = d[a];
      M(j, 2 * a + 1) = d[a] * d[a] / 2;
    }
  }
  Eigen::FullPivLU<Eigen::Matrix<double, 6, 6>> lu(M);
  if (!lu.isInvertible()) return false;
  const Eigen::Matrix<double, 6, 6> W = lu.inverse();
  std::array<double, 6> w;
  for (int j = 0; j < 6; ++j) {
    w[j] = W(1, j) + W(3, j) + W(5, j);
    if (!std::isfinite(w[j]) || w[j] <= 0) return false;
  }
  *weights = w;
  return true;
}

std::array<double, 6> AxisLaplacianWeights(const std::array<Vec3, 6>& offsets, double min_length) {
  std::array<double, 6> w;
  for (int j = 0; j < 6; ++j) {
    const double l = std::max(offsets[j].norm(), min_length), lo = std::max(offsets[j ^ 1].norm(), min_length);
    w[j] = 2 / (l * (l + lo));
  }
  return w;
}

bool FirstOrderAxisWeights(const std::array<Vec3, 6>& offsets, const std::array<double, 6>& axis,
                           std::array<double, 6>* weights) {
  // min sum_j ((w_j - a_j) / a_j)^2 subject to B w = c: w = a + D B^T (B D B^T)^-1 (c - B a),
  // D = diag(a_j^2).
  Eigen::Matrix<double, 4, 6> B;
  Eigen::Matrix<double, 6, 1> a, D;
  for (int j = 0; j < 6; ++j) {
    B.block<3, 1>(0, j) = offsets[j];
    B(3, j) = offsets[j].squaredNorm();
    a[j] = axis[j];
    D[j] = axis[j] * axis[j];
  }
  const Eigen::Vector4d c(0, 0, 0, 6);
  const Eigen::FullPivLU<Eigen::Matrix4d> lu(B * D.asDiagonal() * B.transpose());
  if (!lu.isInvertible()) return false;
  const Eigen::Matrix<double, 6, 1> w = a + D.asDiagonal() * B.transpose() * lu.solve(c - B * a);
  for (int j = 0; j < 6; ++j)
    if (!std::isfinite(w[j]) || w[j] < 0.05 * axis[j]) return false;
  for (int j = 0; j < 6; ++j) (*weights)[j] = w[j];
  return true;
}

namespace {

// TaylorResidual's ten weighted conditions as A w = b (w scaled by scale^2).
using TaylorMatrix = Eigen::Matrix<double, 10, Eigen::Dynamic, 0, 10, 32>;
void TaylorSystem(const std::vector<Vec3>& offsets, double scale, double consistency_weight, TaylorMatrix* A,
                  Eigen::Matrix<double, 10, 1>* b) {
  A->resize(10, Eigen::Index(offsets.size()));
  for (size_t j = 0; j < offsets.size(); ++j) {
    const Vec3 d = offsets[j] / scale;
    A->block<3, 1>(0, j) = consistency_weight * d;
    (*A)(3, j) = d.x() * d.x(), (*A)(4, j) = d.y() * d.y(), (*A)(5, j) = d.z() * d.z();
    (*A)(6, j) = d.x() * d.y(), (*A)(7, j) = d.x() * d.z(), (*A)(8, j) = d.y() * d.z();
    (*A)(9, j) = consistency_weight * d.squaredNorm();
  }
  *b << 0, 0, 0, 2, 2, 2, 0, 0, 0, 6 * consistency_weight;
}

}  // namespace

double TaylorResidual(const std::vector<Vec3>& offsets, const std::vector<double>& weights, double scale,
                      double consistency_weight) {
  TL_CHECK(weights.size() == offsets.size() && offsets.size() <= 32);
  TaylorMatrix A;
  Eigen::Matrix<double, 10, 1> b;
  TaylorSystem(offsets, scale, consistency_weight, &A, &b);
  Eigen::Matrix<double, Eigen::Dynamic, 1, 0, 32, 1> w(Eigen::Index(weights.size()));  // no heap: per node
  for (size_t j = 0; j < weights.size(); ++j) w[j] = weights[j] * scale * scale;
  return (A * w - b).norm();
}

double StencilLaplacianWeights(const std::vector<Vec3>& offsets, double scale, std::vector<double>* weights,
                               double consistency_weight, const std::vector<double>& toward, double lambda) {
  const int n = int(offsets.size());
  TL_CHECK(n <= 32);
  TaylorMatrix T;
  Eigen::Matrix<double, 10, 1> t;
  TaylorSystem(offsets, scale, consistency_weight, &T, &t);
  const bool tikhonov = lambda > 0 && !toward.empty();
  TL_CHECK(!tikhonov || int(toward.size()) == n);
  // The normal equations G x = h of |T x - t|^2 + lambda^2 |x - toward scale^2|^2.
  using Square = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, 32, 32>;
  using Vector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, 32, 1>;
  Square G = T.transpose() * T;
  Vector h = T.transpose() * t;
  if (tikhonov)
    for (int j = 0; j < n; ++j) G(j, j) += lambda * lambda, h[j] += lambda * lambda * toward[j] * scale * scale;
  Vector x = Vector::Zero(n);
  std::array<char, 32> passive{}, stuck{};
  std::array<int, 32> set;
  // Lawson & Hanson: move the variable with the largest gradient h - G x of -(the objective) / 2
  // into the passive set, solve the normal equations there, and step back towards the last
  // feasible x where that solution has a non-positive entry (dropping what reaches 0). A
  // variable that is dropped again at once (its solution not positive: rounding on a
  // near-singular system) is not tried again until x changes, so the loop cannot cycle on it.
  for (int outer = 0; outer < 3 * n; ++outer) {
    const Vector g = h - G * x;
    int best_j = -1;
    double best = 1e-10;
    for (int j = 0; j < n; ++j)
      if (!passive[j] && !stuck[j] && g[j] > best) best = g[j], best_j = j;
    if (best_j < 0) break;
    passive[best_j] = 1;
    const Vector before = x;
    for (int inner = 0; inner < 3 * n; ++inner) {
      int k = 0;
      for (int j = 0; j < n; ++j)
        if (passive[j]) set[k++] = j;
      Square Gp(k, k);
      Vector hp(k);
      for (int a = 0; a < k; ++a) {
        hp[a] = h[set[a]];
        for (int b = 0; b < k; ++b) Gp(a, b) = G(set[a], set[b]);
      }
      const Vector zp = Gp.ldlt().solve(hp);
      double alpha = 1;
      for (int a = 0; a < k; ++a)
        if (zp[a] <= 0) alpha = std::min(alpha, x[set[a]] / (x[set[a]] - zp[a]));
      for (int a = 0; a < k; ++a) x[set[a]] += alpha * (zp[a] - x[set[a]]);
      if (alpha == 1) break;
      for (int a = 0; a < k; ++a)
        if (x[set[a]] <= 1e-14) passive[set[a]] = 0, x[set[a]] = 0;
    }
    if (x == before) stuck[best_j] = 1;
    else stuck.fill(0);
  }
  weights->resize(n);
  for (int j = 0; j < n; ++j) (*weights)[j] = x[j] / (scale * scale);
  return (T * x - t).norm();
}

}  // namespace translume
