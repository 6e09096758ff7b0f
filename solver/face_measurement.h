// SPDX-License-Identifier: MIT
#pragma once

#include <cstdint>
#include <vector>

#include "solver/grid.h"

namespace translume {

// What a camera measures of the front face, per node (docs/inverse.md, "What a camera measures").
//
// The forward model's radiance is a value at each node (SPEC section 3: L_p = (phi_p - q_p) /
// (2 pi)). A camera, through the image-to-grid mapping (acquire/face_mapping.h), and the
// simulators average the face's radiance over node p's face box instead: [x_p - h/2, x_p + h/2]
// per axis, halved at the face's border. The two differ by h^2 L'' / 24 inside and, at the
// border, by h L' / 4: first order, which fits used to absorb by bending the border nodes'
// coefficients. MeasureFace is the box mean of the quadratic through three nodes per axis, a
// tensor product of 1-D rules (exact for polynomials of degree 2 in x and in y):
//   inside:                    (L_{i-1} + 22 L_i + L_{i+1}) / 24
//   at the border (half box):  (8 L_0 + 5 L_1 - L_2) / 12, mirrored at the far end
//   an axis of two nodes:      (3 L_0 + L_1) / 4 (the line through both)
// Faces are nx x ny, x fastest (node i + nx j). `out` must not alias the input.
void MeasureFace(int64_t nx, int64_t ny, const double* L, double* out);
// out = M^T v, the transpose of MeasureFace: the adjoint's source from dJ/d(measured).
void MeasureFaceTranspose(int64_t nx, int64_t ny, const double* v, double* out);
std::vector<float> MeasureFace(const GridShape& shape, const std::vector<float>& L);

// The same box means of a face known on a grid K times finer (RefineShape: (n - 1) K + 1 nodes
// per axis, K = 1 or even, coarse node i at fine node K i): per axis, the fine nodes across each
// coarse node's box (K intervals inside, K / 2 at the border) are integrated by composite Simpson
// (an even number of intervals), Simpson's 3/8 rule (three) or, for one interval, the
// quadratic through it and the next fine node inwards. K = 1 (the face itself) is MeasureFace.
// `simulate` makes its data with this.
std::vector<float> BoxMeansOfFineFace(const GridShape& coarse, int K, const std::vector<float>& fine_L);

}  // namespace translume
