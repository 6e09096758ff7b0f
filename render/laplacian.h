// SPDX-License-Identifier: MIT
#pragma once

#include <array>
#include <vector>

#include "render/shape.h"

namespace translume {

// The six Laplacian weights of a polygrid node (Wang et al. 2008, Appendix B). offsets[j] =
// v_j - v_0 (mm) for the neighbours in the order -x, +x, -y, +y, -z, +z of the polycube
// lattice. A local frame (x', y', z') is taken along the node's grid directions (x' along
// v_+x - v_-x, y' from v_+y - v_-y made orthogonal, z' = x' x y'); in it, Equation (10) without
// the mixed terms gives the 6x6 system M (df/dx', d2f/dx'2, df/dy', d2f/dy'2, df/dz', d2f/dz'2)
// = (f(v_j) - f(v_0)), W = M^-1, and
//   w_j = W_{2j} + W_{4j} + W_{6j}     (1-based rows: the second derivatives),
// so that  Laplacian f(v_0) ~= sum_j w_j (f(v_j) - f(v_0)). Units 1/mm^2.
// On an undistorted grid of spacings (hx, hy, hz) this is the 7-point stencil 1/h_a^2. Returns
// false (weights untouched) when M is singular or a weight is not positive and finite.
bool LaplacianWeights(const std::array<Vec3, 6>& offsets, std::array<double, 6>* weights,
                      bool local_frame = true);

// The per-axis three-point weights 2 / (l_j (l_j + l_opposite)) on the neighbour distances
// l_j = max(|offsets[j]|, min_length): the fallback for nodes whose 6x6 system is singular or
// gives a non-positive weight. min_length > 0 keeps them finite where a neighbour coincides
// with the node (a grid folded onto itself).
std::array<double, 6> AxisLaplacianWeights(const std::array<Vec3, 6>& offsets, double min_length = 0);

// The weights nearest the per-axis ones (least squares relative to each axis weight) that keep
// the conditions the 6x6 weights meet: first order exact (sum_j w_j offsets[j] = 0) and the
// trace of the second order (sum_j w_j |offsets[j]|^2 = 6, so that Laplacian |x|^2 = 6 is
// exact). For nodes whose 6x6 system gives a non-positive weight (first interior nodes along
// the polycube's edges on a smooth shape): the axis weights alone add a drift along the skewed
// grid lines there. Returns false (weights untouched) where a weight would fall below 5 % of
// its axis weight or the system is singular.
bool FirstOrderAxisWeights(const std::array<Vec3, 6>& offsets, const std::array<double, 6>& axis,
                           std::array<double, 6>* weights);

// The second-order Taylor conditions on a node's Laplacian weights w_j (1/mm^2) over offsets
// d_j = v_j - v_0 (mm), met exactly when sum_j w_j (f(v_j) - f(v_0)) = Laplacian f(v_0) for every
// quadratic f:
//   sum_j w_j d_j = 0  (first order, 3),   sum_j w_j d_j d_j^T = 2 I  (second order, 6; the mixed
//   terms included, which Appendix B's six weights leave out),
// and, implied by them, the trace sum_j w_j |d_j|^2 = 6 (Laplacian |x|^2 = 6).
// Returns their residual made dimensionless by the length `scale` (d / scale, w scale^2): the 2-norm
// of the ten conditions' misfits, the first-order ones and the trace times consistency_weight:
// those are what FirstOrderAxisWeights keep exactly where the 6x6 system fails, a drift along
// the grid and a wrong mean (the uniformly lit sphere's: -13 % on the paper's variance-placed
// grid at 17^3 with the trace weighted 1, -8 % with 10) weigh more than a misweighted curvature.
double TaylorResidual(const std::vector<Vec3>& offsets, const std::vector<double>& weights, double scale,
                      double consistency_weight = 10);

// The non-negative weights over `offsets` (any number: a polygrid node's six face and twelve
// edge-diagonal lattice neighbours) that meet those conditions best: non-negative least squares
// (Lawson & Hanson 1974, the active-set method) on TaylorResidual's ten weighted conditions.
// Where the six face neighbours cannot meet the mixed terms (a sheared cell), the diagonal
// ones can, and non-negative weights keep the relaxation convergent. Returns the residual as
// TaylorResidual; weights resized to offsets.size().
// With lambda > 0, the least squares also pulls towards `toward` (1/mm^2, one per offset), by
// lambda |(w - toward) scale^2|^2 on top.
double StencilLaplacianWeights(const std::vector<Vec3>& offsets, double scale, std::vector<double>* weights,
                               double consistency_weight = 10, const std::vector<double>& toward = {},
                               double lambda = 0);

}  // namespace translume
