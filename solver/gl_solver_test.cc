// SPDX-License-Identifier: MIT
#include "solver/gl_solver.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include "solver/gl_context.h"
#include "solver/gl_internal.h"
#include "solver/status.h"

namespace translume {
namespace {

// A smoothly varying heterogeneous material on n nodes (kappa 0.1 .. 0.3, mu 0.01 .. 0.03).
void VaryingMaterial(int64_t n, std::vector<float>& kappa, std::vector<float>& mu) {
  kappa.resize(n);
  mu.resize(n);
  for (int64_t p = 0; p < n; ++p) {
    kappa[p] = 0.2f + 0.1f * std::sin(0.05f * p);
    mu[p] = 0.02f + 0.01f * std::cos(0.03f * p);
  }
}

// m >= 5 right-hand sides of grid s, back to back, and initial guesses (zero but for field 2):
// a back light, a front spot, a smooth interior source, a zero field, field 1 times 1e3, then
// smooth interior sources.
void VariedBatch(const GridShape& s, int m, std::vector<float>& b, std::vector<float>& x0) {
  const int64_t n = s.size();
  b.assign(m * n, 0.0f);
  x0.assign(m * n, 0.0f);
  for (int64_t f = 0; f < s.face_size(); ++f) b[f + n - s.face_size()] = 0.01f;  // back light
  b[n + s.index(5, 4, 0)] = 1.0f;                                                  // spot
  for (int64_t p = 0; p < n; ++p) {
    b[2 * n + p] = 0.001f * (1.0f + std::sin(0.2f * p));
    x0[2 * n + p] = 0.05f * std::cos(0.1f * p);
    b[4 * n + p] = 1e3f * b[n + p];  // field 3 stays zero
    for (int f = 5; f < m; ++f) b[f * n + p] = 0.001f * (1.0f + std::sin(0.2f * p + f));
  }
}

// m right-hand sides of grid s, back to back: smooth interior sources (another phase in each
// field), and a spot at (5, 4, 0) in field 1 (where m > 1).
std::vector<float> SourcesAndASpot(const GridShape& s, int m) {
  const int64_t n = s.size();
  std::vector<float> b(m * n);
  for (int64_t p = 0; p < n; ++p)
    for (int f = 0; f < m; ++f) b[f * n + p] = 0.001f * (1.0f + std::sin(0.2f * p + f));
  if (m > 1) b[n + s.index(5, 4, 0)] = 1.0f;
  return b;
}

// A batch on grid s: VaryingMaterial, VariedBatch's m fields, and a gl solver for them with
// tolerance 1e-6 (h = 0.5 mm, C = 2.6).
struct VariedProblem {
  VariedProblem(const GridShape& shape, int m) : s(shape), n(shape.size()), M(m) {
    VaryingMaterial(n, kappa, mu);
    VariedBatch(s, M, b, x0);
    mo.tolerance = 1e-6;
    gl = std::make_unique<GlMultigridSolver>(s, 0.5, mo);
    gl->SetCoefficients(kappa.data(), mu.data(), 2.6);
  }
  GridShape s;
  int64_t n;
  int M;
  std::vector<float> kappa, mu, b, x0;
  MultigridOptions mo;
  std::unique_ptr<GlMultigridSolver> gl;
};

TEST(GlContext, ReportsACompute43Context) {
  const GlInfo& info = GlContext::Get().info();
  EXPECT_FALSE(info.renderer.empty());
  EXPECT_GE(info.max_work_group_invocations, 256);
  EXPECT_GE(info.max_work_group_count[0], 65535);
}

// The variant the shaders run in: llvmpipe's on llvmpipe, the GPU's elsewhere, or the one
// TRANSLUME_GL_TUNING forces (the ctest GlSolver.GpuTuning runs every gl test with "gpu").
TEST(GlSolver, ReportsItsShaderTuning) {
  const std::string tuning = GlShaderTuning();
  std::printf("shader tuning: %s\n", tuning.c_str());
  const char* forced = std::getenv("TRANSLUME_GL_TUNING");
  const bool llvmpipe = GlContext::Get().info().renderer.find("llvmpipe") != std::string::npos;
  const std::string expected = forced ? forced : (llvmpipe ? "llvmpipe" : "gpu");
  EXPECT_EQ(tuning.substr(0, tuning.find(' ')), expected);
  EXPECT_EQ(gl_internal::GetTuning().images, expected == "llvmpipe");
}

// The error compiling `source` as `file_name` reports ("" and a failed test if it compiles).
std::string CompileError(const std::string& file_name, const std::string& source) {
  try {
    CompileGlShaderForTest(file_name, source);
  } catch (const InputError& e) {
    return e.what();
  }
  ADD_FAILURE() << file_name << " compiled";
  return "";
}

TEST(GlSolver, ShaderCompileErrorsNameTheFileAndLine) {
  const std::string msg = CompileError("solver/shaders/broken.comp",
                                       "// a comment\nvoid main() {\n  undefined_thing = 1.0;\n}\n");
  EXPECT_NE(msg.find("solver/shaders/broken.comp:3"), std::string::npos) << msg;
  EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
  EXPECT_NO_THROW(CompileGlShaderForTest("ok.comp", "void main() {}\n"));
  // An error in an included snippet names the snippet (here: its arrays are not declared).
  const std::string inc = CompileError("solver/shaders/inc.comp",
                                       "#define MG_SMOOTH\n#include \"multigrid.glsl\"\nvoid main() {}\n");
  EXPECT_NE(inc.find("solver/shaders/multigrid.glsl:"), std::string::npos) << inc;
}

TEST(GlSolver, ApplyMatchesTheCpuStencil) {
  const GridShape s{13, 9, 7};
  std::vector<float> kappa(s.size()), mu(s.size()), x(s.size()), y_gl(s.size()), y_cpu(s.size());
  for (int64_t p = 0; p < s.size(); ++p) {
    kappa[p] = 0.1f + 0.05f * std::sin(0.3f * p);
    mu[p] = 0.01f + 0.005f * std::cos(0.7f * p);
    x[p] = std::sin(0.11f * p);
  }
  GlMultigridSolver gl(s, 0.4);
  gl.SetCoefficients(kappa.data(), mu.data(), 2.6);
  gl.Apply(x.data(), y_gl.data());
  MultigridSolver<float> cpu(s, 0.4);
  cpu.SetCoefficients(kappa.data(), mu.data(), 2.6);
  cpu.Apply(x.data(), y_cpu.data());
  double top = 0;
  for (float v : y_cpu) top = std::max(top, double(std::abs(v)));
  for (int64_t p = 0; p < s.size(); ++p) EXPECT_NEAR(y_gl[p], y_cpu[p], 1e-5 * top) << p;
}

TEST(GlSolver, WarmStartAndIterationsMatchTheCpuSolver) {
  const GridShape s{40, 30, 20};
  std::vector<float> kappa(s.size(), 0.2f), mu(s.size(), 0.02f), b(s.size(), 0.0f), x(s.size(), 0.0f);
  for (int64_t f = 0; f < s.face_size(); ++f) b[f + s.size() - s.face_size()] = 0.01f;
  GlMultigridSolver gl(s, 0.5);
  gl.SetCoefficients(kappa.data(), mu.data(), 2.6);
  const SolveSummary cold = gl.Solve(b.data(), x.data());
  EXPECT_TRUE(cold.converged) << cold.BriefReport();
  EXPECT_LE(cold.final_residual, 1e-6);
  MultigridSolver<float> cpu(s, 0.5);
  cpu.SetCoefficients(kappa.data(), mu.data(), 2.6);
  std::vector<float> xc(s.size(), 0.0f);
  const SolveSummary cs = cpu.Solve(b.data(), xc.data());
  EXPECT_LE(std::abs(cold.iterations - cs.iterations), 3) << cold.BriefReport() << " vs " << cs.BriefReport();
  // The same solution: both to a relative residual of 1e-6 in float.
  double dd = 0, xx = 0;
  for (int64_t p = 0; p < s.size(); ++p) {
    dd += (double(x[p]) - xc[p]) * (double(x[p]) - xc[p]);
    xx += double(xc[p]) * xc[p];
  }
  EXPECT_GT(xx, 0.0);
  EXPECT_LE(std::sqrt(dd / xx), 1e-5);
  // A warm start from the solution converges at once.
  const SolveSummary warm = gl.Solve(b.data(), x.data());
  EXPECT_LE(warm.iterations, 1);
}

// The full-multigrid start on gl, as on the cpu: fewer iterations to the same solution, with
// the default coarse tail and without one.
TEST(GlSolver, FullMultigridStartSavesIterationsAndKeepsTheSolution) {
  const GridShape s{33, 33, 17};
  const int64_t n = s.size();
  std::vector<float> kappa, mu, b(n, 0.0f);
  VaryingMaterial(n, kappa, mu);
  for (int64_t f = 0; f < s.face_size(); ++f) b[f + n - s.face_size()] = 0.01f;  // back light
  for (bool tail : {true, false}) {
    SCOPED_TRACE(tail ? "default tail" : "no tail");
    MultigridOptions with, without;
    without.full_multigrid_start = false;
    GlMultigridSolver a(s, 0.25, with), c(s, 0.25, without);
    if (!tail) a.SetCoarseTail(0);
    a.SetCoefficients(kappa.data(), mu.data(), 2.6);
    c.SetCoefficients(kappa.data(), mu.data(), 2.6);
    std::vector<float> xa(n, 0.0f), xc(n, 0.0f);
    const SolveSummary sa = a.Solve(b.data(), xa.data()), sc = c.Solve(b.data(), xc.data());
    ASSERT_TRUE(sa.converged && sc.converged) << sa.BriefReport() << " / " << sc.BriefReport();
    EXPECT_LE(sa.final_residual, 1e-6);
    EXPECT_LE(sa.iterations + 1, sc.iterations) << sa.BriefReport() << " / " << sc.BriefReport();
    double num = 0, den = 0;
    for (int64_t p = 0; p < n; ++p) {
      num += double(xa[p] - xc[p]) * double(xa[p] - xc[p]);
      den += double(xc[p]) * double(xc[p]);
    }
    EXPECT_LT(std::sqrt(num / den), 1e-5);
  }
}

// A batch of different right-hand sides (back light, a front spot, a smooth interior source
// from a nonzero initial guess, a zero field, a 1e3 times larger one) gives each field what its
// own solve gives: the same iterations, the same x within the solver's tolerance, and a true
// residual (recomputed here in double) below the tolerance for every field.
TEST(GlSolver, BatchedSolveMatchesSingleSolvesAndConvergesEveryField) {
  VariedProblem P({24, 18, 10}, 5);
  const GridShape& s = P.s;
  const int64_t n = P.n;
  const int M = P.M;
  const std::vector<float>& kappa = P.kappa, &mu = P.mu, &b = P.b, &x0 = P.x0;
  GlMultigridSolver& gl = *P.gl;
  std::vector<float> xb = x0;
  const std::vector<SolveSummary> batch = gl.SolveBatch(M, b.data(), xb.data());
  ASSERT_EQ(int(batch.size()), M);
  MultigridSolver<double> cpu(s, 0.5);
  std::vector<double> kd(kappa.begin(), kappa.end()), md(mu.begin(), mu.end()), xd(n), ax(n);
  cpu.SetCoefficients(kd.data(), md.data(), 2.6);
  for (int f = 0; f < M; ++f) {
    SCOPED_TRACE(f);
    EXPECT_TRUE(batch[f].converged) << batch[f].BriefReport();
    std::vector<float> xs(x0.begin() + f * n, x0.begin() + (f + 1) * n);
    const SolveSummary single = gl.Solve(b.data() + f * n, xs.data());
    EXPECT_TRUE(single.converged) << single.BriefReport();
    EXPECT_EQ(batch[f].iterations, single.iterations);
    EXPECT_EQ(int(batch[f].history.size()), batch[f].iterations);
    double bb = 0, rr = 0, dd = 0, xx = 0;
    for (int64_t p = 0; p < n; ++p) xd[p] = xb[f * n + p];
    cpu.Apply(xd.data(), ax.data());
    for (int64_t p = 0; p < n; ++p) {
      bb += double(b[f * n + p]) * b[f * n + p];
      rr += (b[f * n + p] - ax[p]) * (b[f * n + p] - ax[p]);
      dd += (double(xb[f * n + p]) - xs[p]) * (double(xb[f * n + p]) - xs[p]);
      xx += double(xs[p]) * xs[p];
    }
    if (f == 3) {  // the zero right-hand side: x = 0 exactly, whatever the initial guess
      EXPECT_EQ(batch[f].message, "zero right-hand side");
      EXPECT_EQ(xx, 0.0);
      EXPECT_EQ(dd, 0.0);
      continue;
    }
    EXPECT_GT(batch[f].iterations, 0);
    EXPECT_LE(batch[f].final_residual, 1e-6);
    // x stored in float: its own rounding adds a few 1e-7 to the residual.
    EXPECT_LE(std::sqrt(rr / bb), 2e-6);
    EXPECT_LE(std::sqrt(dd / xx), 1e-5);
  }
  // The scaled copy of field 1 converges the same way.
  EXPECT_EQ(batch[4].iterations, batch[1].iterations);
}

// The coarse tail (tail.comp: the V-cycle of the small levels in one dispatch per V-cycle)
// and the packed V-cycle (four fields per vec4, FIELDS4) compute what the per-level dispatches
// on one field per value compute: on a grid of 4+ levels, batched (five fields: one group of
// four and one of a single field), with no tail, the tail covering the whole hierarchy and
// only its lower levels, each with one and four fields per value, one V-cycle gives the same z
// within float rounding (a tail with fewer dispatches), and the solves take the same
// iterations to the same solution.
TEST(GlSolver, CoarseTailMatchesThePerLevelVCycle) {
  const GridShape s{30, 22, 12};
  const int64_t n = s.size();
  const int M = 5;
  std::vector<float> kappa, mu, b = SourcesAndASpot(s, M);
  VaryingMaterial(n, kappa, mu);
  MultigridOptions mo;
  mo.tolerance = 1e-6;
  // V(1,1) on the finest level, V(2,2) below: the tail takes each level's own count.
  mo.pre_smoothing = mo.post_smoothing = 1;
  mo.coarse_smoothing = 2;
  // The full-multigrid start takes one V-cycle over the tail as its coarse solve, so with it
  // the solves would differ by design; this test compares the V-cycles.
  mo.full_multigrid_start = false;
  GlMultigridSolver gl(s, 0.5, mo);
  gl.SetCoefficients(kappa.data(), mu.data(), 2.6);
  ASSERT_GE(gl.num_levels(), 4);
  GlMultigridSolver::Impl& I = gl.impl();
  I.Reserve(M);
  // One V-cycle of every field: z, and the dispatches it took.
  auto vcycle = [&](std::vector<float>& z) {
    I.r.Upload(b.data(), M * n * 4);
    const int64_t before = gl_internal::DispatchCount();
    I.Precondition(I.r, I.z, M);
    z.resize(M * n);
    I.z.Download(z.data(), M * n * 4);
    return gl_internal::DispatchCount() - before;
  };
  auto solve = [&](std::vector<float>& x) {
    x.assign(M * n, 0.0f);
    return gl.SolveBatch(M, b.data(), x.data());
  };
  gl.SetCoarseTail(0);
  I.SetPackFields(1);
  EXPECT_EQ(gl.coarse_tail_levels(), 0);
  std::vector<float> z_levels, x_levels;
  const int64_t per_level = vcycle(z_levels);
  const std::vector<SolveSummary> s_levels = solve(x_levels);
  double zmax = 0, xmax = 0;
  for (float v : z_levels) zmax = std::max(zmax, double(std::abs(v)));
  for (float v : x_levels) xmax = std::max(xmax, double(std::abs(v)));
  for (int64_t nodes : {int64_t(0), I.levels[0]->n, I.levels[2]->n})
  for (int fields : {1, 4}) {
    if (nodes == 0 && fields == 1) continue;  // the reference
    SCOPED_TRACE(::testing::Message() << nodes << " nodes, " << fields << " fields per value");
    I.SetPackFields(fields);
    gl.SetCoarseTail(nodes);
    EXPECT_EQ(gl.coarse_tail_levels(), nodes == n ? gl.num_levels() : nodes == 0 ? 0 : gl.num_levels() - 2);
    std::vector<float> z_tail, x_tail;
    const int64_t tail = vcycle(z_tail);
    std::printf("dispatches per V-cycle on %s (%d levels, %d fields per value): %lld per level, %lld with a tail of %d\n",
                s.ToString().c_str(), gl.num_levels(), fields, (long long)per_level, (long long)tail,
                gl.coarse_tail_levels());
    if (nodes > 0) {
      EXPECT_LT(tail, per_level);
    }
    double dz = 0;
    for (int64_t p = 0; p < M * n; ++p) dz = std::max(dz, double(std::abs(z_tail[p] - z_levels[p])));
    EXPECT_LE(dz, 1e-5 * zmax);
    const std::vector<SolveSummary> s_tail = solve(x_tail);
    double dx = 0;
    for (int64_t p = 0; p < M * n; ++p) dx = std::max(dx, double(std::abs(x_tail[p] - x_levels[p])));
    EXPECT_LE(dx, 1e-5 * xmax);
    for (int f = 0; f < M; ++f) {
      EXPECT_TRUE(s_tail[f].converged) << s_tail[f].BriefReport();
      EXPECT_EQ(s_tail[f].iterations, s_levels[f].iterations) << f;
    }
  }
}

// With the whole hierarchy in the coarse tail and four fields per tail group, each conjugate-
// gradient iteration runs as one dispatch (tail.comp's CG_ITERATION) instead of ~9. On six
// fields (VariedBatch: a group of four, a partial group of two) it gives the dispatched
// iteration's results: the same iterations, histories and solutions within float rounding.
TEST(GlSolver, OneDispatchCgIterationMatchesTheDispatchedOne) {
  VariedProblem P({20, 16, 8}, 6);
  const int64_t n = P.n;
  const int M = P.M;
  GlMultigridSolver& gl = *P.gl;
  GlMultigridSolver::Impl& I = gl.impl();
  ASSERT_EQ(gl.coarse_tail_levels(), gl.num_levels());
  auto solve = [&](int pack_fields, std::vector<float>& x, int64_t& dispatches) {
    I.SetPackFields(pack_fields);
    x = P.x0;
    const int64_t before = gl_internal::DispatchCount();
    std::vector<SolveSummary> sums = gl.SolveBatch(M, P.b.data(), x.data());
    dispatches = gl_internal::DispatchCount() - before;
    return sums;
  };
  std::vector<float> xd, xf;
  int64_t nd = 0, nf = 0;
  const std::vector<SolveSummary> dispatched = solve(1, xd, nd);
  const std::vector<SolveSummary> fused = solve(4, xf, nf);
  ASSERT_TRUE(I.CgIterationInTail(M));
  int iterations = 0;
  for (int f = 0; f < M; ++f) {
    SCOPED_TRACE(f);
    EXPECT_TRUE(fused[f].converged) << fused[f].BriefReport();
    EXPECT_EQ(fused[f].message, dispatched[f].message);
    EXPECT_EQ(fused[f].iterations, dispatched[f].iterations);
    ASSERT_EQ(fused[f].history.size(), dispatched[f].history.size());
    for (size_t i = 0; i < fused[f].history.size(); ++i)
      EXPECT_NEAR(fused[f].history[i], dispatched[f].history[i], 1e-3 * dispatched[f].history[i]) << i;
    double dd = 0, xx = 0;
    for (int64_t p = f * n; p < (f + 1) * n; ++p) {
      dd += (double(xf[p]) - xd[p]) * (double(xf[p]) - xd[p]);
      xx += double(xd[p]) * xd[p];
    }
    if (f == 3) {
      EXPECT_EQ(dd + xx, 0.0);
      continue;
    }
    EXPECT_GT(fused[f].iterations, 0);
    EXPECT_LE(std::sqrt(dd / xx), 1e-5);
    iterations = std::max(iterations, fused[f].iterations);
  }
  std::printf("%s, %d fields, %d iterations: %lld dispatches, %lld with one per iteration\n",
              P.s.ToString().c_str(), M, iterations, (long long)nd, (long long)nf);
  EXPECT_LE(nf + 7 * iterations, nd);
}

// A coarse tail whose first level is large. One invocation of tail.comp loops over whole
// levels, and llvmpipe silently ends every loop of a shader once the shader has run 65535 loop
// iterations in all (gl_internal::LoopBudget): a tail over the whole 32^3 hierarchy with 8
// invocations per group broke the preconditioner (100 iterations, not converged). The host
// now starts the tail where one invocation stays within the budget. With SetCoarseTail over
// the whole hierarchy, the tuning's tail group and a larger one, a single solve and a packed
// batch of four (one dispatch per CG iteration where the tail covers every level) converge
// in the cpu solver's iterations to its solutions.
TEST(GlSolver, LargeCoarseTailStaysWithinTheLoopBudgetAndMatchesTheCpu) {
  const GridShape s{32, 32, 32};
  const int M = 4;
  std::vector<float> b = SourcesAndASpot(s, M), kappa, mu;
  const int64_t n = s.size();
  for (int64_t f = 0; f < s.face_size(); ++f) b[f + n - s.face_size()] += 0.01f;  // a back light in field 0
  VaryingMaterial(n, kappa, mu);
  MultigridOptions mo;
  mo.tolerance = 1e-6;
  MultigridSolver<float> cpu(s, 0.5, mo);
  cpu.SetCoefficients(kappa.data(), mu.data(), 2.6);
  std::vector<float> xc(M * n, 0.0f);
  std::vector<int> cpu_iterations(M);
  for (int f = 0; f < M; ++f) cpu_iterations[f] = cpu.Solve(b.data() + f * n, xc.data() + f * n).iterations;
  GlMultigridSolver gl(s, 0.5, mo);
  gl.SetCoefficients(kappa.data(), mu.data(), 2.6);
  GlMultigridSolver::Impl& I = gl.impl();
  const int64_t budget = gl_internal::LoopBudget();
  for (int group : {gl_internal::GetTuning().tail_group, 64}) {
    I.tail_group = group;
    gl.SetCoarseTail(n);
    SCOPED_TRACE(::testing::Message() << group << " invocations per tail group, tail of " << gl.coarse_tail_levels()
                                      << " of " << gl.num_levels() << " levels");
    ASSERT_GE(gl.coarse_tail_levels(), 2);
    if (budget > 0) {
      EXPECT_LT(I.TailLoopIterations(I.tail_level), budget);
    }
    std::printf("%s, tail group %d: tail of %d of %d levels (%lld nodes first), %lld loop iterations counted\n",
                s.ToString().c_str(), group, gl.coarse_tail_levels(), gl.num_levels(),
                (long long)I.levels[I.tail_level]->n, (long long)I.TailLoopIterations(I.tail_level));
    for (int nb : {1, M}) {
      SCOPED_TRACE(::testing::Message() << nb << " field(s)");
      std::vector<float> x(nb * n, 0.0f);
      const std::vector<SolveSummary> sums = gl.SolveBatch(nb, b.data(), x.data());
      for (int f = 0; f < nb; ++f) {
        SCOPED_TRACE(f);
        EXPECT_TRUE(sums[f].converged) << sums[f].BriefReport();
        // (Up to two more where the tail covers every level: the full-multigrid start, which
        // saves one or two, is skipped there.)
        EXPECT_LE(sums[f].iterations, cpu_iterations[f] + 2) << sums[f].BriefReport();
        double dd = 0, xx = 0;
        for (int64_t p = f * n; p < (f + 1) * n; ++p) {
          dd += (double(x[p]) - xc[p]) * (double(x[p]) - xc[p]);
          xx += double(xc[p]) * xc[p];
        }
        EXPECT_LE(std::sqrt(dd / xx), 1e-4);
      }
    }
  }
}

// The grid-stride loops of the element-wise kernels (FlatThreads, DotThreads) stay within
// llvmpipe's loop budget (gl_internal::LoopBudget) on large levels: with few invocations per field,
// one invocation's loops over its elements ran past it, silently (a forward solve on
// 256x256x160 returned NaN). The ctest `GlSolver.LoopBudgetWithEightInvocations` runs this test
// with TRANSLUME_GL_GROUP=8 and TRANSLUME_GL_FLAT_GROUPS=1 (8 invocations per field), where a
// 96^3 solve's element-wise loops (110k nodes per invocation) returned NaN before the fix.
TEST(GlSolver, GridStrideLoopsStayWithinTheLoopBudget) {
  const gl_internal::Tuning& t = gl_internal::GetTuning();
  const int64_t budget = gl_internal::LoopBudget();
  if (budget > 0) {
    for (int64_t n : {int64_t(1000), int64_t(64000), int64_t(10485760)}) {
      for (int64_t loops : {int64_t(0), int64_t(5), gl_internal::kFlatLoopsPerElement, int64_t(129)}) {
        const int64_t threads = gl_internal::FlatThreads(n, loops);
        const int64_t invocations = gl_internal::WorkGroups(threads) * t.group;
        EXPECT_LE((n + invocations - 1) / invocations * (loops + 1) + 1, budget) << n << " x " << loops;
      }
      const int64_t dots = gl_internal::WorkGroups(gl_internal::DotThreads(n)) * t.group;
      EXPECT_LE((n + dots - 1) / dots + 1, budget) << n;
    }
  }
  const GridShape s{96, 96, 96};
  const int64_t n = s.size();
  std::vector<float> kappa, mu, b = SourcesAndASpot(s, 1), x(n, 0.0f), xc(n, 0.0f);
  VaryingMaterial(n, kappa, mu);
  MultigridOptions mo;
  mo.tolerance = 1e-6;
  MultigridSolver<float> cpu(s, 0.5, mo);
  cpu.SetCoefficients(kappa.data(), mu.data(), 2.6);
  const SolveSummary cs = cpu.Solve(b.data(), xc.data());
  GlMultigridSolver gl(s, 0.5, mo);
  gl.SetCoefficients(kappa.data(), mu.data(), 2.6);
  const SolveSummary gs = gl.SolveBatch(1, b.data(), x.data())[0];
  EXPECT_TRUE(gs.converged) << gs.BriefReport();
  EXPECT_LE(gs.iterations, cs.iterations + 1) << gs.BriefReport();
  double dd = 0, xx = 0;
  for (int64_t p = 0; p < n; ++p) {
    dd += (double(x[p]) - xc[p]) * (double(x[p]) - xc[p]);
    xx += double(xc[p]) * xc[p];
  }
  EXPECT_LE(std::sqrt(dd / xx), 1e-4);
}

// A grid deeper than llvmpipe's loop budget lets a z-line solve run is refused with one line
// (the smoother's invocations would silently stop part-way down the line).
TEST(GlSolver, RefusesZLinesLongerThanTheLoopBudget) {
  if (gl_internal::LoopBudget() == 0) GTEST_SKIP() << "no loop budget on this renderer";
  try {
    GlMultigridSolver gl(GridShape{3, 3, 40000}, 0.5, MultigridOptions{});
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("3x3x40000"), std::string::npos) << msg;
    EXPECT_NE(msg.find("--backend cpu"), std::string::npos) << msg;
  }
  EXPECT_NO_THROW(GlMultigridSolver(GridShape{3, 3, 30000}, 0.5, MultigridOptions{}));
}

// A single field's solve in quarter rows (common.glsl's QUARTERS: the finest level four nodes
// of a row per vec4) gives the plain layout's results: the same iterations, solutions within
// float rounding. Widths with padding (13 -> 4 x 4, 26 -> 4 x 8) and without (40), with the
// coarse tail off and on; a back light, a spot beside a quarter's edge, a warm start.
TEST(GlSolver, QuarterRowsMatchThePlainLayout) {
  for (const GridShape shape : {GridShape{13, 9, 6}, GridShape{26, 11, 7}, GridShape{40, 30, 8}}) {
    for (bool tail : {false, true}) {
      SCOPED_TRACE(::testing::Message() << shape.ToString() << (tail ? " with" : " without") << " the tail");
      VariedProblem P(shape, 5);
      GlMultigridSolver& gl = *P.gl;
      GlMultigridSolver::Impl& I = gl.impl();
      if (!tail) gl.SetCoarseTail(0);
      if (I.tail_level == 0) continue;  // the whole hierarchy in the tail: never quartered
      const int64_t n = P.n;
      P.b[n + shape.index(I.qw, 3, 0)] = 1.0f;  // a spot on the second quarter's first column
      for (int f : {0, 1, 2}) {
        SCOPED_TRACE(f);
        std::vector<float> x_plain(P.x0.begin() + f * n, P.x0.begin() + (f + 1) * n), x_rows = x_plain;
        I.SetQuarters(false);
        const SolveSummary plain = gl.SolveBatch(1, P.b.data() + f * n, x_plain.data())[0];
        I.SetQuarters(true);
        ASSERT_TRUE(I.Quartered(1));
        const SolveSummary rows = gl.SolveBatch(1, P.b.data() + f * n, x_rows.data())[0];
        EXPECT_TRUE(rows.converged) << rows.BriefReport();
        EXPECT_EQ(rows.iterations, plain.iterations);
        EXPECT_NEAR(rows.final_residual, plain.final_residual, 0.1 * plain.final_residual);
        double dd = 0, xx = 0;
        for (int64_t p = 0; p < n; ++p) {
          dd += (double(x_rows[p]) - x_plain[p]) * (double(x_rows[p]) - x_plain[p]);
          xx += double(x_plain[p]) * x_plain[p];
        }
        EXPECT_GT(xx, 0.0);
        EXPECT_LE(std::sqrt(dd / xx), 1e-5);
      }
    }
  }
}

// The line smoother by cyclic reduction (Tuning::line_pcr, multigrid.glsl's SmoothLinePcr)
// solves each column's tridiagonal system as the Thomas algorithm (SmoothLine) does: a
// half-sweep of each colour from the same b and x gives the same x within float rounding, on
// columns of 2, 5, 16 (powers of two) and 37 nodes (the Wax I grid's), on the finest level and
// the next (its own shape and coefficients), for two fields one per value and four fields per
// vec4 (FIELDS4); a batched solve without the coarse tail (every level's smoother by cyclic
// reduction) then takes the same iterations to the same solutions.
TEST(GlSolver, CyclicReductionSmootherMatchesTheThomasSweep) {
  for (const GridShape s : {GridShape{9, 7, 2}, GridShape{11, 6, 5}, GridShape{8, 9, 16}, GridShape{7, 5, 37}}) {
    const int64_t n = s.size();
    std::vector<float> kappa, mu;
    VaryingMaterial(n, kappa, mu);
    GlMultigridSolver gl(s, 0.5);
    gl.SetCoefficients(kappa.data(), mu.data(), 2.6);
    GlMultigridSolver::Impl& I = gl.impl();
    I.line_pcr = true;
    for (size_t l = 0; l < std::min<size_t>(2, I.levels.size()); ++l) {
      GLevel& L = *I.levels[l];
      SCOPED_TRACE(::testing::Message() << s.ToString() << " level " << l << " (" << L.s.ToString() << ")");
      if (I.PcrLength(L) == 0) {
        // Both tunings' groups (64, 256) hold these columns; only an override can refuse them.
        if (gl_internal::GetTuning().group % 64 == 0) ADD_FAILURE() << "no cyclic reduction for nz " << L.s.nz;
        continue;
      }
      const int64_t m = L.n;
      for (bool packed : {false, true}) {
        SCOPED_TRACE(packed ? "four fields per value" : "one field per value");
        const int nb = packed ? 4 : 2;
        std::vector<float> b(nb * m), x0(nb * m);
        for (int64_t e = 0; e < nb * m; ++e) {
          b[e] = 0.01f * (1.0f + std::sin(0.37f * e));
          x0[e] = 0.05f * std::cos(0.13f * e);
        }
        const Elem elem = packed ? Elem::kVec4 : Elem::kFloat;
        Buffer bb, xx;
        bb.Alloc(nb * m * 4, b.data(), elem);
        for (int color : {0, 1}) {
          std::vector<float> x[2];
          for (bool pcr : {false, true}) {
            xx.Alloc(nb * m * 4, x0.data(), elem);
            I.line_pcr = pcr;
            I.packed = packed;
            I.Smooth(L, bb, xx, color, nb);
            I.packed = false;
            x[pcr].resize(nb * m);
            xx.Download(x[pcr].data(), nb * m * 4);
          }
          I.line_pcr = true;
          double dmax = 0, xmax = 0, moved = 0;
          for (int64_t e = 0; e < nb * m; ++e) {
            dmax = std::max(dmax, double(std::abs(x[1][e] - x[0][e])));
            xmax = std::max(xmax, double(std::abs(x[0][e])));
            moved = std::max(moved, double(std::abs(x[0][e] - x0[e])));
          }
          EXPECT_GT(moved, 1e-3 * xmax) << "colour " << color;
          EXPECT_LE(dmax, 1e-5 * xmax) << "colour " << color;
        }
      }
    }
  }
  VariedProblem P({20, 14, 21}, 5);
  P.gl->SetCoarseTail(0);
  GlMultigridSolver::Impl& I = P.gl->impl();
  ASSERT_GE(I.levels.size(), 3u);
  std::vector<float> x[2];
  std::vector<SolveSummary> sums[2];
  for (bool pcr : {false, true}) {
    I.line_pcr = pcr;
    x[pcr] = P.x0;
    const int64_t before = gl_internal::DispatchCount();
    sums[pcr] = P.gl->SolveBatch(P.M, P.b.data(), x[pcr].data());
    std::printf("%s smoother: %lld dispatches\n", pcr ? "cyclic-reduction" : "Thomas",
                (long long)(gl_internal::DispatchCount() - before));
  }
  double dd = 0, xx = 0;
  for (int64_t e = 0; e < P.M * P.n; ++e) {
    dd += (double(x[1][e]) - x[0][e]) * (double(x[1][e]) - x[0][e]);
    xx += double(x[0][e]) * x[0][e];
  }
  EXPECT_LE(std::sqrt(dd / xx), 1e-5);
  for (int f = 0; f < P.M; ++f) {
    EXPECT_TRUE(sums[1][f].converged) << sums[1][f].BriefReport();
    EXPECT_EQ(sums[1][f].iterations, sums[0][f].iterations) << f;
  }
}
}  // namespace
}  // namespace translume
