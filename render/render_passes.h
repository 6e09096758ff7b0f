// SPDX-License-Identifier: MIT
// Internal to render/: the incident-light and shading passes of the renderer (Wang et al. 2008,
// Section 5, passes 1 and 3), one implementation per backend with the same arithmetic: cpu
// (renderer.cc, OpenMP, double) and gl (gl_render_passes.cc, compute shaders in the solver's
// headless context, float). No GL headers here.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include "render/diffusion.h"
#include "render/polygrid.h"
#include "render/renderer.h"
#include "render/shape.h"
#include "solver/image.h"

namespace translume {

// A pinhole (perspective) or orthographic view onto a width x height raster: camera-space x
// right, y up, z forward.
struct PassView {
  Vec3 eye = Vec3::Zero(), right = Vec3::UnitX(), up = Vec3::UnitY(), forward = Vec3::UnitZ();
  bool ortho = false;
  double scale = 1;  // perspective: 1 / tan(fov / 2); ortho: 1 / half-width (mm)
  int width = 0, height = 0;
  // The near plane (mm): rasters draw the parts of triangles deeper than this (a triangle that
  // crosses it is clipped, not dropped). LookAt sets 10^-6 of the distance to the target.
  double near = 0;

  static PassView LookAt(const Vec3& eye, const Vec3& target, int w, int h, bool ortho, double scale);
  // Screen position of p: x, y in pixels (pixel (i, j) covers [i, i+1] x [j, j+1], y down) and
  // the depth along `forward` (mm):
  //   x = w/2 (1 + X k / aspect), y = h/2 (1 - Y k), k = scale (ortho) or scale / Z,
  // with (X, Y, Z) = p - eye in camera axes and aspect = w / h.
  Vec3 Project(const Vec3& p) const;
  // The same in homogeneous form, (x w, y w, w, Z) with w = 1 (ortho) or Z (perspective):
  //   (w/2 (w + X scale / aspect), h/2 (w - Y scale), w, Z),
  // affine (ortho) or linear (perspective) in p, and defined behind the eye too, so that a
  // raster can find the point of a triangle under a pixel exactly (RasterTriangle).
  Eigen::Vector4d Homogeneous(const Vec3& p) const;
};

// A triangle set up for a raster: its homogeneous vertices h[0..2] (PassView::Homogeneous).
class RasterTriangle {
 public:
  explicit RasterTriangle(const std::array<Eigen::Vector4d, 3>& h);
  // The point of the triangle on the line of sight through screen position (px, py): its
  // barycentrics l (sum 1) and depth l . (h[0][3], h[1][3], h[2][3]). With H_i = (X_i, Y_i, w_i),
  // e_0 = det(H_1, H_2, (px, py, 1)) (and cyclically) = (H_1 x H_2) . (px, py, 1), so by
  // Cramer's rule l = e / (e_0 + e_1 + e_2): perspective-correct, and the same for a triangle
  // partly behind the eye. True where the line meets the triangle (every l >= 0) deeper than
  // `near`. raster.comp's hit() and covered() are the same in float, with e_0 evaluated as
  // a_1 b_2 - a_2 b_1, a_i = X_i - w_i px, b_i = Y_i - w_i py (the expanded planes lose its
  // digits in float).
  bool Hit(double px, double py, double near, Vec3* l, double* depth) const {
    const Vec3 e = planes_ * Vec3(px, py, 1);
    if (!(e.minCoeff() >= 0 || e.maxCoeff() <= 0)) return false;
    const double sum = e.sum();
    if (sum == 0) return false;
    *l = e / sum;
    *depth = l->dot(depth_);
    return *depth > near;
  }
  // The pixel bounds (x0, y0, x1, y1, inclusive, clipped to a width x height raster) of the part
  // of the triangle deeper than `near` (clipped by the near plane, projected); false where none
  // of it is, or the bounds lie off the raster.
  bool Bounds(double near, int width, int height, std::array<int, 4>* box) const;

 private:
  std::array<Eigen::Vector4d, 3> h_;
  Eigen::Matrix3d planes_;  // row i: H_j x H_k, (i, j, k) cyclic
  Vec3 depth_;
};

// One light sample of pass 1: a directional light (v: unit direction towards the light) or a
// point light (v: position, mm), with irradiance E at normal incidence (RGB; for a point light,
// at the object's centre, falling off as 1/r^2), and the view of its shadow map (S x S).
// cube_face >= 0: a point light close to the object is six samples, the faces of a cube shadow
// map (90-degree frusta along +x, -x, +y, -y, +z, -z from the light: cube_face 0..5); sample f
// lights only the points p with CubeFace(p - v) == f, so each point is lit once, through the
// face whose frustum holds it. -1: the sample lights every point (one map).
struct LightSample {
  bool point = false;
  Vec3 v = Vec3::UnitZ();
  std::array<double, 3> E = {0, 0, 0};
  PassView view;
  int cube_face = -1;
};

// The cube-map face of direction d: 2 a + (d_a < 0) for the axis a of d's largest |component|
// (ties: the lower axis). The gl passes' cube_face (render/shaders/common.glsl) is the same.
int CubeFace(const Vec3& d);

// What the passes draw, fixed for a renderer's lifetime.
struct PassScene {
  const TriangleMesh* mesh = nullptr;
  std::vector<Vec3> vertex_normals;
  const std::vector<Polygrid>* levels = nullptr;  // finest first
  // Mesh vertex -> 4 boundary nodes of the finest level and their weights (sum 1): the vertex's
  // multiple-scattering radiance is sum_k near_w[v][k] L[near_idx[v][k]].
  std::vector<std::array<int32_t, 4>> near_idx;
  std::vector<std::array<float, 4>> near_w;
  Vec3 centre = Vec3::Zero();
  double radius = 1;       // bounding sphere about `centre`, mm
  double shadow_bias = 0;  // mm: a point is shadowed when deeper than the map by more than this
  RenderOptions options;
};

class RenderPasses {
 public:
  virtual ~RenderPasses() = default;
  // Pass 1. Draws every sample's shadow map (the nearest depth per texel; kept for Shade), then
  // returns, at the boundary nodes of every level (finest first),
  //   q = sum_samples E f cos_i F_t(cos_i) V
  // with f the point light's falloff |v - centre|^2 / |v - x|^2 (1 for directional), cos_i > 0
  // the cosine between the node's normal and the direction to the light, F_t the Fresnel
  // transmittance and V = 0 where the node's depth in the sample's map exceeds the map's by
  // more than the bias (the texel under the node, clamped to the map); a cube-map face's
  // sample adds nothing at nodes of the other faces (LightSample::cube_face).
  virtual std::vector<BoundaryLight> Incident(const std::vector<LightSample>& samples) = 0;
  // Pass 3. Rasterises the mesh into camera.width x camera.height samples (nearest triangle per
  // sample centre; ties: the lower triangle index), and returns the (camera.width / s) x
  // (camera.height / s) image (s = options.supersample), each pixel the mean over its s x s
  // samples of F_t(cos_o) L_ms + (Ward isotropic rho_s, alpha + rho_d / pi) E f cos_i V, with
  // L_ms interpolated barycentrically from the vertices' radiance, the normal from the vertex
  // normals, and the light terms of Incident's samples (same shadow maps). `radiance`: the
  // finest level's boundary radiance.
  virtual Image Shade(const PassView& camera, const BoundaryLight& radiance,
                      const std::vector<LightSample>& samples) = 0;

  // gl: compute shaders (render/shaders/raster.comp, incident.comp, shade.comp).
  static std::unique_ptr<RenderPasses> Create(DiffusionBackend backend, const PassScene* scene);
};

// The gl passes, which can also leave a frame's data on the GPU: with the gl relaxation
// (PolygridDiffusion::SolveOnDevice) a frame is IncidentOnDevice, the relaxation, ShadeOnDevice
// and QueueImage, and only the light samples go up and the image comes back (TakeImage, the
// frame's one wait). Incident and Shade above are these plus the transfers of q and the
// radiance. Frames pipeline over kFrameSlots slots: frame k's image and timestamps are kept in
// slot k % kFrameSlots, so the host can issue frame k + 1 before it takes frame k's image.
class DeviceRenderPasses : public RenderPasses {
 public:
  static constexpr int kFrameSlots = 2;
  // Pass 1 as Incident, q left on the GPU: level l's boundary node b, channel c at float
  // result[l].first + b * 3 + c of buffer result[l].buffer.
  virtual std::vector<DeviceFloats> IncidentOnDevice(const std::vector<LightSample>& samples) = 0;
  // Where ShadeOnDevice reads the finest level's radiance: c * num_boundary + b from first.
  virtual DeviceFloats RadianceOnDevice() = 0;
  // Pass 3 as Shade, with the radiance in RadianceOnDevice's buffer; the image stays on the
  // GPU until QueueImage.
  virtual void ShadeOnDevice(const PassView& camera, const std::vector<LightSample>& samples) = 0;
  // Queues the copy of the last ShadeOnDevice's image into `slot` (0 .. kFrameSlots - 1)
  // without waiting; TakeImage waits for that copy and returns the image. With persistent
  // maps (GlInfo::buffer_storage) it waits for nothing else, so commands issued after
  // QueueImage may still run; without, glGetBufferSubData may wait for more. A slot holds one
  // image until taken.
  virtual void QueueImage(int slot) = 0;
  virtual Image TakeImage(int slot) = 0;
  // Submits the commands issued so far to the GPU without waiting (glFlush), so that it works
  // while the host issues the next ones.
  virtual void Flush() = 0;
  // What the last frame issued leaves on the GPU: q of the finest level's boundary nodes, and
  // the radiance in RadianceOnDevice's buffer.
  virtual BoundaryLight ReadFinestQ() = 0;
  virtual BoundaryLight ReadRadiance() = 0;
  // Takes the slot's GPU timestamp k (0 .. 3) once the commands issued before it have
  // completed (GL_TIMESTAMP), without waiting; StampSeconds waits for the slot's four and
  // returns the seconds from stamp k to stamp k + 1 (k = 0, 1, 2).
  virtual void Stamp(int slot, int k) = 0;
  virtual std::array<double, 3> StampSeconds(int slot) = 0;
};

std::unique_ptr<RenderPasses> MakeCpuRenderPasses(const PassScene* scene);        // renderer.cc
std::unique_ptr<DeviceRenderPasses> MakeGlRenderPasses(const PassScene* scene);  // gl_render_passes.cc

}  // namespace translume
