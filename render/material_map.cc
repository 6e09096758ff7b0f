// SPDX-License-Identifier: MIT
#include "render/material_map.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "solver/status.h"

namespace translume {
namespace {

// Material coordinate along an axis of n nodes: wrapped (period n) or clamped to [0, n - 1].
double AxisCoordinate(double x, int64_t n, bool tile) {
  if (!tile || n == 1) return std::clamp(x, 0.0, double(n - 1));
  x = std::fmod(x, double(n));
  return x < 0 ? x + n : x;
}

float Trilinear(const std::vector<float>& v, const GridShape& s, double x, double y, double z,
                bool tile) {
  const int64_t i0 = int64_t(std::floor(x)), j0 = int64_t(std::floor(y)), k0 = int64_t(std::floor(z));
  const double fx = x - i0, fy = y - j0, fz = z - k0;
  auto wrap = [&](int64_t i, int64_t n) { return tile ? (i % n + n) % n : std::clamp<int64_t>(i, 0, n - 1); };
  double acc = 0;
  for (int c = 0; c < 8; ++c) {
    const int dx = c & 1, dy = (c >> 1) & 1, dz = (c >> 2) & 1;
    const double w = (dx ? fx : 1 - fx) * (dy ? fy : 1 - fy) * (dz ? fz : 1 - fz);
    if (w == 0) continue;
    acc += w * v[s.index(wrap(i0 + dx, s.nx), wrap(j0 + dy, s.ny),
                         std::clamp<int64_t>(k0 + dz, 0, s.nz - 1))];
  }
  return float(acc);
}

}  // namespace

std::string ShellMappingOptions::Validate() const {
  if (!(scale > 0) || !std::isfinite(scale)) return "the mapping scale must be > 0";
  return "";
}

NodeMaterial MapShellMaterial(const Polygrid& pg, const Material& material,
                              const ShellMappingOptions& options) {
  if (std::string err = options.Validate(); !err.empty()) throw InputError("--map-scale: " + err);
  NodeMaterial m;
  const GridShape& s = material.shape;
  const double h = material.spacing_mm * options.scale;
  for (int c = 0; c < 3; ++c) {
    m.kappa[c].resize(pg.size());
    m.mu[c].resize(pg.size());
  }
  for (int64_t n = 0; n < pg.size(); ++n) {
    const auto uv = pg.SurfaceUV(pg.source[n]);
    const double x = AxisCoordinate(uv[0] * pg.mean_boundary_spacing / h, s.nx, options.tile);
    const double y = AxisCoordinate(uv[1] * pg.mean_boundary_spacing / h, s.ny, options.tile);
    const double z = std::min(pg.depth_mm[n] / h, double(s.nz - 1));
    for (int c = 0; c < 3; ++c) {
      m.kappa[c][n] = Trilinear(material.kappa[c], s, x, y, z, options.tile);
      m.mu[c][n] = Trilinear(material.mu[c], s, x, y, z, options.tile);
    }
  }
  return m;
}

std::vector<NodeMaterial> RestrictMaterialHierarchy(const std::vector<Polygrid>& levels,
                                                    NodeMaterial finest) {
  std::vector<NodeMaterial> out;
  out.push_back(std::move(finest));
  for (size_t l = 1; l < levels.size(); ++l) {
    NodeMaterial m;
    for (int c = 0; c < 3; ++c) {
      RestrictPolygrid(levels[l - 1], out.back().kappa[c], levels[l], &m.kappa[c]);
      RestrictPolygrid(levels[l - 1], out.back().mu[c], levels[l], &m.mu[c]);
    }
    out.push_back(std::move(m));
  }
  return out;
}

NodeMaterial ConstantNodeMaterial(const Polygrid& pg, const std::array<float, 3>& kappa,
                                  const std::array<float, 3>& mu) {
  NodeMaterial m;
  for (int c = 0; c < 3; ++c) {
    m.kappa[c].assign(pg.size(), kappa[c]);
    m.mu[c].assign(pg.size(), mu[c]);
  }
  return m;
}

NodeMaterial ProceduralNodeMaterial(const Polygrid& pg, const std::string& name) {
  // Marble-like and skin-like coefficients (Jensen et al. 2001, converted to kappa, mu).
  const std::array<float, 3> marble_k = {0.14f, 0.15f, 0.17f}, marble_mu = {0.0021f, 0.0041f, 0.0071f};
  // Veins keep the host kappa (chosen when the interior equation was the paper's form
  // Laplacian(kappa phi), under which phi jumps up where kappa drops; the stored reference
  // image depends on it).
  const std::array<float, 3> vein_k = marble_k, vein_mu = {0.08f, 0.10f, 0.12f};
  const std::array<float, 3> skin_k = {0.45f, 0.30f, 0.25f}, skin_mu = {0.032f, 0.17f, 0.48f};
  if (name != "marble" && name != "layers")
    throw InputError("material: unknown procedural material '" + name + "' (expected marble or layers)");
  NodeMaterial m = ConstantNodeMaterial(pg, marble_k, marble_mu);
  for (int64_t n = 0; n < pg.size(); ++n) {
    const Vec3& p = pg.position[n];
    double t = 0;
    if (name == "marble") {
      const double turb = std::sin(0.9 * p.y() + 0.4 * std::sin(1.7 * p.z())) +
                          0.5 * std::sin(2.3 * p.z() + 1.1 * p.x());
      const double v = std::abs(std::sin(0.6 * p.x() + 1.5 * turb));
      t = std::pow(1 - v, 6);  // thin veins where the sine crosses zero
    } else {
      t = pg.depth_mm[n] < 1.0 ? 1.0 : 0.0;
    }
    for (int c = 0; c < 3; ++c) {
      const auto& k2 = name == "marble" ? vein_k : skin_k;
      const auto& m2 = name == "marble" ? vein_mu : skin_mu;
      m.kappa[c][n] = float((1 - t) * marble_k[c] + t * k2[c]);
      m.mu[c][n] = float((1 - t) * marble_mu[c] + t * m2[c]);
    }
  }
  return m;
}

bool IsNamedNodeMaterial(const std::string& spec) {
  return spec.rfind("procedural:", 0) == 0 || spec.rfind("homogeneous:", 0) == 0;
}

NodeMaterial NamedNodeMaterial(const Polygrid& pg, const std::string& spec) {
  if (spec.rfind("procedural:", 0) == 0) return ProceduralNodeMaterial(pg, spec.substr(11));
  float k = 0, u = 0;
  char comma = 0, rest = 0;
  if (spec.rfind("homogeneous:", 0) != 0 ||
      std::sscanf(spec.c_str() + 12, "%f%c%f%c", &k, &comma, &u, &rest) != 3 || comma != ',' || !(k > 0) ||
      !(u > 0) || !std::isfinite(k) || !std::isfinite(u))
    throw InputError("material " + spec + ": expected procedural:NAME or homogeneous:KAPPA,MU with both > 0");
  return ConstantNodeMaterial(pg, {k, k, k}, {u, u, u});
}

}  // namespace translume
