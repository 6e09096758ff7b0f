// SPDX-License-Identifier: MIT
#include "render/polygrid.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <deque>
#include <fmt/format.h>
#include <limits>
#include <numeric>
#include <tuple>
#include <unordered_map>

#include "render/laplacian.h"
#include "solver/status.h"

namespace translume {
namespace {

// Dense lattice index helpers.
struct Lattice {
  std::array<int, 3> n;  // nodes per axis
  int64_t size() const { return int64_t(n[0]) * n[1] * n[2]; }
  bool inside(const std::array<int, 3>& g) const {
    return g[0] >= 0 && g[1] >= 0 && g[2] >= 0 && g[0] < n[0] && g[1] < n[1] && g[2] < n[2];
  }
  int64_t index(const std::array<int, 3>& g) const {
    return g[0] + int64_t(n[0]) * (g[1] + int64_t(n[1]) * g[2]);
  }
};

// Lattice coordinates are below 1024 cubes x 32 intervals < 2^20.
int64_t Key(const std::array<int, 3>& g, int dir) {
  return ((int64_t(g[0]) << 40) | (int64_t(g[1]) << 20) | int64_t(g[2])) * 8 + dir;
}

// Sum over the interior (free) nodes of the variance of their six edge lengths, and its
// gradient with respect to the free nodes' positions. Two passes, each parallel: the per-edge
// coefficients c_ij = (d Var_i / d l_ij) / l_ij, then per node the gather
//   grad_i = sum_j c_ij (v_i - v_j) - sum_{free j} c_ji (v_j - v_i)
// (interior links are lattice links, so j's link back to i is in the opposite direction).
// `c` is scratch (kept between calls: it is large).
double VarianceObjective(const Polygrid& pg, const std::vector<char>& free_node,
                         std::vector<Vec3>* gradient, std::vector<std::array<double, 6>>& c) {
  const int64_t n = pg.num_interior;
  if (gradient) c.assign(n, {0, 0, 0, 0, 0, 0});
  double f = 0;
#pragma omp parallel for schedule(static) reduction(+ : f) if (n > 20000)
  for (int64_t i = 0; i < n; ++i) {
    if (!free_node[i]) continue;
    double l[6], m = 0;
    for (int j = 0; j < 6; ++j) {
      l[j] = (pg.position[i] - pg.position[pg.neighbours[i][j]]).norm();
      m += l[j] / 6;
    }
    for (int j = 0; j < 6; ++j) {
      const double r = l[j] - m;
      f += r * r / 6;
      // d Var / d l_j = 2 (l_j - m) / 6 (the mean's derivative sums to zero).
      if (gradient) c[i][j] = l[j] > 0 ? 2 * r / 6 / l[j] : 0.0;
    }
  }
  if (!gradient) return f;
  gradient->assign(pg.size(), Vec3::Zero());
#pragma omp parallel for schedule(static) if (n > 20000)
  for (int64_t i = 0; i < n; ++i) {
    if (!free_node[i]) continue;
    Vec3 g = Vec3::Zero();
    for (int j = 0; j < 6; ++j) {
      const int32_t k = pg.neighbours[i][j];
      const Vec3 e = pg.position[i] - pg.position[k];
      g += c[i][j] * e;
      if (k < n && free_node[k]) g += c[k][j ^ 1] * e;
    }
    (*gradient)[i] = g;
  }
  return f;
}

}  // namespace

std::string PolygridOptions::Validate() const {
  if (resolution < 3) return "the polygrid resolution must be >= 3 nodes per cube edge";
  if (resolution > 257) return "the polygrid resolution must be <= 257 nodes per cube edge";
  if (!(first_layer_fraction > 0 && first_layer_fraction < 0.5))
    return "first_layer_fraction must be in (0, 0.5)";
  if (boundary_relax_iterations < 0 || smooth_iterations < 0 || variance_iterations < 0 ||
      align_passes < 0 || winslow_iterations < 0 || winslow_stall < 0)
    return "iteration counts must be >= 0";
  return "";
}

InteriorPlacement ParseInteriorPlacement(const std::string& text) {
  if (text == "variance") return InteriorPlacement::kVariance;
  if (text == "winslow") return InteriorPlacement::kWinslow;
  throw InputError("--placement: unknown placement '" + text + "' (expected variance or winslow)");
}

std::array<double, 2> Polygrid::SurfaceUV(int64_t b) const {
  const int axis = link_dir[b - num_interior] / 2;
  const auto& g = lattice[b];
  return {double(g[axis == 0 ? 1 : 0]), double(g[axis == 2 ? 1 : 2])};
}

namespace {

Polycube WithoutAxes(Polycube polycube) {
  polycube.axes.setIdentity();
  return polycube;
}

// A polygrid built in the frame of a polycube with `axes` (coordinates axes * p), turned back
// to the shape's coordinates: positions and normals by axes^T (the rest is invariant).
void TurnBack(const Eigen::Matrix3d& axes, Polygrid* pg) {
  for (Vec3& x : pg->position) x = axes.transpose() * x;
  for (Vec3& n : pg->normal) n = axes.transpose() * n;
}

}  // namespace

Polygrid BuildPolygrid(const Polycube& polycube, const Shape& shape,
                       const PolygridOptions& options) {
  if (std::string err = options.Validate(); !err.empty()) throw InputError("polygrid: " + err);
  if (std::string err = polycube.Validate(); !err.empty()) throw InputError("polycube: " + err);
  if (polycube.axes != Eigen::Matrix3d::Identity()) {  // built in the polycube's frame, turned back
    Polygrid pg = BuildPolygrid(WithoutAxes(polycube), *MakeRotatedShape(shape, polycube.axes), options);
    TurnBack(polycube.axes, &pg);
    return pg;
  }
  Polygrid pg;
  const int m = options.resolution - 1;
  const std::array<int, 3> cubes = polycube.Extent();
  Lattice lat;
  for (int a = 0; a < 3; ++a) lat.n[a] = cubes[a] * m + 1;
  pg.resolution = options.resolution;
  pg.lattice_extent = lat.n;
  std::vector<char> occupied(int64_t(cubes[0]) * cubes[1] * cubes[2], 0);
  for (const auto& c : polycube.cubes) occupied[c[0] + cubes[0] * (c[1] + cubes[1] * c[2])] = 1;
  auto cube_at = [&](int x, int y, int z) {
    if (x < 0 || y < 0 || z < 0 || x >= cubes[0] || y >= cubes[1] || z >= cubes[2]) return false;
    return bool(occupied[x + cubes[0] * (y + cubes[1] * z)]);
  };
  // Calls f(x, y, z, in_polycube) for every cube around lattice node g (two per axis where g
  // lies on a cube boundary).
  auto for_cubes_around = [&](const std::array<int, 3>& g, auto&& f) {
    int lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
      hi[a] = g[a] / m;
      lo[a] = g[a] % m == 0 ? hi[a] - 1 : hi[a];
    }
    for (int x = lo[0]; x <= hi[0]; ++x)
      for (int y = lo[1]; y <= hi[1]; ++y)
        for (int z = lo[2]; z <= hi[2]; ++z) f(x, y, z, cube_at(x, y, z));
  };
  // A lattice node is interior iff every cube around it is in the polycube.
  auto is_interior = [&](const std::array<int, 3>& g) {
    if (!lat.inside(g)) return false;
    bool all = true;
    for_cubes_around(g, [&](int, int, int, bool in) { all &= in; });
    return all;
  };
  std::vector<int32_t> interior_at(lat.size(), -1);
  for (int z = 0; z < lat.n[2]; ++z)
    for (int y = 0; y < lat.n[1]; ++y)
      for (int x = 0; x < lat.n[0]; ++x)
        if (is_interior({x, y, z})) {
          interior_at[lat.index({x, y, z})] = int32_t(pg.lattice.size());
          pg.lattice.push_back({x, y, z});
        }
  pg.num_interior = int64_t(pg.lattice.size());
  if (pg.num_interior == 0)
    throw InputError("polycube: no interior node at resolution " +
                     std::to_string(options.resolution));
  if (pg.num_interior > (int64_t(1) << 30)) throw InputError("polygrid: too many nodes");
  pg.neighbours.assign(pg.num_interior, {-1, -1, -1, -1, -1, -1});
  std::unordered_map<int64_t, int32_t> boundary_at;  // (lattice, link dir) -> node
  std::unordered_map<int64_t, int> surface_count;    // lattice node -> boundary nodes there
  for (int64_t i = 0; i < pg.num_interior; ++i)
    for (int dir = 0; dir < 6; ++dir) {
      auto g = pg.lattice[i];
      g[dir / 2] += dir % 2 ? 1 : -1;
      const int32_t k = interior_at[lat.index(g)];
      if (k >= 0) {
        pg.neighbours[i][dir] = k;
        continue;
      }
      const int32_t b = int32_t(pg.lattice.size());
      pg.lattice.push_back(g);
      pg.neighbours.push_back({int32_t(i), -1, -1, -1, -1, -1});
      pg.neighbours[i][dir] = b;
      pg.link_dir.push_back(dir);
      boundary_at[Key(g, dir)] = b;
      ++surface_count[Key(g, 0)];
    }
  const int64_t N = int64_t(pg.lattice.size());
  // The polycube stretched onto the shape's bounding box.
  pg.position.resize(N);
  for (int64_t n = 0; n < N; ++n)
    for (int a = 0; a < 3; ++a)
      pg.position[n][a] = shape.lo[a] + (shape.hi[a] - shape.lo[a]) * pg.lattice[n][a] / (lat.n[a] - 1);
  const std::vector<Vec3> lattice_position = pg.position;

  // Boundary nodes: project, then even out within each face.
  pg.normal.resize(N - pg.num_interior);
  std::vector<std::vector<int32_t>> face_nbrs(N - pg.num_interior);
  for (int64_t b = pg.num_interior; b < N; ++b) {
    const int dir = pg.link_dir[b - pg.num_interior];
    for (int a = 0; a < 3; ++a) {
      if (a == dir / 2) continue;
      for (int s : {-1, 1}) {
        auto g = pg.lattice[b];
        g[a] += s;
        if (auto it = boundary_at.find(Key(g, dir)); it != boundary_at.end())
          face_nbrs[b - pg.num_interior].push_back(it->second);
      }
    }
  }
  // Evening out moves a node half-way to the mean of these neighbours: the 4 of its face inside
  // a face; along a concave edge of the polycube (split nodes), its 2 split neighbours along
  // the edge, the same for every copy, so the copies stay together; none on the rims of faces
  // at convex edges and at concave corners, which stay where they were projected. (Along
  // concave edges that a rounded mesh fills in, nodes landed out of order near the edge's ends.)
  // Split (concave) boundary nodes: their lattice point has 2 (edge) or 3 (corner) copies.
  std::vector<char> split(N, 0);
  for (int64_t b = pg.num_interior; b < N; ++b) split[b] = surface_count[Key(pg.lattice[b], 0)] > 1;
  std::vector<std::vector<int32_t>> relax_nbrs(N - pg.num_interior);
  for (int64_t b = pg.num_interior; b < N; ++b) {
    const auto& nb = face_nbrs[b - pg.num_interior];
    auto& out = relax_nbrs[b - pg.num_interior];
    if (nb.size() == 4) {
      out = nb;
    } else if (surface_count[Key(pg.lattice[b], 0)] == 2) {
      for (int32_t k : nb)
        if (split[k]) out.push_back(k);
      int gap = 0;
      if (out.size() == 2)
        for (int a = 0; a < 3; ++a) gap += std::abs(pg.lattice[out[0]][a] - pg.lattice[out[1]][a]);
      if (gap != 2) out.clear();
    }
  }
  // The centre of the polycube's cubes around boundary node b, stretched like the lattice: the
  // first projection goes along the line from there (Shape::ProjectAlong).
  auto cubes_centre = [&](int64_t b) {
    Vec3 sum = Vec3::Zero();
    int count = 0;
    for_cubes_around(pg.lattice[b], [&](int x, int y, int z, bool in) {
      if (!in) return;
      sum += Vec3(x + 0.5, y + 0.5, z + 0.5) * m;
      ++count;
    });
    TL_CHECK(count > 0);
    Vec3 centre;
    for (int a = 0; a < 3; ++a) centre[a] = shape.lo[a] + (shape.hi[a] - shape.lo[a]) * sum[a] / count / (lat.n[a] - 1);
    return centre;
  };
  // along: from the plain stretch, along the lines from the cubes' centres; else (the crease
  // restart below, whose nodes sit off flat sides along their normals) the closest point.
  const double h = ((shape.hi - shape.lo).array() / (Eigen::Array3d(lat.n[0], lat.n[1], lat.n[2]) - 1)).minCoeff();
  auto project_boundary = [&](bool along) {
    for (int64_t b = pg.num_interior; b < N; ++b) {
      Vec3& normal = pg.normal[b - pg.num_interior];
      if (!along) {
        shape.Project(pg.position[b], &pg.position[b], &normal);
        continue;
      }
      const Vec3 p = pg.position[b], centre = cubes_centre(b);
      shape.ProjectAlong(p, centre, &pg.position[b], &normal);
      // Where the line's hit lies further than twice the surface's nearest point plus half a
      // lattice step, the line met the surface at a glancing angle or ran past it near p and
      // met it beyond the cube: a torus's inner wall near the polycube's hole corners, seen from
      // the one cube's centre (the folded boundary inverted ~300 interior cells of a torus
      // mesh), or a concave edge of the polycube that a rounded mesh fills in (nodes along the
      // edge landed out of order; 775 folded cells on a rounded bunny at 13^3). The lines along
      // the node's face normal and along the nearest point's normal instead, where their hits
      // are nearer. (The nearest point itself would gather the nodes near a faceted mesh's
      // convex edges and corners onto them.)
      const double len = (p - centre).norm(), hit = (pg.position[b] - p).norm();
      Vec3 nearest, nearest_normal;
      if (hit > 0.5 * h) shape.Project(p, &nearest, &nearest_normal);  // else the test below fails anyway
      if (hit > 0.5 * h && hit > 2 * (nearest - p).norm() + 0.5 * h) {
        const Vec3 outward = Eigen::Vector3i(LatticeStep(pg.link_dir[b - pg.num_interior]).data()).cast<double>();
        for (const Vec3& dir : {outward, nearest_normal}) {
          Vec3 s2, n2;
          shape.ProjectAlong(p, p - len * dir, &s2, &n2);
          if ((s2 - p).norm() < (pg.position[b] - p).norm()) {
            pg.position[b] = s2;
            normal = n2;
          }
        }
      }
    }
    for (int it = 0; it < options.boundary_relax_iterations; ++it) {
      std::vector<Vec3> next = pg.position;
      for (int64_t b = pg.num_interior; b < N; ++b) {
        const auto& nb = relax_nbrs[b - pg.num_interior];
        if (nb.empty()) continue;
        Vec3 mean = Vec3::Zero();
        for (int32_t k : nb) mean += pg.position[k] / double(nb.size());
        shape.Project(0.5 * (pg.position[b] + mean), &next[b], &pg.normal[b - pg.num_interior]);
      }
      pg.position.swap(next);
    }
  };
  project_boundary(true);
  double spacing_sum = 0;
  int64_t spacing_count = 0;
  for (int64_t b = pg.num_interior; b < N; ++b)
    for (int32_t k : face_nbrs[b - pg.num_interior]) {
      spacing_sum += (pg.position[b] - pg.position[k]).norm();
      ++spacing_count;
    }
  pg.mean_boundary_spacing = spacing_count ? spacing_sum / spacing_count
                                           : (shape.hi - shape.lo).norm() / lat.n[0];
  const double d = options.first_layer_fraction * pg.mean_boundary_spacing;
  pg.first_layer_distance = d;
  // Where a side of the polycube meets creases of the surface (a box's edges), the crease rule
  // below puts the first interior lattice plane at d from the surface. Start again, then, from
  // the lattice stretched so that on such a side the interior lattice plane 1 (or n-2) lies at
  // d inside the bounding box (the other sides keep the plain stretch), and project and even
  // out the boundary nodes as above. On a box every node then already sits where the placement
  // below converges: a tensor-product grid with straight grid lines to the surface. (From the
  // plain stretch the alignment passes carry the inset across the grid only about half-way per
  // pass; measured: grid lines bent by up to 0.07 spacings at 33^3.) A side is a crease side
  // when most of its boundary nodes that share their interior node with a boundary node of
  // another side lie across a crease from it (crease_between).
  std::array<int64_t, 6> crease_votes = {0, 0, 0, 0, 0, 0};
  // Whether boundary nodes b1 and b2 of one interior node (at a convex edge or corner of the
  // polycube) lie on either side of a crease of the surface: their normals more than 30
  // degrees apart, and each turning less than half as much to its face neighbour one step
  // further from the edge (unless that one sits on a concave edge). A rounded edge turns its
  // normals gradually and is no crease, however far apart the nodes beside it are (the bunny's
  // polycube under a rounded mesh: mostly more than 30 degrees at 9^3, where the crease rules
  // merged nodes of two faces).
  auto crease_between = [&](int32_t b1, int32_t b2) {
    auto normal_of = [&](int32_t b) -> const Vec3& { return pg.normal[b - pg.num_interior]; };
    const double across = std::acos(std::clamp(normal_of(b1).dot(normal_of(b2)), -1.0, 1.0));
    if (across <= M_PI / 6) return false;
    for (const auto& [b, other] : {std::pair(b1, b2), std::pair(b2, b1)}) {
      auto g = pg.lattice[b];
      const auto step = LatticeStep(pg.link_dir[other - pg.num_interior]);
      for (int a = 0; a < 3; ++a) g[a] -= step[a];
      const auto it = boundary_at.find(Key(g, pg.link_dir[b - pg.num_interior]));
      if (it != boundary_at.end() && !split[it->second] &&  // not a concave edge's
          std::acos(std::clamp(normal_of(b).dot(normal_of(it->second)), -1.0, 1.0)) > 0.5 * across)
        return false;
    }
    return true;
  };
  {
    std::vector<std::vector<int32_t>> links(pg.num_interior);
    for (int64_t b = pg.num_interior; b < N; ++b) links[pg.neighbours[b][0]].push_back(int32_t(b));
    for (const auto& bl : links)
      for (int32_t b1 : bl)
        for (int32_t b2 : bl) {
          if (pg.link_dir[b1 - pg.num_interior] == pg.link_dir[b2 - pg.num_interior]) continue;
          crease_votes[pg.link_dir[b1 - pg.num_interior]] += crease_between(b1, b2) ? 1 : -1;
        }
  }
  const bool any_crease_side = *std::max_element(crease_votes.begin(), crease_votes.end()) > 0;
  if (any_crease_side) {
    pg.position = lattice_position;
    for (int a = 0; a < 3; ++a) {
      if (lat.n[a] <= 3) continue;
      const double extent = shape.hi[a] - shape.lo[a], plain = extent / (lat.n[a] - 1);
      const double e_lo = crease_votes[2 * a] > 0 ? d : plain;
      const double e_hi = crease_votes[2 * a + 1] > 0 ? d : plain;
      for (int64_t n = 0; n < N; ++n)
        pg.position[n][a] = shape.lo[a] + e_lo + (extent - e_lo - e_hi) * (pg.lattice[n][a] - 1) / (lat.n[a] - 3);
    }
    project_boundary(false);
  }

  // First interior nodes: at distance d along the inward normal of their boundary node.
  // Corner and edge fix: an interior node linked to two or three boundary nodes (a convex edge
  // or corner of the polycube) goes where it is at distance d from every one of their tangent
  // planes (least squares), and each of those boundary nodes slides on the surface to the
  // point at distance d along its normal from it, so every link is again a normal of length d.
  std::vector<char> free_node(pg.num_interior, 1);
  std::vector<std::vector<int32_t>> blinks(pg.num_interior);
  for (int64_t b = pg.num_interior; b < N; ++b) blinks[pg.neighbours[b][0]].push_back(int32_t(b));
  for (int64_t i = 0; i < pg.num_interior; ++i) {
    if (blinks[i].empty()) continue;
    free_node[i] = 0;
    if (blinks[i].size() > 1) continue;
    const int32_t b = blinks[i][0];
    Vec3 u = -pg.normal[b - pg.num_interior];
    if (split[b]) {
      // A split concave node: lean along the lattice link so that the interior nodes of the
      // split copies do not coincide.
      u = (u + (lattice_position[i] - lattice_position[b]).normalized()).normalized();
    }
    pg.position[i] = pg.position[b] + d * u;
  }
  auto place_edge_nodes = [&] {
    for (int64_t i = 0; i < pg.num_interior; ++i) {
      const auto& bl = blinks[i];
      if (bl.size() < 2) continue;
      // Along the edge (the least-squares null space) the node follows the interior nodes
      // opposite its links, so the edge continues the grid lines of the faces.
      Vec3 x = Vec3::Zero();
      for (int32_t b : bl) {
        const int32_t o = pg.neighbours[i][pg.link_dir[b - pg.num_interior] ^ 1];
        x += (o < pg.num_interior ? pg.position[o] : Vec3(pg.position[b] - d * pg.normal[b - pg.num_interior])) /
             double(bl.size());
      }
      // Only a crease (crease_between, e.g. a box edge) has well-posed plane constraints; on a
      // smooth part of the surface the boundary nodes stay and the node takes the mean of its
      // d-offset points (sliding would merge the boundary nodes).
      auto mean_of_offsets = [&] {
        Vec3 mean = Vec3::Zero();
        for (int32_t b : bl) mean += (pg.position[b] - d * pg.normal[b - pg.num_interior]) / double(bl.size());
        return mean;
      };
      bool crease = false;
      for (int32_t b1 : bl)
        for (int32_t b2 : bl) crease |= b1 != b2 && crease_between(b1, b2);
      if (!crease) {
        pg.position[i] = mean_of_offsets();
        continue;
      }
      // At a crease the slide leaves the boundary nodes d |n_1 - n_2| apart (each at d along
      // its normal from the node); at an edge rounded on the scale of d it gathers them.
      double closest = std::numeric_limits<double>::infinity(), expected = closest;
      for (int32_t b1 : bl)
        for (int32_t b2 : bl)
          if (b1 < b2)
            expected = std::min(expected, d * (pg.normal[b1 - pg.num_interior] - pg.normal[b2 - pg.num_interior]).norm());
      std::vector<std::pair<Vec3, Vec3>> before;  // 4 links and more in thin parts (torus, 3^3)
      for (int32_t b : bl) before.emplace_back(pg.position[b], pg.normal[b - pg.num_interior]);
      for (int pass = 0; pass < 3; ++pass) {
        const double eps = 1e-6;
        Eigen::Matrix3d A = eps * Eigen::Matrix3d::Identity();
        Vec3 r = eps * x;
        for (int32_t b : bl) {
          const Vec3& n = pg.normal[b - pg.num_interior];
          A += n * n.transpose();
          r += n * (n.dot(pg.position[b]) - d);
        }
        x = A.ldlt().solve(r);
        for (int32_t b : bl)
          shape.Project(x + d * pg.normal[b - pg.num_interior], &pg.position[b],
                        &pg.normal[b - pg.num_interior]);
      }
      for (int32_t b1 : bl)
        for (int32_t b2 : bl)
          if (b1 < b2) closest = std::min(closest, (pg.position[b1] - pg.position[b2]).norm());
      if (closest < 0.5 * expected) {
        // Gathered (the bunny's polycube under a rounded mesh, 13^3: nodes of two faces on one
        // point): back, and the smooth part's rule.
        for (size_t k = 0; k < bl.size(); ++k)
          std::tie(pg.position[bl[k]], pg.normal[bl[k] - pg.num_interior]) = before[k];
        pg.position[i] = mean_of_offsets();
        continue;
      }
      pg.position[i] = x;
    }
  };
  // Laplacian smoothing of the free nodes: red-black Gauss-Seidel with over-relaxation (omega
  // below), until no node moves more than `tol` boundary spacings in a sweep or `iterations`
  // sweeps.
  // Interior nodes are linked along the lattice only, so the nodes of one lattice parity
  // (x + y + z even or odd) depend only on the other's: each half-sweep runs in parallel and
  // the result does not depend on the thread count.
  std::array<std::vector<int32_t>, 2> colour;
  for (int64_t i = 0; i < pg.num_interior; ++i)
    if (free_node[i]) {
      const auto& g = pg.lattice[i];
      colour[(g[0] + g[1] + g[2]) & 1].push_back(int32_t(i));
    }
  // SOR's optimal factor 2 / (1 + sqrt(1 - rho^2)) (Young), rho the spectral radius of the
  // Jacobi iteration on the free nodes (the mean of the six neighbours, the fixed nodes held):
  // estimated by the Rayleigh quotient of a few power steps from all ones (the dominant
  // eigenvector is positive), which approaches rho from below, so the factor errs low, where
  // SOR slows gently rather than sharply. On a cube of m free nodes per side rho = cos(pi /
  // (m + 1)), the classic 2 / (1 + sin(pi / (m + 1))). The lattice's largest extent, used
  // before, overshot where the solid is thinner than its box: 1.96 where this gives 1.86 on
  // the bunny, whose build at 16^3 then took 10.3 s instead of 7.5 (docs/benchmarks.md,
  // Rendering). 30 steps cost about as much as 30 sweeps.
  const double omega = [&] {
    std::vector<double> x(pg.num_interior, 0.0), y(pg.num_interior, 0.0);
    for (int64_t i = 0; i < pg.num_interior; ++i) x[i] = free_node[i] ? 1.0 : 0.0;
    double rho = 0;
    for (int step = 0; step < 30; ++step) {
      double xy = 0, xx = 0;
#pragma omp parallel for schedule(static) reduction(+ : xy, xx) if (pg.num_interior > 20000)
      for (int64_t i = 0; i < pg.num_interior; ++i) {
        if (!free_node[i]) continue;
        double s = 0;
        for (int j = 0; j < 6; ++j) {
          const int32_t k = pg.neighbours[i][j];
          if (k < pg.num_interior && free_node[k]) s += x[k];
        }
        y[i] = s / 6;
        xy += x[i] * y[i];
        xx += x[i] * x[i];
      }
      if (xx == 0) return 1.0;
      rho = xy / xx;
      const double norm = std::sqrt(std::inner_product(y.begin(), y.end(), y.begin(), 0.0));
      if (norm == 0) return 1.0;
      for (int64_t i = 0; i < pg.num_interior; ++i) x[i] = y[i] / norm;
    }
    return 2 / (1 + std::sqrt(std::max(0.0, 1 - rho * rho)));
  }();
  // Over-relaxed Gauss-Seidel sweeps of the free nodes towards target(i), colour by colour (a
  // colour's nodes depend only on other colours', so each colour updates in parallel and the
  // result does not depend on the thread count), until no node moves more than tol mm in a
  // sweep or `iterations` sweeps.
  // Returns the sweeps run, negated where it stopped without converging: at `iterations`, or
  // with `stall` > 0 after that many sweeps without a new smallest largest step.
  auto relax = [&](const auto& colours, int iterations, double tol, auto&& target, int stall = 0) {
    double best = std::numeric_limits<double>::infinity();
    for (int it = 0, best_it = 0; it < iterations; ++it) {
      double moved = 0;
      for (const std::vector<int32_t>& nodes : colours) {
        const int64_t n = int64_t(nodes.size());
#pragma omp parallel for schedule(static) reduction(max : moved) if (n > 20000)
        for (int64_t c = 0; c < n; ++c) {
          const int32_t i = nodes[c];
          const Vec3 step = omega * (target(i) - pg.position[i]);
          pg.position[i] += step;
          moved = std::max(moved, step.norm());
        }
      }
      if (moved < tol) return it + 1;
      if (moved < best) {
        best = moved;
        best_it = it;
      } else if (stall > 0 && it - best_it >= stall) {
        return -(it + 1);
      }
    }
    return -iterations;
  };
  auto smooth = [&](int iterations, double tol_spacings) {
    relax(colour, iterations, tol_spacings * pg.mean_boundary_spacing, [&](int32_t i) {
      Vec3 mean = Vec3::Zero();
      for (int j = 0; j < 6; ++j) mean += pg.position[pg.neighbours[i][j]];
      return Vec3(mean / 6);
    });
  };
  // Alignment: a boundary node and its first interior node follow the grid line of the free
  // interior node behind them (that node's surface point, and d inside it), so
  // boundary links continue the interior grid lines along the normal. On crease sides only (a
  // box's, the bunny's): on a smooth side the interior grid lines converge towards the
  // polycube's edges, and following them undid the evening out of the boundary nodes, more
  // with every pass. On the sphere at 17^3 after the 10 passes neighbouring boundary nodes were
  // 0.35 mm apart next to the faces' rims and 2.05 mm at their centres (0.69 to 1.22 mm as
  // evened out; the blob: 0.10 to 3.33 mm), and renders showed it: streaks along the cube's
  // edges (docs/benchmarks.md).
  auto align = [&] {
    for (int64_t i = 0; i < pg.num_interior; ++i) {
      if (blinks[i].size() != 1 || split[blinks[i][0]]) continue;
      const int32_t b = blinks[i][0];
      if (crease_votes[pg.link_dir[b - pg.num_interior]] <= 0) continue;  // not a crease side
      const int32_t f = pg.neighbours[i][pg.link_dir[b - pg.num_interior] ^ 1];
      if (f >= pg.num_interior || !free_node[f]) continue;
      // Onto b's tangent plane first, so the projection stays on b's side of the surface.
      const Vec3& n = pg.normal[b - pg.num_interior];
      const Vec3 on_plane = pg.position[f] + n.dot(pg.position[b] - pg.position[f]) * n;
      Vec3 moved, moved_normal;
      shape.ProjectAlong(on_plane, pg.position[f], &moved, &moved_normal);
      // Not past half-way to a neighbour of its face: where a crease side runs onto a rounded
      // part (the sample bar's ends at 9^3), the grid lines converge and following them put
      // nodes out of order (44 of 1127 cells folded).
      bool in_order = true;
      for (int32_t k : face_nbrs[b - pg.num_interior]) {
        const Vec3 to_k = pg.position[k] - pg.position[b];
        in_order &= (moved - pg.position[b]).dot(to_k) <= 0.5 * to_k.squaredNorm();
      }
      if (!in_order) continue;
      pg.position[b] = moved;
      pg.normal[b - pg.num_interior] = moved_normal;
      pg.position[i] = moved - d * moved_normal;
    }
  };
  // Only the last smoothing (before the variance steps) runs to 1e-6 spacings. The ones before
  // an alignment pass stop at 1e-3: the alignment after them moves nodes by 0.04-0.6 spacings
  // (bunny 16^3; torus 17^3: 0.17-1.8), and the warm-started sweeps after it carry on reducing
  // what is left. On the bunny's lattice (omega 1.96 then) a sweep shrinks the largest step only
  // ~0.96x, so 1e-6 needed 250-360 sweeps per smoothing and every pass ran into its cap of
  // 200. Measured (docs/benchmarks.md, Rendering): bunny 16^3 1333 sweeps instead of 2359,
  // nodes within 2.3e-3 spacings of the old ones, the same fallback count; torus 17^3 within
  // 2.6e-2 spacings; renders within 4e-4 (relative L2).
  // Winslow's sweeps start from the smoothed grid and go on to their own fixed point, so that
  // smoothing stops at 1e-3 too (bunny 17^3: 25 sweeps instead of 347 at the finest level, 70
  // Winslow sweeps instead of 50, the build 7.7 -> 6.4 s, the same fallback count, nodes within
  // 0.005 spacings; the other built-in shapes within 3e-6).
  const double loose = 1e-3, tight = 1e-6;
  const double last = options.placement == InteriorPlacement::kWinslow ? loose : tight;
  place_edge_nodes();
  const int align_passes = any_crease_side ? options.align_passes : 0;
  smooth(options.smooth_iterations, align_passes > 0 ? loose : last);
  for (int pass = 0; pass < align_passes; ++pass) {
    align();
    place_edge_nodes();
    if (pass + 1 < align_passes)
      smooth(std::min(200, options.smooth_iterations), loose);  // warm-started
    else
      smooth(options.smooth_iterations, last);
  }
  if (options.placement == InteriorPlacement::kWinslow) {
    // Winslow smoothing of the free nodes (see InteriorPlacement). With unit lattice spacing,
    // x = (sum_a g^aa (x_-a + x_+a) + 2 sum_{a<b} g^ab x_ab) / (2 sum_a g^aa), where
    // x_ab = (x_{+a+b} - x_{+a-b} - x_{-a+b} + x_{-a-b}) / 4 and g = (J^-1)(J^-1)^T with J's
    // columns the central differences (x_+a - x_-a) / 2. A node whose edge-diagonal lattice
    // neighbours are not all interior, or whose J is singular, takes the mean of its six
    // neighbours instead. Gauss-Seidel over the 8 lattice parities (x, y, z mod 2): face and
    // edge-diagonal neighbours always differ in parity, so each colour updates in parallel.
    // Over-relaxed by the Laplacian smoothing's factor (the same fixed point, reached in fewer
    // sweeps), to 1e-4 boundary spacings.
    constexpr int kPairs[3][2] = {{0, 1}, {1, 2}, {0, 2}};
    std::vector<std::array<int32_t, 12>> diag(pg.num_interior);
    std::array<std::vector<int32_t>, 8> parity;
    for (int64_t i = 0; i < pg.num_interior; ++i) {
      if (!free_node[i]) continue;
      const auto& g = pg.lattice[i];
      parity[(g[0] & 1) | (g[1] & 1) << 1 | (g[2] & 1) << 2].push_back(int32_t(i));
      for (int p = 0, k = 0; p < 3; ++p)
        for (int sa : {1, -1})
          for (int sb : {1, -1}) {
            auto h = g;
            h[kPairs[p][0]] += sa;
            h[kPairs[p][1]] += sb;
            diag[i][k++] = lat.inside(h) ? interior_at[lat.index(h)] : -1;
          }
    }
    const std::vector<Vec3> smoothed = pg.position;
    const int sweeps = relax(parity, options.winslow_iterations, 1e-4 * pg.mean_boundary_spacing, [&](int32_t i) {
      const auto& nb = pg.neighbours[i];
      Vec3 target = Vec3::Zero();
      for (int j = 0; j < 6; ++j) target += pg.position[nb[j]] / 6;
      Eigen::Matrix3d J;
      for (int a = 0; a < 3; ++a) J.col(a) = (pg.position[nb[2 * a + 1]] - pg.position[nb[2 * a]]) / 2;
      const double det = J.determinant();
      const bool diagonals = std::none_of(diag[i].begin(), diag[i].end(), [](int32_t k) { return k < 0; });
      if (!diagonals || !(std::abs(det) > 1e-12 * J.norm() * J.squaredNorm())) return target;
      const Eigen::Matrix3d Ji = J.inverse();
      const Eigen::Matrix3d G = Ji * Ji.transpose();
      Vec3 num = Vec3::Zero();
      double den = 0;
      for (int a = 0; a < 3; ++a) {
        num += G(a, a) * (pg.position[nb[2 * a]] + pg.position[nb[2 * a + 1]]);
        den += 2 * G(a, a);
      }
      for (int p = 0; p < 3; ++p) {
        const auto& d = diag[i];
        const Vec3 xab = (pg.position[d[4 * p]] - pg.position[d[4 * p + 1]] - pg.position[d[4 * p + 2]] +
                          pg.position[d[4 * p + 3]]) / 4;
        num += 2 * G(kPairs[p][0], kPairs[p][1]) * xab;
      }
      return den > 0 && num.allFinite() ? Vec3(num / den) : target;
    }, options.winslow_stall);
    // Diverged: a node left the boundary nodes' bounding box (widened by a spacing).
    Eigen::AlignedBox3d box;
    for (int64_t b = pg.num_interior; b < N; ++b) box.extend(pg.position[b]);
    box.min().array() -= pg.mean_boundary_spacing;
    box.max().array() += pg.mean_boundary_spacing;
    const bool diverged = std::any_of(pg.position.begin(), pg.position.begin() + pg.num_interior,
                                      [&](const Vec3& x) { return !x.allFinite() || !box.contains(x); });
    if (diverged) {
      pg.position = smoothed;
      smooth(options.smooth_iterations, tight);
    }
    if (sweeps < 0 || diverged)
      pg.placement_note = fmt::format("Winslow placement {} after {} sweeps{}",
                                      sweeps >= 0 ? "converged" : -sweeps < options.winslow_iterations
                                          ? "stopped unconverged (its steps stalled)" : "stopped unconverged (the cap)",
                                      std::abs(sweeps),
                                      diverged ? " and had diverged: the Laplacian-smoothed nodes are kept" : "");
  }
  const int variance_iterations =
      options.placement == InteriorPlacement::kVariance ? options.variance_iterations : 0;
  std::vector<Vec3> grad;
  std::vector<std::array<double, 6>> scratch;
  double f = variance_iterations > 0 ? VarianceObjective(pg, free_node, &grad, scratch) : 0;
  double step = 0.5;
  for (int it = 0; it < variance_iterations && f > 0; ++it) {
    const std::vector<Vec3> saved = pg.position;
    for (int64_t i = 0; i < pg.num_interior; ++i)
      if (free_node[i]) pg.position[i] -= step * grad[i];
    std::vector<Vec3> g2;
    const double f2 = VarianceObjective(pg, free_node, &g2, scratch);
    if (f2 < f) {
      f = f2;
      grad.swap(g2);
      step *= 1.2;
    } else {
      pg.position = saved;
      step *= 0.5;
      if (step < 1e-8) break;
    }
  }

  // Laplacian weights (Appendix B) and the boundary links.
  pg.weights.assign(N, {0, 0, 0, 0, 0, 0});
  int64_t fallback = 0, axis_only = 0, inverted = 0;
#pragma omp parallel for schedule(static) reduction(+ : fallback, axis_only, inverted) if (pg.num_interior > 50000)
  for (int64_t i = 0; i < pg.num_interior; ++i) {
    std::array<Vec3, 6> off;
    for (int j = 0; j < 6; ++j) off[j] = pg.position[pg.neighbours[i][j]] - pg.position[i];
    std::array<double, 6> w;
    if (!LaplacianWeights(off, &w)) {
      // The 6x6 system gives a non-positive weight (first interior nodes along the polycube's
      // edges on a smooth shape) or is singular. The weights nearest the axis ones that keep
      // its first-order and trace conditions; the axis weights themselves where those fail, such
      // as a neighbour on the node itself (a folded grid: a polycube that does not fit the
      // shape; the bunny under one cube at 9^3 had 12 infinite weights, and its solve went to zero).
      const std::array<double, 6> axis = AxisLaplacianWeights(off, 1e-3 * pg.mean_boundary_spacing);
      if (!FirstOrderAxisWeights(off, axis, &w)) {
        w = axis;
        ++axis_only;
      }
      ++fallback;
    }
    for (int j = 0; j < 6; ++j) pg.weights[i][j] = float(w[j]);
    inverted += (off[1] - off[0]).dot((off[3] - off[2]).cross(off[5] - off[4])) <= 0;
  }
  pg.fallback_weights = fallback;
  pg.axis_weights = axis_only;
  pg.inverted_cells = inverted;
  {
    const std::vector<double> area = BoundaryNodeAreas(pg);
    double mean = 0;
    for (double a : area) mean += a / double(area.size());
    for (double a : area) pg.crowded_boundary_nodes += a < 0.01 * mean;
  }
  // A first interior node with two or three boundary links on a smooth part of the surface sits
  // between its boundary nodes (the mean of the d-offset points above), so its links lean up to
  // ~80 degrees off the normal (|link| up to 5 d). The Robin condition needs dphi/dn, so such a
  // link counts its extent along the boundary node's normal; |link| there made a uniformly lit
  // sphere's radiance 10-19 % too high along the polycube's edges (docs/render.md, "Accuracy on
  // curved shapes"). Other links are normals of length d by construction (at a sharp crease the
  // node's own normal may be the other face's, so it is not used). The floor is a guard only:
  // built-in shapes measure 0.86-2.1 d.
  pg.link_length.resize(N - pg.num_interior);
  for (int64_t b = pg.num_interior; b < N; ++b) {
    const int32_t j = pg.neighbours[b][0];
    const Vec3 link = pg.position[b] - pg.position[j];
    pg.link_length[b - pg.num_interior] =
        blinks[j].size() == 1 ? link.norm()
                   : std::max(link.dot(pg.normal[b - pg.num_interior]), 0.25 * pg.first_layer_distance);
  }

  // Layers, shell sources and depths: breadth-first from the boundary.
  pg.layer.assign(N, -1);
  pg.source.assign(N, -1);
  std::deque<int32_t> queue;
  for (int64_t b = pg.num_interior; b < N; ++b) {
    pg.layer[b] = 0;
    pg.source[b] = int32_t(b);
    queue.push_back(int32_t(b));
  }
  while (!queue.empty()) {
    const int32_t x = queue.front();
    queue.pop_front();
    for (int j = 0; j < 6; ++j) {
      const int32_t k = pg.neighbours[x][j];
      if (k < 0 || pg.is_boundary(k)) continue;
      if (pg.layer[k] < 0) {
        pg.layer[k] = pg.layer[x] + 1;
        pg.source[k] = pg.source[x];
        queue.push_back(k);
      } else if (pg.layer[k] == pg.layer[x] + 1 &&
                 (pg.position[k] - pg.position[pg.source[x]]).squaredNorm() <
                     (pg.position[k] - pg.position[pg.source[k]]).squaredNorm()) {
        pg.source[k] = pg.source[x];
      }
    }
  }
  pg.depth_mm.resize(N);
  for (int64_t n = 0; n < N; ++n) pg.depth_mm[n] = (pg.position[n] - pg.position[pg.source[n]]).norm();
  return pg;
}

std::array<int, 3> LatticeStep(int dir) {
  std::array<int, 3> s = {0, 0, 0};
  s[dir / 2] = dir & 1 ? 1 : -1;
  return s;
}

BoundaryNodeIndex::BoundaryNodeIndex(const Polygrid& pg) {
  at_.reserve(size_t(pg.num_boundary()));
  for (int64_t b = pg.num_interior; b < pg.size(); ++b) at_[Key(pg.lattice[b], pg.link_dir[b - pg.num_interior])] = b;
}

int64_t BoundaryNodeIndex::Find(const std::array<int, 3>& g, int dir) const {
  const auto it = at_.find(Key(g, dir));
  return it == at_.end() ? -1 : it->second;
}

std::vector<double> BoundaryNodeAreas(const Polygrid& pg, double total_mm2) {
  const BoundaryNodeIndex at(pg);
  std::vector<double> area(pg.num_boundary());
  double sum = 0;
  for (int64_t b = pg.num_interior; b < pg.size(); ++b) {
    const int dir = pg.link_dir[b - pg.num_interior];
    std::array<Vec3, 2> t;
    for (int a = 0, k = 0; a < 3; ++a) {
      if (a == dir / 2) continue;
      std::array<int64_t, 2> nb;
      for (int s : {0, 1}) {
        auto g = pg.lattice[b];
        g[a] += s ? 1 : -1;
        nb[s] = at.Find(g, dir);
      }
      if (nb[0] >= 0 && nb[1] >= 0) {
        t[k] = (pg.position[nb[1]] - pg.position[nb[0]]) / 2;
      } else if (nb[0] >= 0 || nb[1] >= 0) {
        // At a face's rim the patch reaches half-way to the neighbour inside the face and
        // half-way to the nearest node of the face across the edge (the lattice node beyond
        // the rim, or one step from it along this face's normal axis), else as far again.
        const int side = nb[1] >= 0 ? 0 : 1;  // the missing side
        const Vec3 inner = pg.position[nb[1 - side]] - pg.position[b];
        auto g = pg.lattice[b];
        g[a] += side ? 1 : -1;
        double across = inner.norm();
        for (int step : {0, -1, 1}) {
          auto h = g;
          h[dir / 2] += step;
          for (int dir2 = 0; dir2 < 6; ++dir2) {
            if (dir2 == dir) continue;
            if (const int64_t k = at.Find(h, dir2); k >= 0)
              across = std::min(across, (pg.position[k] - pg.position[b]).norm());
          }
        }
        t[k] = inner.normalized() * (inner.norm() + across) / 2;
      } else {
        t[k] = Vec3::Zero();
      }
      ++k;
    }
    const double A = t[0].norm() == 0 || t[1].norm() == 0
                         ? pg.mean_boundary_spacing * pg.mean_boundary_spacing
                         : t[0].cross(t[1]).norm();
    area[b - pg.num_interior] = A;
    sum += A;
  }
  if (total_mm2 > 0 && sum > 0)
    for (double& A : area) A *= total_mm2 / sum;
  return area;
}

namespace {

// `shape` in the frame its mesh's faces follow (FitPolycubeFrame; *axes): itself where that is
// its own, else a turned shape kept in *turned (the frame reported).
const Shape& FramedShape(const Shape& shape, const ReportLine& report, Eigen::Matrix3d* axes,
                         std::unique_ptr<Shape>* turned) {
  const PolycubeFrameFit fit = FitPolycubeFrame(shape.mesh());
  *axes = fit.axes;
  if (fit.axes == Eigen::Matrix3d::Identity()) return shape;
  report(fmt::format("  the mesh's faces lie along axes turned by {:.1f} degrees from its own (alignment {:.3f} "
                     "against {:.3f}; 1 is every face along an axis): the cubes follow those axes\n",
                     fit.turn_deg, fit.alignment, fit.identity_alignment));
  *turned = MakeRotatedShape(shape, fit.axes);
  return **turned;
}

}  // namespace

Polycube AutoPolycube(const Shape& shape, const AutoPolycubeOptions& options, const ReportLine& report) {
  const int mesh_genus = shape.mesh().Genus();
  PolygridOptions po;
  po.resolution = options.resolution;
  Eigen::Matrix3d axes;
  std::unique_ptr<Shape> turned;
  const Shape& framed = FramedShape(shape, report, &axes, &turned);
  Polycube best;
  bool best_genus_ok = false;
  double best_inverted = 2;
  int best_n = 0;
  for (int n = 1; n <= options.max_cells; ++n) {
    std::string note;
    Polycube pc;
    Polygrid pg;
    try {
      pc = VoxelPolycube(framed, n, &note);
    } catch (const InputError&) {
      report(fmt::format("  N = {}: no cell's centre inside\n", n));
      continue;
    }
    try {
      pg = BuildPolygrid(pc, framed, po);  // in the frame: the counts below do not turn
    } catch (const InputError& e) {
      report(fmt::format("  N = {}: {}\n", n, e.what()));
      continue;
    }
    pc.axes = axes;
    const int genus = pc.Genus();
    const double inverted = double(pg.inverted_cells) / double(pg.num_interior);
    // The cubes' shape once stretched onto the shape's box (the polycube from its own extent).
    const std::array<int, 3> e = pc.Extent();
    const Vec3 cube = (framed.hi - framed.lo).cwiseQuotient(Vec3(e[0], e[1], e[2]));
    const double aspect = cube.maxCoeff() / cube.minCoeff();
    report(fmt::format("  N = {}: {} cube{}, genus {}, {:.1f} % of the cells inverted at {}^3, cubes stretched "
                       "{:.1f}:1{}\n", n, pc.cubes.size(), pc.cubes.size() == 1 ? "" : "s", genus, 100 * inverted,
                       po.resolution, aspect, note.empty() ? "" : " (" + note + ")"));
    const bool genus_ok = genus == mesh_genus;
    if (genus_ok && inverted <= options.max_inverted && aspect <= options.max_aspect) {
      report(fmt::format("  chose N = {}\n", n));
      return pc;
    }
    if (best_n == 0 || (genus_ok && !best_genus_ok) || (genus_ok == best_genus_ok && inverted < best_inverted)) {
      best = pc;
      best_genus_ok = genus_ok;
      best_inverted = inverted;
      best_n = n;
    }
  }
  if (best_n == 0) throw InputError(shape.name() + ": no voxel polycube up to N = " + std::to_string(options.max_cells));
  report(fmt::format("  none of genus {} with at most {:.1f} % inverted; chose N = {}\n", mesh_genus,
                     100 * options.max_inverted, best_n));
  return best;
}

Polycube ResolvePolycube(const std::string& spec, const Shape& shape, const std::string& builtin,
                         std::string* label, const ReportLine& log) {
  *label = spec;
  if (spec.empty() && !builtin.empty()) {
    *label = "(the shape's own)";
    return BuiltinPolycube(builtin);
  }
  if (!spec.empty() && spec != "auto" && spec.rfind("auto:", 0) != 0) return ReadPolycube(spec);
  Polycube pc;
  if (spec.empty() || spec == "auto") {
    pc = AutoPolycube(shape, AutoPolycubeOptions(), log);
  } else {
    size_t used = 0;
    int n = 0;
    try {
      n = std::stoi(spec.substr(5), &used);
    } catch (const std::exception&) {
    }
    if (used == 0 || used != spec.size() - 5) throw InputError("--polycube " + spec + ": expected auto:N, N an integer");
    std::string note;
    Eigen::Matrix3d axes;
    std::unique_ptr<Shape> turned;
    pc = VoxelPolycube(FramedShape(shape, log, &axes, &turned), n, &note);
    pc.axes = axes;
    if (!note.empty()) log("note: " + note + "\n");
  }
  const std::array<int, 3> e = pc.Extent();
  *label = fmt::format("{} ({} cube{}, {} x {} x {})", spec.empty() ? "auto" : spec, pc.cubes.size(),
                       pc.cubes.size() == 1 ? "" : "s", e[0], e[1], e[2]);
  return pc;
}

std::vector<std::string> PolycubeNotes(const Shape& shape, const Polycube& polycube, const std::string& label) {
  std::vector<std::string> notes;
  if (const int pieces = shape.mesh().Pieces(); pieces > 1)
    notes.push_back(fmt::format("{} has {} separate surface pieces, but a polygrid is one connected solid: light "
                                "diffuses through it between them (across a gap, or through a cavity one encloses); "
                                "render separate objects one mesh at a time", shape.name(), pieces));
  if (const int mesh_genus = shape.mesh().Genus(), pc_genus = polycube.Genus(); pc_genus >= 0 && pc_genus != mesh_genus)
    notes.push_back(fmt::format("{} has genus {} but the polycube {} has genus {}: the polygrid's holes are not the "
                                "shape's, so light diffuses across a hole or stops at one that is not there; give a "
                                "polycube with as many holes (--polycube, docs/render.md \"Polycube files\")",
                                shape.name(), mesh_genus, label, pc_genus));
  return notes;
}

std::vector<std::string> PolygridNotes(const std::vector<Polygrid>& levels, int levels_asked,
                                       const std::string& label, const std::string& shape_name) {
  TL_CHECK(!levels.empty());
  std::vector<std::string> notes;
  const Polygrid& finest = levels[0];
  if (int(levels.size()) < levels_asked)
    notes.push_back(fmt::format("--resolution {} allows {} level{}, not the {} asked for (a coarser level needs "
                                "resolution - 1 even and at least 3 nodes per cube edge: 9, 17 and 33 allow 3 or more)",
                                finest.resolution, levels.size(), levels.size() == 1 ? "" : "s", levels_asked));
  for (size_t l = 0; l < levels.size(); ++l)
    if (!levels[l].placement_note.empty())
      notes.push_back(fmt::format("level {} ({}^3): {}", l, levels[l].resolution, levels[l].placement_note));
  if (finest.inverted_cells > finest.num_interior / 200)
    notes.push_back(fmt::format("{} of the polygrid's {} interior cells are folded (inverted): the polycube {} may "
                                "not follow the shape of {} well (give one whose cubes follow its parts: --polycube "
                                "FILE or auto, docs/render.md \"Polycube files\"), or the resolution is too coarse "
                                "for its curvature (raise --resolution)", finest.inverted_cells, finest.num_interior,
                                label, shape_name));
  if (finest.crowded_boundary_nodes > finest.num_boundary() / 1000)
    notes.push_back(fmt::format("{} of the polygrid's {} boundary nodes crowd together (each stands for under 1 % of "
                                "the mean node's share of the surface): the polycube does not follow sharp edges or "
                                "corners of {}, and the light there is approximate (a polycube whose cube edges lie "
                                "along them does better; docs/render.md \"Polycube files\")",
                                finest.crowded_boundary_nodes, finest.num_boundary(), shape_name));
  return notes;
}

std::vector<Polygrid> BuildPolygridHierarchy(const Polycube& polycube, const Shape& shape,
                                             const PolygridOptions& options, int max_levels) {
  if (polycube.axes != Eigen::Matrix3d::Identity()) {  // one turned shape for every level
    std::vector<Polygrid> levels =
        BuildPolygridHierarchy(WithoutAxes(polycube), *MakeRotatedShape(shape, polycube.axes), options, max_levels);
    for (Polygrid& pg : levels) TurnBack(polycube.axes, &pg);
    return levels;
  }
  std::vector<Polygrid> levels;
  PolygridOptions o = options;
  while (int(levels.size()) < std::max(1, max_levels)) {
    levels.push_back(BuildPolygrid(polycube, shape, o));
    const int m = o.resolution - 1;
    if (m % 2 != 0 || m / 2 + 1 < 3) break;
    o.resolution = m / 2 + 1;
  }
  return levels;
}

Prolongation MakeProlongation(const Polygrid& coarse, const Polygrid& fine) {
  TL_CHECK(fine.resolution - 1 == 2 * (coarse.resolution - 1));
  // Coarse nodes by lattice node (boundary nodes may share one).
  Lattice lat{coarse.lattice_extent};
  std::vector<int32_t> first(lat.size() + 1, 0), nodes(coarse.size());
  for (int64_t n = 0; n < coarse.size(); ++n) ++first[lat.index(coarse.lattice[n]) + 1];
  for (int64_t k = 0; k < lat.size(); ++k) first[k + 1] += first[k];
  std::vector<int32_t> fill(first.begin(), first.end() - 1);
  for (int64_t n = 0; n < coarse.size(); ++n) nodes[fill[lat.index(coarse.lattice[n])]++] = int32_t(n);
  Prolongation P;
  P.start.assign(fine.size() + 1, 0);
  for (int64_t n = 0; n < fine.size(); ++n) {
    const auto& g = fine.lattice[n];
    int base[3];
    double t[3];
    for (int a = 0; a < 3; ++a) {
      base[a] = g[a] / 2;
      t[a] = g[a] % 2 ? 0.5 : 0.0;
    }
    double wsum = 0;
    std::vector<double> w;
    for (int c = 0; c < 8; ++c) {
      std::array<int, 3> q;
      double wc = 1;
      for (int a = 0; a < 3; ++a) {
        const int bit = (c >> a) & 1;
        q[a] = base[a] + bit;
        wc *= bit ? t[a] : 1 - t[a];
      }
      if (wc == 0 || !lat.inside(q)) continue;
      const int64_t k = lat.index(q);
      const int count = first[k + 1] - first[k];
      if (count == 0) continue;
      wsum += wc;
      for (int32_t i = first[k]; i < first[k + 1]; ++i) {
        P.index.push_back(nodes[i]);
        w.push_back(wc / count);
      }
    }
    for (size_t i = 0; i < w.size(); ++i) P.weight.push_back(float(w[i] / wsum));
    P.start[n + 1] = int32_t(P.index.size());
  }
  return P;
}

void ProlongPolygrid(const Polygrid& coarse, const std::vector<float>& coarse_values,
                     const Polygrid& fine, std::vector<float>* fine_values) {
  TL_CHECK(int64_t(coarse_values.size()) == coarse.size());
  const Prolongation P = MakeProlongation(coarse, fine);
  fine_values->assign(fine.size(), 0.f);
  for (int64_t n = 0; n < fine.size(); ++n) {
    double acc = 0;
    for (int32_t k = P.start[n]; k < P.start[n + 1]; ++k) acc += double(P.weight[k]) * coarse_values[P.index[k]];
    (*fine_values)[n] = float(acc);
  }
}

}  // namespace translume

namespace translume {

void RestrictPolygrid(const Polygrid& fine, const std::vector<float>& fine_values,
                      const Polygrid& coarse, std::vector<float>* coarse_values) {
  TL_CHECK(int64_t(fine_values.size()) == fine.size());
  TL_CHECK(fine.resolution - 1 == 2 * (coarse.resolution - 1));
  // Fine nodes by lattice node (CSR: boundary nodes may share a lattice node).
  Lattice lat{fine.lattice_extent};
  std::vector<int32_t> start(lat.size() + 1, 0), nodes(fine.size());
  for (int64_t n = 0; n < fine.size(); ++n) ++start[lat.index(fine.lattice[n]) + 1];
  for (int64_t k = 0; k < lat.size(); ++k) start[k + 1] += start[k];
  std::vector<int32_t> fill(start.begin(), start.end() - 1);
  for (int64_t n = 0; n < fine.size(); ++n) nodes[fill[lat.index(fine.lattice[n])]++] = int32_t(n);
  coarse_values->assign(coarse.size(), 0.f);
  for (int64_t n = 0; n < coarse.size(); ++n) {
    const bool boundary = coarse.is_boundary(n);
    double acc = 0, wsum = 0;
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const std::array<int, 3> g = {2 * coarse.lattice[n][0] + dx, 2 * coarse.lattice[n][1] + dy,
                                        2 * coarse.lattice[n][2] + dz};
          if (!lat.inside(g)) continue;
          const double w = (1 - std::abs(dx) / 2.0) * (1 - std::abs(dy) / 2.0) * (1 - std::abs(dz) / 2.0);
          const int64_t k = lat.index(g);
          for (int32_t i = start[k]; i < start[k + 1]; ++i) {
            if (fine.is_boundary(nodes[i]) != boundary) continue;
            acc += w * fine_values[nodes[i]];
            wsum += w;
          }
        }
    (*coarse_values)[n] = wsum > 0 ? float(acc / wsum) : 0.f;
  }
}

}  // namespace translume
