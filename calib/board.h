// SPDX-License-Identifier: MIT
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace translume::calib {

// A printed calibration target.
//  chessboard:COLSxROWS:SQUARE_MM          COLS x ROWS inner corners (OpenCV's pattern size).
//  charuco:SXxSY:SQUARE_MM:MARKER_MM[:DICT] SX x SY squares, ArUco dictionary DICT (4X4_50,
//                                           4X4_100, 5X5_100 (default), 6X6_250); odd SY is
//                                           advised with OpenCV 4.6 (SPEC section 8).
// Board frame (mm): x along the rows (columns of corners), y down the board, z = 0 on the
// board, pointing away from a camera that sees the board upright. Chessboard inner corner
// (i, j) sits at (i * square, j * square); ChArUco corner id k at
// ((k % (SX - 1) + 1) * square, (k / (SX - 1) + 1) * square).
struct BoardSpec {
  // Limits far beyond printed boards; larger ones were typos that allocated gigabytes.
  static constexpr int kMaxBoardSide = 100;        // corners (chessboard) or squares (charuco)
  static constexpr double kMaxSquareMm = 10000;    // 10 m
  enum class Kind { kChessboard, kCharuco };
  Kind kind = Kind::kChessboard;
  int cols = 9;  // chessboard: inner corners per row; charuco: squares per row
  int rows = 6;  // chessboard: inner corners per column; charuco: squares per column
  double square_mm = 20.0;
  double marker_mm = 15.0;  // charuco only
  int dictionary = 5;       // cv::aruco::PREDEFINED_DICTIONARY_NAME (5 = DICT_5X5_100)

  // Throws CalibError naming `text` when it does not parse or is invalid.
  static BoardSpec Parse(const std::string& text);
  // Empty when valid, else the broken constraint.
  std::string Validate() const;
  std::string ToString() const;

  int NumCorners() const;
  // Corner positions (board frame, mm), indexed by corner id (chessboard: row-major).
  std::vector<cv::Point3f> CornerPositions() const;
  // Printed area of the squares, board frame: [min.x, max.x] x [min.y, max.y] (mm).
  cv::Rect2d SquaresArea() const;
  // Albedo pattern value of the printed board at board point (x, y) mm: true = white, for
  // points inside SquaresArea(); with a white paper margin of one square around it.
  // (ChArUco uses a rasterised texture, cached.)
  bool IsWhite(double x_mm, double y_mm) const;

 private:
  mutable cv::Mat texture_;  // charuco: 8-bit board raster, kTexelsPerSquare per square
};

// Board corners found in one image.
struct BoardDetection {
  bool found = false;
  std::vector<cv::Point2f> image_points;   // pixels (OpenCV convention: pixel centres integer)
  std::vector<cv::Point3f> object_points;  // board frame, mm
  std::vector<int> ids;                    // corner ids
};

// Finds the board in an 8-bit grey or BGR image. Chessboards: findChessboardCornersSB with the
// ACCURACY flag, corners reordered so that the first corner is the top-left one in the image and
// rows run left to right (boards seen upright, rotated by less than 45 degrees). ChArUco: marker
// detection and corner interpolation; found when at least min_charuco_corners corners are seen.
BoardDetection DetectBoard(const BoardSpec& board, const cv::Mat& image,
                           int min_charuco_corners = 8);

// Photos whose longest side exceeds this (px) are searched for a chessboard at 1/s of their
// size (s the smallest whole factor that brings them within it; a 4096 x 3072 photo at
// 1024 x 768; where the board is too small to be found there, at 1/(s/2), ..., full size)
// and the corners refined at full resolution. OpenCV's SB detector is slow on
// large photos (seconds per 12 MP photo) and there put some corners pixels off, where the
// reduced search is within 0.02 px (CameraCalib.LargePhotosKeepTheirCornerAccuracy).
inline constexpr int kChessboardSearchMaxSide = 1280;

// A chessboard pattern detection of an arbitrary grid (used for projected patterns):
// cols x rows inner corners, same ordering rules as above. Empty when not found. OpenCV's SB
// detector first; where it finds nothing (JPEG photos of projected boards), OpenCV's older
// quad detector; corners refined with cornerSubPix either way.
// search_max_side: see kChessboardSearchMaxSide (tests compare with a full-size search).
std::vector<cv::Point2f> FindChessboardGrid(const cv::Mat& image, int cols, int rows,
                                            int search_max_side = kChessboardSearchMaxSide);

}  // namespace translume::calib
