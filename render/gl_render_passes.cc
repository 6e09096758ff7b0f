// SPDX-License-Identifier: MIT
// The gl backend of the renderer's incident-light and shading passes (render_passes.h):
// compute shaders (render/shaders/raster.comp, incident.comp, shade.comp, with common.glsl) in
// the solver's headless context. The mesh, the boundary nodes of every level and the vertex ->
// boundary node weights are uploaded once; per frame the light samples go up and the image
// comes back, and q and the radiance too unless the frame stays on the GPU (DeviceRenderPasses).
#include <algorithm>
#include <array>
#include <cstring>
#include <fmt/format.h>
#include <limits>
#include <memory>

#include "render/gl_internal.h"
#include "render/render_passes.h"
#include "solver/gl_api.h"
#include "solver/gl_context.h"
#include "solver/status.h"

namespace translume {
namespace {

using gl::api;
using render_gl::Dispatch;
using render_gl::Ssbo;

constexpr int kSampleFloats = 28;  // struct Sample in common.glsl: 7 vec4
constexpr int32_t kNoTriangle = std::numeric_limits<int32_t>::max();
// Under llvmpipe's loop budget (GlInfo::loop_budget) raster.comp draws a triangle whose pixel
// bounds hold more than kTile^2 pixels in kTile x kTile tiles, one invocation each: 16385 loop
// iterations at most, a quarter of the budget. kLoopSlack: the other loops' iterations, with room.
constexpr int kTile = 128;
constexpr int64_t kLoopSlack = 64;

void PutVec(float* out, const Vec3& v, double w) {
  for (int a = 0; a < 3; ++a) out[a] = float(v[a]);
  out[3] = float(w);
}

// Fills a buffer of 32-bit words with `value`.
void Fill(const Ssbo& buffer, uint32_t value) {
  api.BindBuffer(GL_SHADER_STORAGE_BUFFER, buffer.id);
  api.ClearBufferData(GL_SHADER_STORAGE_BUFFER, GL_R32UI, GL_RED_INTEGER, GL_UNSIGNED_INT, &value);
}

class GlRenderPasses : public DeviceRenderPasses {
 public:
  explicit GlRenderPasses(const PassScene* scene) : sc_(*scene) {
    loop_budget_ = GlContext::Get().info().loop_budget;
    if (loop_budget_ > 0) tile_ = kTile;
    tiles_.Set(nullptr, size_t(tile_capacity_ + 1) * 4 * sizeof(int32_t));  // ivec4 per tile, after the count
    raster_ = render_gl::Program("render/shaders/raster.comp");
    incident_ = render_gl::Program("render/shaders/incident.comp");
    shade_ = render_gl::Program("render/shaders/shade.comp");
    const TriangleMesh& mesh = *sc_.mesh;
    std::vector<float> v(mesh.vertices.size() * 8);
    for (size_t i = 0; i < mesh.vertices.size(); ++i) {
      PutVec(&v[i * 8], mesh.vertices[i], 1);
      PutVec(&v[i * 8 + 4], sc_.vertex_normals[i], 0);
    }
    verts_.Set(v);
    std::vector<int32_t> t(mesh.triangles.size() * 3);
    for (size_t i = 0; i < mesh.triangles.size(); ++i)
      for (int k = 0; k < 3; ++k) t[i * 3 + k] = mesh.triangles[i][k];
    tris_.Set(t);
    num_tris_ = int(mesh.triangles.size());
    // The boundary nodes of every level, one after the other (finest first).
    std::vector<float> nodes;
    for (const Polygrid& pg : *sc_.levels) {
      level_start_.push_back(int64_t(nodes.size() / 8));
      for (int64_t b = 0; b < pg.num_boundary(); ++b) {
        nodes.resize(nodes.size() + 8);
        PutVec(&nodes[nodes.size() - 8], pg.position[pg.num_interior + b], 1);
        PutVec(&nodes[nodes.size() - 4], pg.normal[b], 0);
      }
    }
    num_nodes_ = int64_t(nodes.size() / 8);
    level_start_.push_back(num_nodes_);
    nodes_.Set(nodes);
    // struct Near { ivec4 idx; vec4 w; }
    std::vector<int32_t> near(sc_.near_idx.size() * 8);
    for (size_t i = 0; i < sc_.near_idx.size(); ++i)
      for (int k = 0; k < 4; ++k) {
        near[i * 8 + k] = sc_.near_idx[i][k];
        std::memcpy(&near[i * 8 + 4 + k], &sc_.near_w[i][k], sizeof(float));
      }
    near_.Set(near);
    q_.Set(nullptr, size_t(num_nodes_) * 3 * sizeof(float));
    num_finest_ = level_start_[1];
    radiance_.Set(nullptr, size_t(num_finest_) * 3 * sizeof(float));
    ids_.Set(nullptr, 16);  // bound (unused) while drawing shadow maps
  }

  ~GlRenderPasses() override {
    for (auto& stamps : stamps_)
      if (stamps[0] != 0) api.DeleteQueries(4, stamps.data());
  }

  std::vector<DeviceFloats> IncidentOnDevice(const std::vector<LightSample>& samples) override {
    TL_CHECK(!samples.empty());
    UploadSamples(samples, nullptr);
    map_size_ = samples[0].view.width;
    const size_t texels = size_t(map_size_) * map_size_;
    if (samples.size() * texels != shadow_texels_) {
      shadow_texels_ = samples.size() * texels;
      shadow_.Set(nullptr, shadow_texels_ * sizeof(uint32_t));
    }
    Fill(shadow_, FarDepth());
    Raster(0, int(samples.size()), map_size_, map_size_, shadow_, 0);  // depth only
    api.UseProgram(incident_);
    api.Uniform1i(0, int(num_nodes_));
    api.Uniform1i(1, int(samples.size()));
    api.Uniform1i(2, map_size_);
    api.Uniform1f(3, float(sc_.shadow_bias));
    api.Uniform1f(4, float(sc_.options.eta));
    Dispatch({&samples_, &shadow_, &verts_, &tris_, &ids_, &nodes_, &q_}, num_nodes_);
    std::vector<DeviceFloats> out;
    for (size_t l = 0; l + 1 < level_start_.size(); ++l) out.push_back({q_.id, level_start_[l] * 3});
    return out;
  }

  std::vector<BoundaryLight> Incident(const std::vector<LightSample>& samples) override {
    IncidentOnDevice(samples);
    std::vector<BoundaryLight> out;
    for (size_t l = 0; l < sc_.levels->size(); ++l) out.push_back(ReadQ(l));
    return out;
  }

  DeviceFloats RadianceOnDevice() override { return {radiance_.id, 0}; }

  void ShadeOnDevice(const PassView& cam, const std::vector<LightSample>& samples) override {
    TL_CHECK_MSG(shadow_.id != 0, "Shade before Incident");
    const RenderOptions& o = sc_.options;
    const int ss = o.supersample;
    image_width_ = cam.width / ss;
    image_height_ = cam.height / ss;
    UploadSamples(samples, &cam);
    const size_t pixels = size_t(cam.width) * cam.height;
    if (pixels != cam_pixels_) {
      cam_depth_.Set(nullptr, pixels * sizeof(uint32_t));
      ids_.Set(nullptr, pixels * sizeof(int32_t));
      image_.Set(nullptr, size_t(image_width_) * image_height_ * 3 * sizeof(float));
      cam_pixels_ = pixels;
    }
    Fill(cam_depth_, FarDepth());
    Fill(ids_, uint32_t(kNoTriangle));
    for (int mode = 0; mode < 2; ++mode)
      Raster(int(samples.size()), 1, cam.width, cam.height, cam_depth_, mode);
    api.UseProgram(shade_);
    api.Uniform1i(0, image_width_);
    api.Uniform1i(1, image_height_);
    api.Uniform1i(2, ss);
    api.Uniform1i(3, int(samples.size()));
    api.Uniform1i(4, map_size_);
    api.Uniform1f(5, float(sc_.shadow_bias));
    api.Uniform1f(6, float(o.eta));
    api.Uniform1f(7, float(o.specular));
    api.Uniform1f(8, float(o.roughness));
    api.Uniform1f(9, float(o.surface_reflectance));
    api.Uniform1i(10, int(num_finest_));
    // The light samples per dispatch: all, or as many as keep an invocation's ss^2 (s1 - s0 +
    // 18) loop iterations (shade.comp) within half the loop budget.
    const int n = int(samples.size());
    const int per = loop_budget_ > 0 ? int(std::max<int64_t>(1, loop_budget_ / 2 / (ss * ss) - 18)) : n;
    for (int s0 = 0; s0 < n; s0 += per) {
      api.Uniform1i(11, s0);
      api.Uniform1i(12, std::min(n, s0 + per));
      Dispatch({&samples_, &shadow_, &verts_, &tris_, &ids_, &near_, &image_, &radiance_},
               int64_t(image_width_) * image_height_);
    }
  }

  void QueueImage(int slot) override {
    TL_CHECK(slot >= 0 && slot < kFrameSlots);
    Staging& st = staging_[slot];
    TL_CHECK_MSG(st.fence == nullptr, "QueueImage: the slot's last image was not taken");
    st.width = image_width_;
    st.height = image_height_;
    st.Reserve(size_t(st.width) * st.height * 3 * sizeof(float));
    api.MemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);  // the copy reads what shade.comp wrote
    api.BindBuffer(GL_COPY_READ_BUFFER, image_.id);
    api.BindBuffer(GL_COPY_WRITE_BUFFER, st.id);
    api.CopyBufferSubData(GL_COPY_READ_BUFFER, GL_COPY_WRITE_BUFFER, 0, 0, GLsizeiptr(st.bytes));
    st.fence = api.FenceSync(GL_SYNC_GPU_COMMANDS_COMPLETE, 0);
  }

  Image TakeImage(int slot) override {
    TL_CHECK(slot >= 0 && slot < kFrameSlots);
    Staging& st = staging_[slot];
    TL_CHECK_MSG(st.fence != nullptr, "TakeImage: no image queued in the slot");
    GLenum waited;
    do waited = api.ClientWaitSync(st.fence, GL_SYNC_FLUSH_COMMANDS_BIT, 1000000000);  // 1 s, again
    while (waited == GL_TIMEOUT_EXPIRED);
    api.DeleteSync(st.fence);
    st.fence = nullptr;
    TL_CHECK_MSG(waited != GL_WAIT_FAILED, "glClientWaitSync failed");
    Image img;
    img.width = st.width;
    img.height = st.height;
    img.channels = 3;
    img.data.resize(size_t(img.width) * img.height * 3);
    st.Read(img.data.data());
    return img;
  }

  void Flush() override { api.Flush(); }

  Image Shade(const PassView& cam, const BoundaryLight& radiance,
              const std::vector<LightSample>& samples) override {
    std::vector<float> rad(size_t(num_finest_) * 3);
    for (int c = 0; c < 3; ++c) std::copy(radiance[c].begin(), radiance[c].end(), rad.begin() + c * num_finest_);
    UploadRadiance(rad.data());
    ShadeOnDevice(cam, samples);
    QueueImage(0);
    return TakeImage(0);
  }

  BoundaryLight ReadFinestQ() override { return ReadQ(0); }

  BoundaryLight ReadRadiance() override {
    BoundaryLight out;
    for (int c = 0; c < 3; ++c) {
      out[c].resize(num_finest_);
      radiance_.Get(out[c].data(), size_t(num_finest_) * sizeof(float), size_t(c * num_finest_) * sizeof(float));
    }
    return out;
  }

  void Stamp(int slot, int k) override {
    TL_CHECK(slot >= 0 && slot < kFrameSlots && k >= 0 && k < 4);
    if (stamps_[slot][0] == 0) api.GenQueries(4, stamps_[slot].data());
    api.QueryCounter(stamps_[slot][k], GL_TIMESTAMP);
  }

  std::array<double, 3> StampSeconds(int slot) override {
    TL_CHECK(slot >= 0 && slot < kFrameSlots && stamps_[slot][0] != 0);
    std::array<uint64_t, 4> t{};
    for (int k = 0; k < 4; ++k) api.GetQueryObjectui64v(stamps_[slot][k], GL_QUERY_RESULT, &t[k]);
    return {(t[1] - t[0]) * 1e-9, (t[2] - t[1]) * 1e-9, (t[3] - t[2]) * 1e-9};
  }

 private:
  // Draws the mesh with raster.comp in `mode` (0: depth, 1: triangle ids after mode 0) into
  // num_rasters rasters of width x height texels, one after the other in `depth`, raster r
  // seen from the uploaded samples' view first_view + r: one dispatch for all of them. Within
  // llvmpipe's loop budget (tile_ > 0), mode 0 lists the tiles of the triangles larger than a
  // tile, over all the rasters, and both modes then draw those tiles in a second dispatch
  // (mode 1 the tiles mode 0 listed last).
  void Raster(int first_view, int num_rasters, int width, int height, const Ssbo& depth, int mode) {
    if (tile_ > 0) {
      // One invocation loops over at most tile_^2 pixels plus, in mode 0, the tiles it lists.
      const int64_t most = (int64_t(width) + tile_ - 1) / tile_ * ((int64_t(height) + tile_ - 1) / tile_);
      if (int64_t(tile_) * tile_ + most + kLoopSlack > loop_budget_)
        throw InputError(fmt::format("--backend gl: a {}x{} raster is too large for llvmpipe (a shader "
                                     "invocation may loop {} times); use --backend cpu",
                                     width, height, loop_budget_));
    }
    api.UseProgram(raster_);
    api.Uniform1i(2, mode);
    api.Uniform1i(4, tile_);
    // As many rasters per dispatch as keep the invocation index an int.
    const int per =
        int(std::min<int64_t>(num_rasters, std::max(1, std::numeric_limits<int32_t>::max() / std::max(1, num_tris_))));
    auto triangles = [&] {
      api.Uniform1i(5, 0);
      api.Uniform1i(6, int(tile_capacity_));
      api.Uniform1i(7, num_tris_);
      api.Uniform1i(8, width * height);
      for (int r0 = 0; r0 < num_rasters; r0 += per) {
        const int n = std::min(per, num_rasters - r0);
        api.Uniform1i(0, num_tris_ * n);
        api.Uniform1i(1, first_view + r0);
        api.Uniform1i(3, r0 * width * height);
        Dispatch({&samples_, &depth, &verts_, &tris_, &ids_, &tiles_}, int64_t(num_tris_) * n);
      }
    };
    auto listed = [&] {
      uint32_t n = 0;
      tiles_.Get(&n, sizeof(n));
      return int64_t(n);
    };
    if (tile_ > 0 && mode == 0) {
      ResetTiles();
      triangles();
      num_tiles_ = listed();
      if (num_tiles_ > tile_capacity_) {  // grow and list again (drawing twice changes nothing)
        tile_capacity_ = std::max(num_tiles_, 2 * tile_capacity_);
        tiles_.Set(nullptr, size_t(tile_capacity_ + 1) * 4 * sizeof(int32_t));
        ResetTiles();
        triangles();
      }
    } else {
      triangles();
    }
    if (tile_ > 0 && num_tiles_ > 0) {
      api.Uniform1i(0, int(num_tiles_));
      api.Uniform1i(5, 1);
      Dispatch({&samples_, &depth, &verts_, &tris_, &ids_, &tiles_}, num_tiles_);
    }
  }

  // Level l's q from the incident pass's buffer ([node * 3 + c], the levels one after the other).
  BoundaryLight ReadQ(size_t l) const {
    const int64_t n = level_start_[l + 1] - level_start_[l];
    std::vector<float> q(size_t(n) * 3);
    q_.Get(q.data(), q.size() * sizeof(float), size_t(level_start_[l]) * 3 * sizeof(float));
    BoundaryLight out;
    for (int c = 0; c < 3; ++c) {
      out[c].resize(n);
      for (int64_t b = 0; b < n; ++b) out[c][b] = q[b * 3 + c];
    }
    return out;
  }

  void UploadRadiance(const float* rad) {
    api.MemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    api.BindBuffer(GL_SHADER_STORAGE_BUFFER, radiance_.id);
    api.BufferSubData(GL_SHADER_STORAGE_BUFFER, 0, num_finest_ * 3 * sizeof(float), rad);
  }

  // Sets raster.comp's count of listed tiles to 0.
  void ResetTiles() {
    const uint32_t zero = 0;
    api.MemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    api.BindBuffer(GL_SHADER_STORAGE_BUFFER, tiles_.id);
    api.BufferSubData(GL_SHADER_STORAGE_BUFFER, 0, sizeof(zero), &zero);
  }

  static uint32_t FarDepth() {
    const float far = 1e30f;  // as the cpu raster's empty texel
    uint32_t bits;
    std::memcpy(&bits, &far, sizeof(bits));
    return bits;
  }

  // struct Sample of common.glsl per light sample, then the camera (if any) as one more.
  void UploadSamples(const std::vector<LightSample>& samples, const PassView* camera) {
    std::vector<float> f((samples.size() + (camera ? 1 : 0)) * kSampleFloats, 0.f);
    auto put_view = [](float* out, const PassView& v) {
      PutVec(out, v.eye, v.near);
      PutVec(out + 4, v.right, 0);
      PutVec(out + 8, v.up, 0);
      PutVec(out + 12, v.forward, 0);
      out[16] = v.ortho ? 1.f : 0.f;
      out[17] = float(v.scale);
      out[18] = float(v.width);
      out[19] = float(v.height);
    };
    for (size_t s = 0; s < samples.size(); ++s) {
      float* out = &f[s * kSampleFloats];
      const LightSample& smp = samples[s];
      PutVec(out, smp.v, !smp.point ? 0 : smp.cube_face < 0 ? 1 : 2 + smp.cube_face);
      PutVec(out + 4, Vec3(smp.E[0], smp.E[1], smp.E[2]), smp.point ? (smp.v - sc_.centre).squaredNorm() : 0);
      put_view(out + 8, smp.view);
    }
    if (camera) put_view(&f[samples.size() * kSampleFloats + 8], *camera);
    samples_.Set(f);
  }

  const PassScene& sc_;
  GLuint raster_ = 0, incident_ = 0, shade_ = 0;
  int num_tris_ = 0, map_size_ = 0, image_width_ = 0, image_height_ = 0;
  int64_t num_nodes_ = 0, num_finest_ = 0;  // boundary nodes of every level, of the finest
  size_t shadow_texels_ = 0;
  std::array<std::array<GLuint, 4>, kFrameSlots> stamps_{};
  // A slot's image on its way to the host: a buffer that only QueueImage's copy writes,
  // persistently mapped for reading where the context has glBufferStorage (GL 4.4), so that
  // once the copy's fence has signalled the host reads it without waiting for later commands.
  struct Staging {
    GLuint id = 0;
    size_t bytes = 0;
    const float* map = nullptr;
    GLsync fence = nullptr;  // the queued copy's, until TakeImage
    int width = 0, height = 0;
    Staging() = default;
    Staging(const Staging&) = delete;
    ~Staging() {
      if (fence) api.DeleteSync(fence);
      if (id) api.DeleteBuffers(1, &id);  // (unmaps it)
    }
    void Reserve(size_t n) {
      if (id && n == bytes) return;
      if (id) api.DeleteBuffers(1, &id);
      bytes = n;
      api.GenBuffers(1, &id);
      api.BindBuffer(GL_COPY_WRITE_BUFFER, id);
      const size_t size = std::max<size_t>(n, 16);
      if (GlContext::Get().info().buffer_storage) {
        const GLbitfield flags = GL_MAP_READ_BIT | GL_MAP_PERSISTENT_BIT | GL_MAP_COHERENT_BIT;
        api.BufferStorage(GL_COPY_WRITE_BUFFER, GLsizeiptr(size), nullptr, flags | GL_CLIENT_STORAGE_BIT);
        map = static_cast<const float*>(api.MapBufferRange(GL_COPY_WRITE_BUFFER, 0, GLsizeiptr(size), flags));
        TL_CHECK_MSG(map != nullptr, "glMapBufferRange of a persistent read buffer failed");
      } else {
        map = nullptr;
        api.BufferData(GL_COPY_WRITE_BUFFER, GLsizeiptr(size), nullptr, GL_STREAM_READ);
      }
    }
    void Read(float* out) const {
      if (map) {
        std::memcpy(out, map, bytes);
      } else {
        api.BindBuffer(GL_COPY_READ_BUFFER, id);
        api.GetBufferSubData(GL_COPY_READ_BUFFER, 0, GLsizeiptr(bytes), out);
      }
    }
  };
  std::array<Staging, kFrameSlots> staging_;
  std::vector<int64_t> level_start_;
  size_t cam_pixels_ = 0;
  // Large triangles drawn in tiles (raster.comp) where GlInfo::loop_budget limits the loop
  // iterations of an invocation: the tile side (pixels; 0: no tiles), the budget, the tiles
  // the buffer holds and the tiles mode 0 listed last.
  int tile_ = 0;
  int64_t loop_budget_ = 0, tile_capacity_ = 4096, num_tiles_ = 0;
  Ssbo verts_, tiles_, tris_, nodes_, near_, samples_, shadow_, q_, cam_depth_, ids_, image_, radiance_;
};

}  // namespace

std::unique_ptr<DeviceRenderPasses> MakeGlRenderPasses(const PassScene* scene) {
  return std::make_unique<GlRenderPasses>(scene);
}

}  // namespace translume
