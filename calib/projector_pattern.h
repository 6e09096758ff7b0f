// SPDX-License-Identifier: MIT
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace translume::calib {

// A chessboard shown by the projector, in projector pixels. Squares are whole pixels: square
// (a, b), a in [0, cols], b in [0, rows], covers pixel columns [origin.x + a square_px,
// origin.x + (a + 1) square_px) and likewise rows. Inner corner (i, j) sits at continuous
// position origin + ((i + 1) square_px - 0.5, (j + 1) square_px - 0.5). Square (0, 0) is
// black; one square of white surrounds the board, black beyond.
struct ProjectorChessboard {
  cv::Size projector_size{1024, 768};
  int cols = 9, rows = 6;  // inner corners
  int square_px = 80;
  cv::Point origin{0, 0};  // top-left pixel of square (0, 0)

  // The board centred on the projector image.
  static ProjectorChessboard Centered(cv::Size projector_size, int cols, int rows, int square_px);
  std::string Validate() const;
  std::vector<cv::Point2f> Corners() const;  // row-major, projector pixels
  // Pattern value (0 or 1) of projector pixel (x, y) (integers).
  int ValueAtPixel(int x, int y) const;
  // The 8-bit image to show on the projector.
  cv::Mat MakeImage() const;
};

}  // namespace translume::calib
