// SPDX-License-Identifier: MIT
#include "solver/face_measurement.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace translume {
namespace {

// c0 + c1 x + c2 y + c3 x^2 + c4 x y + c5 y^2: degree <= 2 in x and in y.
struct Quadratic {
  double c[6];
  double operator()(double x, double y) const {
    return c[0] + c[1] * x + c[2] * y + c[3] * x * x + c[4] * x * y + c[5] * y * y;
  }
  // The exact mean over [x0, x1] x [y0, y1].
  double Mean(double x0, double x1, double y0, double y1) const {
    auto m = [](double a, double b, int k) { return (std::pow(b, k + 1) - std::pow(a, k + 1)) / ((k + 1) * (b - a)); };
    return c[0] + c[1] * m(x0, x1, 1) + c[2] * m(y0, y1, 1) + c[3] * m(x0, x1, 2) +
           c[4] * m(x0, x1, 1) * m(y0, y1, 1) + c[5] * m(y0, y1, 2);
  }
};

// Node i's face box on an axis of n nodes at unit spacing: [i - 1/2, i + 1/2], halved at the ends.
std::pair<double, double> Box(int64_t i, int64_t n) {
  return {std::max(0.0, i - 0.5), std::min(double(n - 1), i + 0.5)};
}

TEST(FaceMeasurement, BoxMeansAreExactForQuadratics) {
  const Quadratic q{{0.7, -0.3, 0.2, 0.05, -0.04, 0.03}};
  for (auto [nx, ny] : {std::pair<int64_t, int64_t>{5, 4}, {3, 7}, {9, 3}}) {
    std::vector<double> L(nx * ny), out(nx * ny);
    for (int64_t j = 0; j < ny; ++j)
      for (int64_t i = 0; i < nx; ++i) L[i + nx * j] = q(double(i), double(j));
    MeasureFace(nx, ny, L.data(), out.data());
    for (int64_t j = 0; j < ny; ++j)
      for (int64_t i = 0; i < nx; ++i) {
        const auto [x0, x1] = Box(i, nx);
        const auto [y0, y1] = Box(j, ny);
        EXPECT_NEAR(out[i + nx * j], q.Mean(x0, x1, y0, y1), 1e-12) << nx << "x" << ny << " node " << i << "," << j;
      }
  }
  // An axis of two nodes: exact for a field linear along it.
  const Quadratic lin_x{{0.7, -0.3, 0.2, 0.0, -0.04, 0.03}};
  std::vector<double> L(2 * 4), out(2 * 4);
  for (int64_t j = 0; j < 4; ++j)
    for (int64_t i = 0; i < 2; ++i) L[i + 2 * j] = lin_x(double(i), double(j));
  MeasureFace(2, 4, L.data(), out.data());
  for (int64_t j = 0; j < 4; ++j)
    for (int64_t i = 0; i < 2; ++i) {
      const auto [x0, x1] = Box(i, 2);
      const auto [y0, y1] = Box(j, 4);
      EXPECT_NEAR(out[i + 2 * j], lin_x.Mean(x0, x1, y0, y1), 1e-12);
    }
}

// The weights by hand: a unit value at node (2, 1) of a 5 x 3 face, seen by its neighbours.
TEST(FaceMeasurement, WeightsByHand) {
  std::vector<double> L(5 * 3, 0.0), out(5 * 3);
  L[2 + 5 * 1] = 1;
  MeasureFace(5, 3, L.data(), out.data());
  const double inside = 22.0 / 24, next = 1.0 / 24;                      // (1, 22, 1) / 24
  const double border_next = 5.0 / 12, border_second = -1.0 / 12;      // (8, 5, -1) / 12
  EXPECT_NEAR(out[2 + 5 * 1], inside * inside, 1e-15);
  EXPECT_NEAR(out[1 + 5 * 1], next * inside, 1e-15);
  EXPECT_NEAR(out[0 + 5 * 1], border_second * inside, 1e-15);  // x border node 0: nodes 0, 1, 2
  EXPECT_NEAR(out[2 + 5 * 0], inside * border_next, 1e-15);    // y border rows
  EXPECT_NEAR(out[2 + 5 * 2], inside * border_next, 1e-15);
  EXPECT_NEAR(out[0 + 5 * 0], border_second * border_next, 1e-15);
  EXPECT_NEAR(out[4 + 5 * 2], border_second * border_next, 1e-15);
}

TEST(FaceMeasurement, TransposeIsTheAdjoint) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (auto [nx, ny] : {std::pair<int64_t, int64_t>{6, 5}, {2, 2}, {2, 5}, {7, 3}}) {
    std::vector<double> a(nx * ny), b(nx * ny), Ma(nx * ny), Mtb(nx * ny);
    for (auto& v : a) v = u(rng);
    for (auto& v : b) v = u(rng);
    MeasureFace(nx, ny, a.data(), Ma.data());
    MeasureFaceTranspose(nx, ny, b.data(), Mtb.data());
    double lhs = 0, rhs = 0;
    for (int64_t p = 0; p < nx * ny; ++p) {
      lhs += Ma[p] * b[p];
      rhs += a[p] * Mtb[p];
    }
    EXPECT_NEAR(lhs, rhs, 1e-13) << nx << "x" << ny;
  }
}

TEST(FaceMeasurement, FineBoxMeansAreExactForQuadratics) {
  const Quadratic q{{0.7, -0.3, 0.2, 0.05, -0.04, 0.03}};
  const GridShape coarse{5, 4, 2};
  for (int K : {1, 2, 4, 6, 8}) {
    const int64_t fnx = (coarse.nx - 1) * K + 1, fny = (coarse.ny - 1) * K + 1;
    std::vector<float> fine(fnx * fny);
    for (int64_t j = 0; j < fny; ++j)
      for (int64_t i = 0; i < fnx; ++i) fine[i + fnx * j] = float(q(double(i) / K, double(j) / K));
    const std::vector<float> out = BoxMeansOfFineFace(coarse, K, fine);
    ASSERT_EQ(int64_t(out.size()), coarse.face_size());
    for (int64_t j = 0; j < coarse.ny; ++j)
      for (int64_t i = 0; i < coarse.nx; ++i) {
        const auto [x0, x1] = Box(i, coarse.nx);
        const auto [y0, y1] = Box(j, coarse.ny);
        EXPECT_NEAR(out[i + coarse.nx * j], q.Mean(x0, x1, y0, y1), 2e-6) << "K " << K << " node " << i << "," << j;
      }
  }
}

}  // namespace
}  // namespace translume
