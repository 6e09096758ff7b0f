// SPDX-License-Identifier: MIT
#include "solver/light.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <numbers>

#include "solver/image_io.h"
#include "solver/status.h"

namespace translume {
namespace {

// Sum of q over the face weighted by each node's dual-box area = integral of the pattern.
double Integral(const std::vector<float>& q, const GridShape& s, double h) {
  double sum = 0;
  for (int64_t j = 0; j < s.ny; ++j)
    for (int64_t i = 0; i < s.nx; ++i) {
      const double wx = (i == 0 || i == s.nx - 1) ? h / 2 : h;
      const double wy = (j == 0 || j == s.ny - 1) ? h / 2 : h;
      sum += wx * wy * q[i + s.nx * j];
    }
  return sum;
}

TEST(Light, RegionsOfASplitSumToUniform) {
  const GridShape s{37, 29, 5};
  const double h = 0.3;
  std::vector<double> total(s.face_size(), 0.0);
  for (const LightSpec& spec : RegionLights("4x4")) {
    const auto q = RasterizeLight(spec, s, h);
    for (int64_t f = 0; f < s.face_size(); ++f) total[f] += q[f];
    // Each region covers 1/16 of the face.
    EXPECT_NEAR(Integral(q, s, h), (36 * h) * (28 * h) / 16, 1e-9);
  }
  for (double v : total) EXPECT_NEAR(v, 1.0, 1e-6);
  const auto u = RasterizeLight(LightSpec::Parse("uniform"), s, h);
  for (float v : u) EXPECT_EQ(v, 1.0f);
}

TEST(Light, RegionIndexIsAlongXThenY) {
  const GridShape s{20, 20, 3};
  const auto q = RasterizeLight(LightSpec::Parse("region:1,0/2"), s, 1.0);
  EXPECT_EQ(q[19 + 20 * 0], 1.0f);  // right half, top
  EXPECT_EQ(q[0 + 20 * 0], 0.0f);
  EXPECT_EQ(q[19 + 20 * 19], 0.0f);  // bottom
}

TEST(Light, SpotCoversItsDiscArea) {
  const GridShape s{61, 61, 3};
  const double h = 0.2, r = 2.0;
  const auto q = RasterizeLight(LightSpec::Parse("spot:6,6,2"), s, h);
  EXPECT_NEAR(Integral(q, s, h), std::numbers::pi * r * r, 0.01 * std::numbers::pi * r * r);
  EXPECT_EQ(q[30 + 61 * 30], 1.0f);
  EXPECT_EQ(q[0], 0.0f);
}

TEST(Light, ImagePatternUsesLuminance) {
  const std::string path = (std::filesystem::temp_directory_path() / "translume_light.exr").string();
  Image img;
  img.width = 4;
  img.height = 2;
  img.channels = 3;
  img.data.assign(4 * 2 * 3, 0.0f);
  for (int x = 2; x < 4; ++x)
    for (int y = 0; y < 2; ++y)
      for (int c = 0; c < 3; ++c) img.at(x, y, c) = 0.5f;
  WriteImage(path, img);
  const GridShape s{9, 5, 3};
  const auto q = RasterizeLightFile(LightSpec::Parse("image:" + path), s, 1.0);
  EXPECT_NEAR(q[0], 0.0, 1e-6);
  EXPECT_NEAR(q[8 + 9 * 4], 0.5, 1e-6);
  std::filesystem::remove(path);
}

TEST(Light, MalformedSpecsAreRejectedWithTheirText) {
  for (const char* bad : {"", "region:1,2", "region:4,0/4", "spot:1,2", "spot:1,2,-3", "image:",
                          "laser:1", "uniformly", "region:1,1/2x"}) {
    try {
      LightSpec::Parse(bad);
      FAIL() << "accepted '" << bad << "'";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(std::string("'") + bad + "'"), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(RegionLights("4x3"), InputError);
  EXPECT_THROW(RasterizeLightFile(LightSpec::Parse("image:/nonexistent.png"), {4, 4, 2}, 1.0), InputError);
}

}  // namespace
}  // namespace translume
