// SPDX-License-Identifier: MIT
#include "render/shape.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "solver/status.h"

namespace translume {
namespace {

namespace fs = std::filesystem;
const std::string kTet = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n";

std::string Write(const std::string& name, const std::string& text) {
  const std::string path = (fs::temp_directory_path() / name).string();
  std::ofstream(path, std::ios::binary) << text;
  return path;
}

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

TEST(Shape, ObjAndPlyMeshes) {
  const auto closed = ReadMesh(Write("tl_closed.obj", kTet + "f 1 3 2\nf 1 2 4\nf 2/1 3/1 4/1\nf -4 -1 -2\n"));
  EXPECT_EQ(closed.triangles.size(), 4u);
  const std::string header =
      "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
      "property float z\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n";
  const auto ascii = ReadMesh(Write("tl_tet.ply", header +
      "0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 1 2 3\n3 0 3 2\n"));
  EXPECT_EQ(ascii.triangles.size(), 4u);
  std::string bin = header;
  bin.replace(bin.find("ascii"), 5, "binary_little_endian");
  const float xyz[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
  bin.append(reinterpret_cast<const char*>(xyz), sizeof(xyz));
  const int32_t faces[4][3] = {{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {0, 3, 2}};
  for (const auto& f : faces) {
    bin.push_back(char(3));
    bin.append(reinterpret_cast<const char*>(f), sizeof(f));
  }
  const auto binary = ReadMesh(Write("tl_tet_bin.ply", bin));
  EXPECT_EQ(binary.vertices[3], Vec3(0, 0, 1));
  EXPECT_EQ(binary.triangles, ascii.triangles);
  // A UTF-8 byte order mark before the first line (it dropped the first vertex).
  EXPECT_EQ(ReadMesh(Write("tl_bom.obj", "\xEF\xBB\xBF" + kTet + "f 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\n")).vertices,
            closed.vertices);
  // A vertex no face uses is dropped (it widened the box the polycube is fitted to).
  const auto stray = ReadMesh(Write("tl_stray.obj", "v 9 9 9\n" + kTet + "v 1000 1000 1000\n"
                                    "f 2 4 3\nf 2 3 5\nf 3 4 5\nf 2 5 4\n"));
  EXPECT_EQ(stray.vertices.size(), 4u);
  EXPECT_EQ(stray.triangles, closed.triangles);
  EXPECT_EQ(stray.vertices, closed.vertices);
}

// Binary big-endian PLY (used to be refused as an unsupported format), with a blank header
// line: the same tetrahedron as the ascii file, double coordinates and uint16 indices.
TEST(Shape, BigEndianPly) {
  std::string ply =
      "ply\nformat binary_big_endian 1.0\ncomment written big endian\nelement vertex 4\n"
      "property double x\nproperty double y\nproperty double z\n\nelement face 4\n"
      "property list uchar ushort vertex_indices\nend_header\n";
  auto put = [&](auto v) {
    char b[sizeof(v)];
    std::memcpy(b, &v, sizeof(v));
    const uint16_t one = 1;
    if (*reinterpret_cast<const uint8_t*>(&one) == 1) std::reverse(b, b + sizeof(v));
    ply.append(b, sizeof(v));
  };
  const double xyz[12] = {0, 0, 0, 1.5, 0, 0, 0, 1, 0, 0, 0, -2};
  for (double v : xyz) put(v);
  const uint16_t faces[4][3] = {{0, 1, 2}, {0, 3, 1}, {1, 3, 2}, {0, 2, 3}};
  for (const auto& f : faces) {
    ply.push_back(char(3));
    for (uint16_t i : f) put(i);
  }
  const auto m = ReadMesh(Write("tl_tet_be.ply", ply));
  EXPECT_EQ(m.vertices[1], Vec3(1.5, 0, 0));
  EXPECT_EQ(m.vertices[3], Vec3(0, 0, -2));
  ASSERT_EQ(m.triangles.size(), 4u);
  EXPECT_EQ(m.triangles[1], (std::array<int, 3>{0, 3, 1}));
}

TEST(Shape, BadMeshesGiveClearErrors) {
  auto expect_error = [](const std::string& path, const std::string& what) {
    try {
      ReadMesh(path);
      FAIL() << path;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    }
  };
  expect_error(Write("tl_open.obj", kTet + "f 1 3 2\nf 1 2 4\nf 2 3 4\n"), "open");
  expect_error(Write("tl_nonmanifold.obj",
                     kTet + "v 1 1 1\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\nf 2 3 5\n"), "non-manifold");
  // Two tetrahedra that share only vertex 1: every edge is fine, the vertex is a bowtie.
  expect_error(Write("tl_bowtie.obj", kTet + "v -1 0 0\nv 0 -1 0\nv 0 0 -1\n"
                                      "f 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\n"
                                      "f 1 5 6\nf 1 7 5\nf 5 7 6\nf 1 6 7\n"),
               "non-manifold vertex 0");
  // A closed tetrahedron with its four vertices in one plane encloses nothing.
  try {
    MakeMeshShape(ReadMesh(Write("tl_flat.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0.2 0.2 0\n"
                                                "f 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\n")), "tl_flat.obj", 0);
    ADD_FAILURE() << "a flat mesh was accepted";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), "tl_flat.obj: the mesh encloses no volume (flat, or folded onto itself)");
  }
  expect_error(Write("tl_flipped.obj", kTet + "f 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 3 4\n"), "orientation");
  expect_error(Write("tl_range.obj", kTet + "f 1 3 9\nf 1 2 4\nf 2 3 4\nf 1 4 3\n"), "out of range");
  // Face indices with trailing text, or 0 (OBJ counts from 1), are not read as numbers.
  expect_error(Write("tl_junk.obj", kTet + "f 1 3 2abc\nf 1 2 4\nf 2 3 4\nf 1 4 3\n"), "line 5: bad face index '2abc'");
  expect_error(Write("tl_zero.obj", kTet + "f 1 3 0\nf 1 2 4\nf 2 3 4\nf 1 4 3\n"), "bad face index '0'");
  expect_error(Write("tl_mesh.stl", "solid"), "unknown mesh format");
  // Binary PLY took NaN coordinates (OBJ refused them): both refuse any non-finite vertex.
  std::string bin = "ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                    "property float z\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n";
  const float xyz[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, NAN};
  bin.append(reinterpret_cast<const char*>(xyz), sizeof(xyz));
  const int32_t faces[4][3] = {{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {0, 3, 2}};
  for (const auto& f : faces) {
    bin.push_back(char(3));
    bin.append(reinterpret_cast<const char*>(f), sizeof(f));
  }
  expect_error(Write("tl_nan.ply", bin), "vertex 4 is not finite");
  const std::string ascii_header =
      "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 4\nproperty list uchar int vertex_indices\nend_header\n";
  const std::string tet_faces = "3 0 2 1\n3 0 1 3\n3 1 2 3\n3 0 3 2\n";
  expect_error(Write("tl_inf.ply", ascii_header + "0 0 0\n1 0 0\n0 1 inf\n0 0 1\n" + tet_faces), "vertex 3 is not finite");
  expect_error(Write("tl_word.ply", ascii_header + "0 0 0\n1 0 0\n0 1 x\n0 0 1\n" + tet_faces), "'x' is not a number");
  std::string no_z = ascii_header;
  no_z.erase(no_z.find("property float z\n"), 17);
  expect_error(Write("tl_noz.ply", no_z + "0 0\n1 0\n0 1\n0 0\n" + tet_faces), "no property 'z'");
  // Counts and indices the file cannot hold: a list of 2^31 - 1 indices allocated 8 GB before
  // the data ran out; -1, 1e3 and 1.5 were read as something else; unknown types passed in ascii.
  std::string long_list = bin;
  long_list.replace(long_list.find("list uchar int"), 14, "list uint int");
  long_list.resize(long_list.find("end_header\n") + 11 + sizeof(xyz));
  const uint32_t count = 2147483647u;
  long_list.append(reinterpret_cast<const char*>(&count), sizeof(count));
  long_list.append(std::string(12, '\0'));
  expect_error(Write("tl_long.ply", long_list), "PLY list length 2147483647 is longer than the rest of the file");
  std::string minus = ascii_header;
  minus.replace(minus.find("vertex 4"), 8, "vertex -1");
  expect_error(Write("tl_minus.ply", minus + tet_faces), "element 'vertex' has count '-1'");
  std::string exp = ascii_header;
  exp.replace(exp.find("vertex 4"), 8, "vertex 1e3");
  expect_error(Write("tl_exp.ply", exp + tet_faces), "count '1e3'");
  expect_error(Write("tl_half.ply", ascii_header + "0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1.5\n3 0 1 3\n3 1 2 3\n3 0 3 2\n"),
               "PLY vertex index 1.5 is not a whole number");
  std::string f128 = ascii_header;
  f128.replace(f128.find("float z"), 7, "float128 z");
  expect_error(Write("tl_f128.ply", f128 + "0 0 0\n1 0 0\n0 1 0\n0 0 1\n" + tet_faces),
               "unsupported PLY property type 'float128'");
  expect_error(Write("tl_garbage.obj", "garbage\nmore\n"), "not an OBJ mesh");
  expect_error((fs::temp_directory_path() / "tl_missing.obj").string(), "cannot open");
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
