// SPDX-License-Identifier: MIT
#include "render/polycube.h"

#include <gtest/gtest.h>

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
  EXPECT_EQ(BuiltinPolycube("torus").cubes.size(), 8u);
  EXPECT_EQ(BuiltinPolycube("slab").cubes.size(), 9u);
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
  EXPECT_THROW(ReadPolycube("/nonexistent/cubes.txt"), InputError);
  EXPECT_THROW(BuiltinPolycube("cone"), InputError);
}

}  // namespace
}  // namespace translume
