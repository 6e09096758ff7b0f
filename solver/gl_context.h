// SPDX-License-Identifier: MIT
#pragma once

#include <cstdint>
#include <string>

namespace translume {

// A headless OpenGL 4.3+ core context for compute shaders, behind a plain C++ interface: no GL,
// EGL or OSMesa header appears outside gl_*.cc. Platforms, in order of preference:
//   device       EGL on a GPU device (EGL_EXT_platform_device; NVIDIA and other vendors);
//                Mesa's software device is skipped in favour of the next platform
//   surfaceless  Mesa's surfaceless EGL platform (llvmpipe on a machine without a GPU)
//   osmesa       OSMesa, core profile 4.5
// TRANSLUME_GL=device|surfaceless|osmesa forces one. libEGL and libOSMesa are loaded at run
// time, so the binary runs (with --backend cpu) where neither is installed.
struct GlInfo {
  std::string platform, vendor, renderer, version;
  int max_work_group_count[3] = {0, 0, 0};
  int max_work_group_invocations = 0;
  int64_t max_ssbo_bytes = 0;
  // The most loop iterations one shader invocation may run, all its loops together; 0: no
  // limit. Mesa's llvmpipe (gallivm, Mesa 22.3: LP_MAX_TGSI_LOOP_ITERATIONS in
  // lp_bld_ir_common.c) gives every invocation, i.e. every SIMD chunk of 8 invocations run
  // together, one counter of 65535, decremented by every iteration of every loop, nested and
  // constant-count loops included (a loop of k iterations counts about k + 1; a chunk counts
  // its slowest lane). Once it is spent each loop still entered runs at most one iteration,
  // silently: the shader computes garbage and no error is raised. 65535 where GL_RENDERER
  // contains "llvmpipe", else 0. Shaders whose loops grow with the input keep each invocation's
  // share well within it (docs/gpu.md, "llvmpipe's loop budget").
  int64_t loop_budget = 0;
  // GL >= 4.4's glBufferStorage: buffers persistently mapped for reading (the renderer's
  // pipelined frames read their images through one; without it, glGetBufferSubData).
  // TRANSLUME_GL_BUFFER_STORAGE=0 turns it off.
  bool buffer_storage = false;
  std::string ToString() const;
};

class GlContext {
 public:
  // The process-wide context, created on first use and current on the calling thread. Throws
  // InputError (one line, with a hint to use --backend cpu) if no platform gives GL >= 4.3.
  static GlContext& Get();
  const GlInfo& info() const { return info_; }

  GlContext(const GlContext&) = delete;
  GlContext& operator=(const GlContext&) = delete;

 private:
  GlContext() = default;
  GlInfo info_;
};

}  // namespace translume
