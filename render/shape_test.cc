// SPDX-License-Identifier: MIT
#include "render/shape.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>

#include "solver/status.h"

namespace translume {
namespace {

TEST(Shape, BuiltinsAreClosedAndProjectOntoThemselves) {
  for (const std::string name : {"sphere", "torus", "slab", "blob"}) {
    SCOPED_TRACE(name);
    const auto s = MakeBuiltinShape(name, 12, 16);
    EXPECT_EQ(s->mesh().Validate(), "");
    EXPECT_NEAR((s->hi - s->lo).maxCoeff(), 12, 0.2);
    for (size_t v = 0; v < s->mesh().vertices.size(); v += 17) {
      Vec3 p, n;
      s->Project(s->mesh().vertices[v], &p, &n);
      EXPECT_NEAR(n.norm(), 1, 1e-9);
      if (name != "blob") {
        EXPECT_NEAR((p - s->mesh().vertices[v]).norm(), 0, 1e-9);
      }
    }
  }
  EXPECT_THROW(MakeBuiltinShape("cone", 10), InputError);
  EXPECT_THROW(MakeBuiltinShape("sphere", -1), InputError);
}

TEST(Shape, MeshGenus) {
  EXPECT_EQ(MakeBuiltinShape("sphere", 12, 16)->mesh().Genus(), 0);
  EXPECT_EQ(MakeBuiltinShape("slab", 12, 16)->mesh().Genus(), 0);
  EXPECT_EQ(MakeBuiltinShape("torus", 12, 16)->mesh().Genus(), 1);
  EXPECT_EQ(MakeBuiltinShape("bunny", 12, 16)->mesh().Genus(), 0);
  // Two separate tori: the handles add up.
  TriangleMesh two = MakeBuiltinShape("torus", 12, 16)->mesh();
  const int n = int(two.vertices.size());
  const TriangleMesh one = two;
  for (const Vec3& v : one.vertices) two.vertices.push_back(v + Vec3(30, 0, 0));
  for (const auto& t : one.triangles) two.triangles.push_back({t[0] + n, t[1] + n, t[2] + n});
  ASSERT_EQ(two.Validate(), "");
  EXPECT_EQ(two.Genus(), 2);
  EXPECT_EQ(two.Pieces(), 2);
  EXPECT_EQ(one.Pieces(), 1);
}

TEST(Shape, MeshProjectionMatchesBruteForce) {
  const auto blob = MakeBuiltinShape("blob", 20, 24);
  const auto mesh = MakeMeshShape(blob->mesh(), "blob.obj", 0);
  const TriangleMesh& m = mesh->mesh();
  uint32_t state = 12345;
  auto uniform = [&] { state = state * 1664525u + 1013904223u; return (state >> 8) / double(1 << 24); };
  for (int i = 0; i < 200; ++i) {
    const Vec3 p(30 * uniform() - 15, 30 * uniform() - 15, 30 * uniform() - 15);
    Vec3 s, n;
    mesh->Project(p, &s, &n);
    double best = 1e300;
    for (const auto& t : m.triangles) {
      double u, v, w;
      best = std::min(best, (ClosestPointOnTriangle(p, m.vertices[t[0]], m.vertices[t[1]], m.vertices[t[2]], &u, &v, &w) - p).norm());
    }
    EXPECT_NEAR((s - p).norm(), best, 1e-9) << i;
  }
}

// The polygrid projects its nodes in place (Project(x, &x, &n)). The mesh projection used to
// write its current best point into *s during the search and go on measuring from it, so in
// place it returned a point on the wrong face: on a 12-triangle cube, boundary nodes of one
// face landed on the next one and the polygrid folded (non-finite Laplacian weights).
TEST(Shape, MeshProjectionInPlace) {
  const auto blob = MakeMeshShape(MakeBuiltinShape("blob", 20, 12)->mesh(), "blob.obj", 0);
  const auto cube = MakeMeshShape(MakeBoxShape(Vec3(4, 4, 4), 1)->mesh(), "cube.obj", 0);
  uint32_t state = 777;
  auto uniform = [&] { state = state * 1664525u + 1013904223u; return (state >> 8) / double(1 << 24); };
  for (const Shape* shape : {blob.get(), cube.get()}) {
    const double r = (shape->hi - shape->lo).maxCoeff();
    for (int i = 0; i < 200; ++i) {
      const Vec3 p = shape->lo + r * Vec3(uniform(), uniform(), uniform()) - 0.1 * r * Vec3::Ones();
      Vec3 s, n, x = p, nx;
      shape->Project(p, &s, &n);
      shape->Project(x, &x, &nx);
      EXPECT_LT((x - s).norm(), 1e-12) << shape->name() << " " << i;
      EXPECT_LT((nx - n).norm(), 1e-12) << shape->name() << " " << i;
    }
  }
  // The cube's face point stays where it is.
  Vec3 x(-1.5, -2, -1.5), n;
  cube->Project(x, &x, &n);
  EXPECT_LT((x - Vec3(-1.5, -2, -1.5)).norm(), 1e-12);
}

TEST(Shape, ClosestPointOnTriangle) {
  double u, v, w;
  const Vec3 a(0, 0, 0), b(1, 0, 0), c(0, 1, 0);
  EXPECT_TRUE(ClosestPointOnTriangle(Vec3(0.2, 0.3, 5), a, b, c, &u, &v, &w).isApprox(Vec3(0.2, 0.3, 0)));
  EXPECT_NEAR(u + v + w, 1, 1e-12);
  EXPECT_TRUE(ClosestPointOnTriangle(Vec3(2, -1, 1), a, b, c, &u, &v, &w).isApprox(Vec3(1, 0, 0)));
  EXPECT_TRUE(ClosestPointOnTriangle(Vec3(1, 1, 0), a, b, c, &u, &v, &w).isApprox(Vec3(0.5, 0.5, 0)));
}

}  // namespace
}  // namespace translume
