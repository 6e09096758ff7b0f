// SPDX-License-Identifier: MIT
#include "solver/stencil.h"

#include <algorithm>
#include <array>
#include <type_traits>

#include "solver/status.h"
#include "solver/threads.h"

namespace translume {

TensorGrid TensorGrid::Uniform(const GridShape& shape, double h) {
  TensorGrid g;
  g.shape = shape;
  for (int a = 0; a < 3; ++a) {
    g.coord[a].resize(shape.n(a));
    for (int64_t i = 0; i < shape.n(a); ++i) g.coord[a][i] = double(i) * h;
  }
  return g;
}

double TensorGrid::Width(int axis, int64_t i) const {
  const int64_t n = shape.n(axis);
  double w = 0;
  if (i > 0) w += 0.5 * Gap(axis, i - 1);
  if (i + 1 < n) w += 0.5 * Gap(axis, i);
  return w;
}

namespace {

// Per-axis geometry of a tensor grid, computed once per pass instead of per node: the dual-box
// widths and the inverse gaps (area over gap of a face = product of the other two widths times
// the inverse gap; AssembleStencil and AccumulateOperatorGradient both form it this way, so
// the gradient stays the exact derivative of the assembly).
struct AxisGeometry {
  std::array<std::vector<double>, 3> width, inv_gap;  // inv_gap[a][i]: between i and i + 1
  explicit AxisGeometry(const TensorGrid& g) {
    for (int a = 0; a < 3; ++a) {
      const int64_t n = g.shape.n(a);
      width[a].resize(n);
      inv_gap[a].assign(n, 0.0);
      for (int64_t i = 0; i < n; ++i) {
        width[a][i] = g.Width(a, i);
        if (i + 1 < n) inv_gap[a][i] = 1.0 / g.Gap(a, i);
      }
    }
  }
};

// Visits every node with its dual-box widths, planes in parallel:
// f(i, j, k, p, wx, wy, wz) with p the linear index.
template <typename F>
void ForEachNode(const TensorGrid& g, const AxisGeometry& geo, F&& f) {
  const GridShape& s = g.shape;
  const double* wxs = geo.width[0].data();
#pragma omp parallel for schedule(static) if (s.size() >= kParallelNodes)
  for (int64_t k = 0; k < s.nz; ++k) {
    const double wz = geo.width[2][k];
    for (int64_t j = 0; j < s.ny; ++j) {
      const double wy = geo.width[1][j];
      for (int64_t i = 0; i < s.nx; ++i) f(i, j, k, i + s.nx * (j + s.ny * k), wxs[i], wy, wz);
    }
  }
}

}  // namespace

template <typename T>
void AssembleStencil(const TensorGrid& g, const T* kappa, const T* mu, double C,
                     Stencil<T>* st) {
  const GridShape& s = g.shape;
  const int64_t nx = s.nx, ny = s.ny, nz = s.nz, nxy = nx * ny;
  st->shape = s;
  st->cx.assign(s.size(), T(0));
  st->cy.assign(s.size(), T(0));
  st->cz.assign(s.size(), T(0));
  st->diag.assign(s.size(), T(0));
  const double robin = 1.0 / (2.0 * C);
  const AxisGeometry geo(g);
  const double *igx = geo.inv_gap[0].data(), *igy = geo.inv_gap[1].data(),
               *igz = geo.inv_gap[2].data();
  T *cx = st->cx.data(), *cy = st->cy.data(), *cz = st->cz.data(), *diag = st->diag.data();
  // Conductances first (each face once), then the diagonal from them.
  ForEachNode(g, geo, [=](int64_t i, int64_t j, int64_t k, int64_t p, double wx, double wy, double wz) {
    if (i + 1 < nx) cx[p] = FaceConductance<T>(wy * wz * igx[i], kappa[p], kappa[p + 1]);
    if (j + 1 < ny) cy[p] = FaceConductance<T>(wx * wz * igy[j], kappa[p], kappa[p + nx]);
    if (k + 1 < nz) cz[p] = FaceConductance<T>(wx * wy * igz[k], kappa[p], kappa[p + nxy]);
  });
  ForEachNode(g, geo, [=](int64_t i, int64_t j, int64_t k, int64_t p, double wx, double wy, double wz) {
    const int bx = (i == 0) + (i == nx - 1), by = (j == 0) + (j == ny - 1),
              bz = (k == 0) + (k == nz - 1);
    double d = wx * wy * wz * double(mu[p]) + robin * (bx * wy * wz + by * wx * wz + bz * wx * wy);
    T c = cx[p] + cy[p] + cz[p];
    if (i > 0) c += cx[p - 1];
    if (j > 0) c += cy[p - nx];
    if (k > 0) c += cz[p - nxy];
    diag[p] = T(d) + c;
  });
}

namespace {

// Row j of plane k of A x (kResidual: b - A x) into y; zx and zc are nx zeros.
template <typename T, typename X, bool kResidual>
inline void StencilRow(const Stencil<T>& A, const T* b, const X* x, T* y, int64_t j, int64_t k,
                       const X* zx, const T* zc) {
  const int64_t nx = A.shape.nx, ny = A.shape.ny, nz = A.shape.nz, nxy = nx * ny;
  const int64_t row = nx * (j + ny * k);
  const bool ym = j > 0, yp = j + 1 < ny, zm = k > 0, zp = k + 1 < nz;
  using Acc = std::conditional_t<kResidual, double, T>;
  StencilRowKernel<T, X, Acc, kResidual>(
      nx, A.diag.data() + row, A.cx.data() + row, x + row, ym ? A.cy.data() + row - nx : zc,
      ym ? x + row - nx : zx, yp ? A.cy.data() + row : zc, yp ? x + row + nx : zx,
      zm ? A.cz.data() + row - nxy : zc, zm ? x + row - nxy : zx, zp ? A.cz.data() + row : zc,
      zp ? x + row + nxy : zx, kResidual ? b + row : nullptr, y + row);
}

}  // namespace

template <typename T>
void ApplyStencil(const Stencil<T>& A, const T* x, T* y) {
  const int64_t nx = A.shape.nx, ny = A.shape.ny, nz = A.shape.nz;
  const std::vector<T> zeros(nx, T(0));
#pragma omp parallel for collapse(2) schedule(static) \
    if (A.shape.size() >= kParallelNodes)
  for (int64_t k = 0; k < nz; ++k)
    for (int64_t j = 0; j < ny; ++j)
      StencilRow<T, T, false>(A, nullptr, x, y, j, k, zeros.data(), zeros.data());
}

template <typename T, typename X>
double ApplyStencilDot(const Stencil<T>& A, const X* x, T* y) {
  const int64_t nx = A.shape.nx, ny = A.shape.ny, nz = A.shape.nz;
  const std::vector<X> zx(nx, X(0));
  const std::vector<T> zc(nx, T(0));
  double dot = 0;
#pragma omp parallel for collapse(2) schedule(static) reduction(+ : dot) \
    if (A.shape.size() >= kParallelNodes)
  for (int64_t k = 0; k < nz; ++k)
    for (int64_t j = 0; j < ny; ++j) {
      StencilRow<T, X, false>(A, nullptr, x, y, j, k, zx.data(), zc.data());
      const int64_t row = nx * (j + ny * k);
      dot += RowDot(x + row, y + row, nx);  // the row is still in L1
    }
  return dot;
}

template <typename T, typename X>
void StencilResidual(const Stencil<T>& A, const T* b, const X* x, T* r) {
  const int64_t nx = A.shape.nx, ny = A.shape.ny, nz = A.shape.nz;
  const std::vector<X> zx(nx, X(0));
  const std::vector<T> zc(nx, T(0));
#pragma omp parallel for collapse(2) schedule(static) \
    if (A.shape.size() >= kParallelNodes)
  for (int64_t k = 0; k < nz; ++k)
    for (int64_t j = 0; j < ny; ++j) StencilRow<T, X, true>(A, b, x, r, j, k, zx.data(), zc.data());
}

template <typename T>
void LitFaceSource(const TensorGrid& g, int64_t k_lit, double C, const float* q, T* b) {
  const GridShape& s = g.shape;
  TL_CHECK(k_lit == 0 || k_lit == s.nz - 1);
  std::fill(b, b + s.size(), T(0));
  const double robin = 1.0 / (2.0 * C);
  for (int64_t j = 0; j < s.ny; ++j)
    for (int64_t i = 0; i < s.nx; ++i)
      b[s.index(i, j, k_lit)] = T(g.Width(0, i) * g.Width(1, j) * robin * q[i + s.nx * j]);
}

template <typename T>
void AccumulateOperatorGradient(const TensorGrid& g, const T* phi, const T* psi, double scale,
                                T* grad_kappa, T* grad_mu) {
  const GridShape& s = g.shape;
  const int64_t nx = s.nx, ny = s.ny, nz = s.nz, nxy = nx * ny;
  const AxisGeometry geo(g);
  const double *igx = geo.inv_gap[0].data(), *igy = geo.inv_gap[1].data(),
               *igz = geo.inv_gap[2].data();
  ForEachNode(g, geo, [=](int64_t i, int64_t j, int64_t k, int64_t p, double wx, double wy, double wz) {
    // One face between p and q with area / gap `aog`: dc_pq/dkappa_p (psi_p - psi_q)(phi_p - phi_q).
    auto face = [=](int64_t q, double aog) {
      const double dc = double(FaceConductance<T>(aog, T(1), T(0)));
      return dc * (double(psi[p]) - double(psi[q])) * (double(phi[p]) - double(phi[q]));
    };
    double gk = 0;
    if (i > 0) gk += face(p - 1, wy * wz * igx[i - 1]);
    if (i + 1 < nx) gk += face(p + 1, wy * wz * igx[i]);
    if (j > 0) gk += face(p - nx, wx * wz * igy[j - 1]);
    if (j + 1 < ny) gk += face(p + nx, wx * wz * igy[j]);
    if (k > 0) gk += face(p - nxy, wx * wy * igz[k - 1]);
    if (k + 1 < nz) gk += face(p + nxy, wx * wy * igz[k]);
    grad_kappa[p] += T(scale * gk);
    grad_mu[p] += T(scale * wx * wy * wz * double(psi[p]) * double(phi[p]));
  });
}

#define TL_INSTANTIATE(T)                                                                     \
  template void AssembleStencil<T>(const TensorGrid&, const T*, const T*, double, Stencil<T>*); \
  template void ApplyStencil<T>(const Stencil<T>&, const T*, T*);                             \
  template double ApplyStencilDot<T, T>(const Stencil<T>&, const T*, T*);                     \
  template void StencilResidual<T, T>(const Stencil<T>&, const T*, const T*, T*);           \
  template void LitFaceSource<T>(const TensorGrid&, int64_t, double, const float*, T*);      \
  template void AccumulateOperatorGradient<T>(const TensorGrid&, const T*, const T*, double, T*, T*);
TL_INSTANTIATE(float)
TL_INSTANTIATE(double)
#undef TL_INSTANTIATE
template void StencilResidual<float, double>(const Stencil<float>&, const float*, const double*, float*);
template double ApplyStencilDot<double, float>(const Stencil<double>&, const float*, double*);

}  // namespace translume
