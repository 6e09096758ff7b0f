// SPDX-License-Identifier: MIT
// Shared by render/'s tests.
#pragma once

#include <cmath>
#include <functional>
#include <vector>

#include "render/shape.h"
#include "solver/image.h"  // RelativeL2, which the tests share with the tools

namespace translume {

// The exact boundary radiance phi(R, theta) / (2 pi) of a homogeneous sphere (radius R mm, kappa
// mm, mu 1/mm, C) whose boundary source q depends on cos theta only (a distant light along
// theta = 0). Inside, kappa Laplacian phi = mu phi, so phi = sum_l a_l i_l(r / l0) P_l(cos theta)
// with l0 = sqrt(kappa / mu) and i_l the modified spherical Bessel functions; each mode meets the
// Robin condition phi + 2 C kappa dphi/dr = q at r = R:
//   phi_l(R) = q_l / (1 + 2 C kappa i_l'(x) / (l0 i_l(x))),  x = R / l0,
//   q_l = (2l + 1) / 2 int_-1^1 q(t) P_l(t) dt  (Simpson, 400 steps per mode: its error grows as
//         l^5 and must stay below the deep shadow's radiance; q may have a kink at t = 0, which
//         falls on a panel's end),
//   i_l' / i_l = i_(l-1) / i_l - (l + 1) / x, the ratio from the series of i_l (no underflow).
class LitSphereRadiance {
 public:
  LitSphereRadiance(double kappa, double mu, double R, double C, const std::function<double(double)>& q,
                    int modes = 160) {
    const double l0 = std::sqrt(kappa / mu), x = R / l0;
    const int kSteps = 400 * modes;  // even; over [-1, 1]
    std::vector<double> ql(modes, 0.0), P(modes);
    for (int s = 0; s <= kSteps; ++s) {
      const double t = -1 + 2.0 * s / kSteps, w = (s == 0 || s == kSteps) ? 1 : (s % 2 ? 4 : 2);
      Legendre(t, &P);
      const double qt = q(t);
      for (int l = 0; l < modes; ++l) ql[l] += w * qt * P[l] * 2.0 / (3.0 * kSteps);
    }
    for (int l = 0; l < modes; ++l) {
      // i_l(x) = x^l / (2l + 1)!! S_l(x), S_l = sum_k (x^2 / 2)^k / (k! (2l + 3) ... (2l + 2k + 1)).
      const double ratio = l == 0 ? (std::cosh(x) / x - std::sinh(x) / (x * x)) / (std::sinh(x) / x)
                                  : (2 * l + 1) / x * SeriesSum(l - 1, x) / SeriesSum(l, x) - (l + 1) / x;
      boundary_.push_back((2 * l + 1) / 2.0 * ql[l] / (1 + 2 * C * kappa * ratio / l0) / (2 * M_PI));
    }
  }
  double operator()(double cos_theta) const {
    std::vector<double> P(boundary_.size());
    Legendre(cos_theta, &P);
    double s = 0;
    for (size_t l = 0; l < P.size(); ++l) s += boundary_[l] * P[l];
    return s;
  }

 private:
  static double SeriesSum(int l, double x) {
    double term = 1, sum = 1;
    for (int k = 1; k < 1000 && term > 1e-17 * sum; ++k) {
      term *= 0.5 * x * x / (k * (2 * l + 2 * k + 1));
      sum += term;
    }
    return sum;
  }
  static void Legendre(double t, std::vector<double>* P) {
    (*P)[0] = 1;
    if (P->size() > 1) (*P)[1] = t;
    for (size_t k = 1; k + 1 < P->size(); ++k) (*P)[k + 1] = ((2 * k + 1) * t * (*P)[k] - k * (*P)[k - 1]) / (k + 1);
  }
  std::vector<double> boundary_;  // the radiance's Legendre coefficients at r = R
};

// A 10 mm right-angled tetrahedron (outward faces): sharp edges and corners that a voxel
// polycube cannot follow, so its polygrid has crowded boundary nodes and distorted cells.
inline TriangleMesh TetrahedronMesh() {
  TriangleMesh tet;
  tet.vertices = {Vec3(0, 0, 0), Vec3(10, 0, 0), Vec3(0, 10, 0), Vec3(0, 0, 10)};
  tet.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  return tet;
}

}  // namespace translume
