// SPDX-License-Identifier: MIT
#pragma once

#include <string>
#include <vector>

#include "solver/grid.h"
#include "solver/image.h"
#include "solver/light.h"

namespace translume {

// Reads any format OpenImageIO knows, converted to float (8/16-bit integers map to [0, 1]).
// Throws InputError naming the file on failure.
Image ReadImage(const std::string& path);

// Writes an image; the format follows the extension (.exr: float, .png: 8-bit after clamping to
// [0, 1]). Written under a temporary name and renamed. Throws InputError on failure.
void WriteImage(const std::string& path, const Image& image);

// q at the lit-face nodes for any light, reading the pattern file of `image:FILE` lights.
std::vector<float> RasterizeLightFile(const LightSpec& spec, const GridShape& shape, double h);

// Channel-separated planes (each width*height, row-major) to an interleaved image.
Image ImageFromPlanes(int width, int height, const std::vector<const float*>& planes);

}  // namespace translume
