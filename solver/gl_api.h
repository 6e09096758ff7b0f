// SPDX-License-Identifier: MIT
// Internal to the gl backend: the GL entry points it uses, loaded through the platform's
// GetProcAddress. Include only from gl_*.cc.
#pragma once

#include <GL/glcorearb.h>

// OpenGL 1.1 entry points, which glcorearb.h declares without pointer types.
typedef void(APIENTRYP TlGenTextures)(GLsizei n, GLuint* textures);
typedef void(APIENTRYP TlDeleteTextures)(GLsizei n, const GLuint* textures);
typedef void(APIENTRYP TlBindTexture)(GLenum target, GLuint texture);

namespace translume::gl {

#define TL_GL_FUNCTIONS(X)                                               \
  X(PFNGLGETSTRINGPROC, GetString)                                       \
  X(PFNGLGETINTEGERVPROC, GetIntegerv)                                   \
  X(PFNGLGETINTEGERI_VPROC, GetIntegeri_v)                               \
  X(PFNGLGETINTEGER64VPROC, GetInteger64v)                               \
  X(PFNGLGETERRORPROC, GetError)                                         \
  X(PFNGLCREATESHADERPROC, CreateShader)                                 \
  X(PFNGLSHADERSOURCEPROC, ShaderSource)                                 \
  X(PFNGLCOMPILESHADERPROC, CompileShader)                               \
  X(PFNGLGETSHADERIVPROC, GetShaderiv)                                   \
  X(PFNGLGETSHADERINFOLOGPROC, GetShaderInfoLog)                         \
  X(PFNGLDELETESHADERPROC, DeleteShader)                                 \
  X(PFNGLCREATEPROGRAMPROC, CreateProgram)                               \
  X(PFNGLATTACHSHADERPROC, AttachShader)                                 \
  X(PFNGLLINKPROGRAMPROC, LinkProgram)                                   \
  X(PFNGLGETPROGRAMIVPROC, GetProgramiv)                                 \
  X(PFNGLGETPROGRAMINFOLOGPROC, GetProgramInfoLog)                       \
  X(PFNGLDELETEPROGRAMPROC, DeleteProgram)                               \
  X(PFNGLUSEPROGRAMPROC, UseProgram)                                     \
  X(PFNGLUNIFORM1IPROC, Uniform1i)                                       \
  X(PFNGLUNIFORM1FPROC, Uniform1f)                                       \
  X(PFNGLUNIFORM3FPROC, Uniform3f)                                       \
  X(PFNGLGENBUFFERSPROC, GenBuffers)                                     \
  X(PFNGLDELETEBUFFERSPROC, DeleteBuffers)                               \
  X(PFNGLBINDBUFFERPROC, BindBuffer)                                     \
  X(PFNGLBUFFERDATAPROC, BufferData)                                     \
  X(PFNGLBUFFERSUBDATAPROC, BufferSubData)                               \
  X(PFNGLGETBUFFERSUBDATAPROC, GetBufferSubData)                         \
  X(PFNGLBINDBUFFERBASEPROC, BindBufferBase)                             \
  X(PFNGLCOPYBUFFERSUBDATAPROC, CopyBufferSubData)                       \
  X(PFNGLCLEARBUFFERDATAPROC, ClearBufferData)                           \
  X(PFNGLDISPATCHCOMPUTEPROC, DispatchCompute)                           \
  X(PFNGLMEMORYBARRIERPROC, MemoryBarrier)                               \
  X(TlGenTextures, GenTextures)                                          \
  X(TlDeleteTextures, DeleteTextures)                                     \
  X(TlBindTexture, BindTexture)                                          \
  X(PFNGLTEXBUFFERPROC, TexBuffer)                                       \
  X(PFNGLBINDIMAGETEXTUREPROC, BindImageTexture)                         \
  X(PFNGLFINISHPROC, Finish)                                             \
  X(PFNGLFLUSHPROC, Flush)                                               \
  X(PFNGLFENCESYNCPROC, FenceSync)                                       \
  X(PFNGLCLIENTWAITSYNCPROC, ClientWaitSync)                             \
  X(PFNGLDELETESYNCPROC, DeleteSync)                                     \
  X(PFNGLMAPBUFFERRANGEPROC, MapBufferRange)                             \
  X(PFNGLGENQUERIESPROC, GenQueries)                                     \
  X(PFNGLDELETEQUERIESPROC, DeleteQueries)                               \
  X(PFNGLQUERYCOUNTERPROC, QueryCounter)                                 \
  X(PFNGLGETQUERYOBJECTUI64VPROC, GetQueryObjectui64v)

// Entry points past GL 4.3, null where the context lacks them (GlInfo says which it has).
#define TL_GL_OPTIONAL_FUNCTIONS(X) X(PFNGLBUFFERSTORAGEPROC, BufferStorage)

struct Api {
#define TL_GL_DECLARE(type, name) type name = nullptr;
  TL_GL_FUNCTIONS(TL_GL_DECLARE)
  TL_GL_OPTIONAL_FUNCTIONS(TL_GL_DECLARE)
#undef TL_GL_DECLARE
};

// Valid once GlContext::Get() has returned.
extern Api api;

}  // namespace translume::gl
