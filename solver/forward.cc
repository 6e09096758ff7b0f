// SPDX-License-Identifier: MIT
#include "solver/forward.h"

#include <cmath>
#include <fmt/format.h>
#include <numbers>

#include "solver/gl_solver.h"
#include "solver/status.h"

namespace translume {

Backend ParseBackend(const std::string& text, const char* flag) {
  if (text == "cpu") return Backend::kCpu;
  if (text == "gl") return Backend::kGl;
  throw InputError(fmt::format("{}: unknown backend '{}' (available: cpu, gl)", flag, text));
}

const char* BackendName(Backend backend) { return backend == Backend::kGl ? "gl" : "cpu"; }

Precision ParsePrecision(const std::string& text) {
  if (text == "float") return Precision::kFloat;
  if (text == "double") return Precision::kDouble;
  throw InputError(fmt::format("--precision: '{}' is not 'float' or 'double'", text));
}

FacePattern GreyPattern(const std::vector<float>& q) { return {q, q, q}; }

namespace {

// The front-face radiance L = (phi - incoming) / (2 pi) of one channel (SPEC section 3).
template <typename T>
std::vector<float> FrontRadiance(const GridShape& s, const T* phi, const std::vector<float>& q,
                                 Setup setup) {
  std::vector<float> L(s.face_size());
  const bool lit_front = setup == Setup::kFront;
  for (int64_t f = 0; f < s.face_size(); ++f) {
    const double incoming = lit_front ? q[f] : 0.0;
    L[f] = float((double(phi[f]) - incoming) / (2 * std::numbers::pi));
  }
  return L;
}

template <typename T>
std::array<std::vector<float>, 4> SideRadiance(const GridShape& s, const T* phi, const std::vector<float>& q,
                                               Setup setup) {
  const int64_t k_lit = LitFaceK(setup, s);
  const auto L = [&](int64_t i, int64_t j, int64_t k) {
    const double incoming = k == k_lit ? q[size_t(i + s.nx * j)] : 0.0;
    return float((double(phi[s.index(i, j, k)]) - incoming) / (2 * std::numbers::pi));
  };
  std::array<std::vector<float>, 4> out;
  for (int64_t k = 0; k < s.nz; ++k) {
    for (int64_t j = 0; j < s.ny; ++j) {
      out[0].push_back(L(0, j, k));
      out[1].push_back(L(s.nx - 1, j, k));
    }
    for (int64_t i = 0; i < s.nx; ++i) {
      out[2].push_back(L(i, 0, k));
      out[3].push_back(L(i, s.ny - 1, k));
    }
  }
  return out;
}

template <typename Solver, typename T>
ForwardResult SolveForwardT(const Material& m, const FacePattern& q, const ForwardOptions& o) {
  const GridShape& s = m.shape;
  Solver solver(s, m.spacing_mm, o.multigrid);
  const TensorGrid grid = TensorGrid::Uniform(s, m.spacing_mm);
  const int64_t n = s.size(), k_lit = LitFaceK(o.setup, s);
  std::vector<T> kappa(n), mu(n), b(n), phi(n);
  ForwardResult result;
  for (int c = 0; c < 3; ++c) {
    TL_CHECK(int64_t(q[c].size()) == s.face_size());
    for (int64_t p = 0; p < n; ++p) {
      kappa[p] = T(m.kappa[c][p]);
      mu[p] = T(m.mu[c][p]);
    }
    solver.SetCoefficients(kappa.data(), mu.data(), m.C);
    LitFaceSource(grid, k_lit, m.C, q[c].data(), b.data());
    std::fill(phi.begin(), phi.end(), T(0));
    result.summaries[c] = solver.Solve(b.data(), phi.data());
    result.radiance[c] = FrontRadiance(s, phi.data(), q[c], o.setup);
    if (o.side_faces) result.sides[c] = SideRadiance(s, phi.data(), q[c], o.setup);
  }
  return result;
}

// All lights of a channel as one batch of the gl solver; fields back to back (gl_solver.h).
std::vector<ForwardResult> SolveForwardGlBatch(const Material& m,
                                               const std::vector<FacePattern>& lights,
                                               const ForwardOptions& o) {
  const GridShape& s = m.shape;
  GlMultigridSolver solver(s, m.spacing_mm, o.multigrid);
  const TensorGrid grid = TensorGrid::Uniform(s, m.spacing_mm);
  const int64_t n = s.size(), k_lit = LitFaceK(o.setup, s);
  const int count = int(lights.size());
  std::vector<float> b(count * n), phi(count * n);
  std::vector<ForwardResult> results(count);
  for (int c = 0; c < 3; ++c) {
    solver.SetCoefficients(m.kappa[c].data(), m.mu[c].data(), m.C);
    for (int l = 0; l < count; ++l) {
      TL_CHECK(int64_t(lights[l][c].size()) == s.face_size());
      LitFaceSource(grid, k_lit, m.C, lights[l][c].data(), b.data() + l * n);
    }
    std::fill(phi.begin(), phi.end(), 0.0f);
    const std::vector<SolveSummary> sums = solver.SolveBatch(count, b.data(), phi.data());
    for (int l = 0; l < count; ++l) {
      results[l].summaries[c] = sums[l];
      results[l].radiance[c] = FrontRadiance(s, phi.data() + l * n, lights[l][c], o.setup);
      if (o.side_faces) results[l].sides[c] = SideRadiance(s, phi.data() + l * n, lights[l][c], o.setup);
    }
  }
  return results;
}

}  // namespace

ForwardResult SolveForward(const Material& material, const FacePattern& q,
                           const ForwardOptions& options) {
  if (std::string err = material.Validate(); !err.empty()) throw InputError("material: " + err);
  if (options.backend == Backend::kGl)
    return SolveForwardT<GlMultigridSolver, float>(material, q, options);
  return options.precision == Precision::kDouble
             ? SolveForwardT<MultigridSolver<double>, double>(material, q, options)
             : SolveForwardT<MultigridSolver<float>, float>(material, q, options);
}

std::vector<ForwardResult> SolveForwardBatch(const Material& material,
                                             const std::vector<FacePattern>& lights,
                                             const ForwardOptions& options) {
  if (std::string err = material.Validate(); !err.empty()) throw InputError("material: " + err);
  if (options.backend == Backend::kGl) return SolveForwardGlBatch(material, lights, options);
  std::vector<ForwardResult> results;
  for (const FacePattern& q : lights) results.push_back(SolveForward(material, q, options));
  return results;
}

}  // namespace translume
