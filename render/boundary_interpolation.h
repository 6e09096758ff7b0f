// SPDX-License-Identifier: MIT
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "render/polygrid.h"

namespace translume {

// The boundary nodes of a polygrid as a surface of elements, for interpolating node values
// (the outgoing radiance) at points of the shape's surface (the shading mesh's vertices):
//  - quads of four lattice neighbours on one polycube face;
//  - quads across a convex polycube edge, where the edge's lattice nodes were removed: two
//    neighbouring rim nodes of one face and their counterparts on the other face (lattice
//    g + s - n, s the step towards the edge, n the first face's outward axis);
//  - triangles at a convex polycube corner: the corner-most node of each of the three faces.
// At a concave edge or corner the split nodes lie on the edge, so the faces' own quads meet
// there. A point takes bilinear weights in the quad (barycentric in the triangle) that holds
// it: the parameters (s, t) in [0, 1]^2 of the patch point nearest to it (Gauss-Newton). So a
// value linear in position is reproduced exactly on a planar face, and the interpolant is
// continuous across elements, which inverse-distance weights over the nearest nodes are not
// (a jump wherever the set of nearest nodes changes: bands in the shading).
class BoundaryElements {
 public:
  explicit BoundaryElements(const Polygrid& pg);

  // Weights for the value at surface point x over boundary nodes (index b - num_interior),
  // from the elements incident to the `near` nodes (boundary indices, e.g. the 4 nearest);
  // unused slots have weight 0. False where no such element holds x (within 1e-3 of its
  // parameter range and one boundary spacing of its patch): the caller falls back.
  bool Weights(const Vec3& x, const std::array<int32_t, 4>& near, std::array<int32_t, 4>* idx,
               std::array<float, 4>* w) const;

  int64_t num_quads() const { return num_quads_; }
  int64_t num_triangles() const { return int64_t(elements_.size()) - num_quads_; }

 private:
  struct Element {
    std::array<int32_t, 4> node;  // quad: P00, P10, P01, P11; triangle: three and -1
  };
  const Polygrid& pg_;
  std::vector<Element> elements_;
  std::vector<std::vector<int32_t>> of_node_;  // elements incident to each boundary node
  int64_t num_quads_ = 0;
};

}  // namespace translume
