// SPDX-License-Identifier: MIT
#pragma once

#include <string>
#include <vector>

namespace translume {

// A float image, interleaved: data[(y * width + x) * channels + c].
struct Image {
  int width = 0, height = 0, channels = 0;
  std::vector<float> data;
  float& at(int x, int y, int c) { return data[(size_t(y) * width + x) * channels + c]; }
  float at(int x, int y, int c) const { return data[(size_t(y) * width + x) * channels + c]; }
};

// Reads any format OpenImageIO knows, converted to float (8/16-bit integers map to [0, 1]).
// Throws InputError naming the file on failure.
Image ReadImage(const std::string& path);

// Writes an image; the format follows the extension (.exr: float, .png: 8-bit after clamping to
// [0, 1]). Written under a temporary name and renamed. Throws InputError on failure.
void WriteImage(const std::string& path, const Image& image);

// Channel-separated planes (each width*height, row-major) to an interleaved image.
Image ImageFromPlanes(int width, int height, const std::vector<const float*>& planes);

}  // namespace translume
