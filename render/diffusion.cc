// SPDX-License-Identifier: MIT
#include "render/diffusion.h"

#include <Eigen/Sparse>
#include <Eigen/IterativeLinearSolvers>
#include <Eigen/SparseLU>
#include <algorithm>
#include <cmath>
#include <fmt/format.h>

#include "solver/status.h"

namespace translume {
namespace {

constexpr double kPi = 3.14159265358979323846;

// One relaxation step of rows [0, count) (n = active[i] where active is given): next = a p + s
// (s: the boundary rows' sources, or null for none), or with Chebyshev's weights w (not
// Jacobi's) prev + w (that - prev).
void RelaxStep(const HierarchyRelaxer::Level& v, int64_t count, const int32_t* active, const float* s,
               const float* p, const float* prev, float* next, const std::array<float, 3>& w) {
  const bool jacobi = ChebyshevSchedule::IsJacobi(w);
  const bool extras = !v.extra_start.empty();
  const int64_t ni = v.num_interior;
#pragma omp parallel for schedule(static) if (count > 50000)
  for (int64_t i = 0; i < count; ++i) {
    const int64_t n = active ? active[i] : i;
    const int32_t* nb = &v.nb[n * 6];
    for (int c = 0; c < 3; ++c) {
      const float* a = &v.a[(n * 3 + c) * 6];
      float acc = n < ni || !s ? 0.f : s[(n - ni) * 3 + c];
      for (int k = 0; k < 6; ++k) acc += a[k] * p[nb[k] * 3 + c];
      if (extras)
        for (int32_t e = v.extra_start[n]; e < v.extra_start[n + 1]; ++e)
          acc += v.extra_a[e * 3 + c] * p[v.extra_nb[e] * 3 + c];
      const int64_t j = n * 3 + c;
      next[j] = jacobi ? acc : prev[j] + w[c] * (acc - prev[j]);
    }
  }
}

class CpuHierarchy : public HierarchyRelaxer {
 public:
  void Load(std::vector<Level> levels) override {
    L_ = std::move(levels);
    phi_.assign(L_.size(), {});
    cur_.assign(L_.size(), 0);
    s_.assign(L_.size(), {});
    for (size_t l = 0; l < L_.size(); ++l) {
      for (std::vector<float>& p : phi_[l]) p.assign(L_[l].size * 3, 0.f);
      s_[l].assign((L_[l].size - L_[l].num_interior) * 3, 0.f);
    }
  }
  void SetSource(int l, const BoundaryLight& q) override {
    const Level& v = L_[l];
    std::vector<float>& s = s_[l];
    for (int64_t b = 0; b < v.size - v.num_interior; ++b)
      for (int c = 0; c < 3; ++c) s[b * 3 + c] = q[c][b] * v.source_coef[b * 3 + c];
  }
  void Zero(int l) override {
    for (std::vector<float>& p : phi_[l]) std::fill(p.begin(), p.end(), 0.f);
  }
  void Prolong(int l) override {
    const Prolongation& P = L_[l].prolong;
    const std::vector<float>& coarse = Current(l + 1);
    std::vector<float>& fine = Current(l);
    const int64_t n = L_[l].size;
#pragma omp parallel for schedule(static) if (n > 50000)
    for (int64_t f = 0; f < n; ++f)
      for (int c = 0; c < 3; ++c) {
        double acc = 0;
        for (int32_t k = P.start[f]; k < P.start[f + 1]; ++k) acc += double(P.weight[k]) * coarse[P.index[k] * 3 + c];
        fine[f * 3 + c] = float(acc);
      }
    for (int k = 1; k < 3; ++k) phi_[l][(cur_[l] + k) % 3] = fine;
  }
  void Relax(int l, bool adaptive, int iterations, bool repeated) override {
    const Level& v = L_[l];
    const int64_t count = adaptive ? int64_t(v.active.size()) : v.size;
    // phi[cur] is the iterate, phi[cur + 2] the one before it (read by Chebyshev's steps from
    // the second on) and phi[cur + 1] the next; all three agree outside the updated nodes.
    ChebyshevSchedule schedule(v.rho, iterations, repeated || v.tails);
    for (int it = 0; it < iterations; ++it) {
      const int cur = cur_[l];
      RelaxStep(v, count, adaptive ? v.active.data() : nullptr, s_[l].data(), phi_[l][cur].data(),
                phi_[l][(cur + 2) % 3].data(), phi_[l][(cur + 1) % 3].data(), schedule.Next());
      cur_[l] = (cur + 1) % 3;
    }
  }
  void Read(int l, int64_t first_row, std::vector<float>* phi) override {
    const std::vector<float>& p = Current(l);
    TL_CHECK(phi->size() == p.size());
    std::copy(p.begin() + first_row * 3, p.end(), phi->begin() + first_row * 3);
  }

 private:
  std::vector<float>& Current(int l) { return phi_[l][cur_[l]]; }

  std::vector<Level> L_;
  // Per level three fluence buffers, as the gl backend's (phi_[l][cur_[l]] the current one).
  std::vector<std::array<std::vector<float>, 3>> phi_;
  std::vector<int> cur_;
  std::vector<std::vector<float>> s_;  // the boundary rows' sources, [b * 3 + c]
};

}  // namespace

std::unique_ptr<HierarchyRelaxer> MakeGlHierarchy();  // gl_diffusion.cc

void HierarchyRelaxer::SetSource(int, DeviceFloats) {
  TL_CHECK_MSG(false, "only the gl relaxation reads q from the GPU");
}

void HierarchyRelaxer::WriteShadedRadiance(DeviceFloats) {
  TL_CHECK_MSG(false, "only the gl relaxation writes radiance on the GPU");
}

std::unique_ptr<HierarchyRelaxer> HierarchyRelaxer::Create(DiffusionBackend backend) {
  if (backend == DiffusionBackend::kGl) return MakeGlHierarchy();
  return std::make_unique<CpuHierarchy>();
}

std::array<double, 3> JacobiSpectralRadii(const HierarchyRelaxer::Level& v, int iterations) {
  const int64_t N = v.size;
  std::vector<double> x(N * 3, 1.0), ax(N * 3);
  std::array<double, 3> lowest{};
  for (int it = 0; it <= iterations; ++it) {
    double ratio[3] = {1e300, 1e300, 1e300}, largest[3] = {0, 0, 0};
#pragma omp parallel for schedule(static) reduction(min : ratio[:3]) reduction(max : largest[:3]) if (N > 50000)
    for (int64_t n = 0; n < N; ++n) {
      double acc[3] = {0, 0, 0};
      for (int k = 0; k < 6; ++k) {
        const int64_t j = v.nb[n * 6 + k];
        for (int c = 0; c < 3; ++c) acc[c] += double(v.a[(n * 3 + c) * 6 + k]) * x[j * 3 + c];
      }
      if (!v.extra_start.empty())
        for (int32_t e = v.extra_start[n]; e < v.extra_start[n + 1]; ++e)
          for (int c = 0; c < 3; ++c) acc[c] += double(v.extra_a[e * 3 + c]) * x[v.extra_nb[e] * 3 + c];
      for (int c = 0; c < 3; ++c) {
        ax[n * 3 + c] = acc[c];
        ratio[c] = std::min(ratio[c], acc[c] / x[n * 3 + c]);
        largest[c] = std::max(largest[c], 0.5 * (x[n * 3 + c] + acc[c]));
      }
    }
    lowest = {ratio[0], ratio[1], ratio[2]};
    if (it == iterations || !(std::min({largest[0], largest[1], largest[2]}) > 0)) break;
#pragma omp parallel for schedule(static) if (N > 50000)
    for (int64_t n = 0; n < N; ++n)
      for (int c = 0; c < 3; ++c) x[n * 3 + c] = 0.5 * (x[n * 3 + c] + ax[n * 3 + c]) / largest[c];
  }
  for (double& r : lowest) r = std::clamp(N > 0 ? r : 0.0, 0.0, 1.0);
  return lowest;
}

namespace {

using StepWeights = std::vector<std::array<float, 3>>;

StepWeights ScheduleWeights(const std::array<double, 3>& rho, int steps, bool repeated) {
  ChebyshevSchedule schedule(rho, steps, repeated);
  StepWeights w(std::max(0, steps));
  for (auto& e : w) e = schedule.Next();
  return w;
}

// ChebyshevRemainder for several schedules in one run: schedules[0] is run from the fixed start;
// every other one shares its first steps (as many as have the same weights) and goes on from a
// copy of the iterates where it parts from it.
std::vector<std::array<double, 3>> Remainders(const HierarchyRelaxer::Level& v, const std::vector<StepWeights>& schedules) {
  const StepWeights& trunk = schedules[0];
  using Iterates = std::array<std::vector<float>, 3>;  // x[cur]: the iterate, x[cur + 2]: the one before
  const auto largest = [&](const std::vector<float>& x) {
    // Jacobi's steps shrink the largest entry (the rows' weight sums are below 1); Chebyshev's,
    // where they converge, shrink it faster.
    std::array<double, 3> m{};
    for (int64_t i = 0; i < v.size * 3; ++i) m[i % 3] = std::max(m[i % 3], double(std::abs(x[i])));
    return m;
  };
  const auto run = [&](Iterates& x, int& cur, const StepWeights& w, size_t from, size_t to) {
    for (size_t t = from; t < to; ++t) {
      RelaxStep(v, v.size, nullptr, nullptr, x[cur].data(), x[(cur + 2) % 3].data(), x[(cur + 1) % 3].data(), w[t]);
      cur = (cur + 1) % 3;
    }
  };
  // A fixed pseudo-random start in [-1, 1] (every mode, oscillating ones included), no source.
  Iterates x;
  for (auto& b : x) b.resize(v.size * 3);
  uint32_t state = 12345u;
  for (float& e : x[0]) {
    state = state * 1664525u + 1013904223u;
    e = float(state >> 8) / float(1u << 23) - 1.f;
  }
  x[2] = x[0];
  int cur = 0;
  std::vector<std::array<double, 3>> out(schedules.size());
  std::vector<std::pair<size_t, size_t>> forks;  // (the trunk's step where it parts, schedule)
  for (size_t s = 1; s < schedules.size(); ++s) {
    size_t fork = 0;
    while (fork < schedules[s].size() && fork < trunk.size() && schedules[s][fork] == trunk[fork]) ++fork;
    forks.emplace_back(fork, s);
  }
  std::sort(forks.begin(), forks.end());
  size_t t = 0;
  for (const auto& [fork, s] : forks) {
    run(x, cur, trunk, t, fork);
    t = fork;
    if (fork == schedules[s].size()) {
      out[s] = largest(x[cur]);
    } else {
      Iterates y = x;
      int c = cur;
      run(y, c, schedules[s], fork, schedules[s].size());
      out[s] = largest(y[c]);
    }
  }
  run(x, cur, trunk, t, trunk.size());
  out[0] = largest(x[cur]);
  return out;
}

}  // namespace

std::array<double, 3> ChebyshevRemainder(const HierarchyRelaxer::Level& v, int steps, bool repeated) {
  return Remainders(v, {ScheduleWeights(v.rho, steps, repeated)})[0];
}

ChebyshevRemainders ChebyshevCallRemainders(const HierarchyRelaxer::Level& v, int call_steps, int steps) {
  const std::vector<std::array<double, 3>> r =
      Remainders(v, {ScheduleWeights(v.rho, steps, true), ScheduleWeights(v.rho, call_steps, false),
                     ScheduleWeights(v.rho, call_steps, true)});
  return {r[0], r[1], r[2]};
}

std::array<float, 3> ChebyshevSchedule::Next() {
  if (cycle_left_ == 0) {
    const int left = std::max(1, steps_ - done_);  // (steps beyond the call's: cycles as if 1 left)
    const int cycles = (left + kMaxCycle - 1) / kMaxCycle;
    cycle_left_ = tails_ ? (left + cycles - 1) / cycles : left;
    run_left_ = tails_ ? cycle_left_ - TailSteps(cycle_left_) : left;
    k_ = 0;
  }
  --cycle_left_;
  ++done_;
  if (run_left_ == 0) return {1.f, 1.f, 1.f};
  --run_left_;
  for (int c = 0; c < 3; ++c) {
    const double r2 = rho_[c] * rho_[c];
    omega_[c] = k_ == 0 ? 1 : k_ == 1 ? 1 / (1 - r2 / 2) : 1 / (1 - r2 * omega_[c] / 4);
  }
  ++k_;
  return {float(omega_[0]), float(omega_[1]), float(omega_[2])};
}

Relaxation ParseRelaxation(const std::string& text) {
  if (text == "jacobi") return Relaxation::kJacobi;
  if (text == "chebyshev") return Relaxation::kChebyshev;
  throw InputError("--relaxation: unknown relaxation '" + text + "' (expected jacobi or chebyshev)");
}

DiffusionBackend ParseDiffusionBackend(const std::string& text) {
  if (text == "cpu") return DiffusionBackend::kCpu;
  if (text == "gl") return DiffusionBackend::kGl;
  throw InputError("--backend: unknown backend '" + text + "' (expected cpu or gl)");
}

namespace {

// The factor of q in the boundary rows' source (see JacobiSystem): kappa_b kappa_j d, per
// boundary node and channel, [b * 3 + c].
std::vector<double> BoundarySourceCoefficients(const Polygrid& pg, const NodeMaterial& m) {
  std::vector<double> coef(pg.num_boundary() * 3);
  for (int64_t b = 0; b < pg.num_boundary(); ++b) {
    const int64_t n = pg.num_interior + b;
    const int32_t j = pg.neighbours[n][0];
    for (int c = 0; c < 3; ++c) coef[b * 3 + c] = double(m.kappa[c][n]) * m.kappa[c][j] * pg.link_length[b];
  }
  return coef;
}

}  // namespace

JacobiSystem BuildJacobiSystem(const Polygrid& pg, const NodeMaterial& m, double C,
                               const BoundaryLight& q) {
  TL_CHECK(pg.foot_weights.empty() || int64_t(pg.foot_weights.size()) == pg.num_boundary());
  const bool wide = !pg.stencil_weights.empty();
  TL_CHECK(!wide || (int64_t(pg.stencil_weights.size()) == pg.num_interior &&
                     int64_t(pg.diagonal_neighbours.size()) == pg.num_interior));
  const std::vector<double> coef = BoundarySourceCoefficients(pg, m);
  JacobiSystem S;
  const int64_t N = pg.size();
  S.size = N;
  S.nb.resize(N * 6);
  S.w.assign(N * 18, 0.f);
  S.s.assign(N * 3, 0.f);
  S.inv_diag.assign(N * 3, 0.f);
  if (wide) S.extra_start.assign(N + 1, 0);
  for (int64_t n = 0; n < N; ++n) {
    for (int k = 0; k < 6; ++k) {
      const int32_t j = pg.neighbours[n][k];
      S.nb[n * 6 + k] = j >= 0 ? j : int32_t(n);
    }
    const bool interior = !pg.is_boundary(n);
    if (wide) {
      S.extra_start[n + 1] = S.extra_start[n];
      if (interior)
        for (int k = 6; k < 18; ++k)
          if (pg.stencil_weights[n][k] > 0) {
            S.extra_nb.push_back(pg.diagonal_neighbours[n][k - 6]);
            ++S.extra_start[n + 1];
          }
      S.extra_w.resize(S.extra_nb.size() * 3);
    }
    for (int c = 0; c < 3; ++c) {
      const double kn = m.kappa[c][n];
      if (interior) {
        // SPEC section 3's flux w_ji (kappa_i + kappa_j) / 2 (phi_j - phi_i), in phi' = kappa phi,
        // over the six face neighbours, and the edge-diagonal ones of Polygrid::stencil_weights.
        double sum = 0;
        auto flux = [&](double w, int32_t j) {
          const double kj = m.kappa[c][j], kbar = 0.5 * (kn + kj);
          sum += w * kbar;
          return float(w * kbar * kn / kj);
        };
        for (int k = 0; k < 6; ++k)
          S.w[(n * 3 + c) * 6 + k] = flux(wide ? pg.stencil_weights[n][k] : pg.weights[n][k], S.nb[n * 6 + k]);
        if (wide)
          for (int k = 6, e = S.extra_start[n]; k < 18; ++k)
            if (pg.stencil_weights[n][k] > 0) {
              S.extra_w[e * 3 + c] = flux(pg.stencil_weights[n][k], S.extra_nb[e]);
              ++e;
            }
        S.inv_diag[n * 3 + c] = float(1 / (m.mu[c][n] + sum));
      } else {
        // The Robin balance over the slab of depth d/2 that the boundary node owns (see the
        // header): the link's flux, the slab's absorption, and its lateral diffusion taken from
        // the lateral part of the first interior node's Laplacian (slots 1..4).
        const int64_t b = n - pg.num_interior;
        const int32_t j = pg.neighbours[n][0];
        const int axis = pg.link_dir[b] / 2;
        const double kj = m.kappa[c][j], d = pg.link_length[b];
        // The link's foot: phi_j's share, the rest from j's lateral neighbours (Polygrid::foot_weights).
        const std::array<float, 6> foot =
            pg.foot_weights.empty() ? std::array<float, 6>{} : pg.foot_weights[b];
        double foot_j = 1;
        for (int k = 0; k < 6; ++k)
          if (k / 2 != axis) foot_j -= foot[k];
        foot_j = std::max(0.0, foot_j);  // the weights' float rounding
        double lateral_sum = 0;
        for (int k = 0; k < 6; ++k)
          if (k / 2 != axis) lateral_sum += pg.weights[j][k];
        // Capped where it would outweigh the link (w_0 < 0; see the header).
        const double lateral = C * d * d * kn * kj * std::min(1.0, 2 * kn * foot_j / (kj * d * d * lateral_sum));
        double w_link = 2 * C * kn * kn * foot_j;
        for (int k = 0, slot = 1; k < 6; ++k) {
          if (k / 2 == axis) continue;
          const int32_t nk = pg.neighbours[j][k];
          S.nb[n * 6 + slot] = nk;
          double w = lateral * pg.weights[j][k];
          if (foot[k] != 0) w += 2 * C * kn * kn * kj * foot[k] / m.kappa[c][nk];
          S.w[(n * 3 + c) * 6 + slot] = float(w);
          w_link -= lateral * pg.weights[j][k];
          ++slot;
        }
        S.w[(n * 3 + c) * 6] = float(std::max(0.0, w_link));  // capped rows: 0 up to rounding
        S.s[n * 3 + c] = float(q[c][b] * coef[b * 3 + c]);
        S.inv_diag[n * 3 + c] = float(1 / (kj * d + 2 * C * kn * kj + C * d * d * m.mu[c][n] * kj));
      }
    }
  }
  return S;
}

HierarchyRelaxer::Level RelaxationRows(const Polygrid& pg, const NodeMaterial& m, double C) {
  // With q = 1 the boundary rows' source is their coefficient kappa_b kappa_j d.
  BoundaryLight unit;
  for (int c = 0; c < 3; ++c) unit[c].assign(pg.num_boundary(), 1.f);
  JacobiSystem S = BuildJacobiSystem(pg, m, C, unit);
  HierarchyRelaxer::Level v;
  v.size = S.size;
  v.num_interior = pg.num_interior;
  v.nb = std::move(S.nb);
  v.a = std::move(S.w);
  v.extra_start = std::move(S.extra_start);
  v.extra_nb = std::move(S.extra_nb);
  v.extra_a = std::move(S.extra_w);
  for (int64_t n = 0; n < v.size; ++n)
    for (int c = 0; c < 3; ++c) {
      for (int k = 0; k < 6; ++k) v.a[(n * 3 + c) * 6 + k] *= S.inv_diag[n * 3 + c];
      if (!v.extra_start.empty())
        for (int32_t e = v.extra_start[n]; e < v.extra_start[n + 1]; ++e) v.extra_a[e * 3 + c] *= S.inv_diag[n * 3 + c];
    }
  v.source_coef.assign(S.s.begin() + v.num_interior * 3, S.s.end());
  for (size_t i = 0; i < v.source_coef.size(); ++i) v.source_coef[i] *= S.inv_diag[v.num_interior * 3 + i];
  return v;
}

BoundaryLight BoundaryRadiance(const Polygrid& pg, const NodeMaterial& m, const BoundaryLight& q,
                               const std::vector<float>& phi) {
  BoundaryLight L;
  for (int c = 0; c < 3; ++c) {
    L[c].resize(pg.num_boundary());
    for (int64_t b = 0; b < pg.num_boundary(); ++b) {
      const int64_t n = pg.num_interior + b;
      const double k = m.kappa[c][n];
      const double qb = q[c].empty() ? 0.0 : q[c][b];  // (ShadedRadiance: none)
      L[c][b] = float(std::max(0.0, (phi[n * 3 + c] - qb * k) / (2 * kPi * k)));
    }
  }
  return L;
}

BoundaryLight ShadedRadiance(const Polygrid& pg, const NodeMaterial& m, const std::vector<float>& phi) {
  return BoundaryRadiance(pg, m, BoundaryLight{}, phi);
}

std::vector<float> SolveReference(const JacobiSystem& S, int channels, bool diagonal_preconditioner) {
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
      if (!S.extra_start.empty())
        for (int32_t e = S.extra_start[n]; e < S.extra_start[n + 1]; ++e)
          t.emplace_back(n, S.extra_nb[e], -S.extra_w[e * 3 + c]);
      b[n] = S.s[n * 3 + c];
    }
    Eigen::SparseMatrix<double> A(S.size, S.size);
    A.setFromTriplets(t.begin(), t.end());
    // BiCGSTAB to 1e-12, preconditioned by the type of `preconditioner`; false if it did not
    // converge.
    Eigen::VectorXd x;
    auto bicgstab = [&](auto preconditioner, int max_iterations) {
      Eigen::BiCGSTAB<Eigen::SparseMatrix<double>, decltype(preconditioner)> solver;
      solver.setTolerance(1e-12);
      solver.setMaxIterations(max_iterations);
      solver.compute(A);
      TL_CHECK_MSG(solver.info() == Eigen::Success, "polygrid system: preconditioner setup failed");
      x = solver.solve(b);
      return solver.info() == Eigen::Success;
    };
    bool solved = diagonal_preconditioner && bicgstab(Eigen::DiagonalPreconditioner<double>(), 20000);
    if (!solved) solved = bicgstab(Eigen::IncompleteLUT<double>(), 2000);
    if (!solved) {  // stiff systems (tiny d): sparse LU instead
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
    if (i < 0 || i > 1000000) return fmt::format("iteration counts must be within 0..1000000, got {}", i);
  if (std::all_of(iterations.begin(), iterations.end(), [](int i) { return i == 0; }))
    return "every iteration count is 0: no diffusion would run";
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
  const std::vector<Polygrid>& L = *levels_;
  const int nl = int(L.size());
  // Per-level lists are coarsest first; a list longer than the hierarchy drops its coarsest
  // entries (so the last entry is always the finest level's), a shorter one repeats its last.
  auto at = [nl](const std::vector<int>& v, int step, int fallback) {
    if (v.empty()) return fallback;
    const int i = step + std::max(0, int(v.size()) - nl);
    return i < int(v.size()) ? v[i] : v.back();
  };
  std::vector<HierarchyRelaxer::Level> hl(nl);
  depth_.assign(nl, -1);
  iterations_.assign(nl, 0);
  for (int l = 0; l < nl; ++l) {
    const int step = nl - 1 - l;  // coarsest first
    depth_[l] = step == 0 ? -1 : at(options_.depth, step, -1);
    iterations_[l] = at(options_.iterations, step, 100);
    const Polygrid& pg = L[l];
    hl[l] = RelaxationRows(pg, materials_[l], C_);
    for (int64_t n = 0; n < pg.size(); ++n)
      if (depth_[l] < 0 || pg.layer[n] <= depth_[l]) hl[l].active.push_back(int32_t(n));
    if (l + 1 < nl) hl[l].prolong = MakeProlongation(L[l + 1], pg);
    // Over the whole level, also where the steps update only the active nodes: the principal
    // submatrix's own estimate, lower and further below its radius after 50 power steps, gave
    // larger errors (docs/benchmarks.md, "Chebyshev's radius in one pass").
    if (options_.relaxation == Relaxation::kChebyshev) {
      // Where Chebyshev's steps would grow (ChebyshevRemainder), a smaller rho widens the ellipse
      // of eigenvalues they shrink; Jacobi's steps (rho 0) where none of these does.
      const std::array<double, 3> rho = JacobiSpectralRadii(hl[l]);
      std::array<bool, 3> done{};
      const bool one_cycle = iterations_[l] > 0 && iterations_[l] <= ChebyshevSchedule::kMaxCycle;
      for (double f : {1.0, 0.95, 0.9, 0.8, 0.6}) {
        for (int c = 0; c < 3; ++c)
          if (!done[c]) hl[l].rho[c] = f * rho[c];
        // As a coherent run (cycles with Jacobi tails) and as a frame's own call of this
        // level's steps: one plain sequence when they are at most a cycle, or where that grows
        // the error with the estimate's radius and the tails leave less, with the tails (for
        // the level's channels together). Where a plain call shrinks the error it keeps the
        // plain sequence, even where the tails shrink this start's largest entry more: the
        // tails' gain is on rough modes, which cost E little, and the plain sequence's on the
        // smooth ones (the sphere at 17^3, renderbench's 30 / 15 / 15 steps: E 5.9e-6 plain, 9.6e-6
        // with the tails).
        const ChebyshevRemainders r = ChebyshevCallRemainders(hl[l], one_cycle ? iterations_[l] : 0, 120);
        std::array<double, 3> call = r.coherent;
        if (one_cycle) {
          if (f == 1) {
            const double plain = *std::max_element(r.plain.begin(), r.plain.end());
            hl[l].tails = plain > 1 && *std::max_element(r.tailed.begin(), r.tailed.end()) < plain;
            tailed_levels_ += hl[l].tails;
          }
          call = hl[l].tails ? r.tailed : r.plain;
        }
        std::array<bool, 3> contracts;
        for (int c = 0; c < 3; ++c) contracts[c] = r.coherent[c] <= 1 && call[c] <= 1;
        for (int c = 0; c < 3; ++c) {
          reduced_radii_ += f == 1 && !contracts[c];
          done[c] = done[c] || contracts[c];
        }
        if (done[0] && done[1] && done[2]) break;
      }
      for (int c = 0; c < 3; ++c)
        if (!done[c]) hl[l].rho[c] = 0, ++jacobi_fallbacks_;
    }
  }
  if (options.backend == DiffusionBackend::kGl) {
    const Polygrid& pg = L[0];
    hl[0].radiance_scale.resize(pg.num_boundary() * 3);
    for (int64_t b = 0; b < pg.num_boundary(); ++b)
      for (int c = 0; c < 3; ++c)
        hl[0].radiance_scale[b * 3 + c] = float(1 / (2 * kPi * materials_[0].kappa[c][pg.num_interior + b]));
  }
  relaxer_ = HierarchyRelaxer::Create(options.backend);
  relaxer_->Load(std::move(hl));
}

template <typename SetSourceFn>
void PolygridDiffusion::Relax(const SetSourceFn& set_source) {
  const int nl = int(levels_->size());
  last_iterations_ = 0;
  if (options_.frame_coherence && have_previous_) {
    set_source(0);
    relaxer_->Relax(0, false, options_.coherent_iterations, true);
    last_iterations_ = options_.coherent_iterations;
    return;
  }
  for (int l = nl - 1; l >= 0; --l) {  // coarsest first
    set_source(l);
    if (l == nl - 1)
      relaxer_->Zero(l);
    else
      relaxer_->Prolong(l);
    relaxer_->Relax(l, depth_[l] >= 0, iterations_[l], false);
    last_iterations_ += iterations_[l];
  }
  have_previous_ = true;
}

const std::vector<float>& PolygridDiffusion::Solve(const std::vector<BoundaryLight>& q,
                                                   bool boundary_only) {
  const std::vector<Polygrid>& L = *levels_;
  TL_CHECK(q.size() == L.size());
  phi_.resize(L[0].size() * 3, 0.f);
  Relax([&](int l) { relaxer_->SetSource(l, q[l]); });
  relaxer_->Read(0, boundary_only ? L[0].num_interior : 0, &phi_);
  return phi_;
}

void PolygridDiffusion::SolveOnDevice(const std::vector<DeviceFloats>& q, DeviceFloats radiance) {
  TL_CHECK_MSG(options_.backend == DiffusionBackend::kGl, "SolveOnDevice needs the gl backend");
  TL_CHECK(q.size() == levels_->size());
  Relax([&](int l) { relaxer_->SetSource(l, q[l]); });
  relaxer_->WriteShadedRadiance(radiance);
}

}  // namespace translume
