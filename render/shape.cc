// SPDX-License-Identifier: MIT
#include "render/shape.h"

#include "render/polycube.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <climits>
#include <cmath>
#include <cstdint>
#include <fmt/format.h>
#include <functional>
#include <map>
#include <set>

#include "solver/status.h"

namespace translume {
namespace {

constexpr double kPi = 3.14159265358979323846;
// Faces meeting at more than this angle (degrees) form a crease of a mesh: its normals are not
// interpolated across it (MeshShape::Project).
constexpr double kMeshCreaseDeg = 45;

// A parametric grid of (nu + 1) x (nv + 1) points, u periodic (wrapping), v either periodic
// (torus) or pole-to-pole (sphere: rows 0 and nv collapse to one vertex each).
TriangleMesh ParametricMesh(int nu, int nv, bool v_periodic,
                            const std::function<Vec3(double, double)>& f) {
  TriangleMesh m;
  std::vector<std::vector<int>> id(nv + 1, std::vector<int>(nu, -1));
  for (int j = 0; j <= nv; ++j) {
    if (v_periodic && j == nv) {
      id[j] = id[0];
      continue;
    }
    const bool pole = !v_periodic && (j == 0 || j == nv);
    for (int i = 0; i < nu; ++i) {
      if (pole && i > 0) {
        id[j][i] = id[j][0];
        continue;
      }
      id[j][i] = int(m.vertices.size());
      m.vertices.push_back(f(2 * kPi * i / nu, (v_periodic ? 2 * kPi : kPi) * j / nv));
    }
  }
  for (int j = 0; j < nv; ++j)
    for (int i = 0; i < nu; ++i) {
      const int a = id[j][i], b = id[j][(i + 1) % nu], c = id[j + 1][(i + 1) % nu],
                d = id[j + 1][i];
      if (a != b) m.triangles.push_back({a, c, b});
      if (c != d) m.triangles.push_back({a, d, c});
    }
  return m;
}

// Flips every triangle if the enclosed signed volume is negative (inward-facing triangles).
void OrientOutward(TriangleMesh* m) {
  if (m->Volume() < 0)
    for (auto& t : m->triangles) std::swap(t[1], t[2]);
}

// Appends the tess x tess quads (two triangles each) of an axis-aligned face whose lattice
// corners are corner + i e_a1 + j e_a2, i, j in [0, tess] (a1 = axis + 1, a2 = axis + 2, mod 3),
// facing +axis (side 1) or -axis (side 0), counter-clockwise seen from outside; vid(lattice
// point) gives the vertex index.
template <typename Vid>
void AppendFaceQuads(TriangleMesh* mesh, int axis, int side, const std::array<int, 3>& corner,
                     int tess, Vid&& vid) {
  const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
  for (int i = 0; i < tess; ++i)
    for (int j = 0; j < tess; ++j) {
      const int di[4] = {0, 1, 1, 0}, dj[4] = {0, 0, 1, 1};
      int q[4];
      for (int k = 0; k < 4; ++k) {
        std::array<int, 3> g = corner;
        g[a1] += i + di[k];
        g[a2] += j + dj[k];
        q[k] = vid(g);
      }
      // (a1, a2, axis) is right-handed, so CCW in (a1, a2) faces +axis.
      if (side == 1) {
        mesh->triangles.push_back({q[0], q[1], q[2]});
        mesh->triangles.push_back({q[0], q[2], q[3]});
      } else {
        mesh->triangles.push_back({q[0], q[2], q[1]});
        mesh->triangles.push_back({q[0], q[3], q[2]});
      }
    }
}

class SphereShape : public Shape {
 public:
  SphereShape(double radius, double bump, int tess) : r_(radius), bump_(bump) {
    name_ = bump > 0 ? "blob" : "sphere";
    mesh_ = ParametricMesh(2 * tess, tess, false, [&](double u, double v) {
      const Vec3 d(std::sin(v) * std::cos(u), std::sin(v) * std::sin(u), std::cos(v));
      return Vec3(Radius(d) * d);
    });
    OrientOutward(&mesh_);
    mesh_.Bounds(&lo, &hi);
  }
  double Radius(const Vec3& d) const {
    return r_ * (1 + bump_ * std::sin(3 * d.x()) * std::sin(2 * d.y() + 1) * std::cos(2 * d.z()));
  }
  // Radial projection; the normal is the gradient of |p| - r(p / |p|).
  void Project(const Vec3& p, Vec3* s, Vec3* n) const override {
    const Vec3 d = p.norm() > 1e-12 ? Vec3(p.normalized()) : Vec3(0, 0, 1);
    *s = Radius(d) * d;
    if (bump_ == 0) {
      *n = d;
      return;
    }
    const double e = 1e-5 * r_;
    Vec3 g;
    for (int a = 0; a < 3; ++a) {
      Vec3 dp = Vec3::Zero();
      dp[a] = e;
      const Vec3 p1 = *s + dp, p0 = *s - dp;
      g[a] = (p1.norm() - Radius(p1.normalized()) - p0.norm() + Radius(p0.normalized())) / (2 * e);
    }
    *n = g.normalized();
  }

 private:
  double r_, bump_;
};

class TorusShape : public Shape {
 public:
  TorusShape(double ring, double tube, int tess) : R_(ring), r_(tube) {
    name_ = "torus";
    mesh_ = ParametricMesh(2 * tess, tess, true, [&](double u, double v) {
      return Vec3((R_ + r_ * std::cos(v)) * std::cos(u), (R_ + r_ * std::cos(v)) * std::sin(u),
                  r_ * std::sin(v));
    });
    OrientOutward(&mesh_);
    mesh_.Bounds(&lo, &hi);
  }
  // Closest point: through the nearest point of the core circle.
  void Project(const Vec3& p, Vec3* s, Vec3* n) const override {
    Vec3 q(p.x(), p.y(), 0);
    q = q.norm() > 1e-12 ? Vec3(R_ * q.normalized()) : Vec3(R_, 0, 0);
    Vec3 d = p - q;
    d = d.norm() > 1e-12 ? Vec3(d.normalized()) : Vec3(q.normalized());
    *s = q + r_ * d;
    *n = d;
  }

 private:
  double R_, r_;
};

class BoxShape : public Shape {
 public:
  BoxShape(const Vec3& extent, int tess, const std::string& name) {
    name_ = name;
    hi = extent / 2;
    lo = -hi;
    // Six faces, each a tess x tess grid (vertices shared along the box edges).
    std::map<std::array<int, 3>, int> ids;
    auto vid = [&](std::array<int, 3> g) {
      auto [it, fresh] = ids.emplace(g, int(mesh_.vertices.size()));
      if (fresh) {
        Vec3 v;
        for (int a = 0; a < 3; ++a) v[a] = lo[a] + (hi[a] - lo[a]) * g[a] / tess;
        mesh_.vertices.push_back(v);
      }
      return it->second;
    };
    for (int axis = 0; axis < 3; ++axis)
      for (int side = 0; side < 2; ++side) {
        std::array<int, 3> corner = {0, 0, 0};
        corner[axis] = side * tess;
        AppendFaceQuads(&mesh_, axis, side, corner, tess, vid);
      }
  }
  // Closest point on the box surface: clamp outside; inside, push to the nearest face.
  void Project(const Vec3& p, Vec3* s, Vec3* n) const override {
    Vec3 c = p.cwiseMax(lo).cwiseMin(hi);
    int best = 0;
    double best_d = 1e300;
    for (int a = 0; a < 3; ++a)
      for (int side = 0; side < 2; ++side) {
        const double d = std::abs(c[a] - (side ? hi[a] : lo[a]));
        if (d < best_d) best_d = d, best = 2 * a + side;
      }
    const int a = best / 2;
    c[a] = best % 2 ? hi[a] : lo[a];
    *s = c;
    *n = Vec3::Zero();
    (*n)[a] = best % 2 ? 1 : -1;
  }
};

// The solid union of a polycube's unit cubes, centred and scaled so that the largest extent is
// size_mm (the built-in bunny): the surface is the cubes' exposed faces, each a tess x tess grid
// of quads in the render mesh (vertices shared on the lattice of step 1/tess). Project: the
// closest point on the exposed faces, with the face's normal; only the faces of the cubes
// around the query's cell are searched when one of them is within a cube's width (no face of
// a farther cube can then be closer), else all.
class PolycubeSolidShape : public Shape {
 public:
  PolycubeSolidShape(const Polycube& pc, double size_mm, int tess, const std::string& name) {
    name_ = name;
    ext_ = pc.Extent();
    unit_ = size_mm / std::max({ext_[0], ext_[1], ext_[2]});
    origin_ = -0.5 * unit_ * Vec3(ext_[0], ext_[1], ext_[2]);
    lo = origin_;
    hi = -origin_;
    cube_faces_.assign(size_t(ext_[0]) * ext_[1] * ext_[2], {});
    std::map<std::array<int, 3>, int> ids;
    auto vid = [&](const std::array<int, 3>& g) {
      auto [it, fresh] = ids.emplace(g, int(mesh_.vertices.size()));
      if (fresh) mesh_.vertices.push_back(origin_ + unit_ * Vec3(g[0], g[1], g[2]) / tess);
      return it->second;
    };
    for (const auto& c : pc.cubes)
      for (int dir = 0; dir < 6; ++dir) {
        const int axis = dir / 2, side = dir % 2;
        std::array<int, 3> nb = c;
        nb[axis] += side ? 1 : -1;
        if (pc.Has(nb[0], nb[1], nb[2])) continue;
        cube_faces_[Cell(c)].push_back(int(faces_.size()));
        faces_.push_back({c, dir});
        std::array<int, 3> corner;
        for (int a = 0; a < 3; ++a) corner[a] = (c[a] + (a == axis ? side : 0)) * tess;
        AppendFaceQuads(&mesh_, axis, side, corner, tess, vid);
      }
  }

  void Project(const Vec3& p, Vec3* s, Vec3* n) const override {
    const Vec3 u = (p - origin_) / unit_;  // cube units
    std::array<int, 3> g;
    for (int a = 0; a < 3; ++a) g[a] = std::clamp(int(std::floor(u[a])), 0, ext_[a] - 1);
    double best = 1e300;
    int best_face = -1;
    Vec3 best_point = Vec3::Zero();
    auto try_face = [&](int f) {
      const auto& [c, dir] = faces_[f];
      Vec3 q;
      for (int a = 0; a < 3; ++a) q[a] = std::clamp(u[a], double(c[a]), double(c[a] + 1));
      q[dir / 2] = c[dir / 2] + dir % 2;
      const double d2 = (q - u).squaredNorm();
      if (d2 < best) best = d2, best_face = f, best_point = q;
    };
    for (int z = std::max(0, g[2] - 1); z <= std::min(ext_[2] - 1, g[2] + 1); ++z)
      for (int y = std::max(0, g[1] - 1); y <= std::min(ext_[1] - 1, g[1] + 1); ++y)
        for (int x = std::max(0, g[0] - 1); x <= std::min(ext_[0] - 1, g[0] + 1); ++x)
          for (int f : cube_faces_[Cell({x, y, z})]) try_face(f);
    if (best > 1)
      for (int f = 0; f < int(faces_.size()); ++f) try_face(f);
    *s = origin_ + unit_ * best_point;
    *n = Vec3::Zero();
    (*n)[faces_[best_face].second / 2] = faces_[best_face].second % 2 ? 1 : -1;
  }

 private:
  size_t Cell(const std::array<int, 3>& c) const {
    return c[0] + size_t(ext_[0]) * (c[1] + size_t(ext_[1]) * c[2]);
  }
  std::array<int, 3> ext_;
  double unit_;
  Vec3 origin_;
  std::vector<std::pair<std::array<int, 3>, int>> faces_;  // exposed faces: cube, direction
  std::vector<std::vector<int>> cube_faces_;               // per lattice cell
};

// Closest-point queries on a mesh, accelerated by a uniform grid of triangle bounding boxes:
// cells are searched in rings of growing Chebyshev radius around the query's cell until no
// unvisited cell can hold a closer point.
class MeshShape : public Shape {
 public:
  MeshShape(TriangleMesh mesh, const std::string& name) {
    mesh_ = std::move(mesh);
    name_ = name;
    OrientOutward(&mesh_);
    mesh_.Bounds(&lo, &hi);
    normals_ = mesh_.CornerNormals(kMeshCreaseDeg);
    const Vec3 ext = (hi - lo).cwiseMax(Vec3::Constant(1e-9));
    const double per_axis = std::clamp(std::cbrt(double(mesh_.triangles.size()) / 2), 1.0, 128.0);
    const double cell = ext.maxCoeff() / per_axis;
    for (int a = 0; a < 3; ++a) dims_[a] = std::max(1, int(std::ceil(ext[a] / cell)));
    cell_ = ext.cwiseQuotient(Vec3(dims_[0], dims_[1], dims_[2]));
    cells_.assign(size_t(dims_[0]) * dims_[1] * dims_[2], {});
    for (size_t t = 0; t < mesh_.triangles.size(); ++t) {
      Vec3 tlo = Vec3::Constant(1e300), thi = Vec3::Constant(-1e300);
      for (int c = 0; c < 3; ++c) {
        tlo = tlo.cwiseMin(mesh_.vertices[mesh_.triangles[t][c]]);
        thi = thi.cwiseMax(mesh_.vertices[mesh_.triangles[t][c]]);
      }
      const auto c0 = CellOf(tlo), c1 = CellOf(thi);
      for (int z = c0[2]; z <= c1[2]; ++z)
        for (int y = c0[1]; y <= c1[1]; ++y)
          for (int x = c0[0]; x <= c1[0]; ++x) cells_[Index(x, y, z)].push_back(int32_t(t));
    }
  }
  void Project(const Vec3& p_in, Vec3* s, Vec3* n) const override {
    const Vec3 p = p_in;  // callers project in place (s == &p_in); *s changes during the search
    double best = 1e300;
    const auto c = CellOf(p);
    // Distance from p to its (clamped) cell: unvisited cells of ring r + 1 are at least
    // r * min(cell) - that far away.
    Vec3 cmin, cmax;
    for (int a = 0; a < 3; ++a) {
      cmin[a] = lo[a] + c[a] * cell_[a];
      cmax[a] = cmin[a] + cell_[a];
    }
    const double outside = (p - p.cwiseMax(cmin).cwiseMin(cmax)).norm();
    const int max_r = std::max({dims_[0], dims_[1], dims_[2]});
    for (int r = 0; r <= max_r; ++r) {
      ForEachCellInRing(c, r, dims_, [&](int x, int y, int z) {
        for (int32_t t : cells_[Index(x, y, z)]) {
          const auto& tri = mesh_.triangles[t];
          double u, v, w;
          const Vec3 q = ClosestPointOnTriangle(p, mesh_.vertices[tri[0]], mesh_.vertices[tri[1]],
                                                mesh_.vertices[tri[2]], &u, &v, &w);
          const double d = (q - p).squaredNorm();
          if (d < best) {
            best = d;
            *s = q;
            *n = (u * normals_[t][0] + v * normals_[t][1] + w * normals_[t][2]).normalized();
          }
        }
      });
      const double bound = r * cell_.minCoeff() - outside;
      if (best < 1e300 && bound > 0 && std::sqrt(best) <= bound) break;
    }
  }
  // Walks the grid cells that the line crosses inside the bounding box (Amanatides and Woo),
  // intersecting their triangles (Moller and Trumbore), and keeps the hit nearest to p.
  void ProjectAlong(const Vec3& p, const Vec3& centre, Vec3* s, Vec3* n) const override {
    const double len = (p - centre).norm();
    if (!(len > 1e-12 * (hi - lo).norm())) return Project(p, s, n);
    const Vec3 u = (p - centre) / len;
    // The line's parameter range inside the (slightly grown) box, from p.
    const Vec3 pad = 1e-6 * (hi - lo) + Vec3::Constant(1e-9);
    double t0 = -1e300, t1 = 1e300;
    for (int a = 0; a < 3; ++a) {
      if (std::abs(u[a]) < 1e-300) {
        if (p[a] < lo[a] - pad[a] || p[a] > hi[a] + pad[a]) return Project(p, s, n);
        continue;
      }
      double ta = (lo[a] - pad[a] - p[a]) / u[a], tb = (hi[a] + pad[a] - p[a]) / u[a];
      if (ta > tb) std::swap(ta, tb);
      t0 = std::max(t0, ta);
      t1 = std::min(t1, tb);
    }
    if (t0 > t1) return Project(p, s, n);
    const Vec3 start = p + t0 * u;
    std::array<int, 3> c = CellOf(start), step;
    Vec3 t_max, t_delta;
    for (int a = 0; a < 3; ++a) {
      step[a] = u[a] > 0 ? 1 : -1;
      const double boundary = lo[a] + (c[a] + (u[a] > 0 ? 1 : 0)) * cell_[a];
      t_max[a] = std::abs(u[a]) < 1e-300 ? 1e300 : t0 + (boundary - start[a]) / u[a];
      t_delta[a] = std::abs(u[a]) < 1e-300 ? 1e300 : cell_[a] / std::abs(u[a]);
    }
    double best_t = 1e300, bu = 0, bv = 0;
    int32_t best_tri = -1;
    for (;;) {
      for (int32_t t : cells_[Index(c[0], c[1], c[2])]) {
        const auto& tri = mesh_.triangles[t];
        const Vec3 &a = mesh_.vertices[tri[0]], e1 = mesh_.vertices[tri[1]] - a, e2 = mesh_.vertices[tri[2]] - a;
        const Vec3 h = u.cross(e2);
        const double det = e1.dot(h);
        if (std::abs(det) < 1e-14 * e1.squaredNorm() * e2.norm()) continue;  // parallel
        const Vec3 w = p - a;
        const double b1 = w.dot(h) / det;
        if (b1 < -1e-12 || b1 > 1 + 1e-12) continue;
        const Vec3 qv = w.cross(e1);
        const double b2 = u.dot(qv) / det;
        if (b2 < -1e-12 || b1 + b2 > 1 + 1e-12) continue;
        const double t_hit = e2.dot(qv) / det;  // p + t_hit u
        if (std::abs(t_hit) < std::abs(best_t)) {
          best_t = t_hit;
          best_tri = t;
          bu = b1;
          bv = b2;
        }
      }
      // Cells further than the best hit (on both sides of p) cannot hold a nearer one.
      const int a = t_max[0] < t_max[1] ? (t_max[0] < t_max[2] ? 0 : 2) : (t_max[1] < t_max[2] ? 1 : 2);
      if (t_max[a] > t1 || (best_tri >= 0 && t_max[a] > std::abs(best_t))) break;
      c[a] += step[a];
      if (c[a] < 0 || c[a] >= dims_[a]) break;
      t_max[a] += t_delta[a];
    }
    if (best_tri < 0) return Project(p, s, n);
    *s = p + best_t * u;
    const auto& cn = normals_[best_tri];
    *n = ((1 - bu - bv) * cn[0] + bu * cn[1] + bv * cn[2]).normalized();
  }

 private:
  std::array<int, 3> CellOf(const Vec3& p) const {
    std::array<int, 3> c;
    for (int a = 0; a < 3; ++a) c[a] = std::clamp(int(std::floor((p[a] - lo[a]) / cell_[a])), 0, dims_[a] - 1);
    return c;
  }
  size_t Index(int x, int y, int z) const { return x + size_t(dims_[0]) * (y + size_t(dims_[1]) * z); }

  std::vector<std::array<Vec3, 3>> normals_;  // per triangle corner, sharp at creases
  std::array<int, 3> dims_ = {1, 1, 1};
  Vec3 cell_ = Vec3::Ones();
  std::vector<std::vector<int32_t>> cells_;
};

}  // namespace

std::string TriangleMesh::Validate() const {
  if (triangles.size() < 4) return "a closed mesh needs at least 4 triangles";
  std::map<std::pair<int, int>, int> directed;
  for (size_t t = 0; t < triangles.size(); ++t) {
    const auto& tri = triangles[t];
    for (int c = 0; c < 3; ++c)
      if (tri[c] < 0 || tri[c] >= int(vertices.size()))
        return "triangle " + std::to_string(t) + " has vertex index out of range";
    if (tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2])
      return "triangle " + std::to_string(t) + " is degenerate (repeated vertex)";
    for (int c = 0; c < 3; ++c) ++directed[{tri[c], tri[(c + 1) % 3]}];
  }
  for (const auto& [e, n] : directed) {
    const auto it = directed.find({e.second, e.first});
    const int back = it == directed.end() ? 0 : it->second;
    if (n + back > 2)
      return "non-manifold edge " + std::to_string(e.first) + "-" + std::to_string(e.second) +
             " (shared by " + std::to_string(n + back) + " triangles)";
    if (back == 0 && n == 1)
      return "the mesh is open: edge " + std::to_string(e.first) + "-" +
             std::to_string(e.second) + " belongs to one triangle only";
    if (n > 1)
      return "inconsistent triangle orientation at edge " + std::to_string(e.first) + "-" +
             std::to_string(e.second);
  }
  // Every edge is now shared by two consistently oriented triangles, so around a vertex v each
  // triangle (v, a, b) links a to b, and the links form cycles. A manifold vertex has one cycle
  // (one fan); two or more fans meeting at one point (a bowtie) make it non-manifold.
  std::vector<std::vector<std::pair<int, int>>> fan(vertices.size());
  for (const auto& tri : triangles)
    for (int c = 0; c < 3; ++c) fan[tri[c]].push_back({tri[(c + 1) % 3], tri[(c + 2) % 3]});
  for (size_t v = 0; v < fan.size(); ++v) {
    auto& links = fan[v];
    if (links.empty()) continue;
    std::sort(links.begin(), links.end());
    size_t steps = 0;
    int at = links.front().first;
    do {
      at = std::lower_bound(links.begin(), links.end(), std::make_pair(at, INT_MIN))->second;
      ++steps;
    } while (at != links.front().first && steps <= links.size());
    if (steps != links.size())
      return "non-manifold vertex " + std::to_string(v) + " (" +
             std::to_string(links.size()) + " triangles around it form more than one fan)";
  }
  return "";
}

namespace {

class RotatedShape : public Shape {
 public:
  RotatedShape(const Shape& base, const Eigen::Matrix3d& r) : base_(base), r_(r) {
    mesh_ = base.mesh();
    for (Vec3& v : mesh_.vertices) v = r * v;
    name_ = base.name();
    mesh_.Bounds(&lo, &hi);
  }
  void Project(const Vec3& p, Vec3* surface, Vec3* normal) const override {
    base_.Project(r_.transpose() * p, surface, normal);
    *surface = r_ * *surface;
    *normal = r_ * *normal;
  }
  void ProjectAlong(const Vec3& p, const Vec3& centre, Vec3* surface, Vec3* normal) const override {
    base_.ProjectAlong(r_.transpose() * p, r_.transpose() * centre, surface, normal);
    *surface = r_ * *surface;
    *normal = r_ * *normal;
  }

 private:
  const Shape& base_;
  Eigen::Matrix3d r_;
};

// Element k of the Halton sequence in base b, in [0, 1).
double Halton(int k, int b) {
  double f = 1, r = 0;
  for (; k > 0; k /= b) {
    f /= b;
    r += f * (k % b);
  }
  return r;
}

}  // namespace

std::unique_ptr<Shape> MakeRotatedShape(const Shape& base, const Eigen::Matrix3d& frame_from_shape) {
  return std::make_unique<RotatedShape>(base, frame_from_shape);
}

PolycubeFrameFit FitPolycubeFrame(const TriangleMesh& mesh) {
  constexpr int kBins = 16;
  std::vector<Vec3> faces;  // area times unit normal
  double area = 0;
  for (const auto& t : mesh.triangles) {
    faces.push_back(0.5 * (mesh.vertices[t[1]] - mesh.vertices[t[0]]).cross(mesh.vertices[t[2]] - mesh.vertices[t[0]]));
    area += faces.back().norm();
  }
  std::vector<Vec3> sums(6 * kBins * kBins, Vec3::Zero());
  for (const Vec3& an : faces) {
    const Vec3 size = an.cwiseAbs();
    if (size.maxCoeff() == 0) continue;
    const int a = size.x() >= size.y() && size.x() >= size.z() ? 0 : size.y() >= size.z() ? 1 : 2;
    const int b = (a + 1) % 3, c = (a + 2) % 3;
    const auto cell = [&](double u) { return std::clamp(int((u / size[a] + 1) / 2 * kBins), 0, kBins - 1); };
    sums[((2 * a + (an[a] < 0)) * kBins + cell(an[b])) * kBins + cell(an[c])] += an;
  }
  std::vector<Vec3> m;
  double total = 0;
  for (const Vec3& v : sums)
    if (v.squaredNorm() > 0) {
      m.push_back(v);
      total += v.norm();
    }
  PolycubeFrameFit fit;
  if (m.empty()) return fit;
  // a(R) over the bins' sums, or over every face (exact; the bins lean towards frames whose
  // axis planes cut through them, ~1 degree).
  const auto alignment = [](const std::vector<Vec3>& normals, double sum, const Eigen::Matrix3d& r) {
    double c = 0;
    for (const Vec3& v : normals) c += (r * v).lpNorm<1>();
    return c / sum;
  };
  const auto cost = [&](const Eigen::Matrix3d& r) { return alignment(m, total, r); };
  const auto exact = [&](const Eigen::Matrix3d& r) { return alignment(faces, area, r); };
  // Halving-step rotations about the axes from r (cost c) while a step of `least` still helps.
  const auto refine = [](const auto& f, Eigen::Matrix3d* r, double* c, double step, double least) {
    while (step > least) {
      bool moved = false;
      for (int a = 0; a < 3; ++a)
        for (double sign : {-1.0, 1.0}) {
          const Eigen::Matrix3d tried = Eigen::AngleAxisd(sign * step, Vec3::Unit(a)).toRotationMatrix() * *r;
          const double ct = f(tried);
          if (ct < *c) {
            *c = ct;
            *r = tried;
            moved = true;
          }
        }
      if (!moved) step /= 2;
    }
  };
  fit.identity_alignment = fit.alignment = exact(Eigen::Matrix3d::Identity());
  // Starts: rotations spread over SO(3) (Shoemake's uniform quaternions from Halton points).
  std::vector<std::pair<double, Eigen::Matrix3d>> starts;
  for (int k = 1; k <= 512; ++k) {
    const double u1 = Halton(k, 2), u2 = 2 * kPi * Halton(k, 3), u3 = 2 * kPi * Halton(k, 5);
    const Eigen::Quaterniond q(std::sqrt(u1) * std::cos(u3), std::sqrt(1 - u1) * std::sin(u2),
                               std::sqrt(1 - u1) * std::cos(u2), std::sqrt(u1) * std::sin(u3));
    const Eigen::Matrix3d r = q.normalized().toRotationMatrix();
    starts.emplace_back(cost(r), r);
  }
  std::sort(starts.begin(), starts.end(), [](const auto& x, const auto& y) { return x.first < y.first; });
  double best = 1e300;
  Eigen::Matrix3d best_r = Eigen::Matrix3d::Identity();
  for (int s = 0; s < 8; ++s) {
    auto [c, r] = starts[size_t(s)];
    refine(cost, &r, &c, 10 * kPi / 180, 0.01 * kPi / 180);
    if (c < best) {
      best = c;
      best_r = r;
    }
  }
  best = exact(best_r);
  refine(exact, &best_r, &best, 2 * kPi / 180, 1e-3 * kPi / 180);
  // The cube's 24 rotations (signed permutations, determinant 1) leave a(R) as it is: take the
  // frame nearest the mesh's axes (largest trace).
  Eigen::Matrix3d nearest = best_r;
  double trace = -4;
  const int perms[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  for (const auto& p : perms)
    for (int signs = 0; signs < 8; ++signs) {
      Eigen::Matrix3d P = Eigen::Matrix3d::Zero();
      for (int i = 0; i < 3; ++i) P(i, p[i]) = signs >> i & 1 ? -1 : 1;
      if (P.determinant() < 0) continue;
      const Eigen::Matrix3d r = P * best_r;
      if (r.trace() > trace) {
        trace = r.trace();
        nearest = r;
      }
    }
  if (fit.identity_alignment - best <= std::max(0.01, 0.1 * (fit.identity_alignment - 1))) return fit;
  fit.axes = nearest;
  fit.alignment = best;
  fit.turn_deg = std::acos(std::clamp((trace - 1) / 2, -1.0, 1.0)) * 180 / kPi;
  return fit;
}

Polycube VoxelPolycube(const Shape& shape, int cubes, std::string* note) {
  if (cubes < 1 || cubes > 1024) throw InputError("polycube: auto:N needs 1 <= N <= 1024, got " + std::to_string(cubes));
  const TriangleMesh& mesh = shape.mesh();
  const Vec3 extent = shape.hi - shape.lo;
  std::array<int, 3> n;
  for (int a = 0; a < 3; ++a) n[a] = std::clamp(int(std::lround(cubes * extent[a] / extent.maxCoeff())), 1, 1024);
  // The winding number of each cell's centre: the signed crossings of the mesh by the ray from
  // it along +x (a triangle counts +1 or -1 by the side it faces). A row of cells along x shares
  // its ray's line, so each triangle is met once per row whose line passes through it: O(cells
  // + triangles + crossings). The lines are moved off the cell centres by 1e-5 cells in y and z
  // (irrational fractions), so that they miss the vertices and edges of meshes built on the same
  // grid (a polycube solid's).
  const Vec3 h = extent.cwiseQuotient(Vec3(n[0], n[1], n[2]));
  const double off_y = 0.6180339887e-5 * h.y(), off_z = 0.4142135624e-5 * h.z();
  std::vector<std::vector<std::pair<double, int>>> crossings(int64_t(n[1]) * n[2]);  // (x, +-1) per row
  for (const auto& t : mesh.triangles) {
    const Vec3 &A = mesh.vertices[t[0]], &B = mesh.vertices[t[1]], &C = mesh.vertices[t[2]];
    const double den = (B.y() - A.y()) * (C.z() - A.z()) - (C.y() - A.y()) * (B.z() - A.z());
    if (den == 0) continue;  // parallel to x
    auto rows = [&](int a, double off, int* first, int* last) {
      const double lo = std::min({A[a], B[a], C[a]}), hi = std::max({A[a], B[a], C[a]});
      *first = std::max(0, int(std::ceil((lo - shape.lo[a] - off) / h[a] - 0.5)));
      *last = std::min(n[a] - 1, int(std::floor((hi - shape.lo[a] - off) / h[a] - 0.5)));
    };
    int j0, j1, k0, k1;
    rows(1, off_y, &j0, &j1);
    rows(2, off_z, &k0, &k1);
    for (int k = k0; k <= k1; ++k)
      for (int j = j0; j <= j1; ++j) {
        const double y = shape.lo.y() + (j + 0.5) * h.y() + off_y, z = shape.lo.z() + (k + 0.5) * h.z() + off_z;
        const double u = ((y - A.y()) * (C.z() - A.z()) - (C.y() - A.y()) * (z - A.z())) / den;
        const double v = ((B.y() - A.y()) * (z - A.z()) - (y - A.y()) * (B.z() - A.z())) / den;
        if (u < 0 || v < 0 || u + v > 1) continue;
        crossings[j + int64_t(n[1]) * k].emplace_back(A.x() + u * (B.x() - A.x()) + v * (C.x() - A.x()), den > 0 ? 1 : -1);
      }
  }
  Polycube all;  // the cells inside, in cell order
  for (int k = 0; k < n[2]; ++k)
    for (int j = 0; j < n[1]; ++j) {
      auto& row = crossings[j + int64_t(n[1]) * k];
      std::sort(row.begin(), row.end());
      std::vector<char> inside(size_t(n[0]), 0);
      int winding = 0;  // of the crossings beyond the cell's centre
      size_t next = row.size();
      for (int i = n[0] - 1; i >= 0; --i) {
        const double x = shape.lo.x() + (i + 0.5) * h.x();
        while (next > 0 && row[next - 1].first > x) winding += row[--next].second;
        inside[size_t(i)] = winding != 0;
      }
      for (int i = 0; i < n[0]; ++i)
        if (inside[size_t(i)]) all.cubes.push_back({i, j, k});
    }
  if (all.cubes.empty())
    throw InputError(shape.name() + ": no cell of a " + std::to_string(n[0]) + " x " + std::to_string(n[1]) + " x " +
                     std::to_string(n[2]) + " grid over its bounding box has its centre inside the mesh; raise N in "
                     "--polycube auto:N");
  // The largest face-connected piece, from 0 on every axis (the polycube is stretched onto the
  // shape's box from its own extent).
  const std::vector<Polycube> pieces = all.Pieces();
  Polycube pc = *std::max_element(pieces.begin(), pieces.end(),
                                  [](const Polycube& a, const Polycube& b) { return a.cubes.size() < b.cubes.size(); });
  std::array<int, 3> first = n;
  for (const auto& cube : pc.cubes)
    for (int a = 0; a < 3; ++a) first[a] = std::min(first[a], cube[a]);
  for (auto& cube : pc.cubes)
    for (int a = 0; a < 3; ++a) cube[a] -= first[a];
  note->clear();
  if (const size_t dropped = all.cubes.size() - pc.cubes.size(); dropped > 0)
    *note = fmt::format("{} of the {} cubes inside {} were apart from the largest face-connected piece and are "
                        "left out", dropped, all.cubes.size(), shape.name());
  return pc;
}

namespace {

// Over the vertices that triangles use: how many, the distinct undirected edges, and the
// connected pieces (union-find).
struct MeshCounts {
  int64_t used = 0, edges = 0, pieces = 0;
};
MeshCounts CountMesh(const TriangleMesh& m) {
  std::vector<int> parent(m.vertices.size(), -1);
  auto find = [&](int v) {
    while (parent[v] != v) v = parent[v] = parent[parent[v]];
    return v;
  };
  std::set<std::pair<int, int>> edges;
  for (const auto& t : m.triangles)
    for (int c = 0; c < 3; ++c) {
      const int a = t[c], b = t[(c + 1) % 3];
      edges.insert({std::min(a, b), std::max(a, b)});
      for (int v : {a, b})
        if (parent[v] < 0) parent[v] = v;
      parent[find(a)] = find(b);
    }
  MeshCounts n;
  n.edges = int64_t(edges.size());
  for (size_t v = 0; v < parent.size(); ++v)
    if (parent[v] >= 0) {
      ++n.used;
      n.pieces += find(int(v)) == int(v);
    }
  return n;
}

}  // namespace

int TriangleMesh::Genus() const {
  const MeshCounts n = CountMesh(*this);
  const int64_t euler = n.used - n.edges + int64_t(triangles.size());
  return int((2 * n.pieces - euler) / 2);
}

int TriangleMesh::Pieces() const { return int(CountMesh(*this).pieces); }

void TriangleMesh::Bounds(Vec3* lo, Vec3* hi) const {
  *lo = Vec3::Constant(1e300);
  *hi = Vec3::Constant(-1e300);
  for (const Vec3& v : vertices) {
    *lo = lo->cwiseMin(v);
    *hi = hi->cwiseMax(v);
  }
}

double TriangleMesh::Volume() const {
  if (vertices.empty()) return 0;
  Vec3 lo, hi;
  Bounds(&lo, &hi);
  const Vec3 c = (lo + hi) / 2;  // about the box's centre: less cancellation far from the origin
  double volume = 0;
  for (const auto& t : triangles)
    volume += (vertices[t[0]] - c).dot((vertices[t[1]] - c).cross(vertices[t[2]] - c)) / 6;
  return volume;
}

double TriangleMesh::Area() const {
  double area = 0;
  for (const auto& t : triangles)
    area += 0.5 * (vertices[t[1]] - vertices[t[0]]).cross(vertices[t[2]] - vertices[t[0]]).norm();
  return area;
}

std::vector<Vec3> TriangleMesh::VertexNormals() const {
  std::vector<Vec3> n(vertices.size(), Vec3::Zero());
  for (const auto& t : triangles) {
    const Vec3 fn = (vertices[t[1]] - vertices[t[0]]).cross(vertices[t[2]] - vertices[t[0]]);
    for (int c = 0; c < 3; ++c) n[t[c]] += fn;
  }
  for (Vec3& v : n) v = v.norm() > 0 ? Vec3(v.normalized()) : Vec3(0, 0, 1);
  return n;
}

std::vector<std::array<Vec3, 3>> TriangleMesh::CornerNormals(double crease_deg) const {
  std::vector<Vec3> fn(triangles.size());  // area-weighted (twice the area)
  std::vector<std::vector<int32_t>> around(vertices.size());
  for (size_t t = 0; t < triangles.size(); ++t) {
    const auto& tri = triangles[t];
    fn[t] = (vertices[tri[1]] - vertices[tri[0]]).cross(vertices[tri[2]] - vertices[tri[0]]);
    for (int c = 0; c < 3; ++c) around[tri[c]].push_back(int32_t(t));
  }
  const double min_cos = std::cos(crease_deg * kPi / 180);
  std::vector<std::array<Vec3, 3>> out(triangles.size());
  for (size_t t = 0; t < triangles.size(); ++t) {
    const Vec3 own = fn[t].norm() > 0 ? Vec3(fn[t].normalized()) : Vec3::Zero();
    for (int c = 0; c < 3; ++c) {
      Vec3 sum = Vec3::Zero();
      for (int32_t s : around[triangles[t][c]])
        if (size_t(s) == t || (fn[s].norm() > 0 && fn[s].normalized().dot(own) >= min_cos)) sum += fn[s];
      out[t][c] = sum.norm() > 0 ? Vec3(sum.normalized()) : Vec3(0, 0, 1);
    }
  }
  return out;
}

TriangleMesh ShadingMesh(const TriangleMesh& mesh, double max_edge, int64_t max_vertices,
                         std::vector<Vec3>* normals) {
  const std::vector<std::array<Vec3, 3>> corner = mesh.CornerNormals(kMeshCreaseDeg);
  TriangleMesh out;
  normals->clear();
  // (vertex, its corner normal rounded to 1e-9) -> new vertex
  std::map<std::pair<int, std::array<int64_t, 3>>, int> copies;
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    std::array<int, 3> tri;
    for (int c = 0; c < 3; ++c) {
      const Vec3& n = corner[t][c];
      const std::array<int64_t, 3> key = {std::llround(n.x() * 1e9), std::llround(n.y() * 1e9),
                                          std::llround(n.z() * 1e9)};
      const auto [it, added] = copies.try_emplace({mesh.triangles[t][c], key}, int(out.vertices.size()));
      if (added) {
        out.vertices.push_back(mesh.vertices[mesh.triangles[t][c]]);
        normals->push_back(n);
      }
      tri[c] = it->second;
    }
    out.triangles.push_back(tri);
  }
  auto longest = [&] {
    double l = 0;
    for (const auto& t : out.triangles)
      for (int c = 0; c < 3; ++c) l = std::max(l, (out.vertices[t[c]] - out.vertices[t[(c + 1) % 3]]).norm());
    return l;
  };
  // A round adds one vertex per edge (~1.5 per triangle).
  while (longest() > max_edge &&
         int64_t(out.vertices.size()) + 3 * int64_t(out.triangles.size()) / 2 <= max_vertices) {
    std::map<std::pair<int, int>, int> mid;
    auto midpoint = [&](int a, int b) {
      const auto [it, added] = mid.try_emplace({std::min(a, b), std::max(a, b)}, int(out.vertices.size()));
      if (added) {
        out.vertices.push_back(0.5 * (out.vertices[a] + out.vertices[b]));
        normals->push_back(((*normals)[a] + (*normals)[b]).normalized());
      }
      return it->second;
    };
    std::vector<std::array<int, 3>> next;
    next.reserve(out.triangles.size() * 4);
    for (const auto& t : out.triangles) {
      const int ab = midpoint(t[0], t[1]), bc = midpoint(t[1], t[2]), ca = midpoint(t[2], t[0]);
      next.push_back({t[0], ab, ca});
      next.push_back({ab, t[1], bc});
      next.push_back({ca, bc, t[2]});
      next.push_back({ab, bc, ca});
    }
    out.triangles.swap(next);
  }
  return out;
}

Vec3 ClosestPointOnTriangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c,
                            double* u, double* v, double* w) {
  // Barycentric coordinates of the projection onto the plane.
  const Vec3 e0 = b - a, e1 = c - a, d = p - a;
  const double d00 = e0.dot(e0), d01 = e0.dot(e1), d11 = e1.dot(e1);
  const double d20 = d.dot(e0), d21 = d.dot(e1);
  const double den = d00 * d11 - d01 * d01;
  if (den > 0) {
    const double bv = (d11 * d20 - d01 * d21) / den, bw = (d00 * d21 - d01 * d20) / den;
    if (bv >= 0 && bw >= 0 && bv + bw <= 1) {
      *u = 1 - bv - bw, *v = bv, *w = bw;
      return a + bv * e0 + bw * e1;
    }
  }
  // Outside: the closest of the three edges.
  const Vec3* pts[3] = {&a, &b, &c};
  double best = 1e300;
  Vec3 out = a;
  for (int e = 0; e < 3; ++e) {
    const Vec3 &s0 = *pts[e], &s1 = *pts[(e + 1) % 3];
    const Vec3 seg = s1 - s0;
    const double len2 = seg.squaredNorm();
    const double t = len2 > 0 ? std::clamp((p - s0).dot(seg) / len2, 0.0, 1.0) : 0.0;
    const Vec3 q = s0 + t * seg;
    if ((q - p).squaredNorm() < best) {
      best = (q - p).squaredNorm();
      out = q;
      double bc[3] = {0, 0, 0};
      bc[e] = 1 - t;
      bc[(e + 1) % 3] = t;
      *u = bc[0], *v = bc[1], *w = bc[2];
    }
  }
  return out;
}

std::string SizeProblem(double size_mm) {
  if (std::isfinite(size_mm) && size_mm >= kMinSizeMm && size_mm <= kMaxSizeMm) return "";
  return fmt::format("must be within {:g}..{:g} mm, got {:g}", kMinSizeMm, kMaxSizeMm, size_mm);
}

std::unique_ptr<Shape> MakeBuiltinShape(const std::string& name, double size_mm,
                                        int tessellation) {
  if (const std::string err = SizeProblem(size_mm); !err.empty()) throw InputError("--size: " + err);
  const double unit = size_mm / 3;  // slab and torus are 3 units wide
  if (name == "sphere") return std::make_unique<SphereShape>(size_mm / 2, 0.0, tessellation);
  if (name == "blob") {
    const SphereShape unit(1.0, 0.15, tessellation);  // measure, then scale to size_mm
    return std::make_unique<SphereShape>(size_mm / (unit.hi - unit.lo).maxCoeff(), 0.15, tessellation);
  }
  if (name == "torus") return std::make_unique<TorusShape>(unit, unit / 2, tessellation);
  if (name == "slab") {
    return std::make_unique<BoxShape>(Vec3(3 * unit, 3 * unit, unit), 24, "slab");
  }
  if (name == "bunny")
    return std::make_unique<PolycubeSolidShape>(BuiltinPolycube("bunny"), size_mm,
                                                std::max(1, tessellation / 12), "bunny");
  throw InputError("--shape: unknown shape '" + name +
                   "' (expected slab, sphere, torus, blob, bunny, or a mesh file .obj/.ply)");
}

std::unique_ptr<Shape> MakeBoxShape(const Vec3& extent_mm, int tessellation) {
  return std::make_unique<BoxShape>(extent_mm, tessellation, "box");
}

std::unique_ptr<Shape> MakePolycubeSolidShape(const Polycube& polycube, double size_mm,
                                              int tessellation, const std::string& name) {
  return std::make_unique<PolycubeSolidShape>(polycube, size_mm, std::max(1, tessellation), name);
}

std::unique_ptr<Shape> MakeMeshShape(TriangleMesh mesh, const std::string& name,
                                     double size_mm) {
  if (std::string err = mesh.Validate(); !err.empty()) throw InputError(name + ": " + err);
  if (const std::string err = SizeProblem(size_mm); size_mm != 0 && !err.empty())
    throw InputError("--size: " + err);
  Vec3 lo, hi;
  mesh.Bounds(&lo, &hi);
  const Vec3 centre = (lo + hi) / 2;
  // A closed mesh folded flat (all vertices in a plane or on a line) passes Validate and then
  // rendered black: its enclosed volume is no more than rounding against its extent cubed.
  if (!(std::abs(mesh.Volume()) > 1e-6 * std::pow((hi - lo).maxCoeff(), 3)))
    throw InputError(name + ": the mesh encloses no volume (flat, or folded onto itself)");
  const double scale = size_mm > 0 ? size_mm / (hi - lo).maxCoeff() : 1.0;
  for (Vec3& v : mesh.vertices) v = (v - centre) * scale;
  return std::make_unique<MeshShape>(std::move(mesh), name);
}

}  // namespace translume
