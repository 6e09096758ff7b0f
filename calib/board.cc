// SPDX-License-Identifier: MIT
#include "calib/board.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <opencv2/aruco/charuco.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <regex>

#include "calib/error.h"

namespace translume::calib {
namespace {

constexpr int kTexelsPerSquare = 64;

struct DictionaryName {
  const char* name;
  int id;
  int markers;
};
const DictionaryName kDictionaries[] = {
    {"4X4_50", cv::aruco::DICT_4X4_50, 50},
    {"4X4_100", cv::aruco::DICT_4X4_100, 100},
    {"5X5_100", cv::aruco::DICT_5X5_100, 100},
    {"6X6_250", cv::aruco::DICT_6X6_250, 250},
};

cv::Ptr<cv::aruco::CharucoBoard> MakeCharuco(const BoardSpec& b) {
  return cv::aruco::CharucoBoard::create(b.cols, b.rows, float(b.square_mm), float(b.marker_mm),
                                         cv::aruco::getPredefinedDictionary(b.dictionary));
}

cv::Mat ToGray(const cv::Mat& image) {
  cv::Mat gray;
  if (image.channels() == 1) gray = image;
  else if (image.channels() == 3) cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  else cv::cvtColor(image, gray, cv::COLOR_BGRA2GRAY);
  return gray;
}

}  // namespace

BoardSpec BoardSpec::Parse(const std::string& text) {
  static const std::regex chess(R"(chessboard:(\d+)x(\d+):([0-9.eE+-]+))");
  static const std::regex charuco(R"(charuco:(\d+)x(\d+):([0-9.eE+-]+):([0-9.eE+-]+)(?::(\w+))?)");
  std::smatch m;
  BoardSpec b;
  try {
    if (std::regex_match(text, m, chess)) {
      b.kind = Kind::kChessboard;
      b.cols = std::stoi(m[1]);
      b.rows = std::stoi(m[2]);
      b.square_mm = std::stod(m[3]);
    } else if (std::regex_match(text, m, charuco)) {
      b.kind = Kind::kCharuco;
      b.cols = std::stoi(m[1]);
      b.rows = std::stoi(m[2]);
      b.square_mm = std::stod(m[3]);
      b.marker_mm = std::stod(m[4]);
      if (m[5].matched) {
        b.dictionary = -1;
        for (const auto& d : kDictionaries)
          if (m[5] == d.name) b.dictionary = d.id;
        if (b.dictionary < 0)
          throw CalibError(fmt::format("board '{}': unknown ArUco dictionary '{}' (4X4_50, "
                                       "4X4_100, 5X5_100, 6X6_250)", text, m[5].str()));
      }
    } else {
      throw CalibError(fmt::format("board '{}': expected chessboard:COLSxROWS:SQUARE_MM or "
                                   "charuco:SXxSY:SQUARE_MM:MARKER_MM[:DICT]", text));
    }
  } catch (const std::out_of_range&) {
    throw CalibError(fmt::format("board '{}': number out of range", text));
  }
  if (std::string why = b.Validate(); !why.empty())
    throw CalibError(fmt::format("board '{}': {}", text, why));
  return b;
}

std::string BoardSpec::Validate() const {
  if (kind == Kind::kChessboard) {
    if (cols < 3 || rows < 3) return "needs at least 3x3 inner corners";
    if (cols > kMaxBoardSide || rows > kMaxBoardSide)
      return fmt::format("at most {} inner corners per side", kMaxBoardSide);
    if (cols == rows) return "needs different corner counts per row and column (orientation)";
  } else {
    if (cols < 3 || rows < 3) return "needs at least 3x3 squares";
    if (cols > kMaxBoardSide || rows > kMaxBoardSide)
      return fmt::format("at most {} squares per side", kMaxBoardSide);
    // Half the squares hold a marker, each a different one of the dictionary's.
    for (const auto& d : kDictionaries)
      if (d.id == dictionary && cols * rows / 2 > d.markers)
        return fmt::format("needs {} markers, dictionary {} has {}", cols * rows / 2, d.name, d.markers);
    if (!(marker_mm > 0 && marker_mm < square_mm)) return "marker size must be in (0, square)";
  }
  if (!(square_mm > 0 && square_mm <= kMaxSquareMm))
    return fmt::format("square size must be within (0, {:g}] mm", kMaxSquareMm);
  return "";
}

std::string BoardSpec::ToString() const {
  if (kind == Kind::kChessboard) return fmt::format("chessboard:{}x{}:{}", cols, rows, square_mm);
  std::string dict = std::to_string(dictionary);
  for (const auto& d : kDictionaries)
    if (d.id == dictionary) dict = d.name;
  return fmt::format("charuco:{}x{}:{}:{}:{}", cols, rows, square_mm, marker_mm, dict);
}

int BoardSpec::NumCorners() const {
  return kind == Kind::kChessboard ? cols * rows : (cols - 1) * (rows - 1);
}

std::vector<cv::Point3f> BoardSpec::CornerPositions() const {
  if (kind == Kind::kCharuco) return MakeCharuco(*this)->chessboardCorners;
  std::vector<cv::Point3f> p;
  for (int j = 0; j < rows; ++j)
    for (int i = 0; i < cols; ++i) p.emplace_back(float(i * square_mm), float(j * square_mm), 0.f);
  return p;
}

cv::Rect2d BoardSpec::SquaresArea() const {
  if (kind == Kind::kCharuco) return {0, 0, cols * square_mm, rows * square_mm};
  return {-square_mm, -square_mm, (cols + 1) * square_mm, (rows + 1) * square_mm};
}

bool BoardSpec::IsWhite(double x, double y) const {
  const cv::Rect2d a = SquaresArea();
  if (x < a.x || y < a.y || x >= a.x + a.width || y >= a.y + a.height) return true;  // margin
  if (kind == Kind::kChessboard) {
    // Square (-1, -1), the top-left one, is black.
    const long ix = long(std::floor(x / square_mm)), iy = long(std::floor(y / square_mm));
    return ((ix + iy) & 1) != 0;
  }
  if (texture_.empty())
    MakeCharuco(*this)->draw(cv::Size(cols * kTexelsPerSquare, rows * kTexelsPerSquare),
                             texture_, 0, 1);
  const int tx = std::min(int(x / square_mm * kTexelsPerSquare), texture_.cols - 1);
  const int ty = std::min(int(y / square_mm * kTexelsPerSquare), texture_.rows - 1);
  return texture_.at<uint8_t>(ty, tx) > 127;
}

std::vector<cv::Point2f> FindChessboardGrid(const cv::Mat& image, int cols, int rows,
                                            int search_max_side) {
  std::vector<cv::Point2f> c;
  const cv::Mat gray = ToGray(image);
  const int side = std::max(gray.cols, gray.rows);
  // The photo at 1/f of its size: whole f x f blocks averaged, so that pixel centre x there is
  // f x + (f - 1) / 2 in the photo.
  const auto reduced = [&](int f) {
    if (f == 1) return gray;
    cv::Mat r;
    cv::resize(gray(cv::Rect(0, 0, gray.cols / f * f, gray.rows / f * f)), r,
               cv::Size(gray.cols / f, gray.rows / f), 0, 0, cv::INTER_AREA);
    return r;
  };
  // A board too small to be found at 1/s is searched again at 1/(s/2), ..., full size.
  const int s0 = std::max(1, (side + search_max_side - 1) / search_max_side);
  int s = s0;
  for (;; s /= 2) {
    if (cv::findChessboardCornersSB(reduced(s), cv::Size(cols, rows), c,
                                    cv::CALIB_CB_ACCURACY | cv::CALIB_CB_NORMALIZE_IMAGE) &&
        int(c.size()) == cols * rows)
      break;
    if (s == 1) break;
  }
  // The SB detector misses most projected boards in JPEG photos (quality 90: 6 of 8 planes of a
  // simulated capture); OpenCV's older quad detector finds them, within 0.2 px before the
  // refinement below. Searched at 1/s0 only (it is slow on large photos without a board).
  if (int(c.size()) != cols * rows) {
    s = s0;
    if (!cv::findChessboardCorners(reduced(s), cv::Size(cols, rows), c,
                                   cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE |
                                       cv::CALIB_CB_FAST_CHECK) ||
        int(c.size()) != cols * rows)
      return {};
  }
  auto at = [&](int i, int j) -> cv::Point2f& { return c[size_t(j) * cols + i]; };
  // Rows left to right, then first row on top.
  if (at(cols - 1, 0).x < at(0, 0).x)
    for (int j = 0; j < rows; ++j)
      for (int i = 0; i < cols / 2; ++i) std::swap(at(i, j), at(cols - 1 - i, j));
  if (at(0, rows - 1).y < at(0, 0).y)
    for (int j = 0; j < rows / 2; ++j)
      for (int i = 0; i < cols; ++i) std::swap(at(i, j), at(i, rows - 1 - j));
  // OpenCV 4.6's SB detector with CALIB_CB_ACCURACY occasionally puts one corner several
  // pixels off (seen on projected boards). A corner is replaced by its neighbours' prediction
  // when every prediction (midpoints of opposite neighbours, or extrapolation at the border)
  // disagrees with it by more than 2 px.
  std::vector<bool> bad(c.size(), false);
  std::vector<cv::Point2f> predicted(c.size());
  for (int j = 0; j < rows; ++j)
    for (int i = 0; i < cols; ++i) {
      std::vector<cv::Point2f> p;
      if (i > 0 && i + 1 < cols) p.push_back((at(i - 1, j) + at(i + 1, j)) * 0.5f);
      else p.push_back(i == 0 ? 2 * at(1, j) - at(2, j) : 2 * at(i - 1, j) - at(i - 2, j));
      if (j > 0 && j + 1 < rows) p.push_back((at(i, j - 1) + at(i, j + 1)) * 0.5f);
      else p.push_back(j == 0 ? 2 * at(i, 1) - at(i, 2) : 2 * at(i, j - 1) - at(i, j - 2));
      double best = 1e30;
      for (const cv::Point2f& q : p) best = std::min(best, double(cv::norm(q - at(i, j))));
      const size_t k = size_t(j) * cols + i;
      bad[k] = best > 2.0;
      predicted[k] = (p[0] + p[1]) * 0.5f;
    }
  for (size_t k = 0; k < c.size(); ++k)
    if (bad[k]) c[k] = predicted[k];
  // The SB detector's corners carry a bias of ~0.1 px on synthetic views with lens
  // distortion; a saddle-point refinement in a window of a quarter square removes most of it.
  // From a reduced search, coarse to fine: at 1/s, 1/(s/2), ..., full size, each level starting
  // from the level above's result.
  for (int f = s;; f /= 2) {
    const cv::Mat level = reduced(f);
    double spacing = 1e30;
    for (int j = 0; j < rows; ++j)
      for (int i = 0; i + 1 < cols; ++i) spacing = std::min(spacing, double(cv::norm(at(i + 1, j) - at(i, j))));
    const int half = std::clamp(int(spacing / 4), 2, 6);
    std::vector<cv::Point2f> refined = c;
    cv::cornerSubPix(level, refined, cv::Size(half, half), cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::EPS | cv::TermCriteria::COUNT, 50, 1e-4));
    // The refinement can run off to a neighbouring edge; keep the start then. Up to an eighth of
    // a square is no run-off (a fixed 0.75 px kept an SB corner 0.86 px off at 1/4 size, 3.6 px
    // at full size, where its squares were 59 px apart).
    for (size_t k = 0; k < c.size(); ++k)
      if (cv::norm(refined[k] - c[k]) < (bad[k] ? std::max(3.0, spacing / 4) : std::max(0.75, spacing / 8)))
        c[k] = refined[k];
    if (f == 1) break;
    const int next = f / 2;  // level f to level next: x_next = (f x + (f - 1) / 2 - (next - 1) / 2) / next
    for (cv::Point2f& p : c) p = (p * float(f) + cv::Point2f(1, 1) * (0.5f * float(f - next))) / float(next);
  }
  return c;
}

BoardDetection DetectBoard(const BoardSpec& board, const cv::Mat& image, int min_charuco_corners) {
  BoardDetection d;
  const std::vector<cv::Point3f> all = board.CornerPositions();
  if (board.kind == BoardSpec::Kind::kChessboard) {
    d.image_points = FindChessboardGrid(image, board.cols, board.rows);
    if (d.image_points.empty()) return d;
    d.object_points = all;
    for (int i = 0; i < int(all.size()); ++i) d.ids.push_back(i);
    d.found = true;
    return d;
  }
  const cv::Ptr<cv::aruco::CharucoBoard> cb = MakeCharuco(board);
  const cv::Mat gray = ToGray(image);
  std::vector<std::vector<cv::Point2f>> marker_corners;
  std::vector<int> marker_ids;
  cv::aruco::detectMarkers(gray, cb->dictionary, marker_corners, marker_ids);
  if (marker_ids.empty()) return d;
  cv::Mat corners, ids;
  cv::aruco::interpolateCornersCharuco(marker_corners, marker_ids, gray, cb, corners, ids);
  if (ids.total() < size_t(std::max(min_charuco_corners, 4))) return d;
  // Refine to the accuracy of the chessboard detector's saddle points.
  std::vector<cv::Point2f> pts(corners.begin<cv::Point2f>(), corners.end<cv::Point2f>());
  cv::cornerSubPix(gray, pts, cv::Size(5, 5), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS | cv::TermCriteria::COUNT, 50, 1e-4));
  for (size_t k = 0; k < pts.size(); ++k) {
    const int id = ids.at<int>(int(k));
    d.ids.push_back(id);
    d.image_points.push_back(pts[k]);
    d.object_points.push_back(all[size_t(id)]);
  }
  d.found = true;
  return d;
}

}  // namespace translume::calib
