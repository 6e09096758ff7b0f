// SPDX-License-Identifier: MIT
#pragma once

#include <opencv2/core.hpp>
#include <vector>

namespace translume::calib {

// Approximate diffuse albedos of the 24 X-Rite ColorChecker Classic patches (2005 formulation)
// in linear sRGB primaries (D65), row-major as seen upright: row 0 dark skin .. cyan, row 3
// white 9.5 .. black 2. Derived from the published 8-bit sRGB patch values through the sRGB
// transfer curve. Accuracy is that of the published averages (~2%); use a measured chart file
// for better absolute numbers.
std::vector<cv::Vec3d> ColorCheckerLinearAlbedos();

}  // namespace translume::calib
