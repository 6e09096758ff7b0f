// SPDX-License-Identifier: MIT
#include "solver/gl_solver.h"

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fmt/format.h>
#include <map>
#include <sstream>

#include "solver/gl_internal.h"
#include "solver/gl_context.h"
#include "solver/gl_shaders.h"
#include "solver/multigrid_hierarchy.h"
#include "solver/status.h"

namespace translume {namespace gl_internal {

// Lines of common.glsl are numbered from kCommonLine on, the file's from 1 (see
// CompileProgram), so a log line "0:12(5): error" (Mesa) or "0(12) : error" (NVIDIA) can name its
// file: "solver/shaders/smooth.comp:12(5): error ...".
constexpr int kCommonLine = 100000;

std::string NameLog(const std::string& log, const std::string& common, const std::string& file) {
  std::istringstream in(log);
  std::string line, out;
  while (std::getline(in, line)) {
    int string_no = 0, number = 0, used = 0;
    if (std::sscanf(line.c_str(), "%d:%d%n", &string_no, &number, &used) == 2 ||
        std::sscanf(line.c_str(), "%d(%d)%n", &string_no, &number, &used) == 2) {
      const bool in_common = number >= kCommonLine;
      line = fmt::format("{}:{}{}", in_common ? common : file,
                         in_common ? number - kCommonLine + 1 : number, line.substr(used));
    }
    out += line + (in.peek() == EOF ? "" : " | ");
  }
  return out;
}

// Compiles and links one compute program from common.glsl, `defines` and the file's text.
GLuint CompileProgram(const gl::EmbeddedShader& common, const std::string& defines,
                      const std::string& file_name, const char* source) {
  GLuint shader = api.CreateShader(GL_COMPUTE_SHADER);
  const std::string text = fmt::format("#version 430\n#line {}\n{}{}#line 1\n{}", kCommonLine,
                                       common.source, defines, source);
  const char* sources[1] = {text.c_str()};
  api.ShaderSource(shader, 1, sources, nullptr);
  api.CompileShader(shader);
  GLint ok = 0;
  api.GetShaderiv(shader, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    char log[8192];
    api.GetShaderInfoLog(shader, sizeof(log), nullptr, log);
    api.DeleteShader(shader);
    throw InputError(fmt::format("--backend gl: compiling {} failed: {}", file_name,
                                 NameLog(log, common.name, file_name)));
  }
  GLuint program = api.CreateProgram();
  api.AttachShader(program, shader);
  api.LinkProgram(program);
  api.DeleteShader(shader);
  api.GetProgramiv(program, GL_LINK_STATUS, &ok);
  if (!ok) {
    char log[8192];
    api.GetProgramInfoLog(program, sizeof(log), nullptr, log);
    throw InputError(fmt::format("--backend gl: linking {} failed: {}", file_name, log));
  }
  return program;
}

const gl::EmbeddedShader& FindShader(const std::string& name) {
  for (int s = 0; s < gl::kNumEmbeddedShaders; ++s)
    if (name == gl::kEmbeddedShaders[s].name) return gl::kEmbeddedShaders[s];
  TL_CHECK_MSG(false, "shader " + name + " is not embedded");
  std::abort();
}

// The program of solver/shaders/NAME.comp, compiled once with `defines` (e.g. "#define X\n").
GLuint Program(const std::string& name, const std::string& defines) {
  static std::map<std::string, GLuint> cache;
  if (auto it = cache.find(name + defines); it != cache.end()) return it->second;
  const gl::EmbeddedShader& file = FindShader("solver/shaders/" + name + ".comp");
  const GLuint program =
      CompileProgram(FindShader("solver/shaders/common.glsl"), defines, file.name, file.source);
  cache[name + defines] = program;
  return program;
}

// Binds `buffers` to bindings 0.., sets int uniforms at locations 0.., and dispatches
// `threads` threads (256 per group, tiled to stay under 65535 groups per dimension).
// Returns the number of work groups.
int64_t Run(const char* name, std::initializer_list<const Buffer*> buffers,
            std::initializer_list<int> ints, int64_t threads, int float_location,
            float float_value, const char* defines) {
  const GLuint prog = Program(name, defines);
  api.UseProgram(prog);
  GLuint b = 0;
  for (const Buffer* buf : buffers) api.BindBufferBase(GL_SHADER_STORAGE_BUFFER, b++, buf->id());
  GLint loc = 0;
  for (int v : ints) api.Uniform1i(loc++, v);
  if (float_location >= 0) api.Uniform1f(float_location, float_value);
  const int64_t groups = std::max<int64_t>(1, (threads + 255) / 256);
  const int64_t gx = std::min<int64_t>(groups, 65535), gy = (groups + gx - 1) / gx;
  api.DispatchCompute(GLuint(gx), GLuint(gy), 1);
  api.MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
  return gx * gy;
}

}  // namespace gl_internal

using gl::api;
using gl_internal::CompileProgram;
using gl_internal::FindShader;

void CompileGlShaderForTest(const std::string& file_name, const std::string& source) {
  GlContext::Get();
  const GLuint program =
      CompileProgram(FindShader("solver/shaders/common.glsl"), "", file_name, source.c_str());
  api.DeleteProgram(program);
}


GlMultigridSolver::GlMultigridSolver(const GridShape& shape, double h, const MultigridOptions& options)
    : impl_(std::make_unique<Impl>()) {
  if (std::string err = options.Validate(); !err.empty())
    throw InputError("multigrid options: " + err);
  if (shape.size() >= (int64_t(1) << 31))
    throw InputError(fmt::format("--backend gl: grid {} has 2^31 nodes or more; use --backend cpu",
                                 shape.ToString()));
  GlContext::Get();
  Impl& I = *impl_;
  I.options = options;
  I.n0 = shape.size();
  for (MultigridLevel& geo : BuildMultigridHierarchy(shape, h, 64)) {
    auto L = std::make_unique<GLevel>();
    L->geo = std::move(geo);
    L->s = L->geo.grid.shape;
    L->n = L->s.size();
    I.levels.push_back(std::move(L));
  }
  for (size_t l = 0; l < I.levels.size(); ++l) {
    GLevel& L = *I.levels[l];
    const int64_t bytes = L.n * 4;
    std::vector<float> geo;
    for (int a = 0; a < 3; ++a)
      for (int64_t i = 0; i < L.s.n(a); ++i) geo.push_back(float(L.geo.grid.Width(a, i)));
    for (int a = 0; a < 3; ++a)
      for (int64_t i = 0; i < L.s.n(a); ++i)
        geo.push_back(i + 1 < L.s.n(a) ? float(L.geo.grid.Gap(a, i)) : 1.0f);
    L.geometry.Alloc(geo.size() * 4, geo.data());
    for (Buffer* b : {&L.kappa, &L.mu, &L.cx, &L.cy, &L.cz, &L.diag, &L.inv, &L.luc, &L.b, &L.x, &L.r})
      b->Alloc(bytes);
    if (l + 1 < I.levels.size()) {
      for (int a = 0; a < 3; ++a) L.t[a].Upload(L.geo.to_coarse[a]);
      const int64_t mx = L.t[0].n_coarse, my = L.t[1].n_coarse;
      L.tmp_a.Alloc(mx * L.s.ny * L.s.nz * 4);
      L.tmp_b.Alloc(mx * my * L.s.nz * 4);
    }
    if (l > 0) {
      // R applied to ones from the finer level: the weights that make restricted kappa and mu
      // averages.
      GLevel& F = *I.levels[l - 1];
      std::vector<float> ones(F.n, 1.0f);
      std::vector<float> rn(L.n), ta(F.t[0].n_coarse * F.s.ny * F.s.nz),
          tb(F.t[0].n_coarse * F.t[1].n_coarse * F.s.nz);
      Restrict3(F.geo, ones.data(), rn.data(), ta.data(), tb.data());
      L.rnorm.Alloc(bytes, rn.data());
    }
  }
  for (Buffer* b : {&I.r, &I.z, &I.p, &I.q}) b->Alloc(I.n0 * 4);
  I.xd.Alloc(I.n0 * 8);
  I.partial.Alloc(((I.n0 + 255) / 256 + 1) * 8);
  I.result.Alloc(8 * 8);
}

GlMultigridSolver::~GlMultigridSolver() = default;

int GlMultigridSolver::num_levels() const { return int(impl_->levels.size()); }

void GlMultigridSolver::SetCoefficients(const float* kappa, const float* mu, double C) {
  Impl& I = *impl_;
  for (size_t l = 0; l < I.levels.size(); ++l) {
    GLevel& L = *I.levels[l];
    if (l == 0) {
      L.kappa.Upload(kappa, L.n * 4);
      L.mu.Upload(mu, L.n * 4);
    } else {
      GLevel& F = *I.levels[l - 1];
      I.Restrict(F, F.kappa, L.kappa);
      I.Restrict(F, F.mu, L.mu);
      Run("vector_ops", {&L.kappa, &L.rnorm, &L.rnorm, &L.rnorm}, {int(L.n), 2}, L.n);
      Run("vector_ops", {&L.mu, &L.rnorm, &L.rnorm, &L.rnorm}, {int(L.n), 2}, L.n);
    }
    Run("assemble", {&L.kappa, &L.mu, &L.geometry, &L.cx, &L.cy, &L.cz, &L.diag},
        {int(L.s.nx), int(L.s.ny), int(L.s.nz)}, L.n, 3, float(1.0 / (2.0 * C)));
    Run("factor", {&L.cz, &L.diag, &L.inv, &L.luc}, {int(L.s.nx), int(L.s.ny), int(L.s.nz)},
        L.s.nx * L.s.ny);
  }
  // The coarsest level: an exact dense inverse when it is small (one dispatch per V-cycle
  // instead of many sweeps); the few values travel to the host and back once per update.
  GLevel& Lc = *I.levels.back();
  I.dense_coarse = Lc.n <= 1024;
  if (I.dense_coarse) {
    const int64_t n = Lc.n;
    const GridShape& s = Lc.s;
    std::vector<float> cx(n), cy(n), cz(n), dg(n);
    Lc.cx.Download(cx.data(), n * 4);
    Lc.cy.Download(cy.data(), n * 4);
    Lc.cz.Download(cz.data(), n * 4);
    Lc.diag.Download(dg.data(), n * 4);
    Eigen::MatrixXd M = Eigen::MatrixXd::Zero(n, n);
    for (int64_t k = 0; k < s.nz; ++k)
      for (int64_t j = 0; j < s.ny; ++j)
        for (int64_t i = 0; i < s.nx; ++i) {
          const int64_t p = s.index(i, j, k);
          M(p, p) = dg[p];
          auto couple = [&](int64_t q, float c) { M(p, q) = M(q, p) = -double(c); };
          if (i + 1 < s.nx) couple(p + 1, cx[p]);
          if (j + 1 < s.ny) couple(p + s.nx, cy[p]);
          if (k + 1 < s.nz) couple(p + s.nx * s.ny, cz[p]);
        }
    const Eigen::MatrixXd inv = M.llt().solve(Eigen::MatrixXd::Identity(n, n));
    std::vector<float> f(n * n);
    for (int64_t r = 0; r < n; ++r)
      for (int64_t c = 0; c < n; ++c) f[r * n + c] = float(inv(r, c));
    I.coarse_inverse.Alloc(n * n * 4, f.data());
  }
}

void GlMultigridSolver::Apply(const float* x, float* y) {
  Impl& I = *impl_;
  GLevel& L = *I.levels[0];
  L.x.Upload(x, L.n * 4);
  I.Stencil(L, L.x, L.x, I.q, 1);
  I.q.Download(y, L.n * 4);
}

SolveSummary GlMultigridSolver::Impl::SolveDevice(const Buffer& b, Buffer& x) {
  const auto t0 = std::chrono::steady_clock::now();
  GLevel& L = *levels[0];
  const int64_t n = n0;
  SolveSummary sum;
  double v[2];
  Dot(b, b, 0);
  Stencil(L, x, b, r, 0, true);
  Dot(r, r, 1);
  ReadResults(v, 2);
  const double bnorm = std::sqrt(v[0]);
  // `rr`: ||b - A x||^2 if the caller has just computed it, else < 0.
  auto finish = [&](bool converged, std::string message, double rr = -1) {
    if (rr < 0) {
      Stencil(L, x, b, r, 0, true);
      Dot(r, r, 0);
      ReadResults(&rr, 1);
    }
    sum.final_residual = bnorm > 0 ? std::sqrt(rr) / bnorm : 0.0;
    sum.converged = converged;
    sum.message = std::move(message);
    sum.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return sum;
  };
  if (bnorm == 0) {
    std::vector<double> zeros(n, 0.0);
    x.Upload(zeros.data(), n * 8);
    return finish(true, "zero right-hand side", 0.0);
  }
  sum.initial_residual = std::sqrt(v[1]) / bnorm;
  if (sum.initial_residual <= options.tolerance) return finish(true, "", v[1]);
  const double tol = options.tolerance * bnorm;
  int restarts = 0;
  double rz = 0;
  auto restart = [&]() {
    VCycle(0, r, z);
    p.CopyFrom(z, n * 4);
    Dot(r, z, 0);
    ReadResults(&rz, 1);
  };
  restart();
  while (sum.iterations < options.max_iterations) {
    Stencil(L, p, p, q, 1);
    Dot(p, q, 0);
    double pq;
    ReadResults(&pq, 1);
    const float alpha = float(rz / pq);
    Run("vector_ops", {&x, &r, &p, &q}, {int(n), 0}, n, 2, alpha, "#define X_DOUBLE\n");
    ++sum.iterations;
    // Precondition before looking at the residual: one read-back per iteration for both dots.
    VCycle(0, r, z);
    Dot(r, r, 0);
    Dot(r, z, 1);
    ReadResults(v, 2);
    sum.history.push_back(std::sqrt(v[0]) / bnorm);
    if (std::sqrt(v[0]) <= tol) {
      Stencil(L, x, b, r, 0, true);
      Dot(r, r, 0);
      double rr;
      ReadResults(&rr, 1);
      if (std::sqrt(rr) <= tol) return finish(true, "", rr);
      if (++restarts > 3) return finish(false, "stagnated", rr);
      restart();
      continue;
    }
    const double beta = v[1] / rz;
    rz = v[1];
    Run("vector_ops", {&p, &z, &z, &z}, {int(n), 1}, n, 2, float(beta));
  }
  return finish(false, fmt::format("reached max_iterations = {}", options.max_iterations));
}

SolveSummary GlMultigridSolver::Solve(const float* b_host, float* x_host) {
  const auto t0 = std::chrono::steady_clock::now();
  Impl& I = *impl_;
  const int64_t n = I.n0;
  // b lives in the finest level's b buffer; the iterate in double (see residual.comp).
  I.levels[0]->b.Upload(b_host, n * 4);
  std::vector<double> xd(x_host, x_host + n);
  I.xd.Upload(xd.data(), n * 8);
  SolveSummary sum = I.SolveDevice(I.levels[0]->b, I.xd);
  I.xd.Download(xd.data(), n * 8);
  for (int64_t i = 0; i < n; ++i) x_host[i] = float(xd[i]);
  sum.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return sum;
}

double GlMultigridSolver::TimeApply(int repetitions) {
  Impl& I = *impl_;
  GLevel& L = *I.levels[0];
  std::vector<double> times;
  api.Finish();
  for (int r = 0; r < repetitions; ++r) {
    const auto t0 = std::chrono::steady_clock::now();
    for (int k = 0; k < 10; ++k) I.Stencil(L, L.x, L.x, I.q, 1);
    api.Finish();
    times.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() / 10);
  }
  std::sort(times.begin(), times.end());
  return times[times.size() / 2];
}

double GlMultigridSolver::TimeCopy(int64_t bytes, int repetitions) {
  Buffer src, dst;
  const int64_t n4 = bytes / 16;
  src.Alloc(n4 * 16);
  dst.Alloc(n4 * 16);
  src.Zero();
  std::vector<double> times;
  api.Finish();
  for (int r = 0; r < repetitions; ++r) {
    const auto t0 = std::chrono::steady_clock::now();
    for (int k = 0; k < 10; ++k) Run("copy", {&src, &dst}, {int(n4)}, n4);
    api.Finish();
    times.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() / 10);
  }
  std::sort(times.begin(), times.end());
  return times[times.size() / 2];
}

int64_t GlMultigridSolver::ApplyBytes() const { return impl_->n0 * 4 * 6; }

}  // namespace translume
