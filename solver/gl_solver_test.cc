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

}  // namespace
}  // namespace translume
