// SPDX-License-Identifier: MIT
#include "calib/photo_io.h"

#include <fmt/format.h>

#include <algorithm>
#include <filesystem>
#include <map>
#include <opencv2/imgproc.hpp>
#include <regex>

#include "calib/error.h"
#include "calib/hdr.h"
#include "calib/parallel.h"

namespace translume::calib {

namespace fs = std::filesystem;

cv::Mat ReadGray8(const std::string& path) {
  cv::Mat rgb = ReadRgbImage(path);
  cv::Mat gray8;
  if (rgb.depth() == CV_16U) rgb.convertTo(rgb, CV_8U, 1.0 / 257);
  else if (rgb.depth() == CV_32F) rgb.convertTo(rgb, CV_8U, 255);
  cv::cvtColor(rgb, gray8, cv::COLOR_RGB2GRAY);
  return gray8;
}

std::vector<NamedImage> ReadPhotoFolder(const std::string& dir) {
  if (!fs::is_directory(dir)) throw CalibError(dir + ": not a folder");
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.is_regular_file() && IsPhotoFile(e.path().string())) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  if (files.empty()) throw CalibError(dir + ": no photos (.png, .jpg, .tif, .bmp, .exr, camera RAW)");
  std::vector<NamedImage> views(files.size());
  ParallelFor(int(files.size()), [&](int i) { views[size_t(i)] = {files[size_t(i)].string(), ReadGray8(files[size_t(i)].string())}; });
  return views;
}

std::vector<PlaneView> ReadPlaneFolder(const std::string& dir) {
  std::vector<NamedImage> photos = ReadPhotoFolder(dir);
  std::map<std::string, PlaneView> planes;
  for (NamedImage& p : photos) {
    const std::string stem = fs::path(p.name).stem().string();
    const size_t us = stem.rfind('_');
    std::string kind = us == std::string::npos ? "" : stem.substr(us + 1);
    std::transform(kind.begin(), kind.end(), kind.begin(), [](unsigned char c) { return std::tolower(c); });
    if (kind != "board" && kind != "pattern")
      throw CalibError(p.name + ": plane photos must be named NAME_board.EXT or NAME_pattern.EXT");
    PlaneView& v = planes[stem.substr(0, us)];
    v.name = (fs::path(dir) / stem.substr(0, us)).string();
    (kind == "board" ? v.board_photo : v.pattern_photo) = p.image;
  }
  std::vector<PlaneView> out;
  for (auto& [name, v] : planes) out.push_back(v);
  return out;
}

ProjectorChessboard ParseProjectorChessboard(const std::string& text, const std::string& size,
                                             const std::string& pattern_name, const std::string& size_name) {
  std::smatch m, n;
  static const std::regex pat(R"((\d{1,6})x(\d{1,6}):(\d{1,6}))"), wh(R"((\d{1,6})x(\d{1,6}))");
  if (!std::regex_match(text, m, pat))
    throw CalibError(fmt::format("{} {}: expected COLSxROWS:SQUARE_PX", pattern_name, text));
  if (!std::regex_match(size, n, wh))
    throw CalibError(fmt::format("{} {}: expected WIDTHxHEIGHT", size_name, size));
  const int w = std::stoi(n[1]), h = std::stoi(n[2]);
  if (w < 64 || h < 64 || w > 16384 || h > 16384)
    throw CalibError(fmt::format("{} {}: each side must be 64..16384 pixels", size_name, size));
  const ProjectorChessboard b = ProjectorChessboard::Centered(
      {std::stoi(n[1]), std::stoi(n[2])}, std::stoi(m[1]), std::stoi(m[2]), std::stoi(m[3]));
  if (std::string why = b.Validate(); !why.empty())
    throw CalibError(fmt::format("{} {}: {}", pattern_name, text, why));
  return b;
}

}  // namespace translume::calib
