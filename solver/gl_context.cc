// SPDX-License-Identifier: MIT
#include "solver/gl_context.h"

#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GL/osmesa.h>
#include <dlfcn.h>

#include <cstdlib>
#include <cstring>
#include <fmt/format.h>
#include <fmt/ranges.h>
#include <mutex>
#include <string>
#include <vector>

#include "solver/gl_api.h"
#include "solver/status.h"

namespace translume {
namespace gl {
Api api;
}  // namespace gl

namespace {

using GetProc = void* (*)(const char*);

// EGL entry points, loaded from libEGL.so.1 at run time.
struct Egl {
  void* lib = nullptr;
  decltype(&eglGetProcAddress) GetProcAddress = nullptr;
  decltype(&eglInitialize) Initialize = nullptr;
  decltype(&eglBindAPI) BindAPI = nullptr;
  decltype(&eglChooseConfig) ChooseConfig = nullptr;
  decltype(&eglCreateContext) CreateContext = nullptr;
  decltype(&eglMakeCurrent) MakeCurrent = nullptr;
  decltype(&eglQueryString) QueryString = nullptr;
  decltype(&eglGetError) GetError = nullptr;
  decltype(&eglTerminate) Terminate = nullptr;
  PFNEGLGETPLATFORMDISPLAYEXTPROC GetPlatformDisplay = nullptr;
  PFNEGLQUERYDEVICESEXTPROC QueryDevices = nullptr;
  PFNEGLQUERYDEVICESTRINGEXTPROC QueryDeviceString = nullptr;

  bool Load(std::string* why) {
    lib = dlopen("libEGL.so.1", RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
      *why = "libEGL.so.1 not found";
      return false;
    }
#define TL_EGL_SYM(member, name) member = reinterpret_cast<decltype(member)>(dlsym(lib, name))
    TL_EGL_SYM(GetProcAddress, "eglGetProcAddress");
    TL_EGL_SYM(Initialize, "eglInitialize");
    TL_EGL_SYM(BindAPI, "eglBindAPI");
    TL_EGL_SYM(ChooseConfig, "eglChooseConfig");
    TL_EGL_SYM(CreateContext, "eglCreateContext");
    TL_EGL_SYM(MakeCurrent, "eglMakeCurrent");
    TL_EGL_SYM(QueryString, "eglQueryString");
    TL_EGL_SYM(GetError, "eglGetError");
    TL_EGL_SYM(Terminate, "eglTerminate");
#undef TL_EGL_SYM
    if (!GetProcAddress || !Initialize || !CreateContext || !MakeCurrent) {
      *why = "libEGL.so.1 lacks EGL 1.4 entry points";
      return false;
    }
    GetPlatformDisplay = reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(
        GetProcAddress("eglGetPlatformDisplayEXT"));
    QueryDevices = reinterpret_cast<PFNEGLQUERYDEVICESEXTPROC>(GetProcAddress("eglQueryDevicesEXT"));
    QueryDeviceString = reinterpret_cast<PFNEGLQUERYDEVICESTRINGEXTPROC>(
        GetProcAddress("eglQueryDeviceStringEXT"));
    if (!GetPlatformDisplay) {
      *why = "EGL has no eglGetPlatformDisplayEXT";
      return false;
    }
    return true;
  }
};

Egl egl;
GetProc get_proc = nullptr;

void* EglProc(const char* name) { return reinterpret_cast<void*>(egl.GetProcAddress(name)); }

// Creates a core 4.3+ context on an initialised display and makes it current (no surface).
bool EglContextOn(EGLDisplay dpy, std::string* why) {
  EGLint major = 0, minor = 0;
  if (!egl.Initialize(dpy, &major, &minor)) {
    *why = fmt::format("eglInitialize failed (0x{:x})", egl.GetError());
    return false;
  }
  if (!egl.BindAPI(EGL_OPENGL_API)) {
    *why = "eglBindAPI(EGL_OPENGL_API) failed";
    return false;
  }
  const EGLint config_attribs[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT, EGL_NONE};
  EGLConfig config = nullptr;
  EGLint count = 0;
  if (!egl.ChooseConfig(dpy, config_attribs, &config, 1, &count) || count < 1) {
    // Surfaceless contexts may not need a config (EGL_KHR_no_config_context).
    config = nullptr;
  }
  const EGLint ctx_attribs[] = {EGL_CONTEXT_MAJOR_VERSION, 4, EGL_CONTEXT_MINOR_VERSION, 3,
                                EGL_CONTEXT_OPENGL_PROFILE_MASK,
                                EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT, EGL_NONE};
  EGLContext ctx = egl.CreateContext(dpy, config, EGL_NO_CONTEXT, ctx_attribs);
  if (ctx == EGL_NO_CONTEXT) {
    *why = fmt::format("no OpenGL 4.3 core context (eglCreateContext 0x{:x})", egl.GetError());
    return false;
  }
  if (!egl.MakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, ctx)) {
    *why = fmt::format("eglMakeCurrent without a surface failed (0x{:x})", egl.GetError());
    return false;
  }
  get_proc = EglProc;
  return true;
}

bool TryDevice(std::string* why) {
  if (!egl.lib && !egl.Load(why)) return false;
  if (!egl.QueryDevices) {
    *why = "EGL has no EGL_EXT_device_enumeration";
    return false;
  }
  EGLDeviceEXT devices[16];
  EGLint n = 0;
  if (!egl.QueryDevices(16, devices, &n) || n == 0) {
    *why = "no EGL devices";
    return false;
  }
  std::vector<std::string> reasons;
  for (EGLint d = 0; d < n; ++d) {
    const char* ext = egl.QueryDeviceString ? egl.QueryDeviceString(devices[d], EGL_EXTENSIONS) : "";
    if (ext && std::strstr(ext, "EGL_MESA_device_software")) {
      reasons.push_back(fmt::format("device {} is Mesa's software renderer, which TRANSLUME_GL=surfaceless or "
                                    "leaving TRANSLUME_GL unset uses", d));
      continue;
    }
    EGLDisplay dpy = egl.GetPlatformDisplay(EGL_PLATFORM_DEVICE_EXT, devices[d], nullptr);
    std::string r = "no EGL display";
    if (dpy != EGL_NO_DISPLAY && EglContextOn(dpy, &r)) return true;
    reasons.push_back(fmt::format("device {}: {}", d, r));
  }
  *why = fmt::format("no usable GPU device ({})", fmt::join(reasons, "; "));
  return false;
}

bool TrySurfaceless(std::string* why) {
  if (!egl.lib && !egl.Load(why)) return false;
  EGLDisplay dpy = egl.GetPlatformDisplay(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
  if (dpy == EGL_NO_DISPLAY) {
    *why = "no surfaceless EGL platform";
    return false;
  }
  return EglContextOn(dpy, why);
}

struct OsMesa {
  decltype(&OSMesaCreateContextAttribs) CreateContextAttribs = nullptr;
  decltype(&OSMesaMakeCurrent) MakeCurrent = nullptr;
  decltype(&OSMesaGetProcAddress) GetProcAddress = nullptr;
};
OsMesa osmesa;
std::vector<unsigned char> osmesa_buffer(4 * 4 * 4);

void* OsMesaProc(const char* name) { return reinterpret_cast<void*>(osmesa.GetProcAddress(name)); }

bool TryOsMesa(std::string* why) {
  void* lib = dlopen("libOSMesa.so.8", RTLD_NOW | RTLD_LOCAL);
  if (!lib) lib = dlopen("libOSMesa.so.6", RTLD_NOW | RTLD_LOCAL);
  if (!lib) {
    *why = "libOSMesa not found";
    return false;
  }
  osmesa.CreateContextAttribs =
      reinterpret_cast<decltype(osmesa.CreateContextAttribs)>(dlsym(lib, "OSMesaCreateContextAttribs"));
  osmesa.MakeCurrent = reinterpret_cast<decltype(osmesa.MakeCurrent)>(dlsym(lib, "OSMesaMakeCurrent"));
  osmesa.GetProcAddress =
      reinterpret_cast<decltype(osmesa.GetProcAddress)>(dlsym(lib, "OSMesaGetProcAddress"));
  if (!osmesa.CreateContextAttribs || !osmesa.MakeCurrent || !osmesa.GetProcAddress) {
    *why = "libOSMesa lacks OSMesaCreateContextAttribs";
    return false;
  }
  const int attribs[] = {OSMESA_FORMAT, OSMESA_RGBA, OSMESA_PROFILE, OSMESA_CORE_PROFILE,
                         OSMESA_CONTEXT_MAJOR_VERSION, 4, OSMESA_CONTEXT_MINOR_VERSION, 5, 0};
  OSMesaContext ctx = osmesa.CreateContextAttribs(attribs, nullptr);
  if (!ctx) {
    *why = "OSMesa gave no 4.5 core context";
    return false;
  }
  if (!osmesa.MakeCurrent(ctx, osmesa_buffer.data(), GL_UNSIGNED_BYTE, 4, 4)) {
    *why = "OSMesaMakeCurrent failed";
    return false;
  }
  get_proc = OsMesaProc;
  return true;
}

bool LoadGl(std::string* why) {
#define TL_GL_LOAD(type, name)                                                     \
  gl::api.name = reinterpret_cast<type>(get_proc("gl" #name));                     \
  if (!gl::api.name) {                                                             \
    *why = "missing GL entry point gl" #name;                                      \
    return false;                                                                  \
  }
  TL_GL_FUNCTIONS(TL_GL_LOAD)
#undef TL_GL_LOAD
#define TL_GL_LOAD_OPTIONAL(type, name) gl::api.name = reinterpret_cast<type>(get_proc("gl" #name));
  TL_GL_OPTIONAL_FUNCTIONS(TL_GL_LOAD_OPTIONAL)
#undef TL_GL_LOAD_OPTIONAL
  return true;
}

}  // namespace

std::string GlInfo::ToString() const {
  return fmt::format(
      "platform {}\nGL_VENDOR {}\nGL_RENDERER {}\nGL_VERSION {}\n"
      "GL_MAX_COMPUTE_WORK_GROUP_COUNT {} x {} x {}\nGL_MAX_COMPUTE_WORK_GROUP_INVOCATIONS {}\n"
      "GL_MAX_SHADER_STORAGE_BLOCK_SIZE {} bytes\nloop budget {}\nglBufferStorage {}",
      platform, vendor, renderer, version, max_work_group_count[0], max_work_group_count[1],
      max_work_group_count[2], max_work_group_invocations, max_ssbo_bytes,
      loop_budget ? std::to_string(loop_budget) + " iterations per invocation (llvmpipe)" : std::string("none"),
      buffer_storage ? "yes (images read through persistent maps)" : "no");
}

GlContext& GlContext::Get() {
  static GlContext* context = nullptr;
  static std::string error;
  static std::once_flag once;
  std::call_once(once, [] {
    const char* forced = std::getenv("TRANSLUME_GL");
    struct Platform {
      const char* name;
      bool (*try_create)(std::string*);
    };
    const Platform platforms[] = {{"device", TryDevice}, {"surfaceless", TrySurfaceless},
                                  {"osmesa", TryOsMesa}};
    std::string reasons;
    bool known = !forced || !*forced;
    for (const Platform& p : platforms) {
      if (forced && *forced && std::strcmp(forced, p.name) != 0) continue;
      known = true;
      std::string why;
      if (!p.try_create(&why)) {
        reasons += fmt::format("{}: {}; ", p.name, why);
        continue;
      }
      if (!LoadGl(&why)) {
        reasons += fmt::format("{}: {}; ", p.name, why);
        continue;
      }
      auto* c = new GlContext();
      GlInfo& info = c->info_;
      info.platform = p.name;
      auto str = [](GLenum e) {
        const GLubyte* s = gl::api.GetString(e);
        return s ? std::string(reinterpret_cast<const char*>(s)) : std::string("?");
      };
      info.vendor = str(GL_VENDOR);
      info.renderer = str(GL_RENDERER);
      info.version = str(GL_VERSION);
      if (info.renderer.find("llvmpipe") != std::string::npos) info.loop_budget = 65535;
      GLint major = 0, minor = 0;
      gl::api.GetIntegerv(GL_MAJOR_VERSION, &major);
      gl::api.GetIntegerv(GL_MINOR_VERSION, &minor);
      if (major * 10 + minor < 43) {
        reasons += fmt::format("{}: OpenGL {}.{} < 4.3; ", p.name, major, minor);
        delete c;
        continue;
      }
      for (int a = 0; a < 3; ++a)
        gl::api.GetIntegeri_v(GL_MAX_COMPUTE_WORK_GROUP_COUNT, a, &info.max_work_group_count[a]);
      gl::api.GetIntegerv(GL_MAX_COMPUTE_WORK_GROUP_INVOCATIONS, &info.max_work_group_invocations);
      GLint64 ssbo = 0;
      gl::api.GetInteger64v(GL_MAX_SHADER_STORAGE_BLOCK_SIZE, &ssbo);
      info.max_ssbo_bytes = ssbo;
      // By the version: a platform's GetProcAddress may return an entry point the context
      // does not have. TRANSLUME_GL_BUFFER_STORAGE=0 does without it (for tests).
      const char* storage = std::getenv("TRANSLUME_GL_BUFFER_STORAGE");
      info.buffer_storage = major * 10 + minor >= 44 && gl::api.BufferStorage != nullptr &&
                            !(storage && std::string(storage) == "0");
      context = c;
      return;
    }
    if (!known)
      error = fmt::format("TRANSLUME_GL='{}' is not device, surfaceless or osmesa", forced);
    else
      error = "no OpenGL 4.3 compute context: " + reasons + "use --backend cpu";
  });
  if (!context) throw InputError("--backend gl: " + error);
  return *context;
}

}  // namespace translume
