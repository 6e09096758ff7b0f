// SPDX-License-Identifier: MIT
#include "render/mesh_io.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <cmath>
#include <fmt/format.h>
#include <fstream>
#include <vector>

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

TEST(MeshIo, ObjAndPlyMeshes) {
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
TEST(MeshIo, BigEndianPly) {
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

TEST(MeshIo, BadMeshesGiveClearErrors) {
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
               "non-manifold vertex 1: the triangles around it form more than one fan");
  // A closed tetrahedron with its four vertices in one plane encloses nothing.
  try {
    MakeMeshShape(ReadMesh(Write("tl_flat.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0.2 0.2 0\n"
                                                "f 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\n")), "tl_flat.obj", 0);
    ADD_FAILURE() << "a flat mesh was accepted";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), "tl_flat.obj: the mesh encloses no volume (flat, or folded onto itself)");
  }
  expect_error(Write("tl_range.obj", kTet + "f 1 3 9\nf 1 2 4\nf 2 3 4\nf 1 4 3\n"), "out of range");
  // Face indices with trailing text, or 0 (OBJ counts from 1), are not read as numbers.
  expect_error(Write("tl_junk.obj", kTet + "f 1 3 2abc\nf 1 2 4\nf 2 3 4\nf 1 4 3\n"), "line 5: bad face index '2abc'");
  expect_error(Write("tl_zero.obj", kTet + "f 1 3 0\nf 1 2 4\nf 2 3 4\nf 1 4 3\n"), "bad face index '0'");
  expect_error(Write("tl_mesh.stl", "solid"), "unknown mesh format");
  // Binary PLY took NaN coordinates (OBJ refused them): both refuse any non-finite vertex (PLY
  // vertices named by their index, from 0, as its faces name them).
  std::string bin = "ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                    "property float z\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n";
  const float xyz[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, NAN};
  bin.append(reinterpret_cast<const char*>(xyz), sizeof(xyz));
  const int32_t faces[4][3] = {{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {0, 3, 2}};
  for (const auto& f : faces) {
    bin.push_back(char(3));
    bin.append(reinterpret_cast<const char*>(f), sizeof(f));
  }
  expect_error(Write("tl_nan.ply", bin), "vertex index 3 is not finite");
  const std::string ascii_header =
      "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 4\nproperty list uchar int vertex_indices\nend_header\n";
  const std::string tet_faces = "3 0 2 1\n3 0 1 3\n3 1 2 3\n3 0 3 2\n";
  expect_error(Write("tl_inf.ply", ascii_header + "0 0 0\n1 0 0\n0 1 inf\n0 0 1\n" + tet_faces), "vertex index 2 is not finite");
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


// A unit cube's 8 corners and its 6 faces as quads, counter-clockwise seen from outside.
const double kCorners[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
const int kQuads[6][4] = {{0, 3, 2, 1}, {4, 5, 6, 7}, {0, 1, 5, 4}, {2, 3, 7, 6}, {1, 2, 6, 5}, {0, 4, 7, 3}};

std::string Vertex(const double* p, double shift = 0) {
  return fmt::format("v {} {} {}\n", p[0] + shift, p[1], p[2]);
}

// Exporters split vertices along UV seams, and STL conversions repeat every vertex per
// triangle: the cube as a soup of 12 triangles with 36 vertices is welded back to 8 corners.
TEST(MeshIo, UnweldedVerticesAreWelded) {
  std::string obj;
  int n = 0;
  for (const auto& q : kQuads)
    for (const auto& tri : {std::array<int, 3>{q[0], q[1], q[2]}, std::array<int, 3>{q[0], q[2], q[3]}}) {
      for (int c : tri) obj += Vertex(kCorners[c]);
      obj += fmt::format("f {} {} {}\n", n + 1, n + 2, n + 3);
      n += 3;
    }
  std::vector<std::string> repairs;
  const TriangleMesh m = ReadMesh(Write("tl_soup.obj", obj), &repairs);
  EXPECT_EQ(m.vertices.size(), 8u);
  EXPECT_EQ(m.triangles.size(), 12u);
  EXPECT_NEAR(m.Volume(), 1.0, 1e-12);
  ASSERT_EQ(repairs.size(), 1u);
  EXPECT_EQ(repairs[0], "28 vertices at the position of another welded to it (seams split by an exporter)");
  // Two cubes touching at one corner, each with its own vertices: welding makes the corner a
  // bowtie, which is split again into two pieces (as the file had them).
  std::string two;
  for (int cube = 0; cube < 2; ++cube) {
    for (const auto& p : kCorners) {
      const double q[3] = {p[0] + cube, p[1] + cube, p[2] + cube};
      two += Vertex(q);
    }
    for (const auto& f : kQuads)
      two += fmt::format("f {} {} {} {}\n", f[0] + 1 + 8 * cube, f[1] + 1 + 8 * cube, f[2] + 1 + 8 * cube, f[3] + 1 + 8 * cube);
  }
  repairs.clear();
  const TriangleMesh touching = ReadMesh(Write("tl_touching.obj", two), &repairs);
  EXPECT_EQ(touching.Pieces(), 2);
  EXPECT_EQ(touching.vertices.size(), 16u);
  EXPECT_NEAR(touching.Volume(), 2.0, 1e-12);
  EXPECT_EQ(repairs, (std::vector<std::string>{
                         "1 vertices at the position of another welded to it (seams split by an exporter)",
                         "1 welded vertices split again where separate pieces touch"}));
}

// A triangle written as a quad with a repeated corner, and a face "f 1 1 2": dropped corners
// and faces, not a refused mesh, each said (the repeated corners were dropped without a word).
TEST(MeshIo, RepeatedCornersAreDropped) {
  std::vector<std::string> repairs;
  const TriangleMesh m = ReadMesh(Write("tl_repeat.obj", kTet + "f 1 3 2 2\nf 1 2 4\nf 2 3 4 4\nf 1 4 3\nf 1 1 2\n"), &repairs);
  EXPECT_EQ(m.triangles.size(), 4u);
  EXPECT_EQ(repairs, (std::vector<std::string>{"2 faces with a repeated corner: the repeats dropped",
                                                "1 faces with fewer than three distinct corners dropped"}));
  // A face written twice (its edges were 'shared by 3 triangles').
  repairs.clear();
  const TriangleMesh twice = ReadMesh(Write("tl_twice.obj", kTet + "f 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\nf 4 2 3\n"), &repairs);
  EXPECT_EQ(twice.triangles.size(), 4u);
  EXPECT_EQ(repairs, (std::vector<std::string>{"1 triangles written twice dropped"}));
}

// An L-shaped prism whose two caps are single non-convex hexagons: a fan from the first corner
// covers the notch twice (the area counts it twice, the render showed it striped); ear
// clipping covers the L once.
TEST(MeshIo, NonConvexPolygonsAreEarClipped) {
  const double L[6][2] = {{0, 0}, {2, 0}, {2, 1}, {1, 1}, {1, 2}, {0, 2}};  // area 3
  std::string obj;
  for (double z : {0.0, 1.0})
    for (const auto& p : L) obj += fmt::format("v {} {} {}\n", p[0], p[1], z);
  // Start the fan at the reflex corner's neighbour so that a fan would overlap.
  obj += "f 3 2 1 6 5 4\nf 9 10 11 12 7 8\n";
  for (int i = 0; i < 6; ++i) {
    const int a = i + 1, b = (i + 1) % 6 + 1;
    obj += fmt::format("f {} {} {} {}\n", a, b, b + 6, a + 6);
  }
  std::vector<std::string> repairs;
  const TriangleMesh m = ReadMesh(Write("tl_ell.obj", obj), &repairs);
  EXPECT_NEAR(m.Volume(), 3.0, 1e-12);
  EXPECT_NEAR(m.Area(), 2 * 3.0 + 8.0, 1e-12);  // two caps and the sides (perimeter 8, height 1)
  EXPECT_EQ(repairs, (std::vector<std::string>{"2 non-convex polygons triangulated by ear clipping"}));
}

// One face of a tetrahedron written the other way round is turned; a mesh with no consistent
// inside (the 6-vertex projective plane, a closed non-orientable surface) is refused.
TEST(MeshIo, OrientationIsMadeConsistent) {
  std::vector<std::string> repairs;
  const TriangleMesh m = ReadMesh(Write("tl_flipped.obj", kTet + "f 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 3 4\n"), &repairs);
  EXPECT_EQ(m.Validate(), "");
  EXPECT_EQ(repairs, (std::vector<std::string>{"1 triangles turned to face the way their neighbours do"}));
  std::string rp2;
  for (int i = 0; i < 6; ++i) rp2 += fmt::format("v {} {} {}\n", std::cos(i), std::sin(i), 0.1 * i * i);
  for (const char* f : {"1 2 3", "1 3 4", "1 4 5", "1 5 6", "1 6 2", "2 3 5", "3 4 6", "4 5 2", "5 6 3", "6 2 4"})
    rp2 += std::string("f ") + f + "\n";
  try {
    ReadMesh(Write("tl_rp2.obj", rp2));
    ADD_FAILURE() << "a non-orientable mesh was read";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("tl_rp2.obj: the mesh is not orientable"), std::string::npos) << e.what();
  }
}

// Errors name vertices as the file numbers them and faces by their OBJ line or PLY index.
TEST(MeshIo, ErrorsUseTheFilesNumbers) {
  try {
    ReadMesh(Write("tl_hole.obj", "v 9 9 9\n" + kTet + "# a comment\nf 2 4 3\nf 2 3 5\nf 3 4 5\n"));
    ADD_FAILURE();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("the mesh is open: the edge between vertex 2 and vertex 4 belongs to "
                                         "the face on line 7 only"), std::string::npos) << e.what();
  }
  const std::string header =
      "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
      "property float z\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n";
  try {
    ReadMesh(Write("tl_range.ply", header + "0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 1 2 7\n3 0 3 2\n"));
    ADD_FAILURE();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("face 2: vertex number 7 is out of range (4 vertices)"), std::string::npos)
        << e.what();
  }
}

// What other exporters write: comments after a record, "\" continuations, PLY triangle
// strips; and a point cloud says what it is.
TEST(MeshIo, CommentsContinuationsStripsAndPointClouds) {
  const TriangleMesh m = ReadMesh(Write("tl_cont.obj", kTet + "f 1 3 2 # bottom\nf 1 2 \\\n 4\nf 2 3 4\nf 1 4 3\n"));
  EXPECT_EQ(m.triangles.size(), 4u);
  EXPECT_EQ(m.Validate(), "");
  const std::string header =
      "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n";
  const TriangleMesh strip = ReadMesh(Write("tl_strip.ply", header +
      "element tristrips 1\nproperty list int int vertex_indices\nend_header\n"
      "0 0 0\n1 0 0\n0 1 0\n0 0 1\n9 0 1 2 3 -1 2 3 0 1\n"));  // two strips of two triangles
  EXPECT_EQ(strip.triangles.size(), 4u);
  EXPECT_EQ(strip.Validate(), "");
  EXPECT_NEAR(std::abs(strip.Volume()), 1.0 / 6, 1e-12);
  try {
    ReadMesh(Write("tl_cloud.ply", header + "end_header\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n"));
    ADD_FAILURE();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("no faces (no 'face' or 'tristrips' element): a point cloud?"),
              std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace translume
