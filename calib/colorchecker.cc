// SPDX-License-Identifier: MIT
#include "calib/colorchecker.h"

#include <cmath>

namespace translume::calib {

std::vector<cv::Vec3d> ColorCheckerLinearAlbedos() {
  // Published 8-bit sRGB averages of the patches.
  static const int kSrgb[24][3] = {
      {115, 82, 68},   {194, 150, 130}, {98, 122, 157},  {87, 108, 67},   {133, 128, 177},
      {103, 189, 170}, {214, 126, 44},  {80, 91, 166},   {193, 90, 99},   {94, 60, 108},
      {157, 188, 64},  {224, 163, 46},  {56, 61, 150},   {70, 148, 73},   {175, 54, 60},
      {231, 199, 31},  {187, 86, 149},  {8, 133, 161},   {243, 243, 242}, {200, 200, 200},
      {160, 160, 160}, {122, 122, 121}, {85, 85, 85},    {52, 52, 52}};
  auto linear = [](int v) {
    const double c = v / 255.0;
    return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4);
  };
  std::vector<cv::Vec3d> out;
  for (const auto& p : kSrgb) out.emplace_back(linear(p[0]), linear(p[1]), linear(p[2]));
  return out;
}

}  // namespace translume::calib
