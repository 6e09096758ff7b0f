// SPDX-License-Identifier: MIT
// Internal to the gl backend (gl_*.cc): buffers, dispatch, and the multigrid solver's device
// state, shared by the solver and the inverse problem's objective. Includes GL headers.
#pragma once

#include <array>
#include <initializer_list>
#include <memory>
#include <string>
#include <vector>

#include "solver/gl_api.h"
#include "solver/gl_shaders.h"
#include "solver/gl_solver.h"
#include "solver/multigrid_hierarchy.h"

namespace translume {
namespace gl_internal {

using gl::api;

// A shader storage buffer.
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

// The program of solver/shaders/NAME.comp, compiled once per `defines` (e.g. "#define X\n").
GLuint Program(const std::string& name, const std::string& defines = "");

// Binds `buffers` to bindings 0.., sets int uniforms at locations 0.., an optional float
// uniform, and dispatches `threads` threads (256 per group, tiled to stay under 65535 groups per
// dimension), followed by a shader-storage barrier. Returns the number of work groups.
int64_t Run(const char* name, std::initializer_list<const Buffer*> buffers,
            std::initializer_list<int> ints, int64_t threads, int float_location = -1,
            float float_value = 0, const char* defines = "");

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

}  // namespace gl_internal

using gl_internal::AxisBuffers;
using gl_internal::Buffer;
using gl_internal::GLevel;
using gl_internal::Run;

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
  // Multigrid-PCG on device buffers: b (float, n0) and the iterate x (double, n0), which holds
  // the initial guess on entry. Coefficients must be set.
  SolveSummary SolveDevice(const Buffer& b, Buffer& x);
};

}  // namespace translume
