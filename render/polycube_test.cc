// SPDX-License-Identifier: MIT
#include "render/polycube.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>

#include "solver/status.h"

namespace translume {
namespace {

TEST(Polycube, ParsesAndRoundTrips) {
  const Polycube p = ParsePolycube("0 0 0 # a cube\n\n  1 0 0\n", "ok.txt");
  ASSERT_EQ(p.cubes.size(), 2u);
  EXPECT_EQ(p.Extent(), (std::array<int, 3>{2, 1, 1}));
  EXPECT_TRUE(p.Has(1, 0, 0));
  EXPECT_FALSE(p.Has(0, 1, 0));
  EXPECT_EQ(ParsePolycube(FormatPolycube(p), "again").cubes, p.cubes);
  // Only the arrangement matters: a lattice offset is removed (it built a different, folded grid).
  EXPECT_EQ(ParsePolycube("300 7 5\n301 7 5\n", "shifted").cubes, p.cubes);
  EXPECT_EQ(BuiltinPolycube("torus").cubes.size(), 8u);
  EXPECT_EQ(BuiltinPolycube("slab").cubes.size(), 9u);
}

// The optional axes line: read as written (17 digits round-trip), hand-written cosines made
// orthonormal, and every malformed one refused with the file and line.
TEST(Polycube, AxesLine) {
  Polycube p = ParsePolycube("0 0 0\n", "cube");
  EXPECT_EQ(p.axes, Eigen::Matrix3d::Identity());
  EXPECT_EQ(FormatPolycube(p).find("axes"), std::string::npos);  // the default is not written
  const double c = std::cos(0.3), s = std::sin(0.3);
  p.axes << c, s, 0, -s, c, 0, 0, 0, 1;
  p.axes = Eigen::Matrix3d(Eigen::AngleAxisd(0.2, Eigen::Vector3d(1, 2, 3).normalized())) * p.axes;
  const Polycube back = ParsePolycube(FormatPolycube(p), "again");
  EXPECT_EQ(back.axes, p.axes);
  EXPECT_EQ(back.cubes, p.cubes);
  // 45 degrees about x to four digits: accepted, then exactly orthonormal.
  const Polycube hand = ParsePolycube("axes 1 0 0  0 0.7071 0.7071  0 -0.7071 0.7071\n0 0 0\n", "hand");
  EXPECT_LT((hand.axes * hand.axes.transpose() - Eigen::Matrix3d::Identity()).norm(), 1e-12);
  EXPECT_NEAR(hand.axes(1, 1), std::sqrt(0.5), 1e-4);
  EXPECT_EQ(hand.Validate(), "");
  const auto error = [](const std::string& text) {
    try {
      ParsePolycube(text, "f.cubes");
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(error("0 0 0\naxes 1 0 0 0 1 0\n").find("f.cubes:2: expected \"axes\" and nine numbers"), std::string::npos);
  EXPECT_NE(error("axes 1 0 0 0 1 0 0 0 1 0\n0 0 0\n").find("f.cubes:1: expected nine numbers"), std::string::npos);
  EXPECT_NE(error("axes 1 0 0 0 1 0 0 0 -1\n0 0 0\n").find("f.cubes:1: the axes must be right-handed"), std::string::npos);
  EXPECT_NE(error("axes 1 0 0 0 0.7 0.7 0 -0.7 0.7\n0 0 0\n").find("f.cubes:1: the axes must be unit vectors"),
            std::string::npos);
  EXPECT_NE(error("axes 1 0 0 0 1 0 0 0 1\naxes 1 0 0 0 1 0 0 0 1\n0 0 0\n").find("f.cubes:2: a second axes line"),
            std::string::npos);
  p.axes(0, 0) = 2;
  EXPECT_NE(p.Validate().find("rotation"), std::string::npos);
}

TEST(Polycube, Genus) {
  EXPECT_EQ(ParsePolycube("0 0 0\n", "cube").Genus(), 0);
  EXPECT_EQ(BuiltinPolycube("slab").Genus(), 0);
  EXPECT_EQ(BuiltinPolycube("torus").Genus(), 1);
  EXPECT_EQ(BuiltinPolycube("bunny").Genus(), 0);
  // Two rings side by side, sharing a bar: two holes.
  EXPECT_EQ(ParsePolycube("0 0 0\n1 0 0\n2 0 0\n3 0 0\n4 0 0\n0 1 0\n2 1 0\n4 1 0\n"
                          "0 2 0\n1 2 0\n2 2 0\n3 2 0\n4 2 0\n", "two rings").Genus(), 2);
  // Cubes (0 0 0) and (1 1 0) meet along an edge only (joined through the layer above).
  EXPECT_EQ(ParsePolycube("0 0 0\n1 1 0\n0 0 1\n1 0 1\n1 1 1\n", "edge").Genus(), -1);
  // (1 1 1) and (2 2 2) meet at a corner only (joined by a path around it); where the cells
  // next to the corner fill it in, the surface is a manifold.
  EXPECT_EQ(ParsePolycube("1 1 1\n1 1 0\n2 1 0\n3 1 0\n3 1 1\n3 1 2\n3 2 2\n2 2 2\n", "corner").Genus(), -1);
  EXPECT_EQ(ParsePolycube("0 0 0\n1 0 0\n1 1 0\n1 1 1\n", "filled corner").Genus(), 0);
}

TEST(Polycube, BadFilesGiveClearErrors) {
  EXPECT_THROW(ParsePolycube("0 0 0\n0 0 0\n", "dup.txt"), InputError);
  EXPECT_THROW(ParsePolycube("0 0 0\n2 0 0\n", "gap.txt"), InputError);
  EXPECT_THROW(ParsePolycube("0 0\n", "short.txt"), InputError);
  EXPECT_THROW(ParsePolycube("# nothing\n", "empty.txt"), InputError);
  EXPECT_THROW(ParsePolycube("0 0 -1\n", "neg.txt"), InputError);
  try {
    ParsePolycube("0 0 0\n1 0 0 extra\n", "bad.txt");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("bad.txt:2"), std::string::npos) << e.what();
  }
  // A NUL quoted from the file ended the message there.
  try {
    ParsePolycube(std::string("0 0 0\n1 \0 0\n", 12), "nul.txt");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("got '1 \\x00 0'"), std::string::npos) << e.what();
  }
  EXPECT_THROW(ReadPolycube("/nonexistent/cubes.txt"), InputError);
  EXPECT_THROW(BuiltinPolycube("cone"), InputError);
}

}  // namespace
}  // namespace translume
