// SPDX-License-Identifier: MIT
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <unordered_map>
#include <vector>

#include "render/polycube.h"
#include "render/shape.h"

namespace translume {

// How the interior nodes behind the first layer are placed after Laplacian smoothing.
//  kVariance: the paper's gradient steps on sum_i Var({|v_i - v_j|}) (Section 5.1).
//  kWinslow (the default): Winslow's elliptic grid generation (the lattice coordinates harmonic
//    functions of position): per free node sum_ab g^ab d^2 x / (d xi_a d xi_b) = 0 with
//    g^ab = grad xi_a . grad xi_b the inverse metric, discretised with the face and
//    edge-diagonal lattice neighbours. The paper names a conformal mapping as the ideal, for the
//    orthogonality Appendix B's weights assume, and uses the variance steps as a practical
//    stand-in; Winslow's grid keeps the cells nearer orthogonal, so a third as many nodes need
//    the fallback Laplacian weights and curved shapes come out closer to their exact
//    solutions (docs/render.md, "Accuracy on curved shapes"), in less build time.
enum class InteriorPlacement { kVariance, kWinslow };
InteriorPlacement ParseInteriorPlacement(const std::string& text);  // "variance" | "winslow"

struct PolygridOptions {
  // Nodes per cube edge (the same in every cube, Section 5.1); >= 3.
  int resolution = 9;
  // Iterations that even out the projected boundary nodes (Turk 1992-style relaxation: move
  // half-way to the mean of the 4 same-face neighbours, re-project).
  int boundary_relax_iterations = 5;
  // First interior nodes sit at d = first_layer_fraction * (mean boundary spacing) along the
  // inward normal (the paper: one tenth).
  double first_layer_fraction = 0.1;
  // Placement of the remaining interior nodes: Laplacian smoothing (the initial guess; at most
  // this many over-relaxed Gauss-Seidel sweeps, stopping when converged), then `placement`
  // (kVariance: this many gradient steps on sum_i Var({|v_i - v_j|}) over the free nodes).
  int smooth_iterations = 2000;
  int variance_iterations = 100;
  InteriorPlacement placement = InteriorPlacement::kWinslow;
  // kWinslow: at most this many Gauss-Seidel sweeps, stopping when no node moves more than 1e-4
  // boundary spacings in a sweep (1e-6 gives the same fallback counts and sphere figures to
  // the digits printed, and doubled the bunny's build), or after winslow_stall sweeps in a row
  // without a new smallest largest step (0: never). Winslow's equations are nonlinear: on some
  // meshes (a rounded polycube solid) the sweeps stall at a cycle and, run on, can diverge (the
  // rounded bunny at 13^3: after 1600 sweeps, 401654 of 460553 nodes on fallback weights). Where the nodes diverged (left the boundary's bounding box), the
  // Laplacian-smoothed nodes are kept. Polygrid::placement_note says what happened.
  int winslow_iterations = 2000;
  int winslow_stall = 100;
  // Interior rows over the face and the edge-diagonal lattice neighbours where Appendix B's six
  // weights miss the second-order Taylor conditions (Polygrid::stencil_weights); false: the six
  // face weights everywhere (the paper's rows, a third of the relaxation's reads).
  bool diagonal_stencil = true;
  // Passes that align each boundary node and its first interior node with the grid line of the
  // free interior node behind them (then re-smooth): links along the normal, grid lines
  // continued to the surface. On a box this gives a tensor-product grid. Only on the sides of
  // the polycube that meet creases of the surface (a box's, the bunny's; none on the sphere,
  // torus and blob), where it keeps the boundary nodes' spacing.
  int align_passes = 10;

  std::string Validate() const;
};

// A polygrid (Wang et al. 2008, Section 5.1): nodes on the lattice of a polycube (every cube a
// regular grid of `resolution`^3 nodes, shared faces joined), mapped into a shape.
//
// Nodes [0, num_interior) are interior: each has exactly six neighbours, in the order -x, +x,
// -y, +y, -z, +z of the lattice. Nodes [num_interior, size) are boundary nodes on the surface;
// each is linked to exactly ONE interior node (neighbours[b][0]; the other five are -1).
// Corner and edge fix: a lattice node on the polycube surface becomes one boundary node per
// link to an interior node. Convex edge and corner lattice nodes have no interior neighbour
// and are removed; a node on a concave edge or corner, linked to two or three interior nodes,
// is split into as many boundary nodes (same surface point, each with its own link). So every
// boundary node connects to exactly one interior node, and every interior node to six nodes.
// Node placement (projection, evening out, first layer at d, the crease rule for interior nodes
// with two or three boundary links, alignment, smoothing, variance minimisation): see
// BuildPolygrid and docs/render.md.
struct Polygrid {
  int resolution = 0;
  std::array<int, 3> lattice_extent = {0, 0, 0};  // lattice nodes per axis
  int64_t num_interior = 0;
  std::vector<Vec3> position;                     // mm
  std::vector<std::array<int, 3>> lattice;        // lattice coordinates (boundary: surface node)
  std::vector<std::array<int32_t, 6>> neighbours;
  std::vector<std::array<float, 6>> weights;      // interior: Laplacian weights w_ji, 1/mm^2
  // Boundary nodes (index b - num_interior): outward unit normal, link direction (0..5, the
  // direction from the interior node to the boundary node), and d_ji (mm): |v_b - v_j| where
  // v_j has this one boundary link (a normal of length d), else (v_b - v_j) . normal, the link's
  // extent along the normal (such links can lean far off it; at least d / 4).
  std::vector<Vec3> normal;
  std::vector<int> link_dir;
  std::vector<double> link_length;
  // The foot of a leaning link: phi at v_b - d_ji n_b (where the Robin condition's normal
  // derivative is taken) interpolated from v_j towards j's lateral neighbours,
  //   phi(foot) = (1 - sum_k alpha_k) phi_j + sum_k alpha_k phi_{neighbours[j][k]},
  // alpha indexed by j's link direction k (0 on b's own axis, >= 0, summing to at most 1).
  // All 0 where j has this one boundary link (its link is a normal of length d; a split concave
  // node's leans along the lattice on purpose, and reads j as before); with two or three the
  // foot lies between j and the interior nodes beside it, away from the polycube's edge.
  std::vector<std::array<float, 6>> foot_weights;
  // The interior rows' Laplacian (empty unless PolygridOptions::diagonal_stencil and some node
  // needs it): per interior node, 18 weights (1/mm^2) over the six face neighbours (the order of
  // `neighbours`) and then the twelve edge-diagonal lattice neighbours in diagonal_neighbours
  // (axis pairs xy, yz, xz, each with signs ++, +-, -+, --; an interior node, or a boundary node
  // at that lattice point; -1 where there is none, weight 0):
  //   Laplacian f(v_i) ~= sum_k stencil_weights[i][k] (f(v_k) - f(v_i)).
  // Where `weights` (Appendix B's six, no mixed terms) nearly meet every second-order Taylor
  // condition (TaylorResidual < 0.1 with the node's mean face-neighbour distance as the scale:
  // an undistorted, stretched or slightly sheared cell) they are kept and the diagonal weights
  // are 0; elsewhere (a sheared cell, such as the single cube's under a sphere) the non-negative
  // weights over all 18 that meet them best (StencilLaplacianWeights), unless they meet them
  // worse than `weights`. `weights` stay Appendix B's: the boundary rows' lateral slab term
  // reads them.
  std::vector<std::array<int32_t, 12>> diagonal_neighbours;
  std::vector<std::array<float, 18>> stencil_weights;
  int64_t diagonal_stencil_nodes = 0;  // interior nodes with a diagonal weight > 0
  // Every node: hops to the nearest boundary node (0 on the boundary), the boundary node it
  // was reached from (the shell mapping's surface point), and its depth |v - v_src| (mm).
  std::vector<int> layer;
  std::vector<int32_t> source;
  std::vector<double> depth_mm;
  double mean_boundary_spacing = 0;  // mm
  double first_layer_distance = 0;   // d, mm
  // Interior nodes whose 6x6 system (LaplacianWeights) failed: they take FirstOrderAxisWeights,
  // or where those fail too (axis_weights of them) AxisLaplacianWeights.
  int64_t fallback_weights = 0;
  int64_t axis_weights = 0;
  // Interior nodes whose grid is folded there: det J <= 0, J's columns the central differences
  // v_+a - v_-a of the lattice neighbours. Many (translume render notes more than 0.5 %) say
  // that the polycube does not follow the shape (one cube for the bunny: 3 % at 17^3).
  int64_t inverted_cells = 0;
  // Boundary nodes that stand for less than 1 % of the mean node's share of the surface
  // (BoundaryNodeAreas): crowded together where the polycube does not follow a sharp edge or
  // corner of the shape (a tetrahedron's voxel polycube: 0.18 % of them at 9^3, 1.5 % at 17^3;
  // the built-in shapes and the rounded bunny: none). translume render notes more than 0.1 %.
  int64_t crowded_boundary_nodes = 0;
  // Empty where the placement converged, else what happened (for the user).
  std::string placement_note;

  int64_t size() const { return int64_t(position.size()); }
  int64_t num_boundary() const { return size() - num_interior; }
  bool is_boundary(int64_t n) const { return n >= num_interior; }
  // Surface coordinates (u, v) of boundary node b in lattice units: the two lattice axes of
  // its polycube face (the axes other than link_dir / 2, in increasing order).
  std::array<double, 2> SurfaceUV(int64_t b) const;
};

// The unit lattice step of link direction dir (0..5: -x, +x, -y, +y, -z, +z).
std::array<int, 3> LatticeStep(int dir);

// Boundary nodes by lattice position and link direction (the split nodes of a concave edge
// share a lattice position and differ in direction).
class BoundaryNodeIndex {
 public:
  explicit BoundaryNodeIndex(const Polygrid& pg);
  // The boundary node (a node index, >= num_interior) at lattice g linked along dir, or -1.
  int64_t Find(const std::array<int, 3>& g, int dir) const;

 private:
  std::unordered_map<int64_t, int64_t> at_;
};

// The surface area each boundary node stands for (mm^2), [b - num_interior]: the parallelogram
// spanned by its half-way vectors to its neighbours on the same polycube face (lattice
// neighbours with the same link direction; at a face's rim, half-way to the nearest node of the
// face across the edge; the mean boundary spacing where a face is one node wide). With
// total_mm2 > 0 they are scaled to sum to it (the surface's area); unscaled they sum to about
// the surface's area. Sums over the surface (the dipole baseline) weight each node by it.
std::vector<double> BoundaryNodeAreas(const Polygrid& pg, double total_mm2 = 0);

// Builds the polygrid of `shape` from `polycube`, stretched onto the shape's bounding box.
// Throws InputError on bad options or a polycube whose grid has no interior node.
Polygrid BuildPolygrid(const Polycube& polycube, const Shape& shape,
                       const PolygridOptions& options);

// `--polycube auto`: the voxel polycubes of the shape (VoxelPolycube) in the frame its mesh's
// faces follow (FitPolycubeFrame; the polycubes' axes) for N = 1, 2, ..., max_cells, each
// tried as a polygrid of `resolution` nodes per cube edge (default options otherwise): the
// first whose genus is the mesh's, whose grid has at most max_inverted of its interior cells
// inverted (Polygrid::inverted_cells) and whose cubes, stretched onto the shape's box in that
// frame, are at most max_aspect times longer than wide (one cube for a 3:1:1 bar is not);
// where none passes, the one of the mesh's genus with the fewest inverted (else the fewest of
// all). Small N first: a smooth shape is best served by few cubes (the sphere by one, the
// torus by a ring of 8). report: called with one line (ending in a newline) for a turned
// frame, per N as it is tried, then one with the choice.
struct AutoPolycubeOptions {
  int max_cells = 12;
  int resolution = 5;
  double max_inverted = 0.005;
  double max_aspect = 2;
};
using ReportLine = std::function<void(const std::string& line)>;
Polycube AutoPolycube(const Shape& shape, const AutoPolycubeOptions& options, const ReportLine& report);

// The polycube of `translume render --polycube SPEC` for `shape`: "" the built-in shape's own
// (builtin: its name), or for a mesh (builtin empty) as "auto"; "auto" AutoPolycube; "auto:N"
// VoxelPolycube(N) in AutoPolycube's frame (auto:1 is one cube); else a polycube file
// (ReadPolycube). *label names it
// in messages ("FILE", "auto (253 cubes, 11 x 7 x 10)", "(the shape's own)"); log gets
// auto's tries as they are made, or auto:N's note.
// Throws InputError on a bad SPEC or file.
Polycube ResolvePolycube(const std::string& spec, const Shape& shape, const std::string& builtin,
                         std::string* label, const ReportLine& log);

// What a user should know about laying `polycube` (named `label` in messages) over `shape`,
// one sentence each: a mesh of several separate pieces (one polygrid joins them), a genus
// other than the mesh's.
std::vector<std::string> PolycubeNotes(const Shape& shape, const Polycube& polycube, const std::string& label);
// And about the hierarchy built from it (finest first; `levels_asked` levels were asked for):
// fewer levels than asked, each level's placement note, more than 0.5 % of the finest level's
// interior cells folded (Polygrid::inverted_cells), more than 0.1 % of its boundary nodes
// crowded (Polygrid::crowded_boundary_nodes).
std::vector<std::string> PolygridNotes(const std::vector<Polygrid>& levels, int levels_asked,
                                       const std::string& label, const std::string& shape_name);

// Levels for the hierarchical scheme (Section 5.3), finest first: resolution n, (n-1)/2+1, ...
// while (n-1) is even and the coarser resolution is >= 3, at most max_levels.
std::vector<Polygrid> BuildPolygridHierarchy(const Polycube& polycube, const Shape& shape,
                                             const PolygridOptions& options, int max_levels);

// A prolongation as a sparse matrix over nodes, rows by fine node (CSR):
//   fine[f] = sum_{k in [start[f], start[f + 1])} weight[k] coarse[index[k]].
struct Prolongation {
  std::vector<int32_t> start, index;
  std::vector<float> weight;
};
// The weights of ProlongPolygrid (below) as a matrix.
Prolongation MakeProlongation(const Polygrid& coarse, const Polygrid& fine);

// Interpolates node values from a coarse level to a fine one (resolution 2(nc-1)+1) through the
// shared lattice: a coarse lattice node's value is its interior node's, or the mean of its
// boundary nodes; a fine node takes the trilinear interpolation at lattice position g/2 over the
// coarse lattice nodes that exist, renormalised.
void ProlongPolygrid(const Polygrid& coarse, const std::vector<float>& coarse_values,
                     const Polygrid& fine, std::vector<float>* fine_values);

// The other way (Section 5.3: a coarse node's material is the average over its children): a
// coarse node at lattice g takes the weighted mean of the fine nodes of its own kind (interior
// or boundary) at lattice 2g + d, d in {-1, 0, 1}^3, weights prod_a (1 - |d_a| / 2),
// normalised over the children that exist.
void RestrictPolygrid(const Polygrid& fine, const std::vector<float>& fine_values,
                      const Polygrid& coarse, std::vector<float>* coarse_values);

}  // namespace translume
