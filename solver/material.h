// SPDX-License-Identifier: MIT
#pragma once

#include <array>
#include <string>
#include <vector>

#include "solver/grid.h"

namespace translume {

// C = (1 + Fdr) / (1 - Fdr) with Fdr(eta) = -1.440/eta^2 + 0.710/eta + 0.668 + 0.0636 eta
// (Jensen et al. 2001; SPEC section 2). eta = 1.3 gives C = 2.6021.
double ReflectionParameterC(double eta);

// A heterogeneous translucent material on the node grid (SPEC section 2), one value per node
// and RGB channel, channel-separated: kappa[c][shape.index(i, j, k)].
//   kappa: diffusion coefficient in mm, mu: absorption coefficient in 1/mm, both > 0.
//   spacing_mm: node spacing h. C: boundary reflection parameter; eta: refractive index.
struct Material {
  GridShape shape;
  double spacing_mm = 0.5;
  double eta = 1.3;
  double C = ReflectionParameterC(1.3);
  std::array<std::vector<float>, 3> kappa;
  std::array<std::vector<float>, 3> mu;

  // Allocates every channel with constant values.
  static Material Constant(const GridShape& shape, double spacing_mm,
                           const std::array<float, 3>& kappa, const std::array<float, 3>& mu,
                           double eta = 1.3);

  // Returns an empty string if the material is usable, else a sentence naming the broken
  // constraint (sizes, positivity, finiteness, spacing, C, eta).
  std::string Validate() const;
};

// Quantiles of one channel's values (kappa[c] or mu[c]): for each q in [0, 1] the value of rank
// round(q (n - 1)) in ascending order (0: the least, 1: the largest); empty values give zeros.
std::vector<float> Quantiles(const std::vector<float>& values, const std::vector<double>& q);

// The material previews (WriteMaterialSlices) show each channel on a log scale from its
// kPreviewQuantile quantile (black) to its 1 - kPreviewQuantile quantile (full), a range widened
// about its geometric centre to a factor of at least kPreviewMinRatio, so that a few percent of
// variation does not fill the scale; `translume info MATERIAL.vdb` prints the quantiles.
inline constexpr double kPreviewQuantile = 0.005;
inline constexpr double kPreviewMinRatio = 2;

}  // namespace translume
