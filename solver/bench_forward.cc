// SPDX-License-Identifier: MIT
#include "solver/bench_forward.h"

#include <Eigen/IterativeLinearSolvers>
#include <Eigen/Sparse>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "solver/gl_context.h"
#include "solver/gl_solver.h"
#include "solver/status.h"
#include "solver/light.h"
#include "solver/multigrid.h"
#include "solver/synthetic.h"

namespace translume {
namespace {

// The bench's clock (seconds): the wall clock, or with ForwardBenchOptions::cpu_time the
// process's CPU time, which other jobs on a shared machine do not inflate.
bool use_cpu_time = false;
double Now() {
  if (use_cpu_time) {
    timespec t;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
  }
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}
double Since(double t0) { return Now() - t0; }
double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

template <typename T>
Eigen::SparseMatrix<double, Eigen::RowMajor> ToSparse(const Stencil<T>& A) {
  const GridShape& s = A.shape;
  const int64_t nxy = s.nx * s.ny;
  std::vector<Eigen::Triplet<double>> trip;
  trip.reserve(s.size() * 7);
  for (int64_t k = 0; k < s.nz; ++k)
    for (int64_t j = 0; j < s.ny; ++j)
      for (int64_t i = 0; i < s.nx; ++i) {
        const int64_t p = s.index(i, j, k);
        trip.emplace_back(p, p, double(A.diag[p]));
        auto off = [&](int64_t q, double c) {
          trip.emplace_back(p, q, -c);
          trip.emplace_back(q, p, -c);
        };
        if (i + 1 < s.nx) off(p + 1, A.cx[p]);
        if (j + 1 < s.ny) off(p + s.nx, A.cy[p]);
        if (k + 1 < s.nz) off(p + nxy, A.cz[p]);
      }
  Eigen::SparseMatrix<double, Eigen::RowMajor> M(s.size(), s.size());
  M.setFromTriplets(trip.begin(), trip.end());
  return M;
}

template <typename Solver>
PeerResult RunEigenCg(const std::string& name, const Eigen::SparseMatrix<double, Eigen::RowMajor>& M,
                      const Eigen::VectorXd& b, double tol, double ours) {
  PeerResult r;
  r.name = name;
  r.ran = true;
  const double t0 = Now();
  Solver cg;
  cg.setTolerance(tol);
  cg.setMaxIterations(100000);
  cg.compute(M);
  Eigen::VectorXd x = cg.solve(b);
  r.seconds = Since(t0);
  r.iterations = cg.iterations();
  r.residual = (b - M * x).norm() / b.norm();
  r.converged = r.residual <= tol * 1.01;
  r.ratio = r.seconds / ours;
  r.lower_bound = !r.converged;
  return r;
}

// The paper's relaxation (Jacobi sweeps, Stam 1995) on the same system, within a time budget.
template <typename T>
PeerResult RunJacobi(const Stencil<T>& A, const std::vector<T>& b, double tol, double budget,
                     double ours) {
  PeerResult r;
  r.name = "Jacobi relaxation (paper)";
  r.ran = true;
  const int64_t n = A.shape.size();
  std::vector<T> x(n, T(0)), res(n);
  double bn = 0;
  for (T v : b) bn += double(v) * double(v);
  bn = std::sqrt(bn);
  const double t0 = Now();
  while (true) {
    for (int s = 0; s < 10; ++s) {
      StencilResidual(A, b.data(), x.data(), res.data());
#pragma omp parallel for schedule(static)
      for (int64_t p = 0; p < n; ++p) x[p] += res[p] / A.diag[p];
    }
    r.iterations += 10;
    StencilResidual(A, b.data(), x.data(), res.data());
    double rn = 0;
#pragma omp parallel for reduction(+ : rn)
    for (int64_t p = 0; p < n; ++p) rn += double(res[p]) * double(res[p]);
    r.residual = std::sqrt(rn) / bn;
    r.seconds = Since(t0);
    if (r.residual <= tol) {
      r.converged = true;
      break;
    }
    if (r.seconds >= budget) break;
  }
  r.ratio = r.seconds / ours;
  r.lower_bound = !r.converged;
  return r;
}

// The benchmark problem on `shape`: the wax preset's green channel under uniform back light.
struct BenchProblem {
  Material material;
  std::vector<double> b;  // right-hand side
  explicit BenchProblem(const GridShape& shape) {
    SynthOptions so;
    so.preset = "wax";
    so.shape = shape;
    material = SynthesizeMaterial(so);
    const Material& m = material;
    const std::vector<float> q = RasterizeLight(LightSpec::Parse("uniform"), shape, m.spacing_mm);
    b.resize(shape.size());
    LitFaceSource(TensorGrid::Uniform(shape, m.spacing_mm), shape.nz - 1, m.C, q.data(), b.data());
  }
  template <typename T>
  std::vector<T> Field(const std::vector<float>& v) const { return {v.begin(), v.end()}; }
};

// Our solver's options as the benchmark asks (either backend): tolerance and cycle.
MultigridOptions SolverOptions(const ForwardBenchOptions& o) {
  MultigridOptions mo;
  mo.tolerance = o.tolerance;
  mo.pre_smoothing = mo.post_smoothing = o.smoothing;
  mo.coarse_smoothing = o.coarse_smoothing;
  mo.z_coarsening = o.z_coarsening;
  mo.full_multigrid_start = o.full_multigrid_start;
  return mo;
}

template <typename T>
ForwardBenchRow BenchOne(const GridShape& shape, const ForwardBenchOptions& o,
                         void (*progress)(const std::string&)) {
  const BenchProblem problem(shape);
  const Material& m = problem.material;
  const int64_t n = shape.size();
  const std::vector<T> kappa = problem.Field<T>(m.kappa[1]), mu = problem.Field<T>(m.mu[1]);
  const MultigridOptions mo = SolverOptions(o);
  MultigridSolver<T> solver(shape, m.spacing_mm, mo);
  solver.SetCoefficients(kappa.data(), mu.data(), m.C);
  std::vector<T> b(problem.b.begin(), problem.b.end()), x(n), y(n);

  ForwardBenchRow row;
  row.shape = shape;
  row.levels = solver.num_levels();
  std::vector<double> applies;
  for (int r = 0; r < 3; ++r) solver.Apply(b.data(), y.data());
  for (int r = 0; r < 21; ++r) {
    const double t0 = Now();
    solver.Apply(b.data(), y.data());
    applies.push_back(Since(t0));
  }
  row.apply_seconds = Median(applies);
  std::vector<double> solves;
  for (int r = 0; r < std::max(1, o.repeats); ++r) {
    std::fill(x.begin(), x.end(), T(0));
    const double t0 = Now();
    const SolveSummary s = solver.Solve(b.data(), x.data());
    solves.push_back(Since(t0));
    row.iterations = s.iterations;
    row.residual = s.final_residual;
  }
  row.seconds = Median(solves);
  row.work_units = row.seconds / row.apply_seconds;
  row.nodes_per_second = double(n) / row.seconds;
  if (progress)
    progress(fmt::format("{}: multigrid-PCG {} iterations, {:.4f} s, {:.1f} work units",
                         shape.ToString(), row.iterations, row.seconds, row.work_units));
  if (o.peers) {
    const auto M = ToSparse(solver.stencil());
    Eigen::VectorXd bd(n);
    for (int64_t p = 0; p < n; ++p) bd[p] = double(b[p]);
    using Diag = Eigen::ConjugateGradient<Eigen::SparseMatrix<double, Eigen::RowMajor>,
                                          Eigen::Lower | Eigen::Upper,
                                          Eigen::DiagonalPreconditioner<double>>;
    using Ic = Eigen::ConjugateGradient<Eigen::SparseMatrix<double, Eigen::RowMajor>,
                                        Eigen::Lower | Eigen::Upper,
                                        Eigen::IncompleteCholesky<double>>;
    row.peers.push_back(RunEigenCg<Diag>("Eigen CG + diagonal", M, bd, o.tolerance, row.seconds));
    if (progress) progress(fmt::format("{}: Eigen CG + diagonal {:.3f} s", shape.ToString(), row.peers.back().seconds));
    row.peers.push_back(RunEigenCg<Ic>("Eigen CG + IncompleteCholesky", M, bd, o.tolerance, row.seconds));
    if (progress) progress(fmt::format("{}: Eigen CG + IC {:.3f} s", shape.ToString(), row.peers.back().seconds));
    const double budget = std::min(o.jacobi_factor * row.seconds, o.jacobi_cap_seconds);
    row.peers.push_back(RunJacobi(solver.stencil(), b, o.tolerance, budget, row.seconds));
    if (progress) progress(fmt::format("{}: Jacobi {:.3f} s, residual {:.2e}", shape.ToString(), row.peers.back().seconds, row.peers.back().residual));
  }
  return row;
}

// The batched gl solve of o.batch right-hand sides (the 4x4 region lights on the lit face,
// cycled).
void BenchGlBatch(const BenchProblem& problem, GlMultigridSolver& solver,
                  const ForwardBenchOptions& o, ForwardBenchRow* row,
                  void (*progress)(const std::string&)) {
  const Material& m = problem.material;
  const GridShape& shape = m.shape;
  const int64_t n = shape.size();
  const TensorGrid grid = TensorGrid::Uniform(shape, m.spacing_mm);
  std::vector<float> b(o.batch * n), x(o.batch * n);
  for (int f = 0; f < o.batch; ++f) {
    const std::string spec = fmt::format("region:{},{}/4", f % 4, (f / 4) % 4);
    const std::vector<float> q = RasterizeLight(LightSpec::Parse(spec), shape, m.spacing_mm);
    LitFaceSource(grid, shape.nz - 1, m.C, q.data(), b.data() + f * n);
  }
  std::vector<double> times;
  for (int r = 0; r < std::max(1, o.repeats); ++r) {
    std::fill(x.begin(), x.end(), 0.0f);
    const std::vector<SolveSummary> sums = solver.SolveBatch(o.batch, b.data(), x.data());
    times.push_back(sums[0].seconds);
    row->batch_iterations = 0;
    for (const SolveSummary& s : sums) row->batch_iterations = std::max(row->batch_iterations, s.iterations);
  }
  row->batch_fields = o.batch;
  row->batch_seconds = Median(times);
  row->batch_apply_fields = std::min(o.batch, solver.max_batch());
  row->batch_apply_bandwidth =
      double(solver.ApplyBytes(row->batch_apply_fields)) / solver.TimeApply(11, row->batch_apply_fields);
  if (progress)
    progress(fmt::format("{}: gl batch of {}: {:.4f} s ({:.4f} s per right-hand side)",
                         shape.ToString(), o.batch, row->batch_seconds, row->batch_seconds / o.batch));
}

// The gl solution x (float, solved to the benchmark's tolerance) against the cpu solver's in
// double, solved to 1e-12: the accuracy the gl backend delivers (GPU issue: radiance within 1e-4
// of the cpu double result).
void GlAgreement(const BenchProblem& problem, const std::vector<float>& x, ForwardBenchRow* row) {
  const Material& m = problem.material;
  const GridShape& s = m.shape;
  MultigridOptions ro;
  ro.tolerance = 1e-12;
  MultigridSolver<double> ref(s, m.spacing_mm, ro);
  const std::vector<double> kappa = problem.Field<double>(m.kappa[1]),
                            mu = problem.Field<double>(m.mu[1]);
  ref.SetCoefficients(kappa.data(), mu.data(), m.C);
  std::vector<double> xr(s.size(), 0.0);
  ref.Solve(problem.b.data(), xr.data());
  double num = 0, den = 0, front_err = 0, front_max = 0;
  for (int64_t p = 0; p < s.size(); ++p) {
    const double d = double(x[p]) - xr[p];
    num += d * d;
    den += xr[p] * xr[p];
    if (p < s.nx * s.ny) {  // plane k = 0
      front_err = std::max(front_err, std::abs(d));
      front_max = std::max(front_max, std::abs(xr[p]));
    }
  }
  row->gl_error_l2 = den > 0 ? std::sqrt(num / den) : 0.0;
  row->gl_error_front = front_max > 0 ? front_err / front_max : 0.0;
}

// The gl backend on the same problem, with the cpu multigrid solver (same precision as
// requested, in the same process) as the peer.
ForwardBenchRow BenchGl(const GridShape& shape, const ForwardBenchOptions& o,
                        void (*progress)(const std::string&)) {
  const BenchProblem problem(shape);
  const Material& m = problem.material;
  const int64_t n = shape.size();
  const MultigridOptions mo = SolverOptions(o);
  GlMultigridSolver solver(shape, m.spacing_mm, mo);
  solver.SetCoefficients(m.kappa[1].data(), m.mu[1].data(), m.C);
  std::vector<float> b(problem.b.begin(), problem.b.end()), x(n);
  ForwardBenchRow row;
  row.shape = shape;
  row.levels = solver.num_levels();
  std::fill(x.begin(), x.end(), 0.0f);
  solver.Solve(b.data(), x.data());  // warm-up: shader compilation, first touch
  std::vector<double> solves;
  for (int r = 0; r < std::max(1, o.repeats); ++r) {
    std::fill(x.begin(), x.end(), 0.0f);
    const int64_t before = GlMultigridSolver::Dispatches();
    const SolveSummary s = solver.Solve(b.data(), x.data());
    row.dispatches = GlMultigridSolver::Dispatches() - before;
    solves.push_back(s.seconds);
    row.iterations = s.iterations;
    row.residual = s.final_residual;
  }
  row.seconds = Median(solves);
  GlAgreement(problem, x, &row);
  row.dispatch_seconds = solver.TimeEmptyDispatch(11);
  row.apply_seconds = solver.TimeApply(11);
  row.work_units = row.seconds / row.apply_seconds;
  row.nodes_per_second = double(n) / row.seconds;
  row.apply_bandwidth = double(solver.ApplyBytes()) / row.apply_seconds;
  const int64_t copy_bytes = std::max<int64_t>(solver.ApplyBytes(), int64_t(256) << 20);
  row.copy_bandwidth = 2.0 * double(copy_bytes) / solver.TimeCopy(copy_bytes, 11);
  row.copy_reference = solver.CopyReference();
  if (progress)
    progress(fmt::format("{}: gl {} iterations, {:.4f} s, stencil {:.1f} GB/s = {:.0f}% of copy "
                         "{:.1f} GB/s", shape.ToString(), row.iterations, row.seconds,
                         row.apply_bandwidth / 1e9, 100 * row.apply_bandwidth / row.copy_bandwidth,
                         row.copy_bandwidth / 1e9));
  if (o.batch > 0) BenchGlBatch(problem, solver, o, &row, progress);
  if (o.peers) {
    ForwardBenchOptions co = o;
    co.peers = false;
    co.backend = Backend::kCpu;
    co.repeats = std::min(o.repeats, 3);
    const ForwardBenchRow cpu = o.precision == Precision::kDouble ? BenchOne<double>(shape, co, nullptr)
                                                                  : BenchOne<float>(shape, co, nullptr);
    PeerResult p;
    p.name = std::string("cpu multigrid-PCG (") +
             (o.precision == Precision::kDouble ? "double" : "float") + ")";
    p.ran = p.converged = true;
    p.iterations = cpu.iterations;
    p.seconds = cpu.seconds;
    p.residual = cpu.residual;
    p.ratio = cpu.seconds / row.seconds;
    row.peers.push_back(p);
  }
  return row;
}

}  // namespace

std::vector<GridShape> DefaultForwardBenchGrids() {
  return {{33, 33, 33}, {65, 65, 65}, {129, 129, 129}, {130, 53, 37}, {256, 256, 20}};
}

std::vector<ForwardBenchRow> RunForwardBench(const ForwardBenchOptions& o,
                                             void (*progress)(const std::string&)) {
  TL_CHECK_MSG(!(o.cpu_time && o.backend == Backend::kGl), "cpu_time is for the cpu backend");
  use_cpu_time = o.cpu_time;
  std::vector<GridShape> grids = o.grids.empty() ? DefaultForwardBenchGrids() : o.grids;
  std::vector<ForwardBenchRow> rows;
  for (const GridShape& g : grids) {
    if (o.backend == Backend::kGl) rows.push_back(BenchGl(g, o, progress));
    else if (o.precision == Precision::kDouble) rows.push_back(BenchOne<double>(g, o, progress));
    else rows.push_back(BenchOne<float>(g, o, progress));
  }
  return rows;
}

std::string ForwardBenchTable(const std::vector<ForwardBenchRow>& rows) {
  std::string out = fmt::format("{:>14} {:>6} {:>5} {:>10} {:>10} {:>8} {:>12}\n", "grid",
                                "levels", "iters", "solve s", "apply s", "work u.", "nodes/s");
  for (const auto& r : rows)
    out += fmt::format("{:>14} {:>6} {:>5} {:>10.4f} {:>10.6f} {:>8.1f} {:>12.3g}\n",
                       r.shape.ToString(), r.levels, r.iterations, r.seconds, r.apply_seconds,
                       r.work_units, r.nodes_per_second);
  if (!rows.empty() && rows[0].copy_bandwidth > 0) {
    // With a batch: the stencil on the batch's fields in one dispatch too.
    const int nb = rows[0].batch_apply_bandwidth > 0 ? rows[0].batch_apply_fields : 0;
    out += fmt::format("\n{:>14} {:>14} {:>14} {:>12}", "grid", "stencil GB/s", "copy GB/s", "stencil/copy");
    if (nb > 0)
      out += fmt::format(" {:>16} {:>14}", fmt::format("x{} stencil GB/s", nb), fmt::format("x{} / copy", nb));
    out += "\n";
    for (const auto& r : rows) {
      out += fmt::format("{:>14} {:>14.1f} {:>14.1f} {:>11.0f}%", r.shape.ToString(), r.apply_bandwidth / 1e9,
                         r.copy_bandwidth / 1e9, 100 * r.apply_bandwidth / r.copy_bandwidth);
      if (nb > 0) {
        // (Labelled where a grid's buffers hold fewer fields per dispatch.)
        const std::string gbs = fmt::format("{:.1f}", r.batch_apply_bandwidth / 1e9);
        out += fmt::format(" {:>16} {:>13.0f}%",
                           r.batch_apply_fields == nb ? gbs : fmt::format("{} (x{})", gbs, r.batch_apply_fields),
                           100 * r.batch_apply_bandwidth / r.copy_bandwidth);
      }
      out += "\n";
    }
    out += fmt::format("(copy: {}{})\n", rows[0].copy_reference,
                       nb > 0 ? fmt::format("; x{}: the stencil on the batch's {} fields in one dispatch, the "
                                            "coefficients read once",
                                            nb, nb)
                              : "");
    out += fmt::format("\n{:>14} {:>16} {:>18}\n", "grid", "gl vs cpu: L2", "front face max");
    for (const auto& r : rows)
      out += fmt::format("{:>14} {:>16.2e} {:>18.2e}\n", r.shape.ToString(), r.gl_error_l2,
                         r.gl_error_front);
    out += "(the gl solution against the cpu solver's in double to 1e-12, relative)\n";
    out += fmt::format("\n{:>14} {:>12} {:>16} {:>18}\n", "grid", "dispatches", "empty dispatch",
                       "their floor / solve");
    for (const auto& r : rows)
      out += fmt::format("{:>14} {:>12} {:>13.1f} us {:>17.0f}%\n", r.shape.ToString(), r.dispatches,
                         1e6 * r.dispatch_seconds, 100 * double(r.dispatches) * r.dispatch_seconds / r.seconds);
    out += "(one solve's dispatches; an empty dispatch's median time, measured in the same run)\n";
  }
  if (!rows.empty() && rows[0].batch_fields > 0) {
    // Per right-hand side against one gl solve and the cpu peer's one solve.
    out += fmt::format("\n{:>14} {:>6} {:>5} {:>10} {:>12} {:>14} {:>14}\n", "grid", "batch",
                       "iters", "gl batch s", "gl s / rhs", "single / rhs", "cpu / gl rhs");
    for (const auto& r : rows) {
      const double per = r.batch_seconds / r.batch_fields;
      out += fmt::format("{:>14} {:>6} {:>5} {:>10.4f} {:>12.5f} {:>13.2f}x {:>14}\n",
                         r.shape.ToString(), r.batch_fields, r.batch_iterations, r.batch_seconds,
                         per, r.seconds / per,
                         r.peers.empty() ? "-" : fmt::format("{:.3f}x", r.peers[0].seconds / per));
    }
  }
  bool any = false;
  for (const auto& r : rows) any |= !r.peers.empty();
  if (any) {
    out += fmt::format("\n{:>14} {:<30} {:>10} {:>9} {:>10} {:>12}\n", "grid", "peer", "time s",
                       "iters", "residual", "peer / ours");
    for (const auto& r : rows)
      for (const auto& p : r.peers)
        out += fmt::format("{:>14} {:<30} {:>10.4f} {:>9} {:>10.2e} {:>12}\n", r.shape.ToString(),
                           p.name, p.seconds, p.iterations, p.residual,
                           fmt::format("{}{:.2f}x", p.lower_bound ? ">= " : "", p.ratio));
  }
  return out;
}

std::string ForwardBenchJson(const std::vector<ForwardBenchRow>& rows) {
  nlohmann::json j = nlohmann::json::array();
  for (const auto& r : rows) {
    nlohmann::json row = {{"grid", r.shape.ToString()}, {"levels", r.levels},
                          {"iterations", r.iterations}, {"seconds", r.seconds},
                          {"apply_seconds", r.apply_seconds}, {"work_units", r.work_units},
                          {"nodes_per_second", r.nodes_per_second}, {"residual", r.residual}};
    if (r.copy_bandwidth > 0) {
      row["stencil_bytes_per_second"] = r.apply_bandwidth;
      row["copy_bytes_per_second"] = r.copy_bandwidth;
      row["copy_reference"] = r.copy_reference;
      row["stencil_fraction_of_copy"] = r.apply_bandwidth / r.copy_bandwidth;
      row["gl_error_l2"] = r.gl_error_l2;
      row["gl_error_front"] = r.gl_error_front;
      row["dispatches"] = r.dispatches;
      row["empty_dispatch_seconds"] = r.dispatch_seconds;
    }
    if (r.batch_fields > 0) {
      row["batch_fields"] = r.batch_fields;
      row["batch_iterations"] = r.batch_iterations;
      row["batch_seconds"] = r.batch_seconds;
      if (r.batch_apply_bandwidth > 0) {
        row["batch_stencil_fields"] = r.batch_apply_fields;
        row["batch_stencil_bytes_per_second"] = r.batch_apply_bandwidth;
      }
    }
    for (const auto& p : r.peers)
      row["peers"].push_back({{"name", p.name}, {"seconds", p.seconds},
                              {"iterations", p.iterations}, {"residual", p.residual},
                              {"converged", p.converged}, {"ratio", p.ratio},
                              {"ratio_is_lower_bound", p.lower_bound}});
    j.push_back(row);
  }
  return j.dump(2);
}

}  // namespace translume
