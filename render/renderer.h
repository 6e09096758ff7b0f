// SPDX-License-Identifier: MIT
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "render/diffusion.h"
#include "render/polygrid.h"
#include "render/shape.h"
#include "solver/image.h"

namespace translume {

// A light for the incident-light pass (Section 5, first pass), z up:
//   dir:X,Y,Z    directional light from direction (X, Y, Z) (towards the light), irradiance 1
//   point:X,Y,Z  point light at (X, Y, Z) mm, irradiance 1 at the object's centre, 1/r^2
//   env:FILE     an environment map: a latitude-longitude HDR image (row 0 looks up +z, column
//                x at azimuth 2 pi (x + 0.5) / width from +x towards +y), loaded by the caller
//                into `environment` (this library does no file IO)
// Visibility from shadow maps: orthographic for dir, perspective for point (one map towards
// the centre where the bounding sphere fills at most a 60-degree half-angle from the light,
// else, nearer or inside the sphere, a cube map of six); for env, one
// orthographic map per direction sample (RenderOptions::environment_directions), so each node's
// irradiance sums only the unoccluded directions (ambient-occlusion visibility).
struct RenderLight {
  enum class Kind { kDirectional, kPoint, kEnvironment } kind = Kind::kDirectional;
  Vec3 v = Vec3(1, 1, 1);
  std::string path;                          // env: the file named in the spec
  std::shared_ptr<const Image> environment;  // env: the image
  static RenderLight Parse(const std::string& text);
};

// "" if `env` can be a latitude-longitude environment map (at least 2 x 1 pixels, every pixel
// finite), else the problem.
std::string EnvironmentMapProblem(const Image& env);

// The environment as `count` directions (a Fibonacci sphere) with the irradiance each carries:
// E_k = sum of L(pixel) dOmega(pixel) over the pixels nearest to direction k (RGB). Throws
// InputError on EnvironmentMapProblem.
std::vector<std::pair<Vec3, std::array<double, 3>>> EnvironmentSamples(const Image& env, int count);

struct RenderOptions {
  int width = 256, height = 256;
  int supersample = 2;           // s x s samples per pixel, box-filtered (antialiasing)
  double azimuth_deg = 30, elevation_deg = 25, fov_deg = 30;  // orbit camera around the centre
  // The eye's distance from the centre (mm); 0: as far as puts the whole bounding sphere in view
  // (1.15 R / sin(fov / 2)). Nearer is a close-up; an eye inside the bounding sphere is fine
  // (triangles reaching behind it are clipped), one inside the solid sees its inner faces.
  double camera_distance_mm = 0;
  double eta = 1.3;              // for the Fresnel transmittance F_t
  double specular = 0.04, roughness = 0.3;  // Ward isotropic rho_s, alpha
  double surface_reflectance = 0.0;         // optional Lambertian rho_d
  // "polygrid" (diffusion) or "dipole" (Jensen et al. 2001 BSSRDF, homogeneous materials).
  std::string model = "polygrid";
  int shadow_map_size = 512;  // environment maps use a quarter of it per direction
  int environment_directions = 64;

  std::string Validate() const;
};

// Pass timings of the last frame, seconds: host time (cpu backend, and the dipole model); on
// the gl backend GPU timestamps between the passes (the host waits only for the image), the
// incident pass's with the host's setup of the light samples before it.
struct FrameTimes {
  double incident = 0, diffusion = 0, shading = 0;
  // gl: the host's seconds to issue the diffusion pass's commands (it does not wait for the
  // GPU there). Near `diffusion`, the GPU waited for the host's commands; 0 on the cpu.
  double diffusion_issue = 0;
};

// Renders a shape with a polygrid hierarchy (finest first) and its per-level material.
class Renderer {
 public:
  Renderer(const Shape* shape, const std::vector<Polygrid>* levels,
           std::vector<NodeMaterial> materials, double C, const DiffusionOptions& diffusion,
           const RenderOptions& options);
  ~Renderer();
  // Linear RGB radiance image (width x height, 3 channels). `turn_deg` rotates camera and light
  // together about the z axis (a turntable, so the light moves relative to the object).
  // Submit then Collect, with no frame in flight (CHECK).
  Image Render(const RenderLight& light, double turn_deg = 0);
  // Pipelined frames: Submit issues a frame and Collect returns the oldest submitted frame's
  // image (the frames in the order submitted, each as Render would return it), with times()
  // then that frame's. On the gl backend Submit issues the frame's GPU work without waiting
  // for it, so submitting frame k + 1 before collecting frame k keeps the GPU busy while the
  // host takes frame k's image and sets up the next (a turntable, renderbench's "fps pipe");
  // elsewhere Submit renders the whole frame. At most kMaxInFlight frames submitted and not
  // collected (more is a bug: CHECK).
  static constexpr int kMaxInFlight = 2;
  void Submit(const RenderLight& light, double turn_deg = 0);
  Image Collect();
  int in_flight() const;
  const FrameTimes& times() const { return times_; }
  // Incident light q and outgoing radiance L at the finest level's boundary nodes of the last
  // frame submitted. The gl backend keeps them on the GPU; the first call after a frame reads
  // them back (waiting for that frame).
  const BoundaryLight& boundary_light() const;
  const BoundaryLight& boundary_radiance() const;
  // What a user should know about the diffusion's steps, one sentence each: levels whose
  // Chebyshev steps run with a smaller radius, or as Jacobi's (PolygridDiffusion::reduced_radii).
  std::vector<std::string> Notes() const;
  // The last frame's diffusion error in the paper's Figure 15 metric: E = sum (L - L0)^2 /
  // sum L0^2 over the finest level's boundary nodes and RGB, L0 the radiance of the converged
  // solution of the same equations and light (SolveReference, in double, with no hierarchy and
  // no adaptive depth, so E counts what the steps and the depth leave out; Figure 15 keeps it
  // below 5e-3). One sparse solve: a fraction of a second on a single cube at 17^3, seconds on
  // the bunny at 9^3, ~50 s at 17^3 (1 M nodes). The polygrid model only, after a frame.
  double ErrorAgainstConverged() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  FrameTimes times_;
  mutable BoundaryLight q_finest_, radiance_;
  mutable bool on_device_ = false;  // the last frame's q and radiance are on the GPU only
};

// Multiple-scattering radiance at the boundary nodes from the dipole BSSRDF (Jensen et al.
// 2001): L_b = (1 / pi) sum_b' R_d(|x_b - x_b'|) q_b' A_b' for a homogeneous material (kappa,
// mu per channel): sigma_a = mu, sigma_s' = 1 / (3 kappa) - mu, sigma_tr = sqrt(mu / kappa),
// z_r = 1 / sigma_t', z_v = z_r (1 + 4 C / 3). A_b', the surface area of boundary node b'
// (mm^2): `node_areas[b']` (BoundaryNodeAreas; the renderer scales them to the mesh's area), or
// where it is empty (mean boundary spacing)^2 for every node, which is blotchy where the nodes'
// spacing varies and falls short of the true area on curved surfaces (8 % on a sphere at 9^3).
// Sources within max(3 z_r, 2.5 mean spacings) of b, b itself included, where R_d changes
// within a patch, count as annuli instead: nearest first, each the ring by which a disc around
// b grows with the source's area, weighted by the closed-form integral of R_d over that ring
// (exact for uniform light on a plane whatever the spacing; sources at one distance share
// their rings, so rounding cannot reorder them; the node's own patch weighted by
// R_d(0) A_b instead overshot: 1.6x for 1 mm^2 at z_r = 0.6 mm).
// Far sources are summed per cell of 4 boundary spacings (Barnes-Hut style): a cell whose
// radius about its light-weighted centroid is below cluster_theta times its distance counts
// as one source of its summed q A at that centroid (0: every source on its own, O(n^2)).
BoundaryLight DipoleRadiance(const Polygrid& pg, const std::array<float, 3>& kappa,
                             const std::array<float, 3>& mu, double C, const BoundaryLight& q,
                             const std::vector<double>& node_areas = {}, double cluster_theta = 0.1);

// Tone map for 8-bit output: scale by 2^stops (any finite stops, negative darkens), or, without
// stops (auto exposure), so that the 99th percentile of the non-zero pixel values is 0.8; then
// the sRGB curve. Returns the scale used.
double ToneMap(Image* image, std::optional<double> stops);

// Fresnel transmittance 1 - F_r for unpolarised light entering a dielectric of relative index
// eta at incidence cosine cos_i.
double FresnelTransmittance(double cos_i, double eta);

}  // namespace translume
