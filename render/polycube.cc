// SPDX-License-Identifier: MIT
#include "render/polycube.h"

#include <Eigen/LU>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <fmt/format.h>
#include <tuple>

#include "solver/status.h"

namespace translume {

namespace {

// The largest deviation of axes * axes^T from the identity (0 for a rotation or a reflection).
double OffOrthonormal(const Eigen::Matrix3d& axes) {
  return (axes * axes.transpose() - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
}

}  // namespace

std::array<int, 3> Polycube::Extent() const {
  std::array<int, 3> e = {0, 0, 0};
  for (const auto& c : cubes)
    for (int a = 0; a < 3; ++a) e[a] = std::max(e[a], c[a] + 1);
  return e;
}

bool Polycube::Has(int x, int y, int z) const {
  return std::find(cubes.begin(), cubes.end(), std::array<int, 3>{x, y, z}) != cubes.end();
}

std::string Polycube::Validate() const {
  if (cubes.empty()) return "a polycube needs at least one cube";
  if (!axes.allFinite() || OffOrthonormal(axes) > 1e-6 || axes.determinant() < 0)
    return "the axes must be a rotation (orthonormal rows, right-handed)";
  std::set<std::array<int, 3>> seen;
  for (const auto& c : cubes) {
    for (int a = 0; a < 3; ++a)
      if (c[a] < 0 || c[a] > 1023)
        return "cube coordinates must be in [0, 1023], got " + std::to_string(c[a]);
    if (!seen.insert(c).second)
      return "duplicate cube " + std::to_string(c[0]) + " " + std::to_string(c[1]) + " " +
             std::to_string(c[2]);
  }
  const size_t first_piece = Pieces()[0].cubes.size();
  if (first_piece != cubes.size())
    return "the cubes are not face-connected (" + std::to_string(cubes.size() - first_piece) +
           " cube(s) not reachable from the first)";
  return "";
}

std::vector<Polycube> Polycube::Pieces() const {
  std::map<std::array<int, 3>, int> piece;  // cube -> piece, -1 before the flood fill reaches it
  for (const auto& c : cubes) piece.emplace(c, -1);
  int count = 0;
  for (const auto& c0 : cubes) {
    if (piece[c0] >= 0) continue;
    piece[c0] = count;
    std::vector<std::array<int, 3>> stack = {c0};
    while (!stack.empty()) {
      const auto c = stack.back();
      stack.pop_back();
      for (int a = 0; a < 3; ++a)
        for (int s : {-1, 1}) {
          auto n = c;
          n[a] += s;
          const auto it = piece.find(n);
          if (it != piece.end() && it->second < 0) {
            it->second = count;
            stack.push_back(n);
          }
        }
    }
    ++count;
  }
  std::vector<Polycube> out(static_cast<size_t>(count));
  for (const auto& c : cubes) out[size_t(piece[c])].cubes.push_back(c);
  return out;
}

int Polycube::Genus() const {
  const std::set<std::array<int, 3>> solid(cubes.begin(), cubes.end());
  auto has = [&](int x, int y, int z) { return solid.count({x, y, z}) > 0; };
  // Manifold at every lattice vertex: around it, the filled cells of the 2 x 2 x 2 block form
  // one face-connected group and so do the empty ones.
  std::set<std::array<int, 3>> corners;
  for (const auto& c : cubes)
    for (int k = 0; k < 8; ++k) corners.insert({c[0] + (k & 1), c[1] + (k >> 1 & 1), c[2] + (k >> 2 & 1)});
  for (const auto& v : corners)
    for (bool filled : {true, false}) {
      int groups = 0, seen = 0;
      for (int k = 0; k < 8; ++k) {
        if (seen >> k & 1 || has(v[0] - 1 + (k & 1), v[1] - 1 + (k >> 1 & 1), v[2] - 1 + (k >> 2 & 1)) != filled)
          continue;
        ++groups;
        std::vector<int> stack = {k};
        seen |= 1 << k;
        while (!stack.empty()) {
          const int a = stack.back();
          stack.pop_back();
          for (int bit : {1, 2, 4}) {
            const int b = a ^ bit;
            if (!(seen >> b & 1) &&
                has(v[0] - 1 + (b & 1), v[1] - 1 + (b >> 1 & 1), v[2] - 1 + (b >> 2 & 1)) == filled) {
              seen |= 1 << b;
              stack.push_back(b);
            }
          }
        }
      }
      if (groups > 1) return -1;
    }
  // Exposed faces: F; their corners and unit edges: V, E.
  int64_t faces = 0;
  std::set<std::array<int, 3>> verts;
  std::set<std::array<int, 4>> edges;  // lower end and axis
  for (const auto& c : cubes)
    for (int a = 0; a < 3; ++a)
      for (int side : {0, 1}) {
        auto n = c;
        n[a] += side ? 1 : -1;
        if (solid.count(n)) continue;
        ++faces;
        const int u = (a + 1) % 3, w = (a + 2) % 3;
        auto o = c;
        o[a] += side;
        for (int k = 0; k < 4; ++k) {
          auto p = o;
          p[u] += k & 1;
          p[w] += k >> 1;
          verts.insert(p);
          // The edge along u from p (k = 0, 2) and along w from p (k = 0, 1).
          if (!(k & 1)) edges.insert({p[0], p[1], p[2], u});
          if (!(k >> 1)) edges.insert({p[0], p[1], p[2], w});
        }
      }
  const int64_t euler = int64_t(verts.size()) - int64_t(edges.size()) + faces;
  return int((2 - euler) / 2);
}

Polycube ParsePolycube(const std::string& text, const std::string& what) {
  Polycube p;
  std::istringstream in(text);
  std::string line;
  int line_no = 0, axes_line = 0;
  while (std::getline(in, line)) {
    ++line_no;
    if (auto hash = line.find('#'); hash != std::string::npos) line.resize(hash);
    std::istringstream ls(line);
    std::array<int, 3> c;
    std::string rest;
    if (!(ls >> std::ws) || ls.eof()) continue;
    std::string first;
    std::istringstream(line) >> first;
    if (first == "axes") {
      const std::string at = what + ":" + std::to_string(line_no) + ": ";
      if (axes_line) throw InputError(at + "a second axes line (the first is line " + std::to_string(axes_line) + ")");
      axes_line = line_no;
      ls >> first;
      for (int k = 0; k < 9; ++k)
        if (!(ls >> p.axes(k / 3, k % 3)) || !std::isfinite(p.axes(k / 3, k % 3)))
          throw InputError(at + "expected \"axes\" and nine numbers (the lattice's x, y and z axes), got '" + line + "'");
      if (ls >> rest) throw InputError(at + "expected nine numbers after \"axes\", got more: '" + line + "'");
      // Three unit vectors, perpendicular and right-handed, to three digits (hand-written
      // cosines); then made orthonormal (the nearest rotation) unless they are to round-off
      // (FormatPolycube's 17 digits read back as written).
      const double off = OffOrthonormal(p.axes);
      if (off > 1e-3)
        throw InputError(at + "the axes must be unit vectors at right angles, to three digits (their dot "
                         "products are off by " + fmt::format("{:.3g}", off) + ")");
      if (p.axes.determinant() < 0)
        throw InputError(at + "the axes must be right-handed (x cross y = z); reverse one of them");
      if (off > 1e-12) {
        const Eigen::JacobiSVD<Eigen::Matrix3d> svd(p.axes, Eigen::ComputeFullU | Eigen::ComputeFullV);
        p.axes = svd.matrixU() * svd.matrixV().transpose();
      }
      continue;
    }
    if (!(ls >> c[0] >> c[1] >> c[2]) || (ls >> rest))
      throw InputError(what + ":" + std::to_string(line_no) +
                       ": expected three integers \"x y z\" per cube, got '" + line + "'");
    p.cubes.push_back(c);
  }
  if (std::string err = p.Validate(); !err.empty()) throw InputError(what + ": " + err);
  // Only the cubes' arrangement matters: the lattice starts at 0 on every axis whatever the
  // file's offset (a polycube one cube over from the origin built a different, folded grid).
  std::array<int, 3> lo = p.cubes[0];
  for (const auto& c : p.cubes)
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], c[a]);
  for (auto& c : p.cubes)
    for (int a = 0; a < 3; ++a) c[a] -= lo[a];
  return p;
}

Polycube ReadPolycube(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw InputError(path + ": cannot open the polycube file");
  std::stringstream ss;
  ss << in.rdbuf();
  return ParsePolycube(ss.str(), path);
}

std::string FormatPolycube(const Polycube& polycube) {
  std::string s;
  if (polycube.axes != Eigen::Matrix3d::Identity()) {
    s = "# the lattice's x, y and z axes in the shape's coordinates\naxes";
    for (int k = 0; k < 9; ++k) s += fmt::format(" {:.17g}", polycube.axes(k / 3, k % 3));
    s += "\n";
  }
  s += "# polycube: one unit cube per line, x y z\n";
  for (const auto& c : polycube.cubes)
    s += std::to_string(c[0]) + " " + std::to_string(c[1]) + " " + std::to_string(c[2]) + "\n";
  return s;
}

namespace {

// The built-in bunny: 253 unit cubes (the cube count of the paper's Bunny polygrid, Table III),
// grown face by face from the best cube of a lattice of 11 x 7 x 10 cells, always adding the
// free face neighbour with the highest f, the largest of 1 - |(p - c) / r|^2 over ellipsoids
// (p: the cell centre, in cube units; c, r: centre and radii) for the body, head, two ears and
// tail. Face-connected by construction; deterministic.
Polycube BunnyPolycube() {
  struct Ellipsoid {
    double c[3], r[3];
  };
  const Ellipsoid parts[] = {
      {{4.5, 3.5, 2.8}, {3.9, 2.9, 2.7}},  // body
      {{8.2, 3.5, 5.2}, {2.1, 1.9, 1.9}},  // head
      {{7.6, 2.6, 7.8}, {0.9, 0.7, 2.2}},  // ears
      {{7.6, 4.4, 7.8}, {0.9, 0.7, 2.2}},
      {{0.7, 3.5, 3.4}, {0.9, 0.9, 0.9}},  // tail
  };
  const int nx = 11, ny = 7, nz = 10;
  auto f = [&](int x, int y, int z) {
    double best = -1e300;
    for (const Ellipsoid& e : parts) {
      const double p[3] = {x + 0.5, y + 0.5, z + 0.5};
      double r2 = 0;
      for (int a = 0; a < 3; ++a) r2 += (p[a] - e.c[a]) * (p[a] - e.c[a]) / (e.r[a] * e.r[a]);
      best = std::max(best, 1 - r2);
    }
    return best;
  };
  std::vector<char> in(nx * ny * nz, 0);
  auto idx = [&](int x, int y, int z) { return x + nx * (y + ny * z); };
  Polycube p;
  std::array<int, 3> start = {0, 0, 0};
  for (int z = 0; z < nz; ++z)
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x)
        if (f(x, y, z) > f(start[0], start[1], start[2])) start = {x, y, z};
  p.cubes.push_back(start);
  in[idx(start[0], start[1], start[2])] = 1;
  while (p.cubes.size() < 253) {
    std::array<int, 3> best = {-1, -1, -1};
    double best_f = -1e300;
    for (const auto& c : p.cubes)
      for (int dir = 0; dir < 6; ++dir) {
        std::array<int, 3> g = c;
        g[dir / 2] += dir % 2 ? 1 : -1;
        if (g[0] < 0 || g[1] < 0 || g[2] < 0 || g[0] >= nx || g[1] >= ny || g[2] >= nz) continue;
        if (in[idx(g[0], g[1], g[2])]) continue;
        const double v = f(g[0], g[1], g[2]);
        if (v > best_f || (v == best_f && g < best)) best_f = v, best = g;
      }
    in[idx(best[0], best[1], best[2])] = 1;
    p.cubes.push_back(best);
  }
  // Shift to the origin.
  std::array<int, 3> lo = p.cubes[0];
  for (const auto& c : p.cubes)
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], c[a]);
  for (auto& c : p.cubes)
    for (int a = 0; a < 3; ++a) c[a] -= lo[a];
  std::sort(p.cubes.begin(), p.cubes.end(), [](const auto& a, const auto& b) {
    return std::tie(a[2], a[1], a[0]) < std::tie(b[2], b[1], b[0]);
  });
  return p;
}

}  // namespace

Polycube BuiltinPolycube(const std::string& shape) {
  Polycube p;
  if (shape == "bunny") return BunnyPolycube();
  if (shape == "sphere" || shape == "blob" || shape == "box") {
    p.cubes = {{0, 0, 0}};
  } else if (shape == "slab") {
    for (int y = 0; y < 3; ++y)
      for (int x = 0; x < 3; ++x) p.cubes.push_back({x, y, 0});
  } else if (shape == "torus") {
    for (int y = 0; y < 3; ++y)
      for (int x = 0; x < 3; ++x)
        if (x != 1 || y != 1) p.cubes.push_back({x, y, 0});
  } else {
    throw InputError("--shape: unknown shape '" + shape +
                     "' (expected slab, sphere, torus, blob, bunny, or a mesh file .obj/.ply)");
  }
  return p;
}

}  // namespace translume
