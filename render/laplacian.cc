// SPDX-License-Identifier: MIT
#include "render/laplacian.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

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

}  // namespace translume
