// SPDX-License-Identifier: MIT
#include "render/renderer.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <deque>
#include <fmt/format.h>
#include <limits>
#include <sstream>

#include "render/boundary_interpolation.h"
#include "render/render_passes.h"
#include "solver/evaluate.h"
#include "solver/status.h"

namespace translume {
namespace {

constexpr double kPi = 3.14159265358979323846;

double Seconds(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// Z-buffer rasterisation: per pixel (sample at its centre) the nearest triangle, the
// barycentrics of the point under the pixel (perspective-correct) and its depth
// (RasterTriangle). raster.comp is the same in float.
struct Raster {
  int width = 0, height = 0;
  std::vector<float> depth;
  std::vector<int32_t> tri;
  std::vector<float> b1, b2;

  void Draw(const PassView& view, const TriangleMesh& mesh) {
    width = view.width;
    height = view.height;
    depth.assign(size_t(width) * height, 1e30f);
    tri.assign(depth.size(), -1);
    b1.assign(depth.size(), 0.f);
    b2.assign(depth.size(), 0.f);
    std::vector<Eigen::Vector4d> s(mesh.vertices.size());
    for (size_t i = 0; i < s.size(); ++i) s[i] = view.Homogeneous(mesh.vertices[i]);
    for (size_t t = 0; t < mesh.triangles.size(); ++t) {
      const RasterTriangle tr({s[mesh.triangles[t][0]], s[mesh.triangles[t][1]], s[mesh.triangles[t][2]]});
      std::array<int, 4> box;
      if (!tr.Bounds(view.near, width, height, &box)) continue;
      for (int y = box[1]; y <= box[3]; ++y)
        for (int x = box[0]; x <= box[2]; ++x) {
          Vec3 l;
          double z;
          if (!tr.Hit(x + 0.5, y + 0.5, view.near, &l, &z)) continue;
          const size_t i = size_t(y) * width + x;
          if (z < depth[i]) {
            depth[i] = float(z);
            tri[i] = int32_t(t);
            b1[i] = float(l[1]);
            b2[i] = float(l[2]);
          }
        }
    }
  }
};

}  // namespace

int CubeFace(const Vec3& d) {
  const Vec3 a = d.cwiseAbs();
  const int axis = a.x() >= a.y() && a.x() >= a.z() ? 0 : a.y() >= a.z() ? 1 : 2;
  return 2 * axis + (d[axis] < 0 ? 1 : 0);
}

PassView PassView::LookAt(const Vec3& eye, const Vec3& target, int w, int h, bool ortho, double scale) {
  PassView v;
  v.eye = eye;
  v.forward = (target - eye).normalized();
  Vec3 up_hint = std::abs(v.forward.z()) > 0.99 ? Vec3(0, 1, 0) : Vec3(0, 0, 1);
  v.right = v.forward.cross(up_hint).normalized();
  v.up = v.right.cross(v.forward);
  v.ortho = ortho;
  v.scale = scale;
  v.width = w;
  v.height = h;
  v.near = 1e-6 * (target - eye).norm();
  return v;
}

Eigen::Vector4d PassView::Homogeneous(const Vec3& p) const {
  const Vec3 d = p - eye;
  const double x = d.dot(right), y = d.dot(up), z = d.dot(forward);
  const double w = ortho ? 1 : z, aspect = double(width) / height;
  return {0.5 * width * (w + x * scale / aspect), 0.5 * height * (w - y * scale), w, z};
}

RasterTriangle::RasterTriangle(const std::array<Eigen::Vector4d, 3>& h) : h_(h) {
  for (int i = 0; i < 3; ++i) {
    const Vec3 a = h[(i + 1) % 3].head<3>(), b = h[(i + 2) % 3].head<3>();
    planes_.row(i) = a.cross(b).transpose();
    depth_[i] = h[i][3];
  }
}

bool RasterTriangle::Bounds(double near, int width, int height, std::array<int, 4>* box) const {
  const auto& h = h_;
  double lo[2] = {1e300, 1e300}, hi[2] = {-1e300, -1e300};
  const auto add = [&](const Eigen::Vector4d& p) {
    for (int k = 0; k < 2; ++k) {
      lo[k] = std::min(lo[k], p[k] / p[2]);
      hi[k] = std::max(hi[k], p[k] / p[2]);
    }
  };
  for (int i = 0; i < 3; ++i) {
    const Eigen::Vector4d& p = h[i];
    const Eigen::Vector4d& q = h[(i + 1) % 3];
    const double dp = p[3] - near, dq = q[3] - near;
    if (dp >= 0) add(p);
    if ((dp < 0) != (dq < 0)) add(p + dp / (dp - dq) * (q - p));  // on the near plane (w > 0)
  }
  if (!(lo[0] <= hi[0] && lo[1] <= hi[1])) return false;
  // Clamped before the conversion: the clipped part of a triangle next to the eye projects far
  // off the raster.
  const auto pixel = [](double v, int n) { return int(std::clamp(v, -1.0, double(n))); };
  *box = {std::max(0, pixel(std::floor(lo[0]), width)), std::max(0, pixel(std::floor(lo[1]), height)),
          std::min(width - 1, pixel(std::ceil(hi[0]), width)), std::min(height - 1, pixel(std::ceil(hi[1]), height))};
  return (*box)[0] <= (*box)[2] && (*box)[1] <= (*box)[3];
}

Vec3 PassView::Project(const Vec3& p) const {
  const Vec3 d = p - eye;
  const double x = d.dot(right), y = d.dot(up), z = d.dot(forward);
  const double aspect = double(width) / height;
  const double k = ortho ? scale : scale / std::max(z, 1e-9);
  return Vec3(0.5 * width * (1 + x * k / aspect), 0.5 * height * (1 - y * k), z);
}

RenderLight RenderLight::Parse(const std::string& text) {
  RenderLight l;
  const auto colon = text.find(':');
  const std::string kind = text.substr(0, colon);
  if (kind == "env") {
    l.kind = Kind::kEnvironment;
    l.path = colon == std::string::npos ? "" : text.substr(colon + 1);
    if (l.path.empty()) throw InputError("--light " + text + ": expected env:FILE (a lat-long HDR image)");
    return l;
  }
  if (colon == std::string::npos || (kind != "dir" && kind != "point"))
    throw InputError("--light " + text + ": expected dir:X,Y,Z, point:X,Y,Z or env:FILE");
  l.kind = kind == "dir" ? Kind::kDirectional : Kind::kPoint;
  std::istringstream in(text.substr(colon + 1));
  char c1 = 0, c2 = 0;
  std::string rest;
  if (!(in >> l.v.x() >> c1 >> l.v.y() >> c2 >> l.v.z()) || c1 != ',' || c2 != ',' || (in >> rest) ||
      !l.v.allFinite())
    throw InputError("--light " + text + ": expected three numbers X,Y,Z");
  if (l.kind == Kind::kDirectional) {
    if (l.v.norm() == 0) throw InputError("--light " + text + ": the direction must be non-zero");
    l.v /= l.v.cwiseAbs().maxCoeff();  // |v| of 1e308 components overflows
    l.v.normalize();
  }
  return l;
}

std::string RenderOptions::Validate() const {
  if (width < 1 || height < 1 || width > 16384 || height > 16384)
    return "the image size must be 1..16384 pixels per side";
  if (supersample < 1 || supersample > 8) return "supersample must be 1..8";
  // The camera's raster holds (width S) x (height S) samples, 16 bytes each, indexed by a
  // 32-bit int on the gl backend.
  if (const int64_t samples = int64_t(width) * supersample * int64_t(height) * supersample;
      samples > std::numeric_limits<int32_t>::max())
    return fmt::format("{}x{} pixels at supersample {} are {} samples (~{} GB of raster); at most 2^31 - 1: "
                       "lower the image size or the supersampling", width, height, supersample, samples,
                       samples * 16 / 1000000000);
  if (!(fov_deg > 1 && fov_deg < 170)) return "the field of view must be in (1, 170) degrees";
  if (!std::isfinite(azimuth_deg) || !std::isfinite(elevation_deg)) return "the camera angles must be finite";
  if (!(camera_distance_mm >= 0 && std::isfinite(camera_distance_mm)))
    return "the camera distance must be >= 0 mm (0: fit the object)";
  if (!(eta >= 1 && std::isfinite(eta))) return "eta must be a finite number >= 1";
  if (!(specular >= 0 && std::isfinite(specular))) return fmt::format("--specular must be a finite number >= 0, got {}", specular);
  if (!(surface_reflectance >= 0 && surface_reflectance <= 1))
    return fmt::format("--reflectance must be within 0..1, got {}", surface_reflectance);
  if (!(roughness > 0 && std::isfinite(roughness))) return fmt::format("--roughness must be a finite number > 0, got {}", roughness);
  if (model != "polygrid" && model != "dipole") return "the model must be polygrid or dipole";
  if (shadow_map_size < 16) return "the shadow map must be >= 16 pixels";
  if (environment_directions < 1 || environment_directions > 4096)
    return "environment_directions must be 1..4096";
  return "";
}

double FresnelTransmittance(double cos_i, double eta) {
  cos_i = std::clamp(cos_i, 0.0, 1.0);
  const double sin_t2 = (1 - cos_i * cos_i) / (eta * eta);
  if (sin_t2 >= 1) return 0;
  const double cos_t = std::sqrt(1 - sin_t2);
  const double rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
  const double rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
  return 1 - 0.5 * (rs * rs + rp * rp);
}

namespace {

// The boundary nodes binned in a uniform grid of cubic cells over their bounds (at most
// max_dims cells per axis); cells[Index(x, y, z)] lists the nodes (b - num_interior) in a cell.
struct NodeGrid {
  Vec3 lo = Vec3::Constant(1e300);
  double cell = 0;
  std::array<int, 3> dims = {1, 1, 1};
  std::vector<std::vector<int32_t>> cells;

  NodeGrid(const Polygrid& pg, double cell_mm, int max_dims) {
    Vec3 hi = Vec3::Constant(-1e300);
    for (int64_t b = pg.num_interior; b < pg.size(); ++b) {
      lo = lo.cwiseMin(pg.position[b]);
      hi = hi.cwiseMax(pg.position[b]);
    }
    cell = std::max(cell_mm, 1e-6 * (hi - lo).norm() + 1e-12);
    for (int a = 0; a < 3; ++a) dims[a] = std::clamp(int((hi[a] - lo[a]) / cell) + 1, 1, max_dims);
    cells.resize(size_t(dims[0]) * dims[1] * dims[2]);
    for (int64_t b = pg.num_interior; b < pg.size(); ++b) {
      const auto c = CellOf(pg.position[b]);
      cells[Index(c[0], c[1], c[2])].push_back(int32_t(b - pg.num_interior));
    }
  }
  // The cell holding p, clamped to the grid.
  std::array<int, 3> CellOf(const Vec3& p) const {
    std::array<int, 3> c;
    for (int a = 0; a < 3; ++a) c[a] = std::clamp(int(std::floor((p[a] - lo[a]) / cell)), 0, dims[a] - 1);
    return c;
  }
  size_t Index(int x, int y, int z) const { return x + size_t(dims[0]) * (y + size_t(dims[1]) * z); }
};

}  // namespace

BoundaryLight DipoleRadiance(const Polygrid& pg, const std::array<float, 3>& kappa,
                             const std::array<float, 3>& mu, double C, const BoundaryLight& q,
                             const std::vector<double>& node_areas, double cluster_theta) {
  const int64_t nb = pg.num_boundary();
  TL_CHECK(node_areas.empty() || int64_t(node_areas.size()) == nb);
  const double spacing_area = pg.mean_boundary_spacing * pg.mean_boundary_spacing;
  auto area_of = [&](int64_t s) { return node_areas.empty() ? spacing_area : node_areas[s]; };
  auto pos = [&](int64_t s) -> const Vec3& { return pg.position[pg.num_interior + s]; };
  // Sources in cubic cells of 4 boundary spacings.
  std::vector<std::vector<int32_t>> members = NodeGrid(pg, 4 * pg.mean_boundary_spacing, 256).cells;
  std::erase_if(members, [](const std::vector<int32_t>& m) { return m.empty(); });
  BoundaryLight L;
  for (int c = 0; c < 3; ++c) {
    // A grey material under white light: the channel repeats an earlier one.
    if (const int same = [&] {
          for (int e = 0; e < c; ++e)
            if (kappa[e] == kappa[c] && mu[e] == mu[c] && q[e] == q[c]) return e;
          return -1;
        }();
        same >= 0) {
      L[c] = L[same];
      continue;
    }
    const double sa = mu[c], ss = std::max(1e-6, 1 / (3.0 * kappa[c]) - mu[c]);
    const double st = sa + ss, alpha = ss / st, tr = std::sqrt(sa / kappa[c]);
    const double zr = 1 / st, zv = zr * (1 + 4 * C / 3);
    L[c].assign(nb, 0.f);
    auto rd = [&](double r2) {
      const double dr = std::sqrt(r2 + zr * zr), dv = std::sqrt(r2 + zv * zv);
      return alpha / (4 * kPi) *
             (zr * (tr * dr + 1) * std::exp(-tr * dr) / (dr * dr * dr) +
              zv * (tr * dv + 1) * std::exp(-tr * dv) / (dv * dv * dv));
    };
    // int_0^rho R_d(r) 2 pi r dr in closed form, since (sigma d + 1) e^(-sigma d) r / d^3 =
    // -d/dr (e^(-sigma d) / d) with d = sqrt(r^2 + z^2).
    auto disc = [&](double rho2) {
      const double dr = std::sqrt(rho2 + zr * zr), dv = std::sqrt(rho2 + zv * zv);
      return alpha / 2 *
             (zr * (std::exp(-tr * zr) / zr - std::exp(-tr * dr) / dr) +
              zv * (std::exp(-tr * zv) / zv - std::exp(-tr * dv) / dv));
    };
    // Per cell: its light q A, the centroid of its sources weighted by q A (a dark cell: their
    // mean position), and its radius about that centroid.
    struct Cluster {
      double qa = 0, radius = 0;
      Vec3 centre = Vec3::Zero();
    };
    std::vector<Cluster> clusters(members.size());
    for (size_t k = 0; k < members.size(); ++k) {
      Cluster& cl = clusters[k];
      for (int32_t s : members[k]) cl.qa += q[c][s] * area_of(s), cl.centre += q[c][s] * area_of(s) * pos(s);
      if (cl.qa > 0) {
        cl.centre /= cl.qa;
      } else {
        for (int32_t s : members[k]) cl.centre += pos(s) / double(members[k].size());
      }
      for (int32_t s : members[k]) cl.radius = std::max(cl.radius, (pos(s) - cl.centre).norm());
    }
    const double near = std::max(3 * zr, 2.5 * pg.mean_boundary_spacing);
#pragma omp parallel for schedule(dynamic, 16)
    for (int64_t b = 0; b < nb; ++b) {
      const Vec3& x = pos(b);
      double acc = 0;
      std::vector<std::pair<double, int64_t>> close;  // (r^2, source) within `near`
      for (size_t k = 0; k < members.size(); ++k) {
        const Cluster& cl = clusters[k];
        if (cl.qa == 0) {
          // Dark sources add no light but still take their ring of a near node's disc.
          if ((x - cl.centre).norm() > near + cl.radius) continue;
        } else if (cluster_theta > 0) {
          const double D = (x - cl.centre).norm();
          if (D > near + cl.radius && cl.radius < cluster_theta * (D - cl.radius)) {
            acc += rd(D * D) * cl.qa;
            continue;
          }
        }
        for (int32_t s : members[k]) {
          const double r2 = (x - pos(s)).squaredNorm();
          if (r2 < near * near)
            close.emplace_back(r2, s);
          else if (q[c][s] != 0)
            acc += rd(r2) * q[c][s] * area_of(s);
        }
      }
      // Near sources, where R_d changes within a node's patch: the patches, nearest first, as
      // the annuli of a disc that grows by each one's area (exact for uniform light on a
      // plane whatever the nodes' spacing).
      std::sort(close.begin(), close.end());
      double area = 0;
      for (size_t i = 0; i < close.size();) {
        // Sources at one distance (to rounding) share their rings, so that the order among
        // them, which rounding decides, does not matter.
        size_t j = i;
        double group_area = 0, group_qa = 0;
        for (; j < close.size() && close[j].first <= close[i].first * (1 + 1e-9) + 1e-18; ++j) {
          group_area += area_of(close[j].second);
          group_qa += q[c][close[j].second] * area_of(close[j].second);
        }
        const double before = disc(area / kPi);
        area += group_area;
        if (group_area > 0) acc += group_qa / group_area * (disc(area / kPi) - before);  // else no ring
        i = j;
      }
      L[c][b] = float(acc / kPi);
    }
  }
  return L;
}

std::string EnvironmentMapProblem(const Image& env) {
  if (env.width < 2 || env.height < 1 || env.channels < 1)
    return fmt::format("a {}x{} image of {} channels: a latitude-longitude map needs at least 2x1 pixels",
                       env.width, env.height, env.channels);
  return NonFinitePixel(env);
}

std::vector<std::pair<Vec3, std::array<double, 3>>> EnvironmentSamples(const Image& env, int count) {
  if (const std::string problem = EnvironmentMapProblem(env); !problem.empty())
    throw InputError("--light env: " + problem);
  std::vector<std::pair<Vec3, std::array<double, 3>>> out(count);
  const double golden = kPi * (3 - std::sqrt(5.0));
  for (int k = 0; k < count; ++k) {
    const double z = 1 - (k + 0.5) * 2.0 / count, r = std::sqrt(std::max(0.0, 1 - z * z));
    out[k].first = Vec3(r * std::cos(golden * k), r * std::sin(golden * k), z);
    out[k].second = {0, 0, 0};
  }
  // Each pixel's radiance times its solid angle goes to the nearest direction (a Voronoi
  // partition of the sphere), so sum_k E_k is the integral of the map over the sphere.
  for (int y = 0; y < env.height; ++y) {
    const double theta = kPi * (y + 0.5) / env.height;
    // The row's exact solid angle over its pixels: (2 pi / W) (cos theta_0 - cos theta_1).
    const double domega =
        (2 * kPi / env.width) * (std::cos(kPi * y / env.height) - std::cos(kPi * (y + 1) / env.height));
    for (int x = 0; x < env.width; ++x) {
      const double phi = 2 * kPi * (x + 0.5) / env.width;
      const Vec3 d(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta));
      int best = 0;
      double best_dot = -2;
      for (int k = 0; k < count; ++k)
        if (const double dd = d.dot(out[k].first); dd > best_dot) best_dot = dd, best = k;
      for (int c = 0; c < 3; ++c) {
        const float v = env.at(x, y, std::min(c, env.channels - 1));
        if (v > 0) out[best].second[c] += v * domega;
      }
    }
  }
  return out;
}

double ToneMap(Image* image, std::optional<double> stops) {
  double scale = stops ? std::pow(2.0, *stops) : 1.0;
  if (!stops) {
    std::vector<float> v;
    for (float x : image->data)
      if (x > 0) v.push_back(x);
    if (!v.empty()) {
      const size_t k = std::min(v.size() - 1, size_t(0.99 * v.size()));
      std::nth_element(v.begin(), v.begin() + k, v.end());
      if (v[k] > 0) scale = 0.8 / v[k];
    }
  }
  for (float& x : image->data) {
    const double y = std::clamp(x * scale, 0.0, 1.0);
    x = float(y <= 0.0031308 ? 12.92 * y : 1.055 * std::pow(y, 1 / 2.4) - 0.055);
  }
  return scale;
}


namespace {

// The cpu implementation of passes 1 and 3 (OpenMP, double; render_passes.h).
class CpuRenderPasses : public RenderPasses {
 public:
  explicit CpuRenderPasses(const PassScene* scene) : sc_(*scene) {}

  std::vector<BoundaryLight> Incident(const std::vector<LightSample>& samples) override {
    shadows_.assign(samples.size(), Raster());
    for (size_t s = 0; s < samples.size(); ++s) shadows_[s].Draw(samples[s].view, *sc_.mesh);
    std::vector<BoundaryLight> q(sc_.levels->size());
    for (size_t l = 0; l < sc_.levels->size(); ++l) {
      const Polygrid& pg = (*sc_.levels)[l];
      for (int c = 0; c < 3; ++c) q[l][c].assign(pg.num_boundary(), 0.f);
#pragma omp parallel for schedule(static) if (pg.num_boundary() > 20000)
      for (int64_t b = 0; b < pg.num_boundary(); ++b) {
        double acc[3] = {0, 0, 0};
        for (size_t s = 0; s < samples.size(); ++s) {
          double cos_i;
          Vec3 dir;
          const double e = Light(samples, s, pg.position[pg.num_interior + b], pg.normal[b], &cos_i, &dir);
          if (e == 0) continue;
          const double v = e * cos_i * FresnelTransmittance(cos_i, sc_.options.eta);
          for (int c = 0; c < 3; ++c) acc[c] += v * samples[s].E[c];
        }
        for (int c = 0; c < 3; ++c) q[l][c][b] = float(acc[c]);
      }
    }
    return q;
  }

  Image Shade(const PassView& cam, const BoundaryLight& radiance,
              const std::vector<LightSample>& samples) override {
    const RenderOptions& o = sc_.options;
    const TriangleMesh& mesh = *sc_.mesh;
    std::vector<std::array<float, 3>> vrad(mesh.vertices.size());
    for (size_t v = 0; v < mesh.vertices.size(); ++v)
      for (int c = 0; c < 3; ++c) {
        double acc = 0;
        for (int k = 0; k < 4; ++k) acc += sc_.near_w[v][k] * radiance[c][sc_.near_idx[v][k]];
        vrad[v][c] = float(acc);
      }
    const int ss = o.supersample, W = cam.width, H = cam.height;
    Raster r;
    r.Draw(cam, mesh);
    Image img;
    img.width = W / ss;
    img.height = H / ss;
    img.channels = 3;
    img.data.assign(size_t(img.width) * img.height * 3, 0.f);
    const double alpha2 = o.roughness * o.roughness;
#pragma omp parallel for schedule(dynamic, 4)
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const size_t i = size_t(y) * W + x;
        if (r.tri[i] < 0) continue;
        const auto& tr = mesh.triangles[r.tri[i]];
        const double w1 = r.b1[i], w2 = r.b2[i], w0 = 1 - w1 - w2;
        const Vec3 p = w0 * mesh.vertices[tr[0]] + w1 * mesh.vertices[tr[1]] + w2 * mesh.vertices[tr[2]];
        const Vec3 n = (w0 * sc_.vertex_normals[tr[0]] + w1 * sc_.vertex_normals[tr[1]] +
                        w2 * sc_.vertex_normals[tr[2]]).normalized();
        const Vec3 view = (cam.eye - p).normalized();
        const double cos_o = std::max(0.0, n.dot(view));
        const double ft = FresnelTransmittance(cos_o, o.eta);
        double surface[3] = {0, 0, 0};
        if (cos_o > 0 && (o.specular > 0 || o.surface_reflectance > 0)) {
          for (size_t s = 0; s < samples.size(); ++s) {
            double cos_i;
            Vec3 l;
            const double e = Light(samples, s, p, n, &cos_i, &l);
            if (e == 0) continue;
            const Vec3 hv = (l + view).normalized();
            const double cd = std::clamp(n.dot(hv), 1e-6, 1.0);
            const double tan2 = (1 - cd * cd) / (cd * cd);
            const double ward = o.specular * std::exp(-tan2 / alpha2) / (4 * kPi * alpha2 * std::sqrt(cos_i * cos_o));
            for (int c = 0; c < 3; ++c)
              surface[c] += (ward + o.surface_reflectance / kPi) * e * cos_i * samples[s].E[c];
          }
        }
        for (int c = 0; c < 3; ++c) {
          const double ms = w0 * vrad[tr[0]][c] + w1 * vrad[tr[1]][c] + w2 * vrad[tr[2]][c];
          const double value = (ft * ms + surface[c]) / (ss * ss);
#pragma omp atomic
          img.data[(size_t(y / ss) * img.width + x / ss) * 3 + c] += float(value);
        }
      }
    return img;
  }

 private:
  // Irradiance factor (falloff x visibility) of sample s at p with normal n; cos_i and the
  // direction l towards the light.
  double Light(const std::vector<LightSample>& samples, size_t s, const Vec3& p, const Vec3& n,
               double* cos_i, Vec3* l) const {
    const LightSample& smp = samples[s];
    double e = 1;
    if (!smp.point) {
      *l = smp.v;
    } else {
      *l = smp.v - p;
      e = (smp.v - sc_.centre).squaredNorm() / std::max(1e-12, l->squaredNorm());
      l->normalize();
    }
    *cos_i = n.dot(*l);
    if (*cos_i <= 0) return 0.0;
    if (smp.cube_face >= 0 && CubeFace(p - smp.v) != smp.cube_face) return 0.0;
    // Every point drawn lies in its map (the maps cover the bounding sphere, a cube face its
    // own directions); the clamp keeps a point on a map's edge (p - v on a cube face's
    // boundary projects to x = S) on its edge texel.
    const Vec3 sp = smp.view.Project(p);
    const int S = smp.view.width;
    const int x = int(std::clamp(sp.x(), 0.0, S - 1.0)), y = int(std::clamp(sp.y(), 0.0, S - 1.0));
    if (sp.z() > shadows_[s].depth[size_t(y) * S + x] + sc_.shadow_bias) return 0.0;
    return e;
  }

  const PassScene& sc_;
  std::vector<Raster> shadows_;
};

}  // namespace

std::unique_ptr<RenderPasses> MakeCpuRenderPasses(const PassScene* scene) {
  return std::make_unique<CpuRenderPasses>(scene);
}

std::unique_ptr<RenderPasses> RenderPasses::Create(DiffusionBackend backend, const PassScene* scene) {
  if (backend == DiffusionBackend::kGl) return MakeGlRenderPasses(scene);
  return MakeCpuRenderPasses(scene);
}

struct Renderer::Impl {
  const Shape* shape;
  const std::vector<Polygrid>* levels;
  std::vector<NodeMaterial> materials;
  double C;
  std::unique_ptr<PolygridDiffusion> diffusion;
  PassScene scene;
  std::unique_ptr<RenderPasses> passes;
  // The gl passes where the diffusion is gl too: the frame stays on the GPU (else null).
  DeviceRenderPasses* device = nullptr;
  // The environment's direction samples, computed once per environment image.
  const Image* env_source = nullptr;
  TriangleMesh shading_mesh;  // ShadingMesh of the shape's
  std::vector<double> node_areas;  // the finest boundary nodes' areas, mm^2 (dipole)
  std::vector<std::pair<Vec3, std::array<double, 3>>> env;
  // Frames submitted and not collected, oldest first: on the GPU, the slot of its image and
  // timestamps and the host's seconds (setup, issue); else the image and times.
  struct Pending {
    int slot = -1;
    double setup = 0, issue = 0;
    Image image;
    FrameTimes times;
  };
  std::deque<Pending> pending;
  int next_slot = 0;
};
static_assert(Renderer::kMaxInFlight <= DeviceRenderPasses::kFrameSlots);

Renderer::Renderer(const Shape* shape, const std::vector<Polygrid>* levels,
                   std::vector<NodeMaterial> materials, double C, const DiffusionOptions& diffusion,
                   const RenderOptions& options)
    : impl_(std::make_unique<Impl>()) {
  if (std::string err = options.Validate(); !err.empty()) throw InputError("render: " + err);
  Impl& I = *impl_;
  I.shape = shape;
  I.levels = levels;
  I.materials = materials;
  I.C = C;
  if (options.model == "polygrid")
    I.diffusion = std::make_unique<PolygridDiffusion>(levels, std::move(materials), C, diffusion);
  PassScene& sc = I.scene;
  sc.options = options;
  sc.levels = levels;
  const Polygrid& pg = (*levels)[0];
  const int64_t nb = pg.num_boundary();
  // Vertices about as dense as the boundary nodes (their radiance is interpolated from them).
  I.shading_mesh = ShadingMesh(shape->mesh(), pg.mean_boundary_spacing,
                               std::max<int64_t>(int64_t(shape->mesh().vertices.size()), 2 * nb), &sc.vertex_normals);
  sc.mesh = &I.shading_mesh;
  if (options.model == "dipole") I.node_areas = BoundaryNodeAreas(pg, shape->mesh().Area());
  const TriangleMesh& mesh = I.shading_mesh;
  sc.centre = (shape->lo + shape->hi) / 2;
  sc.radius = 0;  // bounding sphere about the box centre
  for (const Vec3& v : mesh.vertices) sc.radius = std::max(sc.radius, (v - sc.centre).norm());
  sc.shadow_bias = 0.03 * sc.radius;
  sc.near_idx.resize(mesh.vertices.size());
  sc.near_w.resize(mesh.vertices.size());
  // The 4 nearest boundary nodes of every vertex, through a uniform grid of the nodes (cells of
  // about two node spacings), searched in rings of growing Chebyshev radius until no unvisited
  // cell can hold a nearer node than the 4th found.
  const NodeGrid grid(pg, 2 * pg.mean_boundary_spacing, 512);
  const BoundaryElements elements(pg);
#pragma omp parallel for schedule(dynamic, 64)
  for (int64_t v = 0; v < int64_t(mesh.vertices.size()); ++v) {
    const Vec3& x = mesh.vertices[v];
    std::array<std::pair<double, int32_t>, 4> best;
    best.fill({1e300, 0});
    const auto c = grid.CellOf(x);
    // Distance from x to its (clamped) cell's box: the cells of ring r + 1 are at least
    // r * cell - outside away.
    double outside = 0;
    for (int a = 0; a < 3; ++a) {
      const double lo = grid.lo[a] + c[a] * grid.cell, hi = lo + grid.cell;
      outside = std::max({outside, lo - x[a], x[a] - hi});
    }
    const int max_r = std::max({grid.dims[0], grid.dims[1], grid.dims[2]});
    for (int r = 0; r <= max_r; ++r) {
      ForEachCellInRing(c, r, grid.dims, [&](int cx, int cy, int cz) {
        for (int32_t b : grid.cells[grid.Index(cx, cy, cz)]) {
          const double d2 = (x - pg.position[pg.num_interior + b]).squaredNorm();
          if (d2 >= best[3].first) continue;
          best[3] = {d2, b};
          std::sort(best.begin(), best.end());
        }
      });
      const double bound = r * grid.cell - outside;
      if (best[3].first < 1e300 && bound > 0 && best[3].first <= bound * bound) break;
    }
    if (elements.Weights(x, {best[0].second, best[1].second, best[2].second, best[3].second}, &sc.near_idx[v],
                         &sc.near_w[v]))
      continue;
    // More than a boundary spacing from every element: inverse-distance weights.
    double wsum = 0;
    for (int k = 0; k < 4; ++k) {
      const double w = 1 / (best[k].first + 1e-6 * pg.mean_boundary_spacing * pg.mean_boundary_spacing);
      sc.near_idx[v][k] = best[k].second;
      sc.near_w[v][k] = float(w);
      wsum += w;
    }
    for (int k = 0; k < 4; ++k) sc.near_w[v][k] = float(sc.near_w[v][k] / wsum);
  }
  if (diffusion.backend == DiffusionBackend::kGl) {
    std::unique_ptr<DeviceRenderPasses> gl = MakeGlRenderPasses(&sc);
    if (I.diffusion) I.device = gl.get();
    I.passes = std::move(gl);
  } else {
    I.passes = MakeCpuRenderPasses(&sc);
  }
}

const BoundaryLight& Renderer::boundary_light() const {
  if (on_device_) {
    q_finest_ = impl_->device->ReadFinestQ();
    radiance_ = impl_->device->ReadRadiance();
    on_device_ = false;
  }
  return q_finest_;
}

std::vector<std::string> Renderer::Notes() const {
  std::vector<std::string> notes;
  const PolygridDiffusion* d = impl_->diffusion.get();
  if (d && d->reduced_radii() > 0)
    notes.push_back(fmt::format(
        "{} of the {} level channels take Chebyshev's steps with a smaller spectral radius than estimated "
        "(with the estimate they would grow on this grid, whose rows are far from symmetric) and converge "
        "more slowly{}",
        d->reduced_radii(), 3 * impl_->levels->size(),
        d->jacobi_fallbacks() > 0
            ? fmt::format("; {} of them take Jacobi's steps, much more slowly: raise --iterations", d->jacobi_fallbacks())
            : "; --check-error measures what a frame's steps leave"));
  return notes;
}

double Renderer::ErrorAgainstConverged() const {
  const Impl& I = *impl_;
  TL_CHECK_MSG(I.diffusion, "ErrorAgainstConverged: the dipole model has no diffusion to converge");
  const Polygrid& pg = (*I.levels)[0];
  TL_CHECK_MSG(boundary_light()[0].size() == size_t(pg.num_boundary()), "ErrorAgainstConverged: no frame rendered yet");
  const std::vector<float> phi =
      SolveReference(BuildJacobiSystem(pg, I.materials[0], I.C, boundary_light()), 3, pg.size() > 100000);
  return RelightingError({boundary_radiance()}, {ShadedRadiance(pg, I.materials[0], phi)});
}

const BoundaryLight& Renderer::boundary_radiance() const {
  boundary_light();
  return radiance_;
}

Renderer::~Renderer() = default;

Image Renderer::Render(const RenderLight& light, double turn_deg) {
  TL_CHECK_MSG(impl_->pending.empty(), "Renderer::Render with frames in flight (it would return the oldest)");
  Submit(light, turn_deg);
  return Collect();
}

int Renderer::in_flight() const { return int(impl_->pending.size()); }

Image Renderer::Collect() {
  Impl& I = *impl_;
  TL_CHECK_MSG(!I.pending.empty(), "Renderer::Collect: no frame submitted");
  Impl::Pending p = std::move(I.pending.front());
  I.pending.pop_front();
  if (p.slot < 0) {
    times_ = p.times;
    return std::move(p.image);
  }
  Image img = I.device->TakeImage(p.slot);
  const std::array<double, 3> gpu = I.device->StampSeconds(p.slot);
  times_.incident = p.setup + gpu[0];
  times_.diffusion = gpu[1];
  times_.shading = gpu[2];
  times_.diffusion_issue = p.issue;
  return img;
}

void Renderer::Submit(const RenderLight& light_in, double turn_deg) {
  Impl& I = *impl_;
  TL_CHECK_MSG(int(I.pending.size()) < kMaxInFlight, "Renderer::Submit: kMaxInFlight frames not collected");
  const RenderOptions& o = I.scene.options;
  const auto rot = [&](const Vec3& v) {
    const double a = turn_deg * kPi / 180;
    return Vec3(std::cos(a) * v.x() - std::sin(a) * v.y(), std::sin(a) * v.x() + std::cos(a) * v.y(), v.z());
  };
  RenderLight light = light_in;
  light.v = rot(light.v);

  // Pass 1: incident light at the boundary nodes of every level, shadow-map visibility. Every
  // light is a list of samples: one for dir and distant point lights, six for a point light
  // near the object (a cube map), one per direction for an environment map (EnvironmentSamples).
  auto t0 = std::chrono::steady_clock::now();
  const Vec3& centre = I.scene.centre;
  const double radius = I.scene.radius;
  std::vector<LightSample> samples;
  LightSample smp;
  smp.v = light.v;
  smp.E = {1, 1, 1};
  if (light.kind == RenderLight::Kind::kEnvironment) {
    if (I.env_source != light.environment.get()) {
      I.env = EnvironmentSamples(*light.environment, o.environment_directions);
      I.env_source = light.environment.get();
    }
    const int S = I.env.size() > 1 ? std::max(16, o.shadow_map_size / 4) : o.shadow_map_size;
    for (const auto& [dir, E] : I.env) {
      smp.v = rot(dir);
      smp.E = E;
      smp.view = PassView::LookAt(centre + 3 * radius * smp.v, centre, S, S, true, 1 / radius);
      samples.push_back(smp);
    }
  } else if (light.kind == RenderLight::Kind::kDirectional) {
    const int S = o.shadow_map_size;
    smp.view = PassView::LookAt(centre + 3 * radius * smp.v, centre, S, S, true, 1 / radius);
    samples.push_back(smp);
  } else {
    // A point light sees the bounding sphere within the half-angle asin(radius / distance): up
    // to 60 degrees one perspective map holds it; nearer (and inside the sphere, where the
    // object may lie in every direction) a cube map of six 90-degree frusta, as many texels
    // each.
    const int S = o.shadow_map_size;
    smp.point = true;
    const double sin_half = radius / std::max(1e-9, (smp.v - centre).norm());
    if (sin_half <= std::sin(kPi / 3)) {
      smp.view = PassView::LookAt(smp.v, centre, S, S, false, 1 / std::tan(std::asin(sin_half)));
      samples.push_back(smp);
    } else {
      for (int f = 0; f < 6; ++f) {
        Vec3 axis = Vec3::Zero();
        axis[f / 2] = f % 2 ? -1 : 1;
        smp.cube_face = f;
        smp.view = PassView::LookAt(smp.v, smp.v + axis, S, S, false, 1);  // 1 / tan 45 degrees
        samples.push_back(smp);
      }
    }
  }
  const int ss = o.supersample;
  const double az = (o.azimuth_deg + turn_deg) * kPi / 180, el = o.elevation_deg * kPi / 180;
  const double t = std::tan(o.fov_deg * kPi / 360);
  const double dist = o.camera_distance_mm > 0 ? o.camera_distance_mm : radius / std::sin(o.fov_deg * kPi / 360) * 1.15;
  const Vec3 eye = centre + dist * Vec3(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el));
  const PassView cam = PassView::LookAt(eye, centre, o.width * ss, o.height * ss, false, 1 / t);

  if (I.device) {
    // The three passes on the GPU, q and the radiance kept there: the passes' times come from
    // GPU timestamps between them (the host does not wait between passes), the light samples'
    // setup counted in the first and the image's transfer in none. The flushes let the GPU
    // start each part while the host issues the next.
    Impl::Pending p;
    p.setup = Seconds(t0);
    p.slot = I.next_slot;
    I.device->Stamp(p.slot, 0);
    const std::vector<DeviceFloats> q = I.device->IncidentOnDevice(samples);
    I.device->Stamp(p.slot, 1);
    I.device->Flush();
    const auto t_issue = std::chrono::steady_clock::now();
    I.diffusion->SolveOnDevice(q, I.device->RadianceOnDevice());
    p.issue = Seconds(t_issue);
    I.device->Stamp(p.slot, 2);
    I.device->ShadeOnDevice(cam, samples);
    I.device->Stamp(p.slot, 3);
    I.device->QueueImage(p.slot);
    I.device->Flush();
    on_device_ = true;
    I.next_slot = (p.slot + 1) % DeviceRenderPasses::kFrameSlots;
    I.pending.push_back(std::move(p));
    return;
  }
  on_device_ = false;
  Impl::Pending p;
  std::vector<BoundaryLight> q = I.passes->Incident(samples);
  p.times.incident = Seconds(t0);

  // Pass 2: diffusion (or the dipole baseline).
  t0 = std::chrono::steady_clock::now();
  const Polygrid& pg = (*I.levels)[0];
  if (I.diffusion) {
    const std::vector<float>& phi = I.diffusion->Solve(q, /*boundary_only=*/true);
    radiance_ = ShadedRadiance(pg, I.materials[0], phi);
  } else {
    std::array<float, 3> k, m;
    for (int c = 0; c < 3; ++c) {
      double ks = 0, ms = 0;
      for (int64_t n = 0; n < pg.size(); ++n) ks += I.materials[0].kappa[c][n], ms += I.materials[0].mu[c][n];
      k[c] = float(ks / pg.size());
      m[c] = float(ms / pg.size());
    }
    radiance_ = DipoleRadiance(pg, k, m, I.C, q[0], I.node_areas);
  }
  q_finest_ = q[0];
  p.times.diffusion = Seconds(t0);

  // Pass 3: shading, supersampled.
  t0 = std::chrono::steady_clock::now();
  p.image = I.passes->Shade(cam, radiance_, samples);
  p.times.shading = Seconds(t0);
  I.pending.push_back(std::move(p));
}

}  // namespace translume
