// SPDX-License-Identifier: MIT
// The gl backend of the polygrid relaxation: one compute-shader dispatch per step, ping-ponging
// two fluence buffers (Section 5.2's radiance buffers I_A, I_B) in the solver's headless context.
#include <algorithm>
#include <map>
#include <fmt/format.h>
#include <memory>

#include "render/diffusion.h"
#include "render/gl_internal.h"
#include "render/gl_shaders.h"
#include "solver/gl_api.h"
#include "solver/gl_context.h"
#include "solver/status.h"

namespace translume {
namespace {

using gl::api;
using render_gl::Ssbo;

}  // namespace

namespace render_gl {

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
  return prog;
}

void Dispatch(std::initializer_list<const Ssbo*> buffers, int64_t threads) {
  if (threads <= 0) return;
  GLuint b = 0;
  for (const Ssbo* s : buffers) api.BindBufferBase(GL_SHADER_STORAGE_BUFFER, b++, s->id);
  const int64_t groups = (threads + 255) / 256;
  const int64_t gx = std::min<int64_t>(groups, 65535), gy = (groups + gx - 1) / gx;
  api.DispatchCompute(GLuint(gx), GLuint(gy), 1);
  api.MemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
}

}  // namespace render_gl

namespace {

class GlRelaxer : public JacobiRelaxer {
 public:
  GlRelaxer() {
    GlContext::Get();
    program_ = render_gl::Program("render/shaders/jacobi.comp");
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
    for (int it = 0; it < iterations; ++it)
      render_gl::Dispatch({&nb_, &w_, &s_, &d_, &active_, &buf_[it % 2], &buf_[(it + 1) % 2]},
                          int64_t(active.size()));
    buf_[iterations % 2].Get(phi->data(), phi->size() * sizeof(float));
  }

 private:
  GLuint program_ = 0;
  int64_t size_ = 0;
  Ssbo nb_, w_, s_, d_, active_, buf_[2];
};

}  // namespace

std::unique_ptr<JacobiRelaxer> MakeGlRelaxer() { return std::make_unique<GlRelaxer>(); }

}  // namespace translume
