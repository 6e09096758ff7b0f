// SPDX-License-Identifier: MIT
// Shared by render/'s tests.
#pragma once

#include <cmath>
#include <vector>

namespace translume {

// sqrt(sum (a - ref)^2 / sum ref^2), accumulated in double.
inline double RelativeL2(const std::vector<float>& a, const std::vector<float>& ref) {
  double num = 0, den = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    num += (a[i] - ref[i]) * double(a[i] - ref[i]);
    den += double(ref[i]) * ref[i];
  }
  return std::sqrt(num / den);
}

}  // namespace translume
