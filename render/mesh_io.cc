// SPDX-License-Identifier: MIT
#include "render/mesh_io.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <climits>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fmt/format.h>
#include <fstream>
#include <map>
#include <numeric>
#include <set>
#include <sstream>
#include <unordered_map>

#include "solver/parse.h"
#include "solver/status.h"

namespace translume {
namespace {

// A mesh as its file holds it: polygons over the file's vertices.
struct MeshFile {
  std::vector<Vec3> vertices;
  std::vector<std::vector<int>> faces;  // 0-based vertex indices, three or more
  std::vector<int64_t> face_rows;       // per face: its OBJ line, or its PLY face / strip row
  std::vector<char> from_strip;         // per face: a triangle of a PLY strip (empty: none)
  bool obj = false;                     // OBJ numbers vertices from 1, PLY from 0

  std::string Vertex(int v) const {
    return obj ? fmt::format("vertex {}", int64_t(v) + 1) : fmt::format("vertex index {}", v);
  }
  std::string Face(size_t f) const {
    if (obj) return fmt::format("the face on line {}", face_rows[f]);
    if (f < from_strip.size() && from_strip[f]) return fmt::format("a triangle of tristrips row {}", face_rows[f]);
    return fmt::format("face {}", face_rows[f]);
  }
};

// The triangles of PLY triangle strips (-1 between strips; every other triangle turned, so
// that all face the way the first does).
void AppendStrips(const std::vector<int>& indices, int64_t row, MeshFile* m) {
  m->from_strip.resize(m->faces.size(), 0);
  size_t start = 0;
  for (size_t i = 0; i <= indices.size(); ++i) {
    if (i < indices.size() && indices[i] >= 0) continue;
    for (size_t k = start; k + 2 < i; ++k) {
      const bool odd = (k - start) % 2 == 1;
      m->faces.push_back({indices[odd ? k + 1 : k], indices[odd ? k : k + 1], indices[k + 2]});
      m->face_rows.push_back(row);
      m->from_strip.push_back(1);
    }
    start = i + 1;
  }
}

[[noreturn]] void MeshError(const std::string& path, const std::string& what) {
  throw InputError(path + ": " + what);
}

MeshFile ReadObj(const std::string& path, std::istream& in) {
  MeshFile m;
  m.obj = true;
  std::string line, more;
  int64_t line_no = 0;
  while (std::getline(in, line)) {
    const int64_t first_line = ++line_no;
    if (line_no == 1 && line.rfind("\xEF\xBB\xBF", 0) == 0) line.erase(0, 3);  // a UTF-8 byte order mark
    if (!line.empty() && line.back() == '\r') line.pop_back();
    // A backslash at the end continues the record on the next line.
    while (!line.empty() && line.back() == '\\' && std::getline(in, more)) {
      ++line_no;
      if (!more.empty() && more.back() == '\r') more.pop_back();
      line.back() = ' ';
      line += more;
    }
    if (const size_t hash = line.find('#'); hash != std::string::npos) line.erase(hash);
    std::istringstream ls(line);
    std::string tag;
    if (!(ls >> tag)) continue;
    if (tag == "v") {
      Vec3 v;
      if (!(ls >> v.x() >> v.y() >> v.z()))
        MeshError(path, "line " + std::to_string(first_line) + ": bad vertex");
      m.vertices.push_back(v);
    } else if (tag == "f") {
      std::vector<int> f;
      std::string tok;
      while (ls >> tok) {
        int idx = 0;
        const std::string vertex = tok.substr(0, tok.find('/'));
        size_t used = 0;
        try {
          idx = std::stoi(vertex, &used);
        } catch (...) {
        }
        if (vertex.empty() || used != vertex.size() || idx == 0)
          MeshError(path, "line " + std::to_string(first_line) + ": bad face index '" + tok + "'");
        f.push_back(idx < 0 ? int(m.vertices.size()) + idx : idx - 1);
      }
      if (f.size() < 3) MeshError(path, "line " + std::to_string(first_line) + ": face with < 3 vertices");
      m.faces.push_back(std::move(f));
      m.face_rows.push_back(first_line);
    }
  }
  if (m.vertices.empty() || m.faces.empty())
    MeshError(path, "no vertices ('v' lines) or no faces ('f' lines): not an OBJ mesh");
  return m;
}

// PLY: the vertex x/y/z properties and the face vertex_indices list (or tristrips).
MeshFile ReadPly(const std::string& path, std::istream& in) {
  std::string line, word;
  in.seekg(0, std::ios::end);
  const int64_t file_bytes = int64_t(in.tellg());
  in.seekg(0);
  std::getline(in, line);
  if (line.rfind("ply", 0) != 0) MeshError(path, "not a PLY file (no 'ply' magic)");
  // Bytes per value of each scalar type (binary files).
  const std::map<std::string, int> type_bytes = {
      {"char", 1}, {"int8", 1}, {"uchar", 1}, {"uint8", 1}, {"short", 2}, {"int16", 2},
      {"ushort", 2}, {"uint16", 2}, {"int", 4}, {"int32", 4}, {"uint", 4}, {"uint32", 4},
      {"float", 4}, {"float32", 4}, {"double", 8}, {"float64", 8}};
  const auto check_type = [&](const std::string& type) {
    if (!type_bytes.count(type)) MeshError(path, "unsupported PLY property type '" + type + "'");
  };
  bool binary = false, big_endian = false;
  struct Prop { std::string type, name, count_type; bool list = false; };
  struct Element { std::string name; int64_t count = 0; std::vector<Prop> props; };
  std::vector<Element> elements;
  while (std::getline(in, line)) {
    std::istringstream ls(line);
    word.clear();  // a blank line must not repeat the previous keyword
    ls >> word;
    if (word == "format") {
      ls >> word;
      if (word == "binary_little_endian" || word == "binary_big_endian") {
        binary = true;
        big_endian = word == "binary_big_endian";
      } else if (word != "ascii") MeshError(path, "unsupported PLY format '" + word + "'");
    } else if (word == "element") {
      Element e;
      std::string count;
      ls >> e.name >> count;
      const auto n = WholeNumbers(count, "");
      if (n) e.count = (*n)[0];
      // Every element takes at least a byte of the file: a larger count is no PLY data.
      if (!n || e.count < 0 || e.count > file_bytes)
        MeshError(path, "PLY element '" + e.name + "' has count '" + count +
                            "', not a whole number within the file's size");
      elements.push_back(e);
    } else if (word == "property") {
      if (elements.empty()) MeshError(path, "PLY property before any element");
      Prop p;
      ls >> p.type;
      if (p.type == "list") {
        p.list = true;
        ls >> p.count_type >> p.type;
      }
      ls >> p.name;
      check_type(p.type);
      if (p.list) check_type(p.count_type);
      elements.back().props.push_back(p);
    } else if (word == "end_header") {
      break;
    }
  }
  const uint16_t one = 1;
  const bool host_big_endian = *reinterpret_cast<const uint8_t*>(&one) == 0;
  for (const Element& e : elements)
    if (e.name == "vertex")
      for (const char* axis : {"x", "y", "z"})
        if (std::none_of(e.props.begin(), e.props.end(), [&](const Prop& p) { return !p.list && p.name == axis; }))
          MeshError(path, std::string("PLY vertices have no property '") + axis + "'");
  auto read_value = [&](const std::string& type) -> double {
    if (!binary) {
      std::string text;
      if (!(in >> text)) MeshError(path, "PLY data ends early");
      double v = 0;
      try {
        size_t used = 0;
        v = std::stod(text, &used);
        if (used != text.size()) throw std::invalid_argument(text);
      } catch (const std::exception&) {
        MeshError(path, "PLY value '" + text + "' is not a number");
      }
      return v;
    }
    auto get = [&](auto x) {
      char bytes[sizeof(x)];
      in.read(bytes, sizeof(x));
      if (!in) MeshError(path, "PLY data ends early");
      if (big_endian != host_big_endian) std::reverse(bytes, bytes + sizeof(x));
      std::memcpy(&x, bytes, sizeof(x));
      return double(x);
    };
    if (type == "char" || type == "int8") return get(int8_t());
    if (type == "uchar" || type == "uint8") return get(uint8_t());
    if (type == "short" || type == "int16") return get(int16_t());
    if (type == "ushort" || type == "uint16") return get(uint16_t());
    if (type == "int" || type == "int32") return get(int32_t());
    if (type == "uint" || type == "uint32") return get(uint32_t());
    if (type == "float" || type == "float32") return get(float());
    if (type == "double" || type == "float64") return get(double());
    MeshError(path, "unsupported PLY property type '" + type + "'");
  };
  // A tristrips entry: a vertex index, or -1 between two strips.
  const auto read_strip_index = [&](const std::string& type) {
    const double v = read_value(type);
    if (!(v >= -1 && v <= INT_MAX && v == std::floor(v)))
      MeshError(path, fmt::format("PLY tristrips index {} is neither -1 nor a vertex index", v));
    return int64_t(v);
  };
  // A list's count or a vertex index: a whole number within 0..most.
  const auto read_whole = [&](const std::string& type, double most, const char* what) {
    const double v = read_value(type);
    if (!(v >= 0 && v <= most && v == std::floor(v)))
      MeshError(path, fmt::format("PLY {} {} is not a whole number within 0..{:.0f}", what, v, most));
    return int64_t(v);
  };
  MeshFile m;
  for (const Element& e : elements) {
    for (int64_t r = 0; r < e.count; ++r) {
      Vec3 v = Vec3::Zero();
      for (const Prop& p : e.props) {
        if (p.list) {
          const int64_t n = read_whole(p.count_type, INT_MAX, "list length");
          // Each entry takes its bytes (binary), or a digit and a space (ascii), of what is left
          // (a count of 2^31 allocated 8 GB before the data ran out).
          if (n > 64) {
            const int64_t left = file_bytes - int64_t(in.tellg());
            if (n > (binary ? left / type_bytes.at(p.type) : left / 2))
              MeshError(path, fmt::format("PLY list length {} is longer than the rest of the file", n));
          }
          const bool indices = (e.name == "face" || e.name == "tristrips") &&
                               (p.name == "vertex_indices" || p.name == "vertex_index");
          std::vector<int> f(size_t(n), 0);
          for (int64_t i = 0; i < n; ++i) {
            if (!indices) read_value(p.type);
            else if (e.name == "face") f[size_t(i)] = int(read_whole(p.type, INT_MAX, "vertex index"));
            else f[size_t(i)] = int(read_strip_index(p.type));
          }
          if (indices && e.name == "face") {
            if (n < 3) MeshError(path, fmt::format("face {}: fewer than 3 vertices", r));
            m.faces.push_back(std::move(f));
            m.face_rows.push_back(r);
          }
          if (indices && e.name == "tristrips") AppendStrips(f, r, &m);
        } else {
          const double x = read_value(p.type);
          if (e.name == "vertex" && p.name.size() == 1 && p.name[0] >= 'x' && p.name[0] <= 'z')
            v[p.name[0] - 'x'] = x;
        }
      }
      if (e.name == "vertex") m.vertices.push_back(v);
    }
  }
  if (m.faces.empty())
    MeshError(path, m.vertices.empty() ? "no vertices and no faces: not a PLY mesh"
                                       : "no faces (no 'face' or 'tristrips' element): a point cloud? "
                                         "A closed triangle mesh is needed");
  return m;
}


// Appends the triangles of the polygon `corners` (indices into `v`): a fan from the first
// corner where it is convex, else ear clipping in its plane (Newell's normal, about the
// centroid). Returns whether ear clipping was used.
bool Triangulate(const std::vector<Vec3>& v, const std::vector<int>& corners,
                 std::vector<std::array<int, 3>>* out) {
  const size_t n = corners.size();
  const auto fan = [&](const std::vector<int>& c) {
    for (size_t i = 1; i + 1 < c.size(); ++i) out->push_back({c[0], c[i], c[i + 1]});
  };
  if (n == 3) {
    fan(corners);
    return false;
  }
  Vec3 centroid = Vec3::Zero();
  for (int c : corners) centroid += v[size_t(c)];
  centroid /= double(n);
  Vec3 normal = Vec3::Zero();
  double extent = 0;
  for (size_t i = 0; i < n; ++i) {
    const Vec3 a = v[size_t(corners[i])] - centroid, b = v[size_t(corners[(i + 1) % n])] - centroid;
    normal += a.cross(b);
    extent = std::max(extent, a.norm());
  }
  if (!(normal.norm() > 0)) {
    fan(corners);
    return false;
  }
  normal.normalize();
  const Vec3 u = normal.unitOrthogonal(), w = normal.cross(u);
  std::vector<Eigen::Vector2d> p(n);
  for (size_t i = 0; i < n; ++i) {
    const Vec3 d = v[size_t(corners[i])] - centroid;
    p[i] = {d.dot(u), d.dot(w)};
  }
  // Twice the signed area of (a, b, c): > 0 where it turns like the polygon (counter-clockwise).
  const auto turn = [&](size_t a, size_t b, size_t c) {
    const Eigen::Vector2d ab = p[b] - p[a], ac = p[c] - p[a];
    return ab.x() * ac.y() - ab.y() * ac.x();
  };
  const double eps = 1e-12 * extent * extent;
  bool convex = true;
  for (size_t i = 0; i < n && convex; ++i) convex = turn((i + n - 1) % n, i, (i + 1) % n) >= -eps;
  if (convex) {
    fan(corners);
    return false;
  }
  std::vector<size_t> ring(n);
  std::iota(ring.begin(), ring.end(), size_t(0));
  while (ring.size() > 3) {
    bool clipped = false;
    for (size_t k = 0; k < ring.size() && !clipped; ++k) {
      const size_t a = ring[(k + ring.size() - 1) % ring.size()], b = ring[k], c = ring[(k + 1) % ring.size()];
      if (turn(a, b, c) <= eps) continue;  // a reflex or straight corner is no ear
      bool empty = true;
      for (size_t q : ring)
        if (q != a && q != b && q != c && turn(a, b, q) >= -eps && turn(b, c, q) >= -eps && turn(c, a, q) >= -eps) {
          empty = false;
          break;
        }
      if (!empty) continue;
      out->push_back({corners[a], corners[b], corners[c]});
      ring.erase(ring.begin() + long(k));
      clipped = true;
    }
    if (!clipped) break;  // self-intersecting: the rest as a fan
  }
  std::vector<int> rest;
  for (size_t q : ring) rest.push_back(corners[q]);
  fan(rest);
  return true;
}

// Welding: vertices within 1e-7 of the bounding box's diagonal of an earlier one are that
// vertex (exporters write a seam's copies alike, or within a rounding of each other).
constexpr double kWeldDistance = 1e-7;

struct CellHash {
  size_t operator()(const std::array<int64_t, 3>& c) const {
    return size_t(c[0] * 73856093) ^ size_t(c[1] * 19349663) ^ size_t(c[2] * 83492791);
  }
};

// rep[v]: the first vertex within `eps` of vertex v (v itself if none), over grid cells of
// side eps and their 26 neighbours.
std::vector<int> WeldMap(const std::vector<Vec3>& vertices) {
  std::vector<int> rep(vertices.size());
  std::iota(rep.begin(), rep.end(), 0);
  if (vertices.empty()) return rep;
  Vec3 lo = vertices[0], hi = vertices[0];
  for (const Vec3& p : vertices) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
  const double eps = kWeldDistance * (hi - lo).norm();
  if (!(eps > 0)) return rep;
  std::unordered_map<std::array<int64_t, 3>, std::vector<int>, CellHash> cells;
  cells.reserve(vertices.size());
  for (size_t v = 0; v < vertices.size(); ++v) {
    const Vec3 q = (vertices[v] - lo) / eps;
    const std::array<int64_t, 3> c = {int64_t(q.x()), int64_t(q.y()), int64_t(q.z())};
    bool found = false;
    for (int64_t dz = -1; dz <= 1 && !found; ++dz)
      for (int64_t dy = -1; dy <= 1 && !found; ++dy)
        for (int64_t dx = -1; dx <= 1 && !found; ++dx) {
          const auto it = cells.find({c[0] + dx, c[1] + dy, c[2] + dz});
          if (it == cells.end()) continue;
          for (int r : it->second)
            if ((vertices[size_t(r)] - vertices[v]).norm() <= eps) {
              rep[v] = r;
              found = true;
              break;
            }
        }
    if (!found) cells[c].push_back(int(v));
  }
  return rep;
}

int Find(std::vector<int>& parent, int x) {
  while (parent[size_t(x)] != x) x = parent[size_t(x)] = parent[size_t(parent[size_t(x)])];
  return x;
}

// The repairs and checks of ReadMesh (mesh_io.h), in its order.
TriangleMesh Repair(const std::string& path, const MeshFile& f, std::vector<std::string>* repairs) {
  for (size_t v = 0; v < f.vertices.size(); ++v)
    if (!f.vertices[v].allFinite()) MeshError(path, f.Vertex(int(v)) + " is not finite");
  const auto note = [&](int64_t count, const std::string& what) {
    if (count > 0 && repairs) repairs->push_back(fmt::format("{} {}", count, what));
  };

  // Triangles, each with the face it came from.
  TriangleMesh m;
  std::vector<size_t> source;
  int64_t short_faces = 0, ear_clipped = 0, repeated_corners = 0;
  std::vector<int> corners;
  for (size_t i = 0; i < f.faces.size(); ++i) {
    corners.clear();
    for (int v : f.faces[i]) {
      if (v < 0 || v >= int(f.vertices.size()))
        MeshError(path, fmt::format("{}: vertex number {} is out of range ({} vertices)", f.Face(i),
                                    f.obj ? int64_t(v) + 1 : int64_t(v), f.vertices.size()));
      if (corners.empty() || corners.back() != v) corners.push_back(v);
    }
    while (corners.size() > 1 && corners.back() == corners.front()) corners.pop_back();
    if (corners.size() < 3) {
      ++short_faces;
      continue;
    }
    repeated_corners += corners.size() < f.faces[i].size();
    ear_clipped += Triangulate(f.vertices, corners, &m.triangles);
    source.resize(m.triangles.size(), i);
  }
  note(ear_clipped, "non-convex polygons triangulated by ear clipping");
  note(repeated_corners, "faces with a repeated corner: the repeats dropped");
  note(short_faces, "faces with fewer than three distinct corners dropped");

  // Weld vertices at one position; drop the triangles that this (or a polygon's repeated
  // corner) leaves with a repeated vertex.
  const std::vector<int> rep = WeldMap(f.vertices);
  std::vector<char> used(f.vertices.size(), 0);
  for (const auto& t : m.triangles)
    for (int c : t) used[size_t(c)] = 1;
  int64_t welded = 0, repeated = 0;  // welded: the used vertices less their distinct positions
  {
    std::vector<char> rep_used(f.vertices.size(), 0);
    for (size_t v = 0; v < used.size(); ++v)
      if (used[v]) {
        ++welded;
        rep_used[size_t(rep[v])] = 1;
      }
    welded -= std::count(rep_used.begin(), rep_used.end(), 1);
  }
  {
    size_t kept = 0;
    for (size_t t = 0; t < m.triangles.size(); ++t) {
      std::array<int, 3> tri = m.triangles[t];
      for (int& c : tri) c = rep[size_t(c)];
      if (tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2]) {
        ++repeated;
        continue;
      }
      m.triangles[kept] = tri;
      source[kept++] = source[t];
    }
    m.triangles.resize(kept);
    source.resize(kept);
  }
  note(welded, "vertices at the position of another welded to it (seams split by an exporter)");
  note(repeated, "triangles with a repeated vertex dropped");
  // A face written twice (same corners, same way round) is one face.
  {
    std::set<std::array<int, 3>> seen;
    size_t kept = 0;
    int64_t twice = 0;
    for (size_t t = 0; t < m.triangles.size(); ++t) {
      std::array<int, 3> key = m.triangles[t];
      std::rotate(key.begin(), std::min_element(key.begin(), key.end()), key.end());
      if (!seen.insert(key).second) {
        ++twice;
        continue;
      }
      m.triangles[kept] = m.triangles[t];
      source[kept++] = source[t];
    }
    m.triangles.resize(kept);
    source.resize(kept);
    note(twice, "triangles written twice dropped");
  }

  // Keep the vertices that triangles use, in the file's order, and what the file calls each.
  std::vector<int> index(f.vertices.size(), -1), file_vertex;
  for (const auto& t : m.triangles)
    for (int c : t) index[size_t(c)] = 0;
  for (size_t v = 0; v < index.size(); ++v)
    if (index[v] == 0) {
      index[v] = int(m.vertices.size());
      m.vertices.push_back(f.vertices[v]);
      file_vertex.push_back(int(v));
    }
  for (auto& t : m.triangles)
    for (int& c : t) c = index[size_t(c)];
  std::vector<char> is_weld(m.vertices.size(), 0);
  for (size_t v = 0; v < used.size(); ++v)
    if (used[v] && rep[v] != int(v) && index[size_t(rep[v])] >= 0) is_weld[size_t(index[size_t(rep[v])])] = 1;
  const auto name = [&](int v) { return f.Vertex(file_vertex[size_t(v)]); };
  // Where welding joined vertices, an error below may come from it (coordinates rounded too
  // coarsely for the mesh's size: float32 far from the origin).
  const std::string after_welding =
      welded > 0 ? fmt::format(" (after welding {} vertices to others at their position)", welded) : "";

  // Edges: every one shared by exactly two triangles.
  struct Side { int lo, hi; int32_t tri; bool forward; };
  std::vector<Side> sides;
  sides.reserve(3 * m.triangles.size());
  for (size_t t = 0; t < m.triangles.size(); ++t)
    for (int c = 0; c < 3; ++c) {
      const int a = m.triangles[t][c], b = m.triangles[t][(c + 1) % 3];
      sides.push_back({std::min(a, b), std::max(a, b), int32_t(t), a < b});
    }
  std::sort(sides.begin(), sides.end(), [](const Side& x, const Side& y) {
    return std::tie(x.lo, x.hi, x.tri) < std::tie(y.lo, y.hi, y.tri);
  });
  std::vector<std::array<int32_t, 3>> across(m.triangles.size(), {-1, -1, -1});
  std::vector<std::array<char, 3>> same_way(m.triangles.size());
  const auto slot = [&](int32_t t, int lo, int hi) {
    for (int c = 0; c < 3; ++c) {
      const int a = m.triangles[size_t(t)][c], b = m.triangles[size_t(t)][(c + 1) % 3];
      if (std::min(a, b) == lo && std::max(a, b) == hi) return c;
    }
    return 0;
  };
  for (size_t i = 0; i < sides.size();) {
    size_t j = i;
    while (j < sides.size() && sides[j].lo == sides[i].lo && sides[j].hi == sides[i].hi) ++j;
    const std::string edge = fmt::format("the edge between {} and {}", name(sides[i].lo), name(sides[i].hi));
    if (j - i == 1)
      MeshError(path, fmt::format("the mesh is open: {} belongs to {} only{}", edge,
                                  f.Face(source[size_t(sides[i].tri)]), after_welding));
    if (j - i > 2)
      MeshError(path, fmt::format("non-manifold edge: {} is shared by {} triangles (first {}){}", edge, j - i,
                                  f.Face(source[size_t(sides[i].tri)]), after_welding));
    const Side& x = sides[i];
    const Side& y = sides[i + 1];
    const int cx = slot(x.tri, x.lo, x.hi), cy = slot(y.tri, y.lo, y.hi);
    across[size_t(x.tri)][size_t(cx)] = y.tri;
    across[size_t(y.tri)][size_t(cy)] = x.tri;
    same_way[size_t(x.tri)][size_t(cx)] = same_way[size_t(y.tri)][size_t(cy)] = x.forward == y.forward;
    i = j;
  }

  // Orientation: flip a triangle that runs an edge the same way as its neighbour, piece by
  // piece; each piece keeps the orientation most of its triangles have in the file.
  std::vector<int8_t> flip(m.triangles.size(), -1);
  int64_t flipped = 0;
  std::vector<int32_t> piece, stack;
  for (size_t seed = 0; seed < m.triangles.size(); ++seed) {
    if (flip[seed] >= 0) continue;
    piece.clear();
    flip[seed] = 0;
    stack.assign(1, int32_t(seed));
    while (!stack.empty()) {
      const int32_t t = stack.back();
      stack.pop_back();
      piece.push_back(t);
      for (int c = 0; c < 3; ++c) {
        const int32_t u = across[size_t(t)][size_t(c)];
        const int8_t want = int8_t(flip[size_t(t)] ^ same_way[size_t(t)][size_t(c)]);
        if (flip[size_t(u)] < 0) {
          flip[size_t(u)] = want;
          stack.push_back(u);
        } else if (flip[size_t(u)] != want) {
          const auto& tri = m.triangles[size_t(t)];
          MeshError(path, fmt::format("the mesh is not orientable (no consistent inside and outside: a Klein "
                                      "bottle or a surface through itself), found at the edge between {} and {}{}",
                                      name(tri[c]), name(tri[(c + 1) % 3]), after_welding));
        }
      }
    }
    int64_t ones = 0;
    for (int32_t t : piece) ones += flip[size_t(t)];
    const bool invert = 2 * ones > int64_t(piece.size());
    for (int32_t t : piece) {
      flip[size_t(t)] = int8_t(flip[size_t(t)] ^ invert);
      if (flip[size_t(t)]) std::swap(m.triangles[size_t(t)][1], m.triangles[size_t(t)][2]);
    }
    flipped += invert ? int64_t(piece.size()) - ones : ones;
  }
  note(flipped, "triangles turned to face the way their neighbours do");

  // Fans: the corners of one vertex joined across the edges they share. A vertex with more
  // than one is where pieces touch: split if welding made it, else refused.
  std::vector<int> parent(3 * m.triangles.size());
  std::iota(parent.begin(), parent.end(), 0);
  for (size_t t = 0; t < m.triangles.size(); ++t)
    for (const int32_t u : across[t])  // (the flips above reordered corners: match by vertex)
      for (int ct = 0; ct < 3; ++ct)
        for (int cu = 0; cu < 3; ++cu)
          if (m.triangles[t][ct] == m.triangles[size_t(u)][cu])
            parent[size_t(Find(parent, int(3 * t) + ct))] = Find(parent, 3 * u + cu);
  std::vector<int> fan_vertex(parent.size(), -1);  // per fan root: the vertex it uses
  std::vector<int> first_fan(m.vertices.size(), -1);
  int64_t split = 0;
  for (size_t t = 0; t < m.triangles.size(); ++t)
    for (int c = 0; c < 3; ++c) {
      const int v = m.triangles[t][c];
      const int root = Find(parent, int(3 * t) + c);
      if (fan_vertex[size_t(root)] < 0) {
        if (first_fan[size_t(v)] < 0) {
          first_fan[size_t(v)] = root;
          fan_vertex[size_t(root)] = v;
        } else if (is_weld[size_t(v)]) {
          fan_vertex[size_t(root)] = int(m.vertices.size());
          m.vertices.push_back(m.vertices[size_t(v)]);
          file_vertex.push_back(file_vertex[size_t(v)]);
          ++split;
        } else {
          MeshError(path, fmt::format("non-manifold {}: the triangles around it form more than one fan "
                                      "(pieces touching at one point)", name(v)));
        }
      }
      m.triangles[t][c] = fan_vertex[size_t(root)];
    }
  note(split, "welded vertices split again where separate pieces touch");
  if (std::string err = m.Validate(); !err.empty()) MeshError(path, err);
  return m;
}

}  // namespace

TriangleMesh ReadMesh(const std::string& path, std::vector<std::string>* repairs) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path + ": cannot open the mesh file");
  const auto dot = path.rfind('.');
  std::string ext = dot == std::string::npos ? "" : path.substr(dot);
  std::transform(ext.begin(), ext.end(), ext.begin(), ::tolower);
  if (ext == ".obj") return Repair(path, ReadObj(path, in), repairs);
  if (ext == ".ply") return Repair(path, ReadPly(path, in), repairs);
  throw InputError(path + ": unknown mesh format (expected .obj or .ply)");
}

void WriteObj(const std::string& path, const TriangleMesh& mesh) {
  std::string s;
  for (const Vec3& v : mesh.vertices)
    s += "v " + std::to_string(v.x()) + " " + std::to_string(v.y()) + " " + std::to_string(v.z()) + "\n";
  for (const auto& t : mesh.triangles)
    s += "f " + std::to_string(t[0] + 1) + " " + std::to_string(t[1] + 1) + " " +
         std::to_string(t[2] + 1) + "\n";
  std::ofstream(path) << s;
}


}  // namespace translume
