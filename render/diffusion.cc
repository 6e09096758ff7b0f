// SPDX-License-Identifier: MIT
#include "render/diffusion.h"

#include <Eigen/Sparse>
#include <Eigen/IterativeLinearSolvers>
#include <Eigen/SparseLU>
#include <algorithm>
#include <cmath>

#include "solver/status.h"

namespace translume {
namespace {

constexpr double kPi = 3.14159265358979323846;

class CpuRelaxer : public JacobiRelaxer {
 public:
  void Load(const JacobiSystem& system) override { sys_ = &system; }
  void Relax(const std::vector<int32_t>& active, int iterations,
             std::vector<float>* phi) override {
    const JacobiSystem& S = *sys_;
    TL_CHECK(int64_t(phi->size()) == S.size * 3);
    std::vector<float> next = *phi;
    const int64_t na = int64_t(active.size());
    for (int it = 0; it < iterations; ++it) {
      const float* p = phi->data();
#pragma omp parallel for schedule(static) if (na > 50000)
      for (int64_t a = 0; a < na; ++a) {
        const int64_t n = active[a];
        const int32_t* nb = &S.nb[n * 6];
        for (int c = 0; c < 3; ++c) {
          const float* w = &S.w[(n * 3 + c) * 6];
          float acc = S.s[n * 3 + c];
          for (int k = 0; k < 6; ++k) acc += w[k] * p[nb[k] * 3 + c];
          next[n * 3 + c] = acc * S.inv_diag[n * 3 + c];
        }
      }
      phi->swap(next);  // both buffers agree outside `active`
    }
  }

 private:
  const JacobiSystem* sys_ = nullptr;
};

}  // namespace

std::unique_ptr<JacobiRelaxer> MakeGlRelaxer();  // gl_diffusion.cc

std::unique_ptr<JacobiRelaxer> JacobiRelaxer::Create(DiffusionBackend backend) {
  if (backend == DiffusionBackend::kGl) return MakeGlRelaxer();
  return std::make_unique<CpuRelaxer>();
}

DiffusionBackend ParseDiffusionBackend(const std::string& text) {
  if (text == "cpu") return DiffusionBackend::kCpu;
  if (text == "gl") return DiffusionBackend::kGl;
  throw InputError("--backend: unknown backend '" + text + "' (expected cpu or gl)");
}

JacobiSystem BuildJacobiSystem(const Polygrid& pg, const NodeMaterial& m, double C,
                               const BoundaryLight& q) {
  JacobiSystem S;
  const int64_t N = pg.size();
  S.size = N;
  S.nb.resize(N * 6);
  S.w.assign(N * 18, 0.f);
  S.s.assign(N * 3, 0.f);
  S.inv_diag.assign(N * 3, 0.f);
  for (int64_t n = 0; n < N; ++n) {
    for (int k = 0; k < 6; ++k) {
      const int32_t j = pg.neighbours[n][k];
      S.nb[n * 6 + k] = j >= 0 ? j : int32_t(n);
    }
    for (int c = 0; c < 3; ++c) {
      const double kn = m.kappa[c][n];
      if (!pg.is_boundary(n)) {
        double sum = 0;
        for (int k = 0; k < 6; ++k) {
          S.w[(n * 3 + c) * 6 + k] = pg.weights[n][k];
          sum += pg.weights[n][k];
        }
        S.inv_diag[n * 3 + c] = float(1 / (m.mu[c][n] / kn + sum));
      } else {
        // The Robin balance over the slab of depth d/2 that the boundary node owns (see the
        // header): the link's flux, the slab's absorption, and its lateral diffusion taken from
        // the lateral part of the first interior node's Laplacian (slots 1..4).
        const int64_t b = n - pg.num_interior;
        const int32_t j = pg.neighbours[n][0];
        const int axis = pg.link_dir[b] / 2;
        const double kj = m.kappa[c][j], d = pg.link_length[b];
        const double lateral = C * d * d * kn * kj;
        double w_link = 2 * C * kn * kn;
        for (int k = 0, slot = 1; k < 6; ++k) {
          if (k / 2 == axis) continue;
          S.nb[n * 6 + slot] = pg.neighbours[j][k];
          S.w[(n * 3 + c) * 6 + slot] = float(lateral * pg.weights[j][k]);
          w_link -= lateral * pg.weights[j][k];
          ++slot;
        }
        S.w[(n * 3 + c) * 6] = float(w_link);
        S.s[n * 3 + c] = float(q[c][b] * kn * kj * d);
        S.inv_diag[n * 3 + c] = float(1 / (kj * d + 2 * C * kn * kj + C * d * d * m.mu[c][n] * kj));
      }
    }
  }
  return S;
}

BoundaryLight BoundaryRadiance(const Polygrid& pg, const NodeMaterial& m, const BoundaryLight& q,
                               const std::vector<float>& phi) {
  BoundaryLight L;
  for (int c = 0; c < 3; ++c) {
    L[c].resize(pg.num_boundary());
    for (int64_t b = 0; b < pg.num_boundary(); ++b) {
      const int64_t n = pg.num_interior + b;
      const double k = m.kappa[c][n];
      L[c][b] = float(std::max(0.0, (phi[n * 3 + c] - q[c][b] * k) / (2 * kPi * k)));
    }
  }
  return L;
}

std::vector<float> SolveReference(const JacobiSystem& S, int channels) {
  std::vector<float> phi(S.size * 3, 0.f);
  for (int c = 0; c < channels; ++c) {
    std::vector<Eigen::Triplet<double>> t;
    Eigen::VectorXd b(S.size);
    for (int64_t n = 0; n < S.size; ++n) {
      t.emplace_back(n, n, 1.0 / S.inv_diag[n * 3 + c]);
      for (int k = 0; k < 6; ++k) {
        const double w = S.w[(n * 3 + c) * 6 + k];
        if (w != 0) t.emplace_back(n, S.nb[n * 6 + k], -w);
      }
      b[n] = S.s[n * 3 + c];
    }
    Eigen::SparseMatrix<double> A(S.size, S.size);
    A.setFromTriplets(t.begin(), t.end());
    Eigen::BiCGSTAB<Eigen::SparseMatrix<double>, Eigen::IncompleteLUT<double>> solver;
    solver.setTolerance(1e-12);
    solver.setMaxIterations(2000);
    solver.compute(A);
    TL_CHECK_MSG(solver.info() == Eigen::Success, "polygrid system: ILUT failed");
    Eigen::VectorXd x = solver.solve(b);
    if (solver.info() != Eigen::Success) {  // stiff systems (tiny d): sparse LU instead
      Eigen::SparseLU<Eigen::SparseMatrix<double>> lu(A);
      TL_CHECK_MSG(lu.info() == Eigen::Success, "polygrid system is singular");
      x = lu.solve(b);
    }
    for (int64_t n = 0; n < S.size; ++n) phi[n * 3 + c] = float(x[n]);
  }
  return phi;
}

std::string DiffusionOptions::Validate() const {
  if (iterations.empty()) return "give at least one iteration count";
  for (int i : iterations)
    if (i < 0) return "iteration counts must be >= 0";
  if (coherent_iterations < 0) return "coherent_iterations must be >= 0";
  for (int d : depth)
    if (d < -1) return "adaptive depths must be >= 0 layers (or -1 for all)";
  return "";
}

PolygridDiffusion::PolygridDiffusion(const std::vector<Polygrid>* levels,
                                     std::vector<NodeMaterial> materials, double C,
                                     const DiffusionOptions& options)
    : levels_(levels), materials_(std::move(materials)), C_(C), options_(options) {
  if (std::string err = options.Validate(); !err.empty()) throw InputError("diffusion: " + err);
  TL_CHECK(levels_->size() == materials_.size() && !levels_->empty());
  relaxer_ = JacobiRelaxer::Create(options.backend);
}

const std::vector<float>& PolygridDiffusion::Solve(const std::vector<BoundaryLight>& q) {
  const std::vector<Polygrid>& L = *levels_;
  const int nl = int(L.size());
  TL_CHECK(int(q.size()) == nl);
  // Per-level lists are coarsest first; a list longer than the hierarchy drops its coarsest
  // entries (so the last entry is always the finest level's), a shorter one repeats its last.
  auto at = [nl](const std::vector<int>& v, int step, int fallback) {
    if (v.empty()) return fallback;
    const int i = step + std::max(0, int(v.size()) - nl);
    return i < int(v.size()) ? v[i] : v.back();
  };
  last_iterations_ = 0;
  if (options_.frame_coherence && have_previous_) {
    const JacobiSystem S = BuildJacobiSystem(L[0], materials_[0], C_, q[0]);
    relaxer_->Load(S);
    std::vector<int32_t> all(L[0].size());
    for (int64_t n = 0; n < L[0].size(); ++n) all[n] = int32_t(n);
    relaxer_->Relax(all, options_.coherent_iterations, &phi_);
    last_iterations_ = options_.coherent_iterations;
    return phi_;
  }
  std::vector<float> phi;
  for (int step = 0; step < nl; ++step) {
    const int l = nl - 1 - step;  // coarsest first
    const Polygrid& pg = L[l];
    if (step == 0) {
      phi.assign(pg.size() * 3, 0.f);
    } else {
      std::vector<float> fine[3], coarse[3];
      std::vector<float> next(pg.size() * 3);
      for (int c = 0; c < 3; ++c) {
        coarse[c].resize(L[l + 1].size());
        for (int64_t n = 0; n < L[l + 1].size(); ++n) coarse[c][n] = phi[n * 3 + c];
        ProlongPolygrid(L[l + 1], coarse[c], pg, &fine[c]);
        for (int64_t n = 0; n < pg.size(); ++n) next[n * 3 + c] = fine[c][n];
      }
      phi.swap(next);
    }
    const int depth = step == 0 ? -1 : at(options_.depth, step, -1);
    std::vector<int32_t> active;
    for (int64_t n = 0; n < pg.size(); ++n)
      if (depth < 0 || pg.layer[n] <= depth) active.push_back(int32_t(n));
    const JacobiSystem S = BuildJacobiSystem(pg, materials_[l], C_, q[l]);
    relaxer_->Load(S);
    const int iters = at(options_.iterations, step, 100);
    relaxer_->Relax(active, iters, &phi);
    last_iterations_ += iters;
  }
  phi_.swap(phi);
  have_previous_ = true;
  return phi_;
}

}  // namespace translume
