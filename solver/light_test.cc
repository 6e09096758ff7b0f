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

// An image pattern is stretched over the face, pixel (x, y) over node (i, j) as in the EXRs
// `forward` writes, and weighted by the Rec. 709 luminance: pure red, green, blue and white
// pixels in the top row (y = 0), black below; 9x5 nodes at 1 mm, so each pixel covers 2x2 mm
// and the dual boxes of nodes i = 1, 3, 5, 7 (j = 1: top row; j = 3: bottom) lie in one pixel.
TEST(Light, ImagePatternUsesLuminanceAndTheImageAxes) {
  const std::string path = (std::filesystem::temp_directory_path() / "translume_light.exr").string();
  Image img;
  img.width = 4;
  img.height = 2;
  img.channels = 3;
  img.data.assign(4 * 2 * 3, 0.0f);
  for (int c = 0; c < 3; ++c) {
    img.at(c, 0, c) = 1.0f;  // red, green, blue
    img.at(3, 0, c) = 1.0f;  // white
  }
  WriteImage(path, img);
  const GridShape s{9, 5, 3};
  const auto q = RasterizeLightFile(LightSpec::Parse("image:" + path), s, 1.0);
  const double expected[4] = {0.2126, 0.7152, 0.0722, 1.0};
  for (int x = 0; x < 4; ++x) {
    EXPECT_NEAR(q[(2 * x + 1) + 9 * 1], expected[x], 1e-6) << x;
    EXPECT_NEAR(q[(2 * x + 1) + 9 * 3], 0.0, 1e-6) << x;
  }
  std::filesystem::remove(path);
}

TEST(Light, MalformedSpecsAreRejectedWithTheirText) {
  for (const char* bad : {"", "region:1,2", "region:4,0/4", "spot:1,2", "spot:1,2,-3", "image:",
                          "laser:1", "uniformly", "region:1,1/2x",
                          // Beyond int: sscanf's %d read these as region 0,0/1 and "2x2".
                          "region:4294967296,0/4294967297", "region:0,0/99999999999999999999",
                          "region:0,,0/2", "region:0,0/"}) {
    try {
      LightSpec::Parse(bad);
      FAIL() << "accepted '" << bad << "'";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(std::string("'") + bad + "'"), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(RegionLights("4x3"), InputError);
  EXPECT_THROW(RegionLights("4294967298x4294967298"), InputError);
  EXPECT_EQ(RegionLights("+3x3").size(), 9u);
  EXPECT_THROW(RasterizeLightFile(LightSpec::Parse("image:/nonexistent.png"), {4, 4, 2}, 1.0), InputError);
}

// simulate --lights: NxN regions, or specs separated by ';'.
TEST(Light, TrainingLightsTakeRegionsOrSpecs) {
  EXPECT_EQ(TrainingLights("3x3").size(), 9u);
  const std::vector<LightSpec> l = TrainingLights("spot:4,3,2;region:1,0/2;uniform");
  ASSERT_EQ(l.size(), 3u);
  EXPECT_EQ(l[0].kind, LightSpec::Kind::kSpot);
  EXPECT_EQ(l[1].kind, LightSpec::Kind::kRegion);
  EXPECT_EQ(l[2].kind, LightSpec::Kind::kUniform);
  EXPECT_EQ(TrainingLights("uniform").size(), 1u);
  EXPECT_THROW(TrainingLights("spot:4,3,2;;uniform"), InputError);
  EXPECT_THROW(TrainingLights("spot:4,3,2;"), InputError);
  EXPECT_THROW(TrainingLights("spot:4,3"), InputError);
  EXPECT_THROW(TrainingLights("image:p.png"), InputError);
  EXPECT_THROW(TrainingLights("4x3"), InputError);
  try {
    TrainingLights("spot:1,1,1;blob:2");
    ADD_FAILURE() << "blob:2 accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("blob:2"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace translume
