// SPDX-License-Identifier: MIT
#pragma once

#include <array>
#include <vector>

#include "solver/grid.h"

namespace translume {

// Node coordinates of a tensor-product grid (mm), one list per axis. The finest multigrid
// level is the uniform grid of SPEC section 2; coarser levels keep every other node and may have
// one wider last interval, so the geometry is per axis.
struct TensorGrid {
  GridShape shape;
  std::array<std::vector<double>, 3> coord;

  static TensorGrid Uniform(const GridShape& shape, double h);
  // Distance between node i and i + 1 along `axis`.
  double Gap(int axis, int64_t i) const { return coord[axis][i + 1] - coord[axis][i]; }
  // Width of node i's dual box along `axis`: half the gaps on each side; the box is halved on
  // the boundary (SPEC section 3: half, quarter and eighth boxes).
  double Width(int axis, int64_t i) const;
};

// The canonical finite-volume operator of SPEC section 3 for one channel, as a symmetric
// 7-point stencil:
//   (A phi)_p = diag_p phi_p - sum_{q in N(p)} c_pq phi_q
//   c_pq   = A_pq (kappa_p + kappa_q) / 2 / |x_q - x_p|                  (face conductance)
//   diag_p = sum_q c_pq + V_p mu_p + sum_{boundary axes a of p} A_p^a / (2 C)
// and the right-hand side b_p = A_p^z q_p / (2 C) on the lit face. A phi = b is the paper's
// Equations (1), (2), (8) in conservative, second-order form. cx[p] couples p and p + e_x
// (0 on the last x plane), likewise cy and cz.
template <typename T>
struct Stencil {
  GridShape shape;
  std::vector<T> cx, cy, cz, diag;
};

// The per-node math, written once: conductance of the face between two nodes.
template <typename T>
inline T FaceConductance(double area_over_gap, T kappa_p, T kappa_q) {
  return T(0.5 * area_over_gap) * (kappa_p + kappa_q);
}

// Assembles the stencil from per-node kappa (mm) and mu (1/mm) on `grid`.
template <typename T>
void AssembleStencil(const TensorGrid& grid, const T* kappa, const T* mu, double C,
                     Stencil<T>* stencil);

// sum_i a[i] b[i] over one row, in double, in eight independent partial sums: with one, each
// addition waits on the previous one (the adder's latency), which costs as much as the rest
// of a row's pass over cached data.
template <typename A, typename B>
inline double RowDot(const A* __restrict a, const B* __restrict b, int64_t n) {
  double s[8] = {};
  int64_t i = 0;
  for (; i + 8 <= n; i += 8)
    for (int u = 0; u < 8; ++u) s[u] += double(a[i + u]) * double(b[i + u]);
  for (; i < n; ++i) s[i % 8] += double(a[i]) * double(b[i]);
  return ((s[0] + s[1]) + (s[2] + s[3])) + ((s[4] + s[5]) + (s[6] + s[7]));
}

// One x-row of A x (kResidual: b - A x) for kernels that walk the grid themselves: the
// interior nodes in one branch-free loop that the compiler vectorises, the two ends apart.
// Every pointer is the row's start: the row's diagonal, x-conductances and x, the conductances
// and x of the rows below and above in y and z (nx zeros where the row is on the boundary), b
// (kResidual only) and the output row. Sums accumulate in Acc: double where b - A x must not
// lose the cancellation near convergence, T inside a preconditioner.
template <typename T, typename X, typename Acc, bool kResidual>
inline void StencilRowKernel(int64_t nx, const T* __restrict dg, const T* __restrict cx,
                             const X* __restrict xr, const T* __restrict cym,
                             const X* __restrict xym, const T* __restrict cyp,
                             const X* __restrict xyp, const T* __restrict czm,
                             const X* __restrict xzm, const T* __restrict czp,
                             const X* __restrict xzp, const T* __restrict br, T* __restrict yr) {
  auto vertical = [&](int64_t i) {
    return Acc(dg[i]) * Acc(xr[i]) - Acc(cym[i]) * Acc(xym[i]) - Acc(cyp[i]) * Acc(xyp[i]) -
           Acc(czm[i]) * Acc(xzm[i]) - Acc(czp[i]) * Acc(xzp[i]);
  };
  auto put = [&](int64_t i, Acc v) {
    if constexpr (kResidual) yr[i] = T(Acc(br[i]) - v);
    else yr[i] = T(v);
  };
  if (nx == 1) {
    put(0, vertical(0));
    return;
  }
  put(0, vertical(0) - Acc(cx[0]) * Acc(xr[1]));
  for (int64_t i = 1; i + 1 < nx; ++i)
    put(i, vertical(i) - Acc(cx[i - 1]) * Acc(xr[i - 1]) - Acc(cx[i]) * Acc(xr[i + 1]));
  put(nx - 1, vertical(nx - 1) - Acc(cx[nx - 2]) * Acc(xr[nx - 2]));
}

// y = A x. Multithreaded.
template <typename T>
void ApplyStencil(const Stencil<T>& A, const T* x, T* y);

// y = A x like ApplyStencil, and returns the dot product x . y (accumulated in double) from the
// same pass over memory (conjugate gradients' p . A p). x may be float for a double stencil
// (y is then computed in double from the float values). Multithreaded.
template <typename T, typename X = T>
double ApplyStencilDot(const Stencil<T>& A, const X* x, T* y);

// r = b - A x, accumulated in double. x may be double for a float stencil (a float solver's
// iterate is kept in double; see MultigridSolver). Multithreaded.
template <typename T, typename X>
void StencilResidual(const Stencil<T>& A, const T* b, const X* x, T* r);

// Right-hand side for light q (nx*ny values on face k_lit): b_p = A_p^z q_p / (2 C) at the
// lit-face nodes, 0 elsewhere. The light enters through the lit face only.
template <typename T>
void LitFaceSource(const TensorGrid& grid, int64_t k_lit, double C, const float* q, T* b);

// The derivative of the operator, written with FaceConductance so that it is exactly the
// derivative of AssembleStencil. Adds, for every node p,
//   grad_kappa[p] += scale * sum_{faces (p,q)} dc_pq/dkappa_p (psi_p - psi_q)(phi_p - phi_q)
//   grad_mu[p]    += scale * V_p psi_p phi_p
// with dc_pq/dkappa_p = FaceConductance(A_pq / gap, 1, 0) = A_pq / (2 gap) and V_p the product
// of the node's dual-box widths: d(psi^T A phi)/dkappa_p and d(psi^T A phi)/dmu_p. The Robin
// terms and the source b do not depend on kappa or mu. With A phi = b and A psi = dJ/dphi,
// scale = -1 gives dJ/dkappa and dJ/dmu (the discrete adjoint of the paper's Appendix A).
// Arrays hold grid.shape.size() values; multithreaded over planes (gather form, no races).
template <typename T>
void AccumulateOperatorGradient(const TensorGrid& grid, const T* phi, const T* psi, double scale,
                                T* grad_kappa, T* grad_mu);

}  // namespace translume
