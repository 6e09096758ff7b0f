// SPDX-License-Identifier: MIT
#include "solver/image_io.h"

#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <fmt/format.h>
#include <fstream>
#include <iterator>
#include <string_view>

#include "solver/atomic_file.h"
#include "solver/memory.h"
#include "solver/status.h"

namespace translume {
namespace {

// OpenImageIO's error text can span lines (a decoder's message, then its library's); ours
// are one line.
std::string FirstLine(const std::string& s) {
  const std::string line = s.substr(0, s.find('\n'));
  return line.empty() ? "unknown error" : line;
}

// The end marker of a PNG (an IEND chunk) or JPEG (an EOI marker after the last start-of-scan)
// file, whose absence means the file was cut short: libjpeg then fills the missing rows with
// grey and OpenImageIO reports success, and libpng prints its own line before failing. Empty
// when the file is complete or of another format.
std::string Truncation(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::string bytes(8, '\0');
  in.read(bytes.data(), 8);
  auto starts = [&](std::string_view magic) { return bytes.compare(0, magic.size(), magic) == 0; };
  if (!starts("\x89PNG\r\n\x1a\n") && !starts("\xff\xd8\xff")) return "";
  bytes.append(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  if (starts("\x89PNG\r\n\x1a\n")) {
    if (bytes.rfind(std::string_view("\0\0\0\0IEND", 8)) == std::string::npos)
      return "PNG file is cut short (no IEND chunk)";
  } else if (starts("\xff\xd8\xff")) {
    const size_t scan = bytes.rfind("\xff\xda");
    const size_t end = bytes.rfind("\xff\xd9");
    if (scan == std::string::npos || end == std::string::npos || end < scan)
      return "JPEG file is cut short (no end-of-image marker after its last scan)";
  }
  return "";
}

}  // namespace

Image ReadImage(const std::string& path) {
  if (!std::filesystem::exists(path)) throw InputError(fmt::format("{}: no such file", path));
  if (const std::string cut = Truncation(path); !cut.empty()) throw InputError(fmt::format("{}: {}", path, cut));
  auto in = OIIO::ImageInput::open(path);
  if (!in) {
    throw InputError(fmt::format("{}: cannot read image: {}", path, FirstLine(OIIO::geterror())));
  }
  const OIIO::ImageSpec& spec = in->spec();
  if (spec.depth > 1)
    throw InputError(fmt::format("{}: a volume ({}x{}x{} {}), not a 2-D image", path, spec.width, spec.height,
                                 spec.depth, in->format_name()));
  if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0)
    throw InputError(fmt::format("{}: the image has no pixels", path));
  // The header's size is allocated before the pixels are decoded: a 661-byte PNG that claimed
  // 20000 x 20000 took 4.8 GB.
  if (int64_t(spec.width) * spec.height > kMaxImagePixels || spec.nchannels > kMaxImageChannels)
    throw InputError(fmt::format("{}: a {}x{} image of {} channels is larger than translume reads "
                                 "(at most {} pixels of at most {} channels)", path, spec.width,
                                 spec.height, spec.nchannels, kMaxImagePixels, kMaxImageChannels));
  CheckFitsInMemory(int64_t(spec.width) * spec.height * spec.nchannels * int64_t(sizeof(float)),
                    fmt::format("{}: its {}x{} pixels", path, spec.width, spec.height));
  Image img;
  img.width = spec.width;
  img.height = spec.height;
  img.channels = spec.nchannels;
  if (!spec.format.is_floating_point()) img.integer_bits = int(spec.format.size()) * 8;
  img.data.resize(size_t(img.width) * img.height * img.channels);
  if (!in->read_image(0, 0, 0, img.channels, OIIO::TypeDesc::FLOAT, img.data.data())) {
    throw InputError(fmt::format("{}: cannot read image: {}", path, FirstLine(in->geterror())));
  }
  in->close();
  return img;
}

void WriteImage(const std::string& path, const Image& image) {
  TL_CHECK(image.data.size() == size_t(image.width) * image.height * image.channels);
  WriteAtomically(path, [&](const std::string& tmp) {
    auto out = OIIO::ImageOutput::create(tmp);
    if (!out) throw InputError(fmt::format("{}: no image writer for this extension", path));
    OIIO::ImageSpec spec(image.width, image.height, image.channels,
                         tmp.ends_with(".exr") ? OIIO::TypeDesc::FLOAT : OIIO::TypeDesc::UINT8);
    if (tmp.ends_with(".exr")) spec.attribute("compression", "zip");
    if (!out->open(tmp, spec) ||
        !out->write_image(OIIO::TypeDesc::FLOAT, image.data.data()) || !out->close()) {
      throw InputError(fmt::format("{}: cannot write image: {}", path, FirstLine(out->geterror())));
    }
  });
}

std::vector<float> RasterizeLightFile(const LightSpec& spec, const GridShape& shape, double h) {
  if (spec.kind != LightSpec::Kind::kImage) return RasterizeLight(spec, shape, h);
  const Image pattern = ReadImage(spec.image_path);
  if (pattern.width < 1 || pattern.height < 1)
    throw InputError(fmt::format("{}: empty light pattern image", spec.image_path));
  for (size_t v = 0; v < pattern.data.size(); ++v)
    if (!std::isfinite(pattern.data[v]) || pattern.data[v] < 0) {
      const size_t pixel = v / size_t(pattern.channels);
      throw InputError(fmt::format("{}: light pattern pixel ({}, {}) is {}; light must be finite and >= 0",
                                   spec.image_path, pixel % size_t(pattern.width), pixel / size_t(pattern.width),
                                   pattern.data[v]));
    }
  return RasterizeLight(spec, shape, h, &pattern);
}

Image ImageFromPlanes(int width, int height, const std::vector<const float*>& planes) {
  Image img;
  img.width = width;
  img.height = height;
  img.channels = int(planes.size());
  img.data.resize(size_t(width) * height * img.channels);
  for (size_t p = 0; p < size_t(width) * height; ++p)
    for (int c = 0; c < img.channels; ++c) img.data[p * img.channels + c] = planes[c][p];
  return img;
}

void WriteFitComparison(const std::string& path, const GridShape& s, const FacePattern& measured,
                        const FacePattern& fitted, const std::vector<float>& mask) {
  const size_t face = size_t(s.nx * s.ny);
  TL_CHECK(mask.size() == face);
  for (int c = 0; c < 3; ++c) TL_CHECK(measured[size_t(c)].size() == face && fitted[size_t(c)].size() == face);
  float top = 0;
  for (size_t f = 0; f < face; ++f)
    if (mask[f] > 0)
      for (int c = 0; c < 3; ++c) top = std::max(top, measured[size_t(c)][f]);
  if (!(top > 0)) top = 1e-30f;
  const float gamma = 1.0f / 2.2f;
  const auto shown = [&](float v) { return std::pow(std::clamp(v / top, 0.0f, 1.0f), gamma); };
  // The three panels' node values, each nx x ny, then expanded to pixel blocks.
  constexpr int kGap = 2;
  const int64_t z = PreviewPixelsPerNode(s.nx), panel = s.nx + kGap;
  const int64_t W = (3 * s.nx + 2 * kGap) * z, H = s.ny * z;
  std::array<std::vector<float>, 3> rgb;
  for (auto& ch : rgb) ch.assign(size_t(W * H), 0.0f);
  const std::array<float, 3> kRed{1.0f, 0.15f, 0.1f}, kBlue{0.15f, 0.45f, 1.0f};
  const float kMasked = 0.35f;
  for (int64_t j = 0; j < s.ny; ++j)
    for (int64_t i = 0; i < s.nx; ++i) {
      const size_t f = size_t(i + s.nx * j);
      std::array<std::array<float, 3>, 3> node{};  // panel, channel
      if (mask[f] > 0) {
        float r = 0;  // the channel that misses most, with its sign
        for (int c = 0; c < 3; ++c) {
          node[0][c] = shown(measured[size_t(c)][f]);
          const float rc = (fitted[size_t(c)][f] - measured[size_t(c)][f]) / top;
          if (std::abs(rc) > std::abs(r)) r = rc;
        }
        const float level = std::min(std::abs(r) / kResidualPreviewRange, 1.0f);
        for (int c = 0; c < 3; ++c) node[2][c] = level * (r > 0 ? kRed : kBlue)[size_t(c)];
      } else {
        node[2] = {kMasked, kMasked, kMasked};
      }
      for (int c = 0; c < 3; ++c) node[1][c] = shown(fitted[size_t(c)][f]);
      for (int p = 0; p < 3; ++p)
        for (int64_t y = j * z; y < (j + 1) * z; ++y)
          for (int64_t x = (p * panel + i) * z; x < (p * panel + i + 1) * z; ++x)
            for (int c = 0; c < 3; ++c) rgb[size_t(c)][size_t(x + W * y)] = node[size_t(p)][size_t(c)];
    }
  WriteImage(path, ImageFromPlanes(int(W), int(H), {rgb[0].data(), rgb[1].data(), rgb[2].data()}));
}

std::vector<int64_t> MaterialSliceDepths(const GridShape& s) {
  std::vector<int64_t> depths = {0, s.nz / 4, s.nz / 2, 3 * s.nz / 4, s.nz - 1};
  depths.erase(std::unique(depths.begin(), depths.end()), depths.end());
  return depths;
}

std::vector<std::string> MaterialSlicePaths(const std::string& prefix, const GridShape& shape) {
  std::vector<std::string> paths;
  for (const char* name : {"kappa", "mu"})
    for (int64_t k : MaterialSliceDepths(shape)) paths.push_back(fmt::format("{}_{}_k{:02d}.png", prefix, name, k));
  return paths;
}

int PreviewPixelsPerNode(int64_t nx) {
  nx = std::max<int64_t>(nx, 1);
  return int(std::max<int64_t>(1, (256 + nx - 1) / nx));
}

std::vector<std::string> WriteMaterialSlices(const std::string& prefix, const Material& m) {
  const GridShape& s = m.shape;
  const std::vector<std::string> paths = MaterialSlicePaths(prefix, s);
  const std::vector<int64_t> depths = MaterialSliceDepths(s);
  const int64_t z = PreviewPixelsPerNode(s.nx), W = s.nx * z, H = s.ny * z;
  size_t next = 0;
  for (const auto* field : {&m.kappa, &m.mu}) {
    std::array<std::array<double, 2>, 3> range;  // log values shown as 0 and 1
    for (int c = 0; c < 3; ++c) {
      const std::vector<float> q = Quantiles((*field)[c], {kPreviewQuantile, 1 - kPreviewQuantile});
      double a = std::log(std::max(double(q[0]), 1e-30)), b = std::log(std::max(double(q[1]), 1e-30));
      if (b - a < std::log(kPreviewMinRatio)) {
        const double centre = (a + b) / 2, half = std::log(kPreviewMinRatio) / 2;
        a = centre - half;
        b = centre + half;
      }
      range[c] = {a, b};
    }
    for (int64_t k : depths) {
      std::array<std::vector<float>, 3> planes;
      for (int c = 0; c < 3; ++c) {
        const auto [a, b] = range[c];
        std::vector<float> node(size_t(s.face_size()));  // the slice's values, one per node
        for (int64_t f = 0; f < s.face_size(); ++f) {
          const double v = (*field)[c][size_t(f + s.face_size() * k)];
          node[size_t(f)] = float(std::clamp((std::log(std::max(v, 1e-30)) - a) / (b - a), 0.0, 1.0));
        }
        planes[c].resize(size_t(W * H));
        for (int64_t y = 0; y < H; ++y)
          for (int64_t x = 0; x < W; ++x) planes[c][size_t(x + W * y)] = node[size_t(x / z + s.nx * (y / z))];
      }
      WriteImage(paths[next++], ImageFromPlanes(int(W), int(H), {planes[0].data(), planes[1].data(), planes[2].data()}));
    }
  }
  return paths;
}

}  // namespace translume
