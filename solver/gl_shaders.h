// SPDX-License-Identifier: MIT
#pragma once

namespace translume::gl {

// The files of solver/shaders/, embedded at build time (cmake/EmbedShaders.cmake).
struct EmbeddedShader {
  const char* name;    // "solver/shaders/smooth.comp"
  const char* source;  // the file's text
};
extern const EmbeddedShader kEmbeddedShaders[];
extern const int kNumEmbeddedShaders;

}  // namespace translume::gl
