// SPDX-License-Identifier: MIT
#pragma once

#include <string>
#include <vector>

#include "solver/grid.h"
#include "solver/image.h"

namespace translume {

// An illumination condition on the lit face, shared by every command:
//   uniform          the whole lit face, q = 1
//   region:I,J/N     cell (I, J) of an N x N split of the lit face (I along x, J along y),
//                    0 <= I, J < N
//   spot:X,Y,R       disc of radius R mm centred at (X, Y) mm on the lit face
//   image:FILE       a pattern image stretched over the lit face; its luminance
//                    (0.2126 R + 0.7152 G + 0.0722 B, pixel values taken as linear) is q
struct LightSpec {
  enum class Kind { kUniform, kRegion, kSpot, kImage };
  Kind kind = Kind::kUniform;
  int region_i = 0, region_j = 0, region_n = 1;
  double spot_x = 0, spot_y = 0, spot_r = 0;
  std::string image_path;
  std::string text;  // as given

  // Throws InputError naming the spec on malformed text.
  static LightSpec Parse(const std::string& text);
};

// q at the lit-face nodes, nx*ny values (i + nx * j). Each node's value is the mean of the
// pattern over the node's dual box on the face (the face area it owns in the finite-volume
// discretisation, SPEC section 3), so region patterns of an N x N split sum to `uniform`
// exactly and partially covered nodes get fractional light.
// `image:` lights need the decoded pattern (RasterizeLightFile in image_io.h reads it).
std::vector<float> RasterizeLight(const LightSpec& spec, const GridShape& shape, double h,
                                  const Image* pattern = nullptr);

// "4x4" -> the 16 region specs region:I,J/4 in row-major order (J outer). Throws InputError.
std::vector<LightSpec> RegionLights(const std::string& nxn);

// Training lights as `simulate --lights` takes them: "NxN" (RegionLights), or light specs
// separated by ';' ("spot:4,3,2;spot:12,3,2;region:0,0/2"), at most 4096; image lights are
// refused (they need their file read at every grid). Throws InputError naming the bad entry.
std::vector<LightSpec> TrainingLights(const std::string& text);

}  // namespace translume
