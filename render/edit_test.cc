// SPDX-License-Identifier: MIT
#include "render/edit.h"

#include <gtest/gtest.h>

#include "solver/status.h"

namespace translume {
namespace {

TEST(Edit, ScaleAddMaskAndDepth) {
  const Material m = Material::Constant({4, 2, 3}, 0.5, {0.2f, 0.2f, 0.2f}, {0.01f, 0.02f, 0.03f});
  EditOptions o;
  o.ParseTerm("kappa=2", false);
  o.ParseTerm("mu=0.01", true);
  o.ParseDepth("1:1");
  Image mask;
  mask.width = 2;
  mask.height = 1;
  mask.channels = 1;
  mask.data = {1.f, 0.5f};  // left half full edit, right half half-way
  const Material e = EditMaterial(m, o, &mask);
  // Layer 0 and 2 untouched; layer 1: left v' = 2 kappa, mu + 0.01; right half-way.
  EXPECT_FLOAT_EQ(e.kappa[0][m.shape.index(0, 0, 0)], 0.2f);
  EXPECT_FLOAT_EQ(e.kappa[0][m.shape.index(0, 0, 1)], 0.4f);
  EXPECT_FLOAT_EQ(e.mu[2][m.shape.index(1, 1, 1)], 0.04f);
  EXPECT_FLOAT_EQ(e.kappa[1][m.shape.index(3, 0, 1)], 0.3f);
  EXPECT_FLOAT_EQ(e.mu[0][m.shape.index(3, 1, 1)], 0.015f);
  EXPECT_FLOAT_EQ(e.kappa[0][m.shape.index(3, 0, 2)], 0.2f);
}

// Repeated terms compose (the last one used to replace the others).
TEST(Edit, RepeatedTermsCompose) {
  EditOptions o;
  o.ParseTerm("kappa=2", false);
  o.ParseTerm("kappa=3", false);
  o.ParseTerm("mu=0.01", true);
  o.ParseTerm("mu=0.02", true);
  EXPECT_DOUBLE_EQ(o.scale_kappa, 6);
  EXPECT_DOUBLE_EQ(o.add_mu, 0.03);
  EXPECT_DOUBLE_EQ(o.scale_mu, 1);
  EXPECT_DOUBLE_EQ(o.add_kappa, 0);
}

// A tint: only the named channels change.
TEST(Edit, ChosenChannelsOnly) {
  const Material m = Material::Constant({2, 2, 2}, 0.5, {0.2f, 0.3f, 0.4f}, {0.01f, 0.02f, 0.03f});
  EditOptions o;
  o.ParseTerm("mu=4", false);
  o.ParseChannels("R");
  EXPECT_EQ(o.channels, (std::array<bool, 3>{true, false, false}));
  Material e = EditMaterial(m, o);
  EXPECT_FLOAT_EQ(e.mu[0][5], 0.04f);
  EXPECT_FLOAT_EQ(e.mu[1][5], 0.02f);
  EXPECT_FLOAT_EQ(e.mu[2][5], 0.03f);
  EXPECT_FLOAT_EQ(e.kappa[0][5], 0.2f);
  o.ParseChannels("gb");
  e = EditMaterial(m, o);
  EXPECT_FLOAT_EQ(e.mu[0][5], 0.01f);
  EXPECT_FLOAT_EQ(e.mu[1][5], 0.08f);
  EXPECT_FLOAT_EQ(e.mu[2][5], 0.12f);
  EXPECT_THROW(o.ParseChannels(""), InputError);
  EXPECT_THROW(o.ParseChannels("rr"), InputError);
  EXPECT_THROW(o.ParseChannels("x"), InputError);
  EXPECT_THROW(o.ParseChannels("red"), InputError);
}

TEST(Edit, BadEditsAreRefused) {
  EditOptions o;
  EXPECT_THROW(o.ParseTerm("sigma=2", false), InputError);
  EXPECT_THROW(o.ParseTerm("kappa=two", false), InputError);
  EXPECT_THROW(o.ParseTerm("kappa", true), InputError);
  EXPECT_THROW(o.ParseDepth("3"), InputError);
  // Trailing text and a negative end (the internal 'to the deepest layer') used to be accepted:
  // "2:-1" silently edited every layer from 2 down.
  EXPECT_THROW(o.ParseDepth("1:2x"), InputError);
  EXPECT_THROW(o.ParseDepth("2:-1"), InputError);
  EXPECT_THROW(o.ParseDepth("-1:2"), InputError);
  EXPECT_THROW(o.ParseDepth("3:1"), InputError);
  // Past int's range: refused, not wrapped (4294967296:4294967298 edited layers 0:2).
  EXPECT_THROW(o.ParseDepth("4294967296:4294967298"), InputError);
  EXPECT_THROW(o.ParseDepth("0:99999999999"), InputError);
  o.ParseDepth("2:2");
  EXPECT_EQ(o.depth_begin, 2);
  EXPECT_EQ(o.depth_end, 2);
  o.depth_begin = 3;
  EXPECT_FALSE(o.Validate().empty());
  const Material m = Material::Constant({2, 2, 2}, 0.5, {0.2f, 0.2f, 0.2f}, {0.01f, 0.01f, 0.01f});
  EditOptions neg;
  neg.ParseTerm("mu=-0.5", true);
  EXPECT_THROW(EditMaterial(m, neg), InputError);
}

}  // namespace
}  // namespace translume
