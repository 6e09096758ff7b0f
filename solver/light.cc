// SPDX-License-Identifier: MIT
#include "solver/light.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fmt/format.h>

#include "solver/parse.h"
#include "solver/status.h"

namespace translume {
namespace {

[[noreturn]] void Bad(const std::string& text, const std::string& why) {
  throw InputError(fmt::format("light '{}': {} (expected uniform, region:I,J/N, spot:X,Y,R "
                               "or image:FILE)", text, why));
}

// Dual box of node i along an axis with n nodes and spacing h: [lo, hi] in mm.
void DualBox(int64_t i, int64_t n, double h, double* lo, double* hi) {
  *lo = std::max(0.0, (double(i) - 0.5) * h);
  *hi = std::min(double(n - 1) * h, (double(i) + 0.5) * h);
}

double Overlap(double a0, double a1, double b0, double b1) {
  return std::max(0.0, std::min(a1, b1) - std::max(a0, b0));
}

}  // namespace

LightSpec LightSpec::Parse(const std::string& text) {
  LightSpec s;
  s.text = text;
  if (text == "uniform") return s;
  const size_t colon = text.find(':');
  if (colon == std::string::npos) Bad(text, "unknown kind");
  const std::string kind = text.substr(0, colon), args = text.substr(colon + 1);
  char tail = 0;
  if (kind == "region") {
    s.kind = Kind::kRegion;
    const auto ijn = WholeNumbers(args, ",/");
    if (!ijn) Bad(text, "region needs I,J/N");
    const int64_t i = (*ijn)[0], j = (*ijn)[1], n = (*ijn)[2];
    if (n < 1 || n > kMaxGridAxis || i < 0 || j < 0 || i >= n || j >= n)
      Bad(text, fmt::format("region needs 0 <= I, J < N <= {}", kMaxGridAxis));
    s.region_i = int(i), s.region_j = int(j), s.region_n = int(n);
  } else if (kind == "spot") {
    s.kind = Kind::kSpot;
    if (std::sscanf(args.c_str(), "%lf,%lf,%lf%c", &s.spot_x, &s.spot_y, &s.spot_r, &tail) != 3)
      Bad(text, "spot needs X,Y,R in mm");
    if (!std::isfinite(s.spot_x) || !std::isfinite(s.spot_y)) Bad(text, "the spot centre must be finite (mm)");
    if (!(s.spot_r > 0) || !std::isfinite(s.spot_r)) Bad(text, "spot radius must be finite and > 0");
  } else if (kind == "image") {
    s.kind = Kind::kImage;
    s.image_path = args;
    if (args.empty()) Bad(text, "image needs a file name");
  } else {
    Bad(text, "unknown kind '" + kind + "'");
  }
  return s;
}

std::vector<float> RasterizeLight(const LightSpec& spec, const GridShape& shape, double h,
                                  const Image* pattern) {
  const int64_t nx = shape.nx, ny = shape.ny;
  std::vector<float> q(nx * ny, 0.0f);
  const double width = double(nx - 1) * h, height = double(ny - 1) * h;
  if (spec.kind == LightSpec::Kind::kImage)
    TL_CHECK_MSG(pattern && pattern->width > 0 && pattern->height > 0,
                 "image lights need their decoded pattern (see RasterizeLightFile)");
  static const Image kNone;
  const Image& img = pattern ? *pattern : kNone;
  // Supersampling for spots and images: S x S samples per dual box.
  constexpr int S = 8;
  for (int64_t j = 0; j < ny; ++j) {
    double y0, y1;
    DualBox(j, ny, h, &y0, &y1);
    for (int64_t i = 0; i < nx; ++i) {
      double x0, x1;
      DualBox(i, nx, h, &x0, &x1);
      double value = 0;
      switch (spec.kind) {
        case LightSpec::Kind::kUniform:
          value = 1;
          break;
        case LightSpec::Kind::kRegion: {
          const double n = spec.region_n;
          const double cx0 = width * spec.region_i / n, cx1 = width * (spec.region_i + 1) / n;
          const double cy0 = height * spec.region_j / n, cy1 = height * (spec.region_j + 1) / n;
          value = Overlap(x0, x1, cx0, cx1) * Overlap(y0, y1, cy0, cy1) / ((x1 - x0) * (y1 - y0));
          break;
        }
        case LightSpec::Kind::kSpot:
        case LightSpec::Kind::kImage: {
          double sum = 0;
          for (int b = 0; b < S; ++b)
            for (int a = 0; a < S; ++a) {
              const double x = x0 + (a + 0.5) / S * (x1 - x0);
              const double y = y0 + (b + 0.5) / S * (y1 - y0);
              if (spec.kind == LightSpec::Kind::kSpot) {
                const double dx = x - spec.spot_x, dy = y - spec.spot_y;
                sum += (dx * dx + dy * dy <= spec.spot_r * spec.spot_r) ? 1.0 : 0.0;
              } else {
                // Nearest image pixel; the image covers [0, width] x [0, height].
                const int px = std::clamp(int(x / width * img.width), 0, img.width - 1);
                const int py = std::clamp(int(y / height * img.height), 0, img.height - 1);
                double lum;
                if (img.channels >= 3)
                  lum = 0.2126 * img.at(px, py, 0) + 0.7152 * img.at(px, py, 1) +
                        0.0722 * img.at(px, py, 2);
                else
                  lum = img.at(px, py, 0);
                sum += lum;
              }
            }
          value = sum / (S * S);
          break;
        }
      }
      q[i + nx * j] = float(value);
    }
  }
  return q;
}

std::vector<LightSpec> RegionLights(const std::string& nxn) {
  const auto ab = WholeNumbers(nxn, "x");
  if (!ab || (*ab)[0] != (*ab)[1] || (*ab)[0] < 1 || (*ab)[0] > 64)
    throw InputError(fmt::format("--lights: '{}' is not NxN with 1 <= N <= 64", nxn));
  const int a = int((*ab)[0]);
  std::vector<LightSpec> lights;
  for (int j = 0; j < a; ++j)
    for (int i = 0; i < a; ++i)
      lights.push_back(LightSpec::Parse(fmt::format("region:{},{}/{}", i, j, a)));
  return lights;
}

std::vector<LightSpec> TrainingLights(const std::string& text) {
  if (text.find(':') == std::string::npos && text.find(';') == std::string::npos && text != "uniform")
    return RegionLights(text);
  std::vector<LightSpec> lights;
  size_t from = 0;
  while (from <= text.size()) {
    const size_t semi = std::min(text.find(';', from), text.size());
    const std::string entry = text.substr(from, semi - from);
    if (entry.empty()) throw InputError(fmt::format("--lights: an empty entry in '{}' (specs are separated by ';')", text));
    LightSpec spec;
    try {
      spec = LightSpec::Parse(entry);
    } catch (const InputError& e) {
      throw InputError(fmt::format("--lights: {}", e.what()));
    }
    if (spec.kind == LightSpec::Kind::kImage)
      throw InputError(fmt::format("--lights: '{}': image lights are not supported here; use regions or spots", entry));
    lights.push_back(spec);
    if (lights.size() > 4096) throw InputError("--lights: more than 4096 lights");
    from = semi + 1;
  }
  return lights;
}

}  // namespace translume
