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

#include "solver/gl_api.h"
#include "solver/gl_context.h"
#include "solver/gl_shaders.h"
#include "solver/multigrid_hierarchy.h"
#include "solver/status.h"

namespace translume {
namespace {

using gl::api;

class Buffer {
 public:
  Buffer() = default;
  Buffer(const Buffer&) = delete;
  ~Buffer() {
    if (id_) api.DeleteBuffers(1, &id_);
  }
  void Alloc(int64_t bytes, const void* data = nullptr) {
    if (!id_) api.GenBuffers(1, &id_);
    bytes_ = std::max<int64_t>(bytes, 16);
    api.BindBuffer(GL_SHADER_STORAGE_BUFFER, id_);
    api.BufferData(GL_SHADER_STORAGE_BUFFER, bytes_, data, GL_DYNAMIC_DRAW);
  }
  void Upload(const void* data, int64_t bytes) {
    api.BindBuffer(GL_SHADER_STORAGE_BUFFER, id_);
    api.BufferSubData(GL_SHADER_STORAGE_BUFFER, 0, bytes, data);
  }
  void Download(void* data, int64_t bytes) const {
    api.MemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    api.BindBuffer(GL_SHADER_STORAGE_BUFFER, id_);
    api.GetBufferSubData(GL_SHADER_STORAGE_BUFFER, 0, bytes, data);
  }
  void Zero() {
    api.BindBuffer(GL_SHADER_STORAGE_BUFFER, id_);
    api.ClearBufferData(GL_SHADER_STORAGE_BUFFER, GL_R32F, GL_RED, GL_FLOAT, nullptr);
  }
  void CopyFrom(const Buffer& src, int64_t bytes) {
    api.BindBuffer(GL_COPY_READ_BUFFER, src.id_);
    api.BindBuffer(GL_COPY_WRITE_BUFFER, id_);
    api.CopyBufferSubData(GL_COPY_READ_BUFFER, GL_COPY_WRITE_BUFFER, 0, 0, bytes);
  }
  GLuint id() const { return id_; }

 private:
  GLuint id_ = 0;
  int64_t bytes_ = 0;
};

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
GLuint Program(const std::string& name, const std::string& defines = "") {
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
            std::initializer_list<int> ints, int64_t threads, int float_location = -1,
            float float_value = 0, const char* defines = "") {
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

struct AxisBuffers {
  Buffer gstart, gidx, gw, lohi, w;
  int n_fine = 0, n_coarse = 0;
  void Upload(const AxisTransfer& t) {
    n_fine = int(t.n_fine);
    n_coarse = int(t.n_coarse);
    std::vector<int> gs(t.g_start.begin(), t.g_start.end()), gi(t.g_idx.begin(), t.g_idx.end());
    std::vector<float> gwf(t.g_w.begin(), t.g_w.end());
    std::vector<int> lh(2 * t.n_fine);
    std::vector<float> wf(2 * t.n_fine);
    for (int64_t f = 0; f < t.n_fine; ++f) {
      lh[2 * f] = int(t.lo[f]);
      lh[2 * f + 1] = int(t.hi[f]);
      wf[2 * f] = float(t.wlo[f]);
      wf[2 * f + 1] = float(t.whi[f]);
    }
    gstart.Alloc(gs.size() * 4, gs.data());
    gidx.Alloc(gi.size() * 4, gi.data());
    gw.Alloc(gwf.size() * 4, gwf.data());
    lohi.Alloc(lh.size() * 4, lh.data());
    w.Alloc(wf.size() * 4, wf.data());
  }
};

struct GLevel {
  MultigridLevel geo;
  GridShape s;
  int64_t n = 0;
  Buffer geometry, kappa, mu, cx, cy, cz, diag, inv, luc, b, x, r, rnorm, tmp_a, tmp_b;
  std::array<AxisBuffers, 3> t;
};

}  // namespace

void CompileGlShaderForTest(const std::string& file_name, const std::string& source) {
  GlContext::Get();
  const GLuint program =
      CompileProgram(FindShader("solver/shaders/common.glsl"), "", file_name, source.c_str());
  api.DeleteProgram(program);
}

struct GlMultigridSolver::Impl {
  MultigridOptions options;
  std::vector<std::unique_ptr<GLevel>> levels;
  Buffer r, z, p, q, partial, result;
  Buffer xd;  // the conjugate-gradient iterate, double
  Buffer coarse_inverse;  // dense inverse of the coarsest operator (when small enough)
  bool dense_coarse = false;
  int64_t n0 = 0;
  int coarse_sweeps = 8;

  void Restrict(GLevel& L, const Buffer& f, Buffer& c) {
    const int ny = int(L.s.ny), nz = int(L.s.nz), mx = L.t[0].n_coarse, my = L.t[1].n_coarse;
    auto pass = [&](const AxisBuffers& a, const Buffer& in, Buffer& out, int inner, int outer) {
      Run("restrict_axis", {&in, &out, &a.gstart, &a.gidx, &a.gw},
          {a.n_fine, a.n_coarse, inner, outer}, int64_t(outer) * a.n_coarse * inner);
    };
    pass(L.t[0], f, L.tmp_a, 1, ny * nz);
    pass(L.t[1], L.tmp_a, L.tmp_b, mx, nz);
    pass(L.t[2], L.tmp_b, c, mx * my, 1);
  }

  void ProlongAdd(GLevel& L, const Buffer& c, Buffer& f) {
    const int ny = int(L.s.ny), nz = int(L.s.nz), mx = L.t[0].n_coarse, my = L.t[1].n_coarse;
    auto pass = [&](const AxisBuffers& a, const Buffer& in, Buffer& out, int inner, int outer,
                    int add) {
      Run("prolong_axis", {&in, &out, &a.lohi, &a.w}, {a.n_coarse, a.n_fine, inner, outer, add},
          int64_t(outer) * a.n_fine * inner);
    };
    pass(L.t[2], c, L.tmp_b, mx * my, 1, 0);
    pass(L.t[1], L.tmp_b, L.tmp_a, mx, nz, 0);
    pass(L.t[0], L.tmp_a, f, 1, ny * nz, 1);
  }

  void Smooth(GLevel& L, const Buffer& b, Buffer& x, int color) {
    const int half = int((L.s.nx + 1) / 2);
    Run("smooth", {&L.cx, &L.cy, &L.cz, &L.inv, &L.luc, &b, &x},
        {int(L.s.nx), int(L.s.ny), int(L.s.nz), color}, int64_t(half) * L.s.ny);
  }

  void Stencil(GLevel& L, const Buffer& x, const Buffer& b, Buffer& out, int mode,
               bool x_double = false) {
    Run("residual", {&L.cx, &L.cy, &L.cz, &L.diag, &x, &b, &out},
        {int(L.s.nx), int(L.s.ny), int(L.s.nz), mode}, L.n, -1, 0,
        x_double ? "#define X_DOUBLE\n" : "");
  }

  void VCycle(size_t l, const Buffer& b, Buffer& x) {
    GLevel& L = *levels[l];
    x.Zero();
    if (l + 1 == levels.size()) {
      if (dense_coarse) {
        Run("dense_solve", {&coarse_inverse, &b, &x}, {int(L.n)}, L.n);
        return;
      }
      for (int s = 0; s < coarse_sweeps; ++s) {
        Smooth(L, b, x, 0);
        Smooth(L, b, x, 1);
        Smooth(L, b, x, 1);
        Smooth(L, b, x, 0);
      }
      return;
    }
    for (int s = 0; s < options.pre_smoothing; ++s) {
      Smooth(L, b, x, 0);
      Smooth(L, b, x, 1);
    }
    Stencil(L, x, b, L.r, 0);
    GLevel& C = *levels[l + 1];
    Restrict(L, L.r, C.b);
    VCycle(l + 1, C.b, C.x);
    ProlongAdd(L, C.x, x);
    for (int s = 0; s < options.post_smoothing; ++s) {
      Smooth(L, b, x, 1);
      Smooth(L, b, x, 0);
    }
  }

  // Dots into result[slot] (double); read with ReadResults.
  void Dot(const Buffer& a, const Buffer& b, int slot) {
    const int64_t m = Run("dot", {&a, &b, &partial}, {int(n0)}, n0);
    Run("reduce", {&partial, &result}, {int(m), slot}, 256);
  }
  void ReadResults(double* out, int count) { result.Download(out, count * 8); }
};

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

SolveSummary GlMultigridSolver::Solve(const float* b_host, float* x_host) {
  const auto t0 = std::chrono::steady_clock::now();
  Impl& I = *impl_;
  GLevel& L = *I.levels[0];
  const int64_t n = I.n0;
  // b lives in the finest level's b buffer; the iterate in double (see residual.comp).
  Buffer& b = L.b;
  Buffer& x = I.xd;
  b.Upload(b_host, n * 4);
  {
    std::vector<double> x0(x_host, x_host + n);
    x.Upload(x0.data(), n * 8);
  }
  SolveSummary sum;
  double v[2];
  I.Dot(b, b, 0);
  I.Stencil(L, x, b, I.r, 0, true);
  I.Dot(I.r, I.r, 1);
  I.ReadResults(v, 2);
  const double bnorm = std::sqrt(v[0]);
  auto finish = [&](bool converged, std::string message) {
    I.Stencil(L, x, b, I.r, 0, true);
    I.Dot(I.r, I.r, 0);
    double rr;
    I.ReadResults(&rr, 1);
    sum.final_residual = bnorm > 0 ? std::sqrt(rr) / bnorm : 0.0;
    sum.converged = converged;
    sum.message = std::move(message);
    std::vector<double> xh(n);
    x.Download(xh.data(), n * 8);
    for (int64_t i = 0; i < n; ++i) x_host[i] = float(xh[i]);
    sum.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return sum;
  };
  if (bnorm == 0) {
    std::vector<double> zeros(n, 0.0);
    x.Upload(zeros.data(), n * 8);
    return finish(true, "zero right-hand side");
  }
  sum.initial_residual = std::sqrt(v[1]) / bnorm;
  if (sum.initial_residual <= I.options.tolerance) return finish(true, "");
  const double tol = I.options.tolerance * bnorm;
  int restarts = 0;
  double rz = 0;
  auto restart = [&]() {
    I.VCycle(0, I.r, I.z);
    I.p.CopyFrom(I.z, n * 4);
    I.Dot(I.r, I.z, 0);
    I.ReadResults(&rz, 1);
  };
  restart();
  while (sum.iterations < I.options.max_iterations) {
    I.Stencil(L, I.p, I.p, I.q, 1);
    I.Dot(I.p, I.q, 0);
    double pq;
    I.ReadResults(&pq, 1);
    const float alpha = float(rz / pq);
    Run("vector_ops", {&x, &I.r, &I.p, &I.q}, {int(n), 0}, n, 2, alpha, "#define X_DOUBLE\n");
    ++sum.iterations;
    // Precondition before looking at the residual: one read-back per iteration for both dots.
    I.VCycle(0, I.r, I.z);
    I.Dot(I.r, I.r, 0);
    I.Dot(I.r, I.z, 1);
    I.ReadResults(v, 2);
    if (std::sqrt(v[0]) <= tol) {
      I.Stencil(L, x, b, I.r, 0, true);
      I.Dot(I.r, I.r, 0);
      double rr;
      I.ReadResults(&rr, 1);
      if (std::sqrt(rr) <= tol) return finish(true, "");
      if (++restarts > 3) return finish(false, "stagnated at the precision of float");
      restart();
      continue;
    }
    const double beta = v[1] / rz;
    rz = v[1];
    Run("vector_ops", {&I.p, &I.z, &I.z, &I.z}, {int(n), 1}, n, 2, float(beta));
  }
  return finish(false, fmt::format("reached max_iterations = {}", I.options.max_iterations));
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
