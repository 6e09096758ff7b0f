// SPDX-License-Identifier: MIT
#pragma once

#include <cstddef>
#include <vector>

namespace translume {

// A float image, interleaved: data[(y * width + x) * channels + c].
struct Image {
  int width = 0, height = 0, channels = 0;
  std::vector<float> data;
  float& at(int x, int y, int c) { return data[(size_t(y) * width + x) * channels + c]; }
  float at(int x, int y, int c) const { return data[(size_t(y) * width + x) * channels + c]; }
};

}  // namespace translume
