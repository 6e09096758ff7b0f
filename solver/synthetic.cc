// SPDX-License-Identifier: MIT
#include "solver/synthetic.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <fmt/format.h>
#include <random>

#include "solver/status.h"

namespace translume {
namespace {

using Rgb = std::array<double, 3>;

// Reduced scattering and absorption coefficients (1/mm) from Jensen et al. 2001, Table 2.
struct Measured {
  Rgb sigma_s, sigma_a;
};
constexpr Measured kMarble{{2.19, 2.62, 3.00}, {0.0021, 0.0041, 0.0071}};
constexpr Measured kSkin2{{1.09, 1.59, 1.79}, {0.013, 0.070, 0.145}};
constexpr Measured kApple{{2.29, 2.39, 1.97}, {0.0030, 0.0034, 0.046}};
constexpr Measured kPotato{{0.68, 0.70, 0.55}, {0.0024, 0.0090, 0.12}};
constexpr Measured kSkimmilk{{0.70, 1.22, 1.90}, {0.0014, 0.0025, 0.0142}};
constexpr Measured kSkin1{{0.74, 0.88, 1.01}, {0.032, 0.17, 0.48}};

struct Coeffs {
  Rgb kappa, mu;
};

// kappa = 1 / (3 (sigma_a + sigma_s')), mu = sigma_a, with mu clamped into [0.001, 0.1] /mm.
Coeffs FromMeasured(const Measured& m, double absorption_scale = 1.0) {
  Coeffs c;
  for (int i = 0; i < 3; ++i) {
    const double sa = std::clamp(m.sigma_a[i] * absorption_scale, 0.001, 0.1);
    c.kappa[i] = 1.0 / (3.0 * (sa + m.sigma_s[i]));
    c.mu[i] = sa;
  }
  return c;
}

Coeffs Mix(const Coeffs& a, const Coeffs& b, double t) {
  Coeffs c;
  for (int i = 0; i < 3; ++i) {
    c.kappa[i] = std::exp((1 - t) * std::log(a.kappa[i]) + t * std::log(b.kappa[i]));
    c.mu[i] = std::exp((1 - t) * std::log(a.mu[i]) + t * std::log(b.mu[i]));
  }
  return c;
}

// Smooth 3-D value noise on an integer lattice with a seeded hash, in [-1, 1].
class Noise {
 public:
  explicit Noise(uint64_t seed) : seed_(seed) {}
  double operator()(double x, double y, double z) const {
    const double fx = std::floor(x), fy = std::floor(y), fz = std::floor(z);
    const int64_t ix = int64_t(fx), iy = int64_t(fy), iz = int64_t(fz);
    auto fade = [](double t) { return t * t * t * (t * (t * 6 - 15) + 10); };
    const double u = fade(x - fx), v = fade(y - fy), w = fade(z - fz);
    double acc = 0;
    for (int c = 0; c < 8; ++c) {
      const int dx = c & 1, dy = (c >> 1) & 1, dz = (c >> 2) & 1;
      const double wgt = (dx ? u : 1 - u) * (dy ? v : 1 - v) * (dz ? w : 1 - w);
      acc += wgt * Lattice(ix + dx, iy + dy, iz + dz);
    }
    return acc;
  }
  // Fractal sum of `octaves` octaves, roughly in [-1, 1].
  double Fbm(double x, double y, double z, int octaves) const {
    double sum = 0, amp = 0.5, freq = 1, norm = 0;
    for (int o = 0; o < octaves; ++o) {
      sum += amp * (*this)(x * freq, y * freq, z * freq);
      norm += amp;
      amp *= 0.5;
      freq *= 2.0;
    }
    return sum / norm;
  }

 private:
  double Lattice(int64_t x, int64_t y, int64_t z) const {
    uint64_t h = seed_ * 0x9E3779B97F4A7C15ull;
    h ^= uint64_t(x) * 0xBF58476D1CE4E5B9ull;
    h = (h ^ (h >> 31)) * 0x94D049BB133111EBull;
    h ^= uint64_t(y) * 0xD6E8FEB86659FD93ull;
    h = (h ^ (h >> 29)) * 0xBF58476D1CE4E5B9ull;
    h ^= uint64_t(z) * 0x94D049BB133111EBull;
    h ^= h >> 32;
    return double(h & 0xFFFFFF) / double(0xFFFFFF) * 2.0 - 1.0;
  }
  uint64_t seed_;
};

struct PresetInfo {
  const char* name;
  GridShape shape;
};
constexpr PresetInfo kPresets[] = {
    {"homogeneous", {64, 48, 16}}, {"layered", {64, 48, 16}}, {"marble", {256, 256, 20}},
    {"inclusions", {64, 48, 16}},  {"wax", {64, 48, 16}},     {"wax1", {130, 53, 37}},
    {"wax2", {140, 75, 48}},       {"stone", {128, 128, 41}},
};

}  // namespace

std::vector<std::string> SynthPresetNames() {
  std::vector<std::string> names;
  for (const auto& p : kPresets) names.push_back(p.name);
  return names;
}

GridShape DefaultSynthShape(const std::string& preset) {
  for (const auto& p : kPresets)
    if (preset == p.name) return p.shape;
  std::string list;
  for (const auto& p : kPresets) list += std::string(list.empty() ? "" : ", ") + p.name;
  throw InputError(fmt::format("--preset: unknown preset '{}' (available: {})", preset, list));
}

Material SynthesizeMaterial(const SynthOptions& o) {
  GridShape shape = DefaultSynthShape(o.preset);
  if (o.shape.size() > 0) shape = o.shape;
  if (shape.nx < 2 || shape.ny < 2 || shape.nz < 2)
    throw InputError("--grid: every dimension must be at least 2 nodes");
  if (const std::string p = SpacingProblem(o.spacing_mm); !p.empty()) throw InputError("--spacing: " + p);
  // (Jensen's Fdr fit, which gives C, passes 1 near eta = 3.9.)
  if (!(o.eta > 1 && o.eta <= 3.5))
    throw InputError(fmt::format("--eta: {} is not a refractive index in (1, 3.5]", o.eta));
  Material m = Material::Constant(shape, o.spacing_mm, {1, 1, 1}, {1, 1, 1}, o.eta);
  const Noise noise(o.seed);
  std::mt19937_64 rng(o.seed);
  const double h = o.spacing_mm;
  const double sx = (shape.nx - 1) * h, sy = (shape.ny - 1) * h, sz = (shape.nz - 1) * h;

  // Inclusions: random buried spheres, away from the front face.
  struct Blob { double x, y, z, r; };
  std::vector<Blob> blobs;
  if (o.preset == "inclusions" || o.preset == "stone") {
    std::uniform_real_distribution<double> U(0, 1);
    const int count = o.preset == "stone" ? 24 : 6;
    const double rmax = std::min({sx, sy, sz}) * (o.preset == "stone" ? 0.12 : 0.25);
    for (int b = 0; b < count; ++b) {
      const double r = rmax * (0.5 + 0.5 * U(rng));
      blobs.push_back({sx * U(rng), sy * U(rng), std::min(sz, r + (sz - r) * U(rng)) , r});
    }
  }

  const Coeffs marble = FromMeasured(kMarble, 4.0);
  const Coeffs vein = FromMeasured(kSkin1, 0.2);
  const Coeffs skin = FromMeasured(kSkin2, 0.5);
  const Coeffs apple = FromMeasured(kApple, 2.0);
  const Coeffs wax = FromMeasured(kPotato, 1.0);
  const Coeffs milk = FromMeasured(kSkimmilk, 3.0);

  for (int64_t k = 0; k < shape.nz; ++k)
    for (int64_t j = 0; j < shape.ny; ++j)
      for (int64_t i = 0; i < shape.nx; ++i) {
        const double x = i * h, y = j * h, z = k * h;
        Coeffs c = marble;
        if (o.preset == "homogeneous") {
          c = marble;
        } else if (o.preset == "layered") {
          const double t = z / std::max(sz, 1e-9);
          c = t < 0.2 ? skin : t < 0.6 ? marble : apple;
        } else if (o.preset == "marble") {
          // Classic marble: veins where a turbulent phase crosses a sine's zero.
          const double turb = noise.Fbm(x / 6.0, y / 6.0, z / 6.0, 4);
          const double phase = (x + 0.6 * y) / 5.0 + 6.0 * turb;
          const double v = std::pow(1.0 - std::abs(std::sin(phase)), 6.0);
          c = Mix(marble, vein, std::clamp(v, 0.0, 1.0));
        } else if (o.preset == "inclusions" || o.preset == "stone") {
          double inside = 0;
          for (const Blob& b : blobs) {
            const double d = std::sqrt((x - b.x) * (x - b.x) + (y - b.y) * (y - b.y) +
                                       (z - b.z) * (z - b.z));
            inside = std::max(inside, std::clamp((b.r - d) / h + 0.5, 0.0, 1.0));
          }
          const Coeffs& host = o.preset == "stone" ? apple : wax;
          c = Mix(host, o.preset == "stone" ? vein : skin, inside);
        } else {  // wax, wax1, wax2: smooth variation
          const double a = noise.Fbm(x / 12.0, y / 12.0, z / 12.0, 2);
          const double b = noise.Fbm(x / 12.0 + 17.3, y / 12.0 + 5.1, z / 12.0 + 9.7, 2);
          const Coeffs& base = o.preset == "wax2" ? milk : wax;
          c = base;
          for (int ch = 0; ch < 3; ++ch) {
            c.kappa[ch] *= std::exp(0.35 * a);
            c.mu[ch] *= std::exp(0.6 * b);
          }
        }
        const int64_t p = shape.index(i, j, k);
        for (int ch = 0; ch < 3; ++ch) {
          m.kappa[ch][p] = float(std::clamp(c.kappa[ch], 0.04, 0.55));
          m.mu[ch][p] = float(std::clamp(c.mu[ch], 0.001, 0.1));
        }
      }
  TL_CHECK(m.Validate().empty());
  return m;
}

}  // namespace translume
