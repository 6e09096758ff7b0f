// SPDX-License-Identifier: MIT
#pragma once

#include <cmath>
#include <cstddef>
#include <string>
#include <vector>

namespace translume {

// A float image, interleaved: data[(y * width + x) * channels + c].
struct Image {
  int width = 0, height = 0, channels = 0;
  std::vector<float> data;
  // Bits per value of the file's integer format (8, 16, 32; ReadImage maps them to [0, 1]), or
  // 0 where the file stores float or half values (and for images made in memory).
  int integer_bits = 0;
  float& at(int x, int y, int c) { return data[(size_t(y) * width + x) * channels + c]; }
  float at(int x, int y, int c) const { return data[(size_t(y) * width + x) * channels + c]; }
};

// sqrt(sum (a - ref)^2 / sum ref^2), accumulated in double: a's relative L2 difference from ref
// (images' data, fields, radiance lists; the same size).
inline double RelativeL2(const std::vector<float>& a, const std::vector<float>& ref) {
  double num = 0, den = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    num += (a[i] - ref[i]) * double(a[i] - ref[i]);
    den += double(ref[i]) * ref[i];
  }
  return std::sqrt(num / den);
}

// "pixel (X, Y) is not finite" at an image's first NaN or inf, "" if there is none.
inline std::string NonFinitePixel(const Image& image) {
  for (size_t i = 0; i < image.data.size(); ++i)
    if (!std::isfinite(image.data[i])) {
      const size_t pixel = i / size_t(image.channels);
      return "pixel (" + std::to_string(pixel % size_t(image.width)) + ", " +
             std::to_string(pixel / size_t(image.width)) + ") is not finite";
    }
  return "";
}

}  // namespace translume
