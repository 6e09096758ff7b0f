// SPDX-License-Identifier: MIT
#pragma once

#include "solver/gl_shaders.h"

namespace translume::gl {

// The files of render/shaders/, embedded at build time (cmake/EmbedShaders.cmake).
extern const EmbeddedShader kRenderShaders[];
extern const int kNumRenderShaders;

}  // namespace translume::gl
