// SPDX-License-Identifier: MIT
// The gl backend of the polygrid relaxation: one compute-shader dispatch per step, rotating
// three fluence buffers (Section 5.2's radiance buffers I_A, I_B, and the iterate before them
// for Chebyshev's steps) in the solver's headless context.
#include <algorithm>
#include <bit>
#include <fmt/format.h>
#include <map>
#include <memory>
#include <string>

#include "render/diffusion.h"
#include "render/gl_internal.h"
#include "render/gl_shaders.h"
#include "solver/gl_api.h"
#include "solver/gl_context.h"
#include "solver/gl_profile.h"
#include "solver/status.h"

namespace translume {
namespace {

using gl::api;
using render_gl::Ssbo;

// Shader file per program, for TRANSLUME_GL_PROFILE's keys (solver/gl_profile.h).
std::map<GLuint, std::string> program_files;

}  // namespace

namespace render_gl {

namespace {

// Dispatches `threads` invocations of the program in use (buffers bound), then a barrier.
void DispatchBound(int64_t threads) {
  const int64_t groups = (threads + 255) / 256;
  const int64_t gx = std::min<int64_t>(groups, 65535), gy = (groups + gx - 1) / gx;
  gl::Profiler& profile = gl::Profiler::Get();  // (TRANSLUME_GL_PROFILE)
  if (profile.on()) profile.Before();
  api.DispatchCompute(GLuint(gx), GLuint(gy), 1);
  if (profile.on()) {
    GLint prog = 0;
    api.GetIntegerv(GL_CURRENT_PROGRAM, &prog);
    // (TRANSLUME_GL_PROFILE=gpu2 or 2: per level too, keyed by the invocations.)
    const std::string& file = program_files[GLuint(prog)];
    profile.After(profile.detailed() ? fmt::format("{} x {}", file, threads) : file);
  }
  api.MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
}

}  // namespace

GLuint Program(const std::string& file) {
  static std::map<std::string, GLuint> cache;
  if (auto it = cache.find(file); it != cache.end()) return it->second;
  auto embedded = [](const std::string& name) {
    for (int i = 0; i < gl::kNumRenderShaders; ++i)
      if (name == gl::kRenderShaders[i].name) return gl::kRenderShaders[i].source;
    TL_CHECK_MSG(false, name + " is not embedded");
    return "";
  };
  // A file without its own #version line gets "#version 430" and common.glsl before it (the
  // compiler's log then numbers the three strings 0, 1, 2).
  const char* source = embedded(file);
  const char* strings[3] = {"#version 430\n", embedded("render/shaders/common.glsl"), source};
  const bool standalone = std::string(source).find("#version") != std::string::npos;
  const GLuint sh = api.CreateShader(GL_COMPUTE_SHADER);
  if (standalone)
    api.ShaderSource(sh, 1, &source, nullptr);
  else
    api.ShaderSource(sh, 3, strings, nullptr);
  api.CompileShader(sh);
  GLint ok = 0;
  char log[4096] = "";
  api.GetShaderiv(sh, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    api.GetShaderInfoLog(sh, sizeof(log), nullptr, log);
    throw InputError(fmt::format("--backend gl: {}: compile error: {}", file, log));
  }
  const GLuint prog = api.CreateProgram();
  api.AttachShader(prog, sh);
  api.LinkProgram(prog);
  api.DeleteShader(sh);
  api.GetProgramiv(prog, GL_LINK_STATUS, &ok);
  if (!ok) {
    api.GetProgramInfoLog(prog, sizeof(log), nullptr, log);
    throw InputError(fmt::format("--backend gl: {}: link error: {}", file, log));
  }
  cache[file] = prog;
  program_files[prog] = file;
  return prog;
}

void Dispatch(std::initializer_list<const Ssbo*> buffers, int64_t threads) {
  if (threads <= 0) return;
  GLuint b = 0;
  for (const Ssbo* s : buffers) api.BindBufferBase(GL_SHADER_STORAGE_BUFFER, b++, s->id);
  DispatchBound(threads);
}

void Dispatch(std::initializer_list<GLuint> buffers, int64_t threads) {
  if (threads <= 0) return;
  GLuint b = 0;
  for (GLuint id : buffers) api.BindBufferBase(GL_SHADER_STORAGE_BUFFER, b++, id);
  DispatchBound(threads);
}

}  // namespace render_gl

namespace {

// The fluence and the boundary sources are RGB vec4s on the device (jacobi.comp).
constexpr size_t kVec4Bytes = 4 * sizeof(float);

// Per level: the rows (neighbours, weights over the diagonal), the boundary rows' source
// coefficients, q and sources, the active list, the prolongation from the coarser level, and
// three fluence buffers (the current one is phi[cur]).
class GlHierarchy : public HierarchyRelaxer {
 public:
  GlHierarchy() {
    GlContext::Get();
    jacobi_ = render_gl::Program("render/shaders/jacobi.comp");
    source_ = render_gl::Program("render/shaders/source.comp");
    prolong_ = render_gl::Program("render/shaders/prolong.comp");
    radiance_ = render_gl::Program("render/shaders/radiance.comp");
  }
  void Load(std::vector<Level> levels) override {
    dev_ = std::vector<Device>(levels.size());
    for (size_t l = 0; l < levels.size(); ++l) {
      const Level& v = levels[l];
      Device& d = dev_[l];
      d.size = v.size;
      d.num_interior = v.num_interior;
      TL_CHECK(int64_t(v.nb.size()) == v.size * 6 && int64_t(v.a.size()) == v.size * 18);
      // Entries as jacobi.comp reads them, (weight R, G, B as float bits, neighbour): k < 3 in
      // rows0 at k * size + n, the others in rows1 at (k - 3) * size + n, then the extra ones.
      const int64_t extras = int64_t(v.extra_nb.size());
      std::vector<int32_t> rows0(v.size * 3 * 4), rows1((v.size * 3 + extras) * 4);
      const auto put = [](std::vector<int32_t>* rows, int64_t j, int32_t neighbour, float r, float g, float b) {
        (*rows)[j * 4] = std::bit_cast<int32_t>(r);
        (*rows)[j * 4 + 1] = std::bit_cast<int32_t>(g);
        (*rows)[j * 4 + 2] = std::bit_cast<int32_t>(b);
        (*rows)[j * 4 + 3] = neighbour;
      };
      for (int64_t n = 0; n < v.size; ++n)
        for (int k = 0; k < 6; ++k)
          put(k < 3 ? &rows0 : &rows1, (k % 3) * v.size + n, v.nb[n * 6 + k], v.a[n * 18 + k], v.a[n * 18 + 6 + k],
              v.a[n * 18 + 12 + k]);
      for (int64_t e = 0; e < extras; ++e)
        put(&rows1, v.size * 3 + e, v.extra_nb[e], v.extra_a[e * 3], v.extra_a[e * 3 + 1], v.extra_a[e * 3 + 2]);
      // The largest buffers a shader binds (GL_MAX_SHADER_STORAGE_BLOCK_SIZE; 128 MiB on
      // llvmpipe, which a level of ~2 M nodes reaches): past it the shader would read zeros.
      const int64_t limit = GlContext::Get().info().max_ssbo_bytes, bytes = int64_t(rows1.size()) * 4;
      if (limit > 0 && bytes > limit)
        throw InputError(fmt::format("--backend gl: the polygrid's level of {} nodes needs a {:.0f} MiB buffer of "
                                     "relaxation rows, over this GL's limit of {:.0f} MiB "
                                     "(GL_MAX_SHADER_STORAGE_BLOCK_SIZE); use a lower resolution or --backend cpu",
                                     v.size, bytes / 1048576.0, limit / 1048576.0));
      d.rows0.Set(rows0);
      d.rows1.Set(rows1);
      if (!v.extra_start.empty()) {
        d.extra_rows = v.size;
        d.extra_start.Set(v.extra_start);
      }
      d.coef.Set(v.source_coef);
      d.q.Set(nullptr, v.source_coef.size() * sizeof(float));
      d.s.Set(nullptr, size_t(v.size - v.num_interior) * kVec4Bytes);
      d.s.Zero();
      d.active.Set(v.active);
      d.num_active = int64_t(v.active.size());
      d.rho = v.rho;
      d.tails = v.tails;
      d.p_start.Set(v.prolong.start);
      d.p_index.Set(v.prolong.index);
      d.p_weight.Set(v.prolong.weight);
      for (Ssbo& b : d.phi) b.Set(nullptr, size_t(d.size) * kVec4Bytes);
    }
    if (!levels.empty() && !levels[0].radiance_scale.empty()) radiance_scale_.Set(levels[0].radiance_scale);
  }
  void SetSource(int l, const BoundaryLight& q) override {
    Device& d = dev_[l];
    const int64_t nb = d.size - d.num_interior;
    host_q_.resize(nb * 3);
    for (int64_t b = 0; b < nb; ++b)
      for (int c = 0; c < 3; ++c) host_q_[b * 3 + c] = q[c][b];
    d.q.Set(host_q_);
    SetSource(l, DeviceFloats{d.q.id, 0});
  }
  void SetSource(int l, DeviceFloats q) override {
    Device& d = dev_[l];
    const int64_t nb = d.size - d.num_interior;
    api.UseProgram(source_);
    api.Uniform1i(0, int(nb));
    api.Uniform1i(1, int(q.first));
    render_gl::Dispatch({q.buffer, d.coef.id, d.s.id}, nb);
  }
  void WriteShadedRadiance(DeviceFloats out) override {
    TL_CHECK_MSG(radiance_scale_.id != 0, "no radiance_scale loaded for the finest level");
    const Device& d = dev_[0];
    const int64_t nb = d.size - d.num_interior;
    api.UseProgram(radiance_);
    api.Uniform1i(0, int(nb));
    api.Uniform1i(1, int(d.num_interior));
    api.Uniform1i(2, int(out.first));
    render_gl::Dispatch({d.phi[d.cur].id, radiance_scale_.id, out.buffer}, nb);
  }
  void Zero(int l) override { Start(l, false); }
  void Prolong(int l) override { Start(l, true); }
  void Relax(int l, bool adaptive, int iterations, bool repeated) override {
    Device& d = dev_[l];
    const int64_t count = adaptive ? d.num_active : d.size;
    if (count == 0) return;
    api.UseProgram(jacobi_);
    api.Uniform1i(0, int(count));
    api.Uniform1i(1, int(d.num_interior));
    api.Uniform1i(2, adaptive ? 1 : 0);
    api.Uniform1i(5, int(d.extra_rows));
    api.Uniform1i(6, int(d.size));
    // Without the list (or the extra entries) the shader never reads binding 3 (or 0); the
    // rows stand in for them.
    const Ssbo& list = adaptive ? d.active : d.rows0;
    const Ssbo& extra_start = d.extra_rows > 0 ? d.extra_start : d.rows0;
    // phi[cur] is the iterate, phi[cur + 2] the one before it (read by Chebyshev's steps from
    // the second on) and phi[cur + 1] the next; all three agree outside the updated nodes.
    ChebyshevSchedule schedule(d.rho, iterations, repeated || d.tails);
    for (int it = 0; it < iterations; ++it) {
      const std::array<float, 3> w = schedule.Next();
      const bool jacobi = ChebyshevSchedule::IsJacobi(w);
      api.Uniform1i(3, jacobi ? 0 : 1);
      api.Uniform3f(4, w[0], w[1], w[2]);
      const Ssbo &cur = d.phi[d.cur], &next = d.phi[(d.cur + 1) % 3], &prev = d.phi[(d.cur + 2) % 3];
      render_gl::Dispatch({&extra_start, &d.rows0, &d.s, &list, &cur, &next, &prev, &d.rows1}, count);
      d.cur = (d.cur + 1) % 3;
    }
    api.Flush();  // the GPU starts on the level's steps while the host issues what follows
  }
  void Read(int l, int64_t first_row, std::vector<float>* phi) override {
    const Device& d = dev_[l];
    TL_CHECK(int64_t(phi->size()) == d.size * 3);
    host_phi_.resize(size_t(d.size - first_row) * 4);
    d.phi[d.cur].Get(host_phi_.data(), host_phi_.size() * sizeof(float), size_t(first_row) * kVec4Bytes);
    for (int64_t n = first_row; n < d.size; ++n)
      for (int c = 0; c < 3; ++c) (*phi)[n * 3 + c] = host_phi_[(n - first_row) * 4 + c];
  }

 private:
  struct Device {
    int64_t size = 0, num_interior = 0, num_active = 0, extra_rows = 0;  // extra_rows: 0 without extra entries
    int cur = 0;
    Ssbo rows0, rows1, extra_start, coef, q, s, active, p_start, p_index, p_weight, phi[3];
    std::array<double, 3> rho{};
    bool tails = false;
  };
  // Sets the level's three fluence buffers in one dispatch of prolong.comp (no copies, no
  // clears): prolonged from the next coarser level's current one, or zeros.
  void Start(int l, bool prolong) {
    Device& d = dev_[l];
    api.UseProgram(prolong_);
    api.Uniform1i(0, int(d.size));
    api.Uniform1i(1, prolong ? 0 : 1);
    if (prolong) {
      const Device& coarse = dev_[l + 1];
      render_gl::Dispatch(
          {&d.p_start, &d.p_index, &d.p_weight, &coarse.phi[coarse.cur], &d.phi[0], &d.phi[1], &d.phi[2]}, d.size);
    } else {
      const Ssbo& any = d.phi[0];  // (bindings 0-3, unread)
      render_gl::Dispatch({&any, &any, &any, &any, &d.phi[0], &d.phi[1], &d.phi[2]}, d.size);
    }
  }

  GLuint jacobi_ = 0, source_ = 0, prolong_ = 0, radiance_ = 0;
  std::vector<Device> dev_;
  Ssbo radiance_scale_;
  std::vector<float> host_q_, host_phi_;
};

}  // namespace

std::unique_ptr<HierarchyRelaxer> MakeGlHierarchy() { return std::make_unique<GlHierarchy>(); }

}  // namespace translume
