// SPDX-License-Identifier: MIT
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

namespace translume {

struct Polycube;  // render/polycube.h

using Vec3 = Eigen::Vector3d;

// A triangle mesh in mm. Triangles are counter-clockwise seen from outside.
struct TriangleMesh {
  std::vector<Vec3> vertices;
  std::vector<std::array<int, 3>> triangles;

  // Empty if the mesh is a closed 2-manifold (every undirected edge shared by exactly two
  // triangles, used once in each direction), else the first broken constraint: too few
  // triangles, an index out of range, a degenerate triangle, an open (boundary) edge, a
  // non-manifold edge (three or more triangles), inconsistent orientation or a non-manifold
  // vertex (two or more fans of triangles meeting at one vertex: a bowtie).
  std::string Validate() const;
  void Bounds(Vec3* lo, Vec3* hi) const;
  double Area() const;  // mm^2
  // Enclosed signed volume (mm^3) of a closed mesh: > 0 when its triangles face outward.
  double Volume() const;
  // For a closed 2-manifold (Validate() empty): the handles summed over the connected pieces,
  // from V - E + F = 2 (pieces - genus) over the vertices that triangles use.
  int Genus() const;
  // The connected pieces (triangles joined through shared vertices).
  int Pieces() const;
  // Area-weighted vertex normals (unit length).
  std::vector<Vec3> VertexNormals() const;
  // Per triangle corner: the area-weighted mean of the face normals of the triangles around
  // the corner's vertex whose normal is within crease_deg of this triangle's own (unit length).
  // Smooth across shallow edges, sharp at creases: on a 12-triangle cube every corner normal is
  // its face's, where VertexNormals gives the cube's diagonals.
  std::vector<std::array<Vec3, 3>> CornerNormals(double crease_deg) const;
};

// The mesh the shading pass draws (renderer.cc), with one unit normal per vertex in *normals:
// `mesh` split at creases (a vertex gets one copy per distinct corner normal, CornerNormals
// at the renderer's 45 degrees), so that flat faces shade flat; then, while an edge is longer
// than `max_edge` (mm) and the vertex count below `max_vertices`, every triangle split into
// four at its edge midpoints (all at once: no T-junctions; midpoints take the mean normal of
// their edge). Vertex radiance comes from the nearest polygrid boundary nodes, so a mesh
// coarser than the polygrid would otherwise blur its light between few vertices.
TriangleMesh ShadingMesh(const TriangleMesh& mesh, double max_edge, int64_t max_vertices,
                         std::vector<Vec3>* normals);


// A closed surface for the polygrid: the projection used to place boundary nodes (Section 5.1)
// and a triangle mesh for the final shading pass.
class Shape {
 public:
  virtual ~Shape() = default;
  // Maps p to a point on the surface and returns the outward unit normal there. Built-in shapes
  // use an analytic projection (radial for star-shaped ones, closest point otherwise), meshes
  // the closest point with the normal interpolated from its triangle's corner normals
  // (TriangleMesh::CornerNormals, crease at 45 degrees). `surface` may be &p (in place).
  virtual void Project(const Vec3& p, Vec3* surface, Vec3* normal) const = 0;
  // The first projection of a boundary node from the stretched polycube (Section 5.1): the
  // surface point on the line through `centre` (inside the polycube: the centre of the node's
  // cubes) and p that is nearest to p. Two nodes apart on the polycube then stay apart, where a
  // closest point on a faceted mesh would take every node in a convex vertex's or edge's
  // region to that vertex or edge (coincident nodes, infinite Laplacian weights). Meshes cast
  // the line; where it misses the surface, and for the built-in shapes (whose Project is one to
  // one), Project(p).
  virtual void ProjectAlong(const Vec3& p, const Vec3& centre, Vec3* surface, Vec3* normal) const {
    (void)centre;
    Project(p, surface, normal);
  }
  const TriangleMesh& mesh() const { return mesh_; }
  const std::string& name() const { return name_; }
  // Axis-aligned box that the polycube is stretched onto (mm).
  Vec3 lo, hi;

 protected:
  TriangleMesh mesh_;
  std::string name_;
};

// Built-in shapes, centred at the origin, sized so that the largest extent is `size_mm`:
//   slab   a box of 3 x 3 x 1 units           sphere  a ball
//   torus  ring radius 1, tube radius 0.5 units (a hole; extent 3 x 3 x 1 units)
//   blob   a ball with a smooth radial bump r(d) = R (1 + 0.15 sin(3 d.x) sin(2 d.y + 1) cos(2 d.z))
//   box    an axis-aligned box with the given extents (used by tests: `size` per axis)
//   bunny  the solid of BuiltinPolycube("bunny"), 253 unit cubes (body, head, ears, tail; the
//          cube count of the paper's Bunny, for the frame-rate benchmark): a blocky bunny,
//          11 x 7 x 10 cubes at most; each exposed face is tessellation/12 quads per side
// `tessellation` sets the render mesh's resolution. Throws InputError on an unknown name or a
// size that SizeProblem refuses.
std::unique_ptr<Shape> MakeBuiltinShape(const std::string& name, double size_mm,
                                        int tessellation = 48);
std::unique_ptr<Shape> MakeBoxShape(const Vec3& extent_mm, int tessellation = 8);
// The solid union of a polycube's unit cubes (as the bunny), centred, largest extent size_mm;
// each exposed cube face is a tessellation x tessellation grid of quads.
std::unique_ptr<Shape> MakePolycubeSolidShape(const Polycube& polycube, double size_mm,
                                              int tessellation, const std::string& name);
// A validated mesh, scaled and centred so that its largest extent is size_mm (0: as is; other
// sizes as SizeProblem allows).
std::unique_ptr<Shape> MakeMeshShape(TriangleMesh mesh, const std::string& name,
                                     double size_mm);
// What is wrong with an object's largest extent in mm ("" if nothing): it must be finite and
// within kMinSizeMm..kMaxSizeMm (a micron to a kilometre). Beyond that the renderer's float
// geometry overflows: a sphere of 1e30 mm rendered black, one of 1e300 mm crashed.
constexpr double kMinSizeMm = 1e-3, kMaxSizeMm = 1e6;
std::string SizeProblem(double size_mm);

// A polycube for a mesh shape (`--polycube auto:N`): the shape's bounding box (lo, hi) cut into
// cells, `cubes` along its longest axis and proportionally many (at least 1) along the others;
// a cell is a cube where its centre lies inside the mesh (its winding number, from the signed
// crossings of a ray along +x, is not 0; O(cells + triangles + crossings)). Where the cubes
// fall apart, the face-connected piece with the most cubes is kept and *note says how many
// were dropped (else it is emptied).
// Throws InputError where no cell's centre is inside (a part thinner than a cell everywhere).
Polycube VoxelPolycube(const Shape& shape, int cubes, std::string* note);

// The shape seen in a rotated frame: coordinates frame_from_shape * p (a rotation), its mesh
// rotated, Project and ProjectAlong those of `base` (which must outlive it) rotated, lo and hi
// the rotated mesh's bounds.
std::unique_ptr<Shape> MakeRotatedShape(const Shape& base, const Eigen::Matrix3d& frame_from_shape);

// The frame that lays a polycube best over a mesh (`--polycube auto`): the rotation R (rows:
// the frame's axes in the mesh's coordinates) that minimises the alignment
//   a(R) = sum_t A_t |R n_t|_1 / sum_t A_t |n_t|_2
// over the mesh's faces (area A_t, unit normal n_t): 1 where every face is perpendicular to an
// axis, sqrt(3) where all lie diagonally, 1.5 for a sphere in any frame. The normals are summed
// in 6 x 16 x 16 bins (cube-map cells); a(R) over the bins is minimised from the best 8 of 512
// rotations spread over SO(3) (a Halton sequence, deterministic) by rotations about the axes
// in halving steps; the best is refined over the faces themselves (the bins lean ~1 degree
// towards frames whose axis planes cut through them) and taken among its 24 symmetric frames
// as the one nearest the mesh's own axes. Those are kept (axes = identity) unless R aligns better
// by more than 0.01 and a tenth of a(I) - 1: a shape as round in every frame as the blob
// (1.475 against 1.498) keeps them, the rounded bunny turned by 30 degrees (1.217 against
// 1.367) gets its cubes' axes back.
struct PolycubeFrameFit {
  Eigen::Matrix3d axes = Eigen::Matrix3d::Identity();
  double alignment = 0;           // a(axes)
  double identity_alignment = 0;  // a(I)
  double turn_deg = 0;            // the rotation angle of axes
};
PolycubeFrameFit FitPolycubeFrame(const TriangleMesh& mesh);

// Calls visit(x, y, z) for every cell of a dims[0] x dims[1] x dims[2] grid at Chebyshev
// distance exactly r from cell c (ring r: the cell itself for r = 0). Nearest-neighbour
// searches visit rings of growing r until no unvisited cell can hold a nearer item.
template <typename Visit>
void ForEachCellInRing(const std::array<int, 3>& c, int r, const std::array<int, 3>& dims, Visit&& visit) {
  for (int z = std::max(0, c[2] - r); z <= std::min(dims[2] - 1, c[2] + r); ++z)
    for (int y = std::max(0, c[1] - r); y <= std::min(dims[1] - 1, c[1] + r); ++y)
      for (int x = std::max(0, c[0] - r); x <= std::min(dims[0] - 1, c[0] + r); ++x)
        if (std::max({std::abs(x - c[0]), std::abs(y - c[1]), std::abs(z - c[2])}) == r) visit(x, y, z);
}

// The closest point to p on triangle (a, b, c).
Vec3 ClosestPointOnTriangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c,
                            double* u, double* v, double* w);

}  // namespace translume
