// SPDX-License-Identifier: MIT
// The gl backend of the polygrid relaxation: one compute-shader dispatch per step, ping-ponging
// two fluence buffers (Section 5.2's radiance buffers I_A, I_B) in the solver's headless context.
#include <algorithm>
#include <fmt/format.h>
#include <memory>

#include "render/diffusion.h"
#include "render/gl_shaders.h"
#include "solver/gl_api.h"
#include "solver/gl_context.h"
#include "solver/status.h"

namespace translume {
namespace {

using gl::api;

GLuint CompileRenderShader(const std::string& file) {
  static std::string cached_name;
  static GLuint cached = 0;
  if (cached && cached_name == file) return cached;
  const gl::EmbeddedShader* src = nullptr;
  for (int i = 0; i < gl::kNumRenderShaders; ++i)
    if (file == gl::kRenderShaders[i].name) src = &gl::kRenderShaders[i];
  TL_CHECK_MSG(src, file + " is not embedded");
  const GLuint sh = api.CreateShader(GL_COMPUTE_SHADER);
  api.ShaderSource(sh, 1, &src->source, nullptr);
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
  cached_name = file;
  cached = prog;
  return prog;
}

struct Ssbo {
  GLuint id = 0;
  ~Ssbo() {
    if (id) api.DeleteBuffers(1, &id);
  }
  void Set(const void* data, size_t bytes) {
    if (!id) api.GenBuffers(1, &id);
    api.BindBuffer(GL_SHADER_STORAGE_BUFFER, id);
    api.BufferData(GL_SHADER_STORAGE_BUFFER, std::max<size_t>(bytes, 16), data, GL_DYNAMIC_DRAW);
  }
  template <typename T>
  void Set(const std::vector<T>& v) { Set(v.data(), v.size() * sizeof(T)); }
};

class GlRelaxer : public JacobiRelaxer {
 public:
  GlRelaxer() {
    GlContext::Get();
    program_ = CompileRenderShader("render/shaders/jacobi.comp");
  }
  void Load(const JacobiSystem& S) override {
    size_ = S.size;
    nb_.Set(S.nb);
    w_.Set(S.w);
    s_.Set(S.s);
    d_.Set(S.inv_diag);
  }
  void Relax(const std::vector<int32_t>& active, int iterations,
             std::vector<float>* phi) override {
    TL_CHECK(int64_t(phi->size()) == size_ * 3);
    if (iterations == 0 || active.empty()) return;
    active_.Set(active);
    buf_[0].Set(*phi);
    buf_[1].Set(*phi);
    api.UseProgram(program_);
    api.Uniform1i(0, int(active.size()));
    const int64_t groups = (int64_t(active.size()) + 255) / 256;
    const int64_t gx = std::min<int64_t>(groups, 65535), gy = (groups + gx - 1) / gx;
    const Ssbo* fixed[5] = {&nb_, &w_, &s_, &d_, &active_};
    for (int b = 0; b < 5; ++b) api.BindBufferBase(GL_SHADER_STORAGE_BUFFER, b, fixed[b]->id);
    for (int it = 0; it < iterations; ++it) {
      api.BindBufferBase(GL_SHADER_STORAGE_BUFFER, 5, buf_[it % 2].id);
      api.BindBufferBase(GL_SHADER_STORAGE_BUFFER, 6, buf_[(it + 1) % 2].id);
      api.DispatchCompute(GLuint(gx), GLuint(gy), 1);
      api.MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
    }
    api.MemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    api.BindBuffer(GL_SHADER_STORAGE_BUFFER, buf_[iterations % 2].id);
    api.GetBufferSubData(GL_SHADER_STORAGE_BUFFER, 0, phi->size() * sizeof(float), phi->data());
  }

 private:
  GLuint program_ = 0;
  int64_t size_ = 0;
  Ssbo nb_, w_, s_, d_, active_, buf_[2];
};

}  // namespace

std::unique_ptr<JacobiRelaxer> MakeGlRelaxer() { return std::make_unique<GlRelaxer>(); }

}  // namespace translume
