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

// Laplacian smoothing's tolerance (boundary spacings) where it is the last placement step.
constexpr double kTightSmoothing = 1e-6;

// The steps of BuildPolygrid (paper Section 5.1; docs/render.md), in the order Build() runs them.
// Each step leaves what later steps read in the members under its heading.
class PolygridBuilder {
 public:
  PolygridBuilder(const Polycube& polycube, const Shape& shape, const PolygridOptions& options)
      : shape_(shape), options_(options), m_(options.resolution - 1), cubes_(polycube.Extent()) {
    for (int a = 0; a < 3; ++a) lat_.n[a] = cubes_[a] * m_ + 1;
    occupied_.assign(int64_t(cubes_[0]) * cubes_[1] * cubes_[2], 0);
    for (const auto& c : polycube.cubes) occupied_[c[0] + cubes_[0] * (c[1] + cubes_[1] * c[2])] = 1;
  }
  // Once per builder: the polygrid is moved out.
  Polygrid Build();

 private:
  bool CubeAt(int x, int y, int z) const {
    if (x < 0 || y < 0 || z < 0 || x >= cubes_[0] || y >= cubes_[1] || z >= cubes_[2]) return false;
    return bool(occupied_[x + cubes_[0] * (y + cubes_[1] * z)]);
  }
  // Calls f(x, y, z, in_polycube) for every cube around lattice node g (two per axis where g
  // lies on a cube boundary).
  template <class F>
  void ForCubesAround(const std::array<int, 3>& g, F&& f) const {
    int lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
      hi[a] = g[a] / m_;
      lo[a] = g[a] % m_ == 0 ? hi[a] - 1 : hi[a];
    }
    for (int x = lo[0]; x <= hi[0]; ++x)
      for (int y = lo[1]; y <= hi[1]; ++y)
        for (int z = lo[2]; z <= hi[2]; ++z) f(x, y, z, CubeAt(x, y, z));
  }
  // A lattice node is interior iff every cube around it is in the polycube.
  bool IsInterior(const std::array<int, 3>& g) const {
    if (!lat_.inside(g)) return false;
    bool all = true;
    ForCubesAround(g, [&](int, int, int, bool in) { all &= in; });
    return all;
  }
  const Vec3& Normal(int64_t b) const { return pg_.normal[b - pg_.num_interior]; }
  int LinkDir(int64_t b) const { return pg_.link_dir[b - pg_.num_interior]; }

  void LinkNodes();
  void FindFaceNeighbours();
  Vec3 CubesCentre(int64_t b) const;
  void ProjectBoundary(bool along);
  void MeasureBoundarySpacing();
  bool CreaseBetween(int32_t b1, int32_t b2) const;
  void RestartOnCreaseSides();
  void PlaceFirstInteriorNodes();
  void PlaceEdgeNodes();
  double SorFactor() const;
  template <class Colours, class Target>
  int Relax(const Colours& colours, int iterations, double tol, Target&& target, int stall = 0);
  void Smooth(int iterations, double tol_spacings);
  void Align();
  void PlaceInteriorNodes();
  void PlaceByWinslow();
  void PlaceByVariance();
  std::array<int32_t, 12> EdgeDiagonals(int64_t i, bool boundary) const;
  void SetWeights();
  void SetStencil();
  void SetLinkLengths();
  std::array<float, 6> FootWeights(int64_t b, int32_t j, const Vec3& foot) const;
  void SetLayers();

  const Shape& shape_;
  const PolygridOptions& options_;
  const int m_;  // lattice intervals per cube edge
  const std::array<int, 3> cubes_;
  Lattice lat_;
  std::vector<char> occupied_;  // per cube of the polycube's extent
  Polygrid pg_;

  // LinkNodes.
  int64_t N_ = 0;                                     // nodes, interior and boundary
  std::vector<int32_t> interior_at_;                  // lattice index -> interior node (-1: none)
  std::unordered_map<int64_t, int32_t> boundary_at_;  // (lattice, link dir) -> node
  std::unordered_map<int64_t, int> surface_count_;    // lattice node -> boundary nodes there
  std::vector<Vec3> lattice_position_;                // the polycube stretched onto the shape's box
  double h_ = 0;                                      // the stretched lattice's smallest step

  // FindFaceNeighbours (per boundary node b, at b - num_interior).
  std::vector<std::vector<int32_t>> face_nbrs_;   // the boundary nodes beside it on its face
  std::vector<std::vector<int32_t>> relax_nbrs_;  // those it is evened out towards
  // Split (concave) boundary nodes: their lattice point has 2 (edge) or 3 (corner) copies
  // (per node).
  std::vector<char> split_;

  // MeasureBoundarySpacing, RestartOnCreaseSides.
  double d_ = 0;  // the first interior nodes' distance from the surface
  std::array<int64_t, 6> crease_votes_ = {0, 0, 0, 0, 0, 0};  // per link direction
  bool any_crease_side_ = false;

  // PlaceFirstInteriorNodes.
  std::vector<char> free_node_;                // interior nodes that the placement moves
  std::vector<std::vector<int32_t>> blinks_;   // per interior node: its boundary nodes

  // PlaceInteriorNodes.
  std::array<std::vector<int32_t>, 2> colour_;  // the free nodes by lattice parity
  double omega_ = 1;                            // SOR's factor
};

Polygrid PolygridBuilder::Build() {
  pg_.resolution = options_.resolution;
  pg_.lattice_extent = lat_.n;
  LinkNodes();
  // Boundary nodes: project, then even out within each face.
  FindFaceNeighbours();
  ProjectBoundary(true);
  MeasureBoundarySpacing();
  RestartOnCreaseSides();
  PlaceFirstInteriorNodes();
  PlaceInteriorNodes();
  SetWeights();
  SetStencil();
  SetLinkLengths();
  SetLayers();
  return std::move(pg_);
}

// Interior nodes (every cube around them in the polycube), their lattice links, and a boundary
// node per link that leaves the interior; then the polycube stretched onto the shape's bounding
// box.
void PolygridBuilder::LinkNodes() {
  interior_at_.assign(lat_.size(), -1);
  for (int z = 0; z < lat_.n[2]; ++z)
    for (int y = 0; y < lat_.n[1]; ++y)
      for (int x = 0; x < lat_.n[0]; ++x)
        if (IsInterior({x, y, z})) {
          interior_at_[lat_.index({x, y, z})] = int32_t(pg_.lattice.size());
          pg_.lattice.push_back({x, y, z});
        }
  pg_.num_interior = int64_t(pg_.lattice.size());
  if (pg_.num_interior == 0)
    throw InputError("polycube: no interior node at resolution " + std::to_string(options_.resolution));
  if (pg_.num_interior > (int64_t(1) << 30)) throw InputError("polygrid: too many nodes");
  pg_.neighbours.assign(pg_.num_interior, {-1, -1, -1, -1, -1, -1});
  for (int64_t i = 0; i < pg_.num_interior; ++i)
    for (int dir = 0; dir < 6; ++dir) {
      auto g = pg_.lattice[i];
      g[dir / 2] += dir % 2 ? 1 : -1;
      const int32_t k = interior_at_[lat_.index(g)];
      if (k >= 0) {
        pg_.neighbours[i][dir] = k;
        continue;
      }
      const int32_t b = int32_t(pg_.lattice.size());
      pg_.lattice.push_back(g);
      pg_.neighbours.push_back({int32_t(i), -1, -1, -1, -1, -1});
      pg_.neighbours[i][dir] = b;
      pg_.link_dir.push_back(dir);
      boundary_at_[Key(g, dir)] = b;
      ++surface_count_[Key(g, 0)];
    }
  N_ = int64_t(pg_.lattice.size());
  pg_.position.resize(N_);
  for (int64_t n = 0; n < N_; ++n)
    for (int a = 0; a < 3; ++a)
      pg_.position[n][a] = shape_.lo[a] + (shape_.hi[a] - shape_.lo[a]) * pg_.lattice[n][a] / (lat_.n[a] - 1);
  lattice_position_ = pg_.position;
  h_ = ((shape_.hi - shape_.lo).array() / (Eigen::Array3d(lat_.n[0], lat_.n[1], lat_.n[2]) - 1)).minCoeff();
}

void PolygridBuilder::FindFaceNeighbours() {
  pg_.normal.resize(N_ - pg_.num_interior);
  face_nbrs_.resize(N_ - pg_.num_interior);
  for (int64_t b = pg_.num_interior; b < N_; ++b) {
    const int dir = LinkDir(b);
    for (int a = 0; a < 3; ++a) {
      if (a == dir / 2) continue;
      for (int s : {-1, 1}) {
        auto g = pg_.lattice[b];
        g[a] += s;
        if (auto it = boundary_at_.find(Key(g, dir)); it != boundary_at_.end())
          face_nbrs_[b - pg_.num_interior].push_back(it->second);
      }
    }
  }
  // Evening out moves a node half-way to the mean of these neighbours: the 4 of its face inside
  // a face; along a concave edge of the polycube (split nodes), its 2 split neighbours along
  // the edge, the same for every copy, so the copies stay together; none on the rims of faces
  // at convex edges and at concave corners, which stay where they were projected. (Along
  // concave edges that a rounded mesh fills in, nodes landed out of order near the edge's ends.)
  split_.assign(N_, 0);
  for (int64_t b = pg_.num_interior; b < N_; ++b) split_[b] = surface_count_.at(Key(pg_.lattice[b], 0)) > 1;
  relax_nbrs_.resize(N_ - pg_.num_interior);
  for (int64_t b = pg_.num_interior; b < N_; ++b) {
    const auto& nb = face_nbrs_[b - pg_.num_interior];
    auto& out = relax_nbrs_[b - pg_.num_interior];
    if (nb.size() == 4) {
      out = nb;
    } else if (surface_count_.at(Key(pg_.lattice[b], 0)) == 2) {
      for (int32_t k : nb)
        if (split_[k]) out.push_back(k);
      int gap = 0;
      if (out.size() == 2)
        for (int a = 0; a < 3; ++a) gap += std::abs(pg_.lattice[out[0]][a] - pg_.lattice[out[1]][a]);
      if (gap != 2) out.clear();
    }
  }
}

// The centre of the polycube's cubes around boundary node b, stretched like the lattice: the
// first projection goes along the line from there (Shape::ProjectAlong).
Vec3 PolygridBuilder::CubesCentre(int64_t b) const {
  Vec3 sum = Vec3::Zero();
  int count = 0;
  ForCubesAround(pg_.lattice[b], [&](int x, int y, int z, bool in) {
    if (!in) return;
    sum += Vec3(x + 0.5, y + 0.5, z + 0.5) * m_;
    ++count;
  });
  TL_CHECK(count > 0);
  Vec3 centre;
  for (int a = 0; a < 3; ++a)
    centre[a] = shape_.lo[a] + (shape_.hi[a] - shape_.lo[a]) * sum[a] / count / (lat_.n[a] - 1);
  return centre;
}

// The boundary nodes onto the surface, then evened out. along: from the plain stretch, along the
// lines from the cubes' centres; else (the crease restart, whose nodes sit off flat sides along
// their normals) the closest point.
void PolygridBuilder::ProjectBoundary(bool along) {
  for (int64_t b = pg_.num_interior; b < N_; ++b) {
    Vec3& normal = pg_.normal[b - pg_.num_interior];
    if (!along) {
      shape_.Project(pg_.position[b], &pg_.position[b], &normal);
      continue;
    }
    const Vec3 p = pg_.position[b], centre = CubesCentre(b);
    shape_.ProjectAlong(p, centre, &pg_.position[b], &normal);
    // Where the line's hit lies further than twice the surface's nearest point plus half a
    // lattice step, the line met the surface at a glancing angle or ran past it near p and
    // met it beyond the cube: a torus's inner wall near the polycube's hole corners, seen from
    // the one cube's centre (the folded boundary inverted ~300 interior cells of a torus
    // mesh), or a concave edge of the polycube that a rounded mesh fills in (nodes along the
    // edge landed out of order; 775 folded cells on a rounded bunny at 13^3). The lines along
    // the node's face normal and along the nearest point's normal instead, where their hits
    // are nearer. (The nearest point itself would gather the nodes near a faceted mesh's
    // convex edges and corners onto them.)
    const double len = (p - centre).norm(), hit = (pg_.position[b] - p).norm();
    Vec3 nearest, nearest_normal;
    if (hit > 0.5 * h_) shape_.Project(p, &nearest, &nearest_normal);  // else the test below fails anyway
    if (hit > 0.5 * h_ && hit > 2 * (nearest - p).norm() + 0.5 * h_) {
      const Vec3 outward = Eigen::Vector3i(LatticeStep(LinkDir(b)).data()).cast<double>();
      for (const Vec3& dir : {outward, nearest_normal}) {
        Vec3 s2, n2;
        shape_.ProjectAlong(p, p - len * dir, &s2, &n2);
        if ((s2 - p).norm() < (pg_.position[b] - p).norm()) {
          pg_.position[b] = s2;
          normal = n2;
        }
      }
    }
  }
  for (int it = 0; it < options_.boundary_relax_iterations; ++it) {
    std::vector<Vec3> next = pg_.position;
    for (int64_t b = pg_.num_interior; b < N_; ++b) {
      const auto& nb = relax_nbrs_[b - pg_.num_interior];
      if (nb.empty()) continue;
      Vec3 mean = Vec3::Zero();
      for (int32_t k : nb) mean += pg_.position[k] / double(nb.size());
      shape_.Project(0.5 * (pg_.position[b] + mean), &next[b], &pg_.normal[b - pg_.num_interior]);
    }
    pg_.position.swap(next);
  }
}

void PolygridBuilder::MeasureBoundarySpacing() {
  double spacing_sum = 0;
  int64_t spacing_count = 0;
  for (int64_t b = pg_.num_interior; b < N_; ++b)
    for (int32_t k : face_nbrs_[b - pg_.num_interior]) {
      spacing_sum += (pg_.position[b] - pg_.position[k]).norm();
      ++spacing_count;
    }
  pg_.mean_boundary_spacing = spacing_count ? spacing_sum / spacing_count : (shape_.hi - shape_.lo).norm() / lat_.n[0];
  d_ = options_.first_layer_fraction * pg_.mean_boundary_spacing;
  pg_.first_layer_distance = d_;
}

// Whether boundary nodes b1 and b2 of one interior node (at a convex edge or corner of the
// polycube) lie on either side of a crease of the surface: their normals more than 30
// degrees apart, and each turning less than half as much to its face neighbour one step
// further from the edge (unless that one sits on a concave edge). A rounded edge turns its
// normals gradually and is no crease, however far apart the nodes beside it are (the bunny's
// polycube under a rounded mesh: mostly more than 30 degrees at 9^3, where the crease rules
// merged nodes of two faces).
bool PolygridBuilder::CreaseBetween(int32_t b1, int32_t b2) const {
  const double across = std::acos(std::clamp(Normal(b1).dot(Normal(b2)), -1.0, 1.0));
  if (across <= M_PI / 6) return false;
  for (const auto& [b, other] : {std::pair(b1, b2), std::pair(b2, b1)}) {
    auto g = pg_.lattice[b];
    const auto step = LatticeStep(LinkDir(other));
    for (int a = 0; a < 3; ++a) g[a] -= step[a];
    const auto it = boundary_at_.find(Key(g, LinkDir(b)));
    if (it != boundary_at_.end() && !split_[it->second] &&  // not a concave edge's
        std::acos(std::clamp(Normal(b).dot(Normal(it->second)), -1.0, 1.0)) > 0.5 * across)
      return false;
  }
  return true;
}

// Where a side of the polycube meets creases of the surface (a box's edges), the crease rule
// below puts the first interior lattice plane at d from the surface. Start again, then, from
// the lattice stretched so that on such a side the interior lattice plane 1 (or n-2) lies at
// d inside the bounding box (the other sides keep the plain stretch), and project and even
// out the boundary nodes as above. On a box every node then already sits where the placement
// below converges: a tensor-product grid with straight grid lines to the surface. (From the
// plain stretch the alignment passes carry the inset across the grid only about half-way per
// pass; measured: grid lines bent by up to 0.07 spacings at 33^3.) A side is a crease side
// when most of its boundary nodes that share their interior node with a boundary node of
// another side lie across a crease from it (CreaseBetween).
void PolygridBuilder::RestartOnCreaseSides() {
  std::vector<std::vector<int32_t>> links(pg_.num_interior);
  for (int64_t b = pg_.num_interior; b < N_; ++b) links[pg_.neighbours[b][0]].push_back(int32_t(b));
  for (const auto& bl : links)
    for (int32_t b1 : bl)
      for (int32_t b2 : bl) {
        if (LinkDir(b1) == LinkDir(b2)) continue;
        crease_votes_[LinkDir(b1)] += CreaseBetween(b1, b2) ? 1 : -1;
      }
  any_crease_side_ = *std::max_element(crease_votes_.begin(), crease_votes_.end()) > 0;
  if (!any_crease_side_) return;
  pg_.position = lattice_position_;
  for (int a = 0; a < 3; ++a) {
    if (lat_.n[a] <= 3) continue;
    const double extent = shape_.hi[a] - shape_.lo[a], plain = extent / (lat_.n[a] - 1);
    const double e_lo = crease_votes_[2 * a] > 0 ? d_ : plain;
    const double e_hi = crease_votes_[2 * a + 1] > 0 ? d_ : plain;
    for (int64_t n = 0; n < N_; ++n)
      pg_.position[n][a] = shape_.lo[a] + e_lo + (extent - e_lo - e_hi) * (pg_.lattice[n][a] - 1) / (lat_.n[a] - 3);
  }
  ProjectBoundary(false);
}

// First interior nodes: at distance d along the inward normal of their boundary node.
// Corner and edge fix: an interior node linked to two or three boundary nodes (a convex edge
// or corner of the polycube) goes where it is at distance d from every one of their tangent
// planes (least squares), and each of those boundary nodes slides on the surface to the
// point at distance d along its normal from it, so every link is again a normal of length d
// (PlaceEdgeNodes).
void PolygridBuilder::PlaceFirstInteriorNodes() {
  free_node_.assign(pg_.num_interior, 1);
  blinks_.resize(pg_.num_interior);
  for (int64_t b = pg_.num_interior; b < N_; ++b) blinks_[pg_.neighbours[b][0]].push_back(int32_t(b));
  for (int64_t i = 0; i < pg_.num_interior; ++i) {
    if (blinks_[i].empty()) continue;
    free_node_[i] = 0;
    if (blinks_[i].size() > 1) continue;
    const int32_t b = blinks_[i][0];
    Vec3 u = -Normal(b);
    if (split_[b]) {
      // A split concave node: lean along the lattice link so that the interior nodes of the
      // split copies do not coincide.
      u = (u + (lattice_position_[i] - lattice_position_[b]).normalized()).normalized();
    }
    pg_.position[i] = pg_.position[b] + d_ * u;
  }
}

void PolygridBuilder::PlaceEdgeNodes() {
  for (int64_t i = 0; i < pg_.num_interior; ++i) {
    const auto& bl = blinks_[i];
    if (bl.size() < 2) continue;
    // Along the edge (the least-squares null space) the node follows the interior nodes
    // opposite its links, so the edge continues the grid lines of the faces.
    Vec3 x = Vec3::Zero();
    for (int32_t b : bl) {
      const int32_t o = pg_.neighbours[i][LinkDir(b) ^ 1];
      x += (o < pg_.num_interior ? pg_.position[o] : Vec3(pg_.position[b] - d_ * Normal(b))) / double(bl.size());
    }
    // Only a crease (CreaseBetween, e.g. a box edge) has well-posed plane constraints; on a
    // smooth part of the surface the boundary nodes stay and the node takes the mean of its
    // d-offset points (sliding would merge the boundary nodes).
    auto mean_of_offsets = [&] {
      Vec3 mean = Vec3::Zero();
      for (int32_t b : bl) mean += (pg_.position[b] - d_ * Normal(b)) / double(bl.size());
      return mean;
    };
    bool crease = false;
    for (int32_t b1 : bl)
      for (int32_t b2 : bl) crease |= b1 != b2 && CreaseBetween(b1, b2);
    if (!crease) {
      pg_.position[i] = mean_of_offsets();
      continue;
    }
    // At a crease the slide leaves the boundary nodes d |n_1 - n_2| apart (each at d along
    // its normal from the node); at an edge rounded on the scale of d it gathers them.
    double closest = std::numeric_limits<double>::infinity(), expected = closest;
    for (int32_t b1 : bl)
      for (int32_t b2 : bl)
        if (b1 < b2) expected = std::min(expected, d_ * (Normal(b1) - Normal(b2)).norm());
    std::vector<std::pair<Vec3, Vec3>> before;  // 4 links and more in thin parts (torus, 3^3)
    for (int32_t b : bl) before.emplace_back(pg_.position[b], Normal(b));
    for (int pass = 0; pass < 3; ++pass) {
      const double eps = 1e-6;
      Eigen::Matrix3d A = eps * Eigen::Matrix3d::Identity();
      Vec3 r = eps * x;
      for (int32_t b : bl) {
        const Vec3& n = Normal(b);
        A += n * n.transpose();
        r += n * (n.dot(pg_.position[b]) - d_);
      }
      x = A.ldlt().solve(r);
      for (int32_t b : bl)
        shape_.Project(x + d_ * Normal(b), &pg_.position[b], &pg_.normal[b - pg_.num_interior]);
    }
    for (int32_t b1 : bl)
      for (int32_t b2 : bl)
        if (b1 < b2) closest = std::min(closest, (pg_.position[b1] - pg_.position[b2]).norm());
    if (closest < 0.5 * expected) {
      // Gathered (the bunny's polycube under a rounded mesh, 13^3: nodes of two faces on one
      // point): back, and the smooth part's rule.
      for (size_t k = 0; k < bl.size(); ++k)
        std::tie(pg_.position[bl[k]], pg_.normal[bl[k] - pg_.num_interior]) = before[k];
      pg_.position[i] = mean_of_offsets();
      continue;
    }
    pg_.position[i] = x;
  }
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
double PolygridBuilder::SorFactor() const {
  const int64_t ni = pg_.num_interior;
  std::vector<double> x(ni, 0.0), y(ni, 0.0);
  for (int64_t i = 0; i < ni; ++i) x[i] = free_node_[i] ? 1.0 : 0.0;
  double rho = 0;
  for (int step = 0; step < 30; ++step) {
    double xy = 0, xx = 0;
#pragma omp parallel for schedule(static) reduction(+ : xy, xx) if (ni > 20000)
    for (int64_t i = 0; i < ni; ++i) {
      if (!free_node_[i]) continue;
      double s = 0;
      for (int j = 0; j < 6; ++j) {
        const int32_t k = pg_.neighbours[i][j];
        if (k < ni && free_node_[k]) s += x[k];
      }
      y[i] = s / 6;
      xy += x[i] * y[i];
      xx += x[i] * x[i];
    }
    if (xx == 0) return 1.0;
    rho = xy / xx;
    const double norm = std::sqrt(std::inner_product(y.begin(), y.end(), y.begin(), 0.0));
    if (norm == 0) return 1.0;
    for (int64_t i = 0; i < ni; ++i) x[i] = y[i] / norm;
  }
  return 2 / (1 + std::sqrt(std::max(0.0, 1 - rho * rho)));
}

// Over-relaxed Gauss-Seidel sweeps of the free nodes towards target(i), colour by colour (a
// colour's nodes depend only on other colours', so each colour updates in parallel and the
// result does not depend on the thread count), until no node moves more than tol mm in a
// sweep or `iterations` sweeps.
// Returns the sweeps run, negated where it stopped without converging: at `iterations`, or
// with `stall` > 0 after that many sweeps without a new smallest largest step.
template <class Colours, class Target>
int PolygridBuilder::Relax(const Colours& colours, int iterations, double tol, Target&& target, int stall) {
  double best = std::numeric_limits<double>::infinity();
  for (int it = 0, best_it = 0; it < iterations; ++it) {
    double moved = 0;
    for (const std::vector<int32_t>& nodes : colours) {
      const int64_t n = int64_t(nodes.size());
#pragma omp parallel for schedule(static) reduction(max : moved) if (n > 20000)
      for (int64_t c = 0; c < n; ++c) {
        const int32_t i = nodes[c];
        const Vec3 step = omega_ * (target(i) - pg_.position[i]);
        pg_.position[i] += step;
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
}

// Laplacian smoothing of the free nodes (red-black over the lattice parity: interior nodes are
// linked along the lattice only, so the nodes of one parity depend only on the other's), until
// no node moves more than `tol_spacings` boundary spacings in a sweep or `iterations` sweeps.
void PolygridBuilder::Smooth(int iterations, double tol_spacings) {
  Relax(colour_, iterations, tol_spacings * pg_.mean_boundary_spacing, [&](int32_t i) {
    Vec3 mean = Vec3::Zero();
    for (int j = 0; j < 6; ++j) mean += pg_.position[pg_.neighbours[i][j]];
    return Vec3(mean / 6);
  });
}

// Alignment: a boundary node and its first interior node follow the grid line of the free
// interior node behind them (that node's surface point, and d inside it), so
// boundary links continue the interior grid lines along the normal. On crease sides only (a
// box's, the bunny's): on a smooth side the interior grid lines converge towards the
// polycube's edges, and following them undid the evening out of the boundary nodes, more
// with every pass. On the sphere at 17^3 after the 10 passes neighbouring boundary nodes were
// 0.35 mm apart next to the faces' rims and 2.05 mm at their centres (0.69 to 1.22 mm as
// evened out; the blob: 0.10 to 3.33 mm), and renders showed it: streaks along the cube's
// edges (docs/benchmarks.md).
void PolygridBuilder::Align() {
  for (int64_t i = 0; i < pg_.num_interior; ++i) {
    if (blinks_[i].size() != 1 || split_[blinks_[i][0]]) continue;
    const int32_t b = blinks_[i][0];
    if (crease_votes_[LinkDir(b)] <= 0) continue;  // not a crease side
    const int32_t f = pg_.neighbours[i][LinkDir(b) ^ 1];
    if (f >= pg_.num_interior || !free_node_[f]) continue;
    // Onto b's tangent plane first, so the projection stays on b's side of the surface.
    const Vec3& n = Normal(b);
    const Vec3 on_plane = pg_.position[f] + n.dot(pg_.position[b] - pg_.position[f]) * n;
    Vec3 moved, moved_normal;
    shape_.ProjectAlong(on_plane, pg_.position[f], &moved, &moved_normal);
    // Not past half-way to a neighbour of its face: where a crease side runs onto a rounded
    // part (the sample bar's ends at 9^3), the grid lines converge and following them put
    // nodes out of order (44 of 1127 cells folded).
    bool in_order = true;
    for (int32_t k : face_nbrs_[b - pg_.num_interior]) {
      const Vec3 to_k = pg_.position[k] - pg_.position[b];
      in_order &= (moved - pg_.position[b]).dot(to_k) <= 0.5 * to_k.squaredNorm();
    }
    if (!in_order) continue;
    pg_.position[b] = moved;
    pg_.normal[b - pg_.num_interior] = moved_normal;
    pg_.position[i] = moved - d_ * moved_normal;
  }
}

// The edge nodes, Laplacian smoothing and the alignment passes, then Winslow's placement or the
// paper's variance steps.
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
void PolygridBuilder::PlaceInteriorNodes() {
  for (int64_t i = 0; i < pg_.num_interior; ++i)
    if (free_node_[i]) {
      const auto& g = pg_.lattice[i];
      colour_[(g[0] + g[1] + g[2]) & 1].push_back(int32_t(i));
    }
  omega_ = SorFactor();
  const double loose = 1e-3;
  const double last = options_.placement == InteriorPlacement::kWinslow ? loose : kTightSmoothing;
  PlaceEdgeNodes();
  const int align_passes = any_crease_side_ ? options_.align_passes : 0;
  Smooth(options_.smooth_iterations, align_passes > 0 ? loose : last);
  for (int pass = 0; pass < align_passes; ++pass) {
    Align();
    PlaceEdgeNodes();
    if (pass + 1 < align_passes)
      Smooth(std::min(200, options_.smooth_iterations), loose);  // warm-started
    else
      Smooth(options_.smooth_iterations, last);
  }
  if (options_.placement == InteriorPlacement::kWinslow) PlaceByWinslow();
  else PlaceByVariance();
}

constexpr int kPairs[3][2] = {{0, 1}, {1, 2}, {0, 2}};  // the edge-diagonals' axis pairs

// The edge-diagonal lattice neighbours of interior node i in Polygrid::diagonal_neighbours'
// order (axis pairs kPairs, signs ++, +-, -+, --): interior nodes, or with `boundary` a boundary
// node at that lattice point (where a concave edge's node is split, the one linked to a face
// neighbour of i, on i's side; all share the surface point); -1 where there is none.
std::array<int32_t, 12> PolygridBuilder::EdgeDiagonals(int64_t i, bool boundary) const {
  std::array<int32_t, 12> diag;
  const auto& g = pg_.lattice[i];
  const auto& face = pg_.neighbours[i];
  for (int p = 0, k = 0; p < 3; ++p)
    for (int sa : {1, -1})
      for (int sb : {1, -1}) {
        auto h = g;
        h[kPairs[p][0]] += sa;
        h[kPairs[p][1]] += sb;
        int32_t n = lat_.inside(h) ? interior_at_[lat_.index(h)] : -1;
        if (n < 0 && boundary)
          for (int dir = 0; dir < 6; ++dir) {
            const auto it = boundary_at_.find(Key(h, dir));
            if (it == boundary_at_.end()) continue;
            const bool beside = std::find(face.begin(), face.end(), pg_.neighbours[it->second][0]) != face.end();
            if (n < 0 || beside) n = it->second;  // the first, unless one is beside i
            if (beside) break;
          }
        diag[k++] = n;
      }
  return diag;
}

// Winslow smoothing of the free nodes (see InteriorPlacement). With unit lattice spacing,
// x = (sum_a g^aa (x_-a + x_+a) + 2 sum_{a<b} g^ab x_ab) / (2 sum_a g^aa), where
// x_ab = (x_{+a+b} - x_{+a-b} - x_{-a+b} + x_{-a-b}) / 4 and g = (J^-1)(J^-1)^T with J's
// columns the central differences (x_+a - x_-a) / 2. A node whose edge-diagonal lattice
// neighbours are not all interior, or whose J is singular, takes the mean of its six
// neighbours instead. Gauss-Seidel over the 8 lattice parities (x, y, z mod 2): face and
// edge-diagonal neighbours always differ in parity, so each colour updates in parallel.
// Over-relaxed by the Laplacian smoothing's factor (the same fixed point, reached in fewer
// sweeps), to 1e-4 boundary spacings.
void PolygridBuilder::PlaceByWinslow() {
  std::vector<std::array<int32_t, 12>> diag(pg_.num_interior);
  std::array<std::vector<int32_t>, 8> parity;
  for (int64_t i = 0; i < pg_.num_interior; ++i) {
    if (!free_node_[i]) continue;
    const auto& g = pg_.lattice[i];
    parity[(g[0] & 1) | (g[1] & 1) << 1 | (g[2] & 1) << 2].push_back(int32_t(i));
    diag[i] = EdgeDiagonals(i, false);
  }
  const std::vector<Vec3> smoothed = pg_.position;
  const int sweeps = Relax(parity, options_.winslow_iterations, 1e-4 * pg_.mean_boundary_spacing, [&](int32_t i) {
    const auto& nb = pg_.neighbours[i];
    Vec3 target = Vec3::Zero();
    for (int j = 0; j < 6; ++j) target += pg_.position[nb[j]] / 6;
    Eigen::Matrix3d J;
    for (int a = 0; a < 3; ++a) J.col(a) = (pg_.position[nb[2 * a + 1]] - pg_.position[nb[2 * a]]) / 2;
    const double det = J.determinant();
    const bool diagonals = std::none_of(diag[i].begin(), diag[i].end(), [](int32_t k) { return k < 0; });
    if (!diagonals || !(std::abs(det) > 1e-12 * J.norm() * J.squaredNorm())) return target;
    const Eigen::Matrix3d Ji = J.inverse();
    const Eigen::Matrix3d G = Ji * Ji.transpose();
    Vec3 num = Vec3::Zero();
    double den = 0;
    for (int a = 0; a < 3; ++a) {
      num += G(a, a) * (pg_.position[nb[2 * a]] + pg_.position[nb[2 * a + 1]]);
      den += 2 * G(a, a);
    }
    for (int p = 0; p < 3; ++p) {
      const auto& d = diag[i];
      const Vec3 xab = (pg_.position[d[4 * p]] - pg_.position[d[4 * p + 1]] - pg_.position[d[4 * p + 2]] +
                        pg_.position[d[4 * p + 3]]) / 4;
      num += 2 * G(kPairs[p][0], kPairs[p][1]) * xab;
    }
    return den > 0 && num.allFinite() ? Vec3(num / den) : target;
  }, options_.winslow_stall);
  // Diverged: a node left the boundary nodes' bounding box (widened by a spacing).
  Eigen::AlignedBox3d box;
  for (int64_t b = pg_.num_interior; b < N_; ++b) box.extend(pg_.position[b]);
  box.min().array() -= pg_.mean_boundary_spacing;
  box.max().array() += pg_.mean_boundary_spacing;
  const bool diverged = std::any_of(pg_.position.begin(), pg_.position.begin() + pg_.num_interior,
                                    [&](const Vec3& x) { return !x.allFinite() || !box.contains(x); });
  if (diverged) {
    pg_.position = smoothed;
    Smooth(options_.smooth_iterations, kTightSmoothing);
  }
  if (sweeps < 0 || diverged)
    pg_.placement_note = fmt::format("Winslow placement {} after {} sweeps{}",
                                     sweeps >= 0 ? "converged" : -sweeps < options_.winslow_iterations
                                         ? "stopped unconverged (its steps stalled)" : "stopped unconverged (the cap)",
                                     std::abs(sweeps),
                                     diverged ? " and had diverged: the Laplacian-smoothed nodes are kept" : "");
}

// The paper's placement: gradient steps on the sum of the free nodes' edge-length variances
// (VarianceObjective), the step grown 1.2x after a decrease and halved after an increase.
void PolygridBuilder::PlaceByVariance() {
  std::vector<Vec3> grad;
  std::vector<std::array<double, 6>> scratch;
  double f = options_.variance_iterations > 0 ? VarianceObjective(pg_, free_node_, &grad, scratch) : 0;
  double step = 0.5;
  for (int it = 0; it < options_.variance_iterations && f > 0; ++it) {
    const std::vector<Vec3> saved = pg_.position;
    for (int64_t i = 0; i < pg_.num_interior; ++i)
      if (free_node_[i]) pg_.position[i] -= step * grad[i];
    std::vector<Vec3> g2;
    const double f2 = VarianceObjective(pg_, free_node_, &g2, scratch);
    if (f2 < f) {
      f = f2;
      grad.swap(g2);
      step *= 1.2;
    } else {
      pg_.position = saved;
      step *= 0.5;
      if (step < 1e-8) break;
    }
  }
}

// Laplacian weights (Appendix B), the counts of fallbacks and inverted cells, and the crowded
// boundary nodes.
void PolygridBuilder::SetWeights() {
  pg_.weights.assign(N_, {0, 0, 0, 0, 0, 0});
  int64_t fallback = 0, axis_only = 0, inverted = 0;
#pragma omp parallel for schedule(static) reduction(+ : fallback, axis_only, inverted) if (pg_.num_interior > 50000)
  for (int64_t i = 0; i < pg_.num_interior; ++i) {
    std::array<Vec3, 6> off;
    for (int j = 0; j < 6; ++j) off[j] = pg_.position[pg_.neighbours[i][j]] - pg_.position[i];
    std::array<double, 6> w;
    if (!LaplacianWeights(off, &w)) {
      // The 6x6 system gives a non-positive weight (first interior nodes along the polycube's
      // edges on a smooth shape) or is singular. The weights nearest the axis ones that keep
      // its first-order and trace conditions; the axis weights themselves where those fail, such
      // as a neighbour on the node itself (a folded grid: a polycube that does not fit the
      // shape; the bunny under one cube at 9^3 had 12 infinite weights, and its solve went to zero).
      const std::array<double, 6> axis = AxisLaplacianWeights(off, 1e-3 * pg_.mean_boundary_spacing);
      if (!FirstOrderAxisWeights(off, axis, &w)) {
        w = axis;
        ++axis_only;
      }
      ++fallback;
    }
    for (int j = 0; j < 6; ++j) pg_.weights[i][j] = float(w[j]);
    inverted += (off[1] - off[0]).dot((off[3] - off[2]).cross(off[5] - off[4])) <= 0;
  }
  pg_.fallback_weights = fallback;
  pg_.axis_weights = axis_only;
  pg_.inverted_cells = inverted;
  const std::vector<double> area = BoundaryNodeAreas(pg_);
  double mean = 0;
  for (double a : area) mean += a / double(area.size());
  for (double a : area) pg_.crowded_boundary_nodes += a < 0.01 * mean;
}

// Polygrid::stencil_weights. The Taylor conditions are scaled by the node's mean face-neighbour
// distance. Rows whose six weights miss them by less than kMet keep those: on the blocky bunny
// at 9^3 the median miss is 0.04 (slightly sheared cells everywhere), on the sphere's single
// cube 1.1; a threshold of 0.1 instead of 1e-3 leaves the sphere's figures as they are (rms
// 2.56 against 2.55 %) and puts 6 % of the bunny's rows on the wide stencil instead of 99 %.
// The fit is pulled a little towards Appendix B's weights (kTowardFace): where the
// conditions leave a choice, neighbouring rows then choose alike, which keeps the rows nearer
// symmetric and the relaxation's eigenvalues nearer the real axis that Chebyshev's steps
// assume (largest imaginary part on the bunny at 3^3 0.71 without, 0.28 with, 0.32 for the six
// weights; docs/render.md), at a small cost in accuracy (directionally lit sphere 17^3: rms
// 2.50 -> 2.55 %).
void PolygridBuilder::SetStencil() {
  if (!options_.diagonal_stencil) return;
  constexpr double kMet = 0.1, kTowardFace = 0.03;
  std::vector<std::array<int32_t, 12>> diag(pg_.num_interior);
  std::vector<std::array<float, 18>> stencil(pg_.num_interior);
  int64_t with_diagonals = 0, refitted = 0;
#pragma omp parallel for schedule(dynamic, 256) reduction(+ : with_diagonals, refitted) if (pg_.num_interior > 20000)
  for (int64_t i = 0; i < pg_.num_interior; ++i) {
    diag[i] = EdgeDiagonals(i, true);
    std::vector<Vec3> off;
    double scale = 0;
    for (int k = 0; k < 6; ++k) {
      off.push_back(pg_.position[pg_.neighbours[i][k]] - pg_.position[i]);
      scale += off.back().norm() / 6;
    }
    std::vector<double> w(pg_.weights[i].begin(), pg_.weights[i].end());
    stencil[i].fill(0.f);
    for (int k = 0; k < 6; ++k) stencil[i][k] = pg_.weights[i][k];
    if (!(scale > 0)) continue;
    const double face = TaylorResidual(off, w, scale);
    if (face < kMet) continue;
    std::vector<int> slot;  // off[6 + m] is diagonal slot slot[m]
    for (int k = 0; k < 12; ++k)
      if (diag[i][k] >= 0) {
        off.push_back(pg_.position[diag[i][k]] - pg_.position[i]);
        slot.push_back(k);
      }
    std::vector<double> toward = w;
    toward.resize(off.size(), 0.0);
    if (StencilLaplacianWeights(off, scale, &w, 10, toward, kTowardFace) >= face) continue;
    ++refitted;
    const double largest = *std::max_element(w.begin(), w.end());
    for (int k = 0; k < 6; ++k) stencil[i][k] = float(w[k]);
    bool any = false;
    for (size_t m = 0; m < slot.size(); ++m) {
      // Weights below 1e-6 of the row's largest would cost a read each and change nothing.
      const float wd = w[6 + m] < 1e-6 * largest ? 0.f : float(w[6 + m]);
      stencil[i][6 + slot[m]] = wd;
      any |= wd > 0;
    }
    with_diagonals += any;
  }
  if (refitted == 0) return;
  pg_.diagonal_neighbours = std::move(diag);
  pg_.stencil_weights = std::move(stencil);
  pg_.diagonal_stencil_nodes = with_diagonals;
}

// A first interior node with two or three boundary links on a smooth part of the surface sits
// between its boundary nodes (the mean of the d-offset points above), so its links lean up to
// ~80 degrees off the normal (|link| up to 5 d). The Robin condition needs dphi/dn, so such a
// link counts its extent along the boundary node's normal; |link| there made a uniformly lit
// sphere's radiance 10-19 % too high along the polycube's edges (docs/render.md, "Accuracy on
// curved shapes"). Other links are normals of length d by construction (at a sharp crease the
// node's own normal may be the other face's, so it is not used). The floor is a guard only:
// built-in shapes measure 0.86-2.1 d.
// Such a link's normal derivative is taken at its foot, v_b - d n_b, which lies beside j: phi
// there is interpolated between j and the lateral neighbours of j towards it (foot_weights).
// With phi_j itself, the two boundary nodes of an edge node shared its value, and the surface
// between them rendered as a flat band along the polycube's edges (a point light behind a
// sphere at 17^3: a visible step in the radiance's slope, where the dipole and 33^3 have none).
void PolygridBuilder::SetLinkLengths() {
  pg_.link_length.resize(N_ - pg_.num_interior);
  pg_.foot_weights.assign(N_ - pg_.num_interior, {0, 0, 0, 0, 0, 0});
  for (int64_t b = pg_.num_interior; b < N_; ++b) {
    const int32_t j = pg_.neighbours[b][0];
    const Vec3 link = pg_.position[b] - pg_.position[j];
    if (blinks_[j].size() == 1) {
      pg_.link_length[b - pg_.num_interior] = link.norm();
      continue;
    }
    const double d = std::max(link.dot(Normal(b)), 0.25 * pg_.first_layer_distance);
    pg_.link_length[b - pg_.num_interior] = d;
    pg_.foot_weights[b - pg_.num_interior] = FootWeights(b, j, pg_.position[b] - d * Normal(b));
  }
}

// foot - v_j as a combination of j's offsets to one lateral neighbour per lateral axis (the one
// on the foot's side), by non-negative least squares; only interior neighbours, the weights
// scaled to sum to at most 1 (a convex combination of j and its neighbours).
std::array<float, 6> PolygridBuilder::FootWeights(int64_t b, int32_t j, const Vec3& foot) const {
  const Vec3 t = foot - pg_.position[j];
  const int axis = LinkDir(b) / 2;
  std::array<int, 2> dirs = {-1, -1};
  std::array<Vec3, 2> off;
  for (int a = 0, m = 0; a < 3; ++a) {
    if (a == axis) continue;
    const Vec3 lo = pg_.position[pg_.neighbours[j][2 * a]] - pg_.position[j];
    const Vec3 hi = pg_.position[pg_.neighbours[j][2 * a + 1]] - pg_.position[j];
    const int dir = t.dot(hi - lo) >= 0 ? 2 * a + 1 : 2 * a;
    if (pg_.neighbours[j][dir] < pg_.num_interior) {
      dirs[m] = dir;
      off[m] = dir & 1 ? hi : lo;
    }
    ++m;
  }
  // Non-negative least squares over the (at most two) axes that have a neighbour: the joint
  // solution where it is well conditioned and non-negative, else the better of the single axes'
  // projections (offsets nearly parallel, in a folded cell, would give huge weights of opposite
  // signs), else none.
  const auto residual = [&](const Eigen::Vector2d& a) {
    Vec3 e = t;
    for (int p = 0; p < 2; ++p)
      if (dirs[p] >= 0) e -= a[p] * off[p];
    return e.squaredNorm();
  };
  Eigen::Vector2d alpha = Eigen::Vector2d::Zero();
  if (dirs[0] >= 0 && dirs[1] >= 0) {
    Eigen::Matrix2d A;
    A << off[0].dot(off[0]), off[0].dot(off[1]), off[1].dot(off[0]), off[1].dot(off[1]);
    const double det = A.determinant();
    if (det > 1e-6 * A(0, 0) * A(1, 1)) {
      const Eigen::Vector2d joint = A.inverse() * Eigen::Vector2d(off[0].dot(t), off[1].dot(t));
      if (joint.allFinite() && joint.minCoeff() >= 0) alpha = joint;
    }
  }
  if (alpha.isZero()) {
    for (int p = 0; p < 2; ++p) {
      if (dirs[p] < 0 || !(off[p].squaredNorm() > 0)) continue;
      Eigen::Vector2d single = Eigen::Vector2d::Zero();
      single[p] = std::max(0.0, off[p].dot(t) / off[p].squaredNorm());
      if (residual(single) < residual(alpha)) alpha = single;
    }
  }
  const double sum = alpha.sum();
  if (sum > 1) alpha /= sum;
  std::array<float, 6> w = {0, 0, 0, 0, 0, 0};
  for (int p = 0; p < 2; ++p)
    if (dirs[p] >= 0) w[dirs[p]] = float(alpha[p]);
  return w;
}

// Layers, shell sources and depths: breadth-first from the boundary.
void PolygridBuilder::SetLayers() {
  pg_.layer.assign(N_, -1);
  pg_.source.assign(N_, -1);
  std::deque<int32_t> queue;
  for (int64_t b = pg_.num_interior; b < N_; ++b) {
    pg_.layer[b] = 0;
    pg_.source[b] = int32_t(b);
    queue.push_back(int32_t(b));
  }
  while (!queue.empty()) {
    const int32_t x = queue.front();
    queue.pop_front();
    for (int j = 0; j < 6; ++j) {
      const int32_t k = pg_.neighbours[x][j];
      if (k < 0 || pg_.is_boundary(k)) continue;
      if (pg_.layer[k] < 0) {
        pg_.layer[k] = pg_.layer[x] + 1;
        pg_.source[k] = pg_.source[x];
        queue.push_back(k);
      } else if (pg_.layer[k] == pg_.layer[x] + 1 &&
                 (pg_.position[k] - pg_.position[pg_.source[x]]).squaredNorm() <
                     (pg_.position[k] - pg_.position[pg_.source[k]]).squaredNorm()) {
        pg_.source[k] = pg_.source[x];
      }
    }
  }
  pg_.depth_mm.resize(N_);
  for (int64_t n = 0; n < N_; ++n) pg_.depth_mm[n] = (pg_.position[n] - pg_.position[pg_.source[n]]).norm();
}

}  // namespace

Polygrid BuildPolygrid(const Polycube& polycube, const Shape& shape, const PolygridOptions& options) {
  if (std::string err = options.Validate(); !err.empty()) throw InputError("polygrid: " + err);
  if (std::string err = polycube.Validate(); !err.empty()) throw InputError("polycube: " + err);
  if (polycube.axes != Eigen::Matrix3d::Identity()) {  // built in the polycube's frame, turned back
    Polygrid pg = BuildPolygrid(WithoutAxes(polycube), *MakeRotatedShape(shape, polycube.axes), options);
    TurnBack(polycube.axes, &pg);
    return pg;
  }
  return PolygridBuilder(polycube, shape, options).Build();
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
