// SPDX-License-Identifier: MIT
// Internal to the gl implementation files of render/ (gl_*.cc): the programs of
// render/shaders/ and shader storage buffers. Includes GL headers.
#pragma once

#include <algorithm>
#include <cstdint>
#include <initializer_list>
#include <string>
#include <vector>

#include "solver/gl_api.h"

namespace translume::render_gl {

// The compute program of the embedded render/shaders/FILE (e.g. "render/shaders/jacobi.comp"),
// compiled and linked once per process (the context is the solver's single headless one).
// Throws InputError with the compiler's log on failure.
GLuint Program(const std::string& file);

// A shader storage buffer, resized on upload.
struct Ssbo {
  GLuint id = 0;
  Ssbo() = default;
  Ssbo(const Ssbo&) = delete;
  ~Ssbo() {
    if (id) gl::api.DeleteBuffers(1, &id);
  }
  void Set(const void* data, size_t bytes) {
    if (!id) gl::api.GenBuffers(1, &id);
    gl::api.BindBuffer(GL_SHADER_STORAGE_BUFFER, id);
    gl::api.BufferData(GL_SHADER_STORAGE_BUFFER, std::max<size_t>(bytes, 16), data, GL_DYNAMIC_DRAW);
  }
  template <typename T>
  void Set(const std::vector<T>& v) { Set(v.data(), v.size() * sizeof(T)); }
  // Reads `bytes` from byte `offset` (after the shader writes are visible).
  void Get(void* data, size_t bytes, size_t offset = 0) const {
    gl::api.MemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    gl::api.BindBuffer(GL_SHADER_STORAGE_BUFFER, id);
    gl::api.GetBufferSubData(GL_SHADER_STORAGE_BUFFER, offset, bytes, data);
  }
  // Zeroes the buffer.
  void Zero() {
    const uint32_t zero = 0;
    gl::api.BindBuffer(GL_SHADER_STORAGE_BUFFER, id);
    gl::api.ClearBufferData(GL_SHADER_STORAGE_BUFFER, GL_R32UI, GL_RED_INTEGER, GL_UNSIGNED_INT, &zero);
  }
};

// Binds buffers to bindings 0.. of the program in use and dispatches `threads` invocations
// (256 per work group, tiled over x and y to stay under 65535 groups per dimension; shaders
// compute their index as gl_WorkGroupID.y * gl_NumWorkGroups.x * 256 + gl_GlobalInvocationID.x),
// followed by a shader-storage barrier.
void Dispatch(std::initializer_list<const Ssbo*> buffers, int64_t threads);
// The same with buffer names (a buffer another object owns: DeviceFloats::buffer).
void Dispatch(std::initializer_list<GLuint> buffers, int64_t threads);

}  // namespace translume::render_gl
