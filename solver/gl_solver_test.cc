// SPDX-License-Identifier: MIT
#include "solver/gl_solver.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "solver/gl_context.h"
#include "solver/status.h"

namespace translume {
namespace {

TEST(GlContext, ReportsACompute43Context) {
  const GlInfo& info = GlContext::Get().info();
  EXPECT_FALSE(info.renderer.empty());
  EXPECT_GE(info.max_work_group_invocations, 256);
  EXPECT_GE(info.max_work_group_count[0], 65535);
}

TEST(GlSolver, ShaderCompileErrorsNameTheFileAndLine) {
  try {
    CompileGlShaderForTest("solver/shaders/broken.comp",
                           "// a comment\nvoid main() {\n  undefined_thing = 1.0;\n}\n");
    FAIL() << "compiled a broken shader";
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("solver/shaders/broken.comp:3"), std::string::npos) << msg;
    EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
  }
  EXPECT_NO_THROW(CompileGlShaderForTest("ok.comp", "void main() {}\n"));
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
  // A warm start from the solution converges at once.
  const SolveSummary warm = gl.Solve(b.data(), x.data());
  EXPECT_LE(warm.iterations, 1);
}

// A batch of different right-hand sides (back light, a front spot, a smooth interior source
// from a nonzero initial guess, a zero field, a 1e3 times larger one) gives each field what its
// own solve gives: the same iterations, the same x within the solver's tolerance, and a true
// residual (recomputed here in double) below the tolerance for every field.
TEST(GlSolver, BatchedSolveMatchesSingleSolvesAndConvergesEveryField) {
  const GridShape s{24, 18, 10};
  const int64_t n = s.size();
  const int M = 5;
  std::vector<float> kappa(n), mu(n), b(M * n, 0.0f), x0(M * n, 0.0f);
  for (int64_t p = 0; p < n; ++p) {
    kappa[p] = 0.2f + 0.1f * std::sin(0.05f * p);
    mu[p] = 0.02f + 0.01f * std::cos(0.03f * p);
  }
  for (int64_t f = 0; f < s.face_size(); ++f) b[f + n - s.face_size()] = 0.01f;  // back light
  b[n + s.index(5, 4, 0)] = 1.0f;                                                  // spot
  for (int64_t p = 0; p < n; ++p) {
    b[2 * n + p] = 0.001f * (1.0f + std::sin(0.2f * p));
    x0[2 * n + p] = 0.05f * std::cos(0.1f * p);
  }
  for (int64_t p = 0; p < n; ++p) b[4 * n + p] = 1e3f * b[n + p];  // field 3 stays zero
  MultigridOptions mo;
  mo.tolerance = 1e-6;
  GlMultigridSolver gl(s, 0.5, mo);
  gl.SetCoefficients(kappa.data(), mu.data(), 2.6);
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

}  // namespace
}  // namespace translume
