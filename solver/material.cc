// SPDX-License-Identifier: MIT
#include "solver/material.h"

#include <algorithm>
#include <cmath>
#include <fmt/format.h>

namespace translume {

double ReflectionParameterC(double eta) {
  const double fdr = -1.440 / (eta * eta) + 0.710 / eta + 0.668 + 0.0636 * eta;
  return (1.0 + fdr) / (1.0 - fdr);
}

Material Material::Constant(const GridShape& shape, double spacing_mm,
                            const std::array<float, 3>& kappa, const std::array<float, 3>& mu,
                            double eta) {
  Material m;
  m.shape = shape;
  m.spacing_mm = spacing_mm;
  m.eta = eta;
  m.C = ReflectionParameterC(eta);
  for (int c = 0; c < 3; ++c) {
    m.kappa[c].assign(shape.size(), kappa[c]);
    m.mu[c].assign(shape.size(), mu[c]);
  }
  return m;
}

std::string Material::Validate() const {
  if (shape.nx < 2 || shape.ny < 2 || shape.nz < 2)
    return fmt::format("grid {} has fewer than 2 nodes along an axis", shape.ToString());
  if (const std::string p = SpacingProblem(spacing_mm); !p.empty()) return "spacing " + p;
  if (!(C >= 1) || !std::isfinite(C)) return fmt::format("C = {} is not a finite number >= 1", C);
  if (!(eta > 0) || !std::isfinite(eta)) return fmt::format("eta = {} is not positive", eta);
  const char* names[3] = {"R", "G", "B"};
  for (int c = 0; c < 3; ++c) {
    if (static_cast<int64_t>(kappa[c].size()) != shape.size() ||
        static_cast<int64_t>(mu[c].size()) != shape.size())
      return fmt::format("channel {} does not have {} values", names[c], shape.size());
    for (int64_t p = 0; p < shape.size(); ++p) {
      const float k = kappa[c][p], a = mu[c][p];
      if (!(k > 0) || !std::isfinite(k) || !(a > 0) || !std::isfinite(a)) {
        const int64_t i = p % shape.nx, j = (p / shape.nx) % shape.ny, kk = p / shape.face_size();
        return fmt::format("node ({}, {}, {}) channel {} has kappa = {}, mu = {}: both must be "
                           "finite and > 0", i, j, kk, names[c], k, a);
      }
    }
  }
  return "";
}

std::vector<float> Quantiles(const std::vector<float>& values, const std::vector<double>& q) {
  std::vector<float> sorted = values, out(q.size(), 0.0f);
  if (sorted.empty()) return out;
  std::sort(sorted.begin(), sorted.end());
  for (size_t i = 0; i < q.size(); ++i)
    out[i] = sorted[size_t(std::lround(std::clamp(q[i], 0.0, 1.0) * double(sorted.size() - 1)))];
  return out;
}

}  // namespace translume
