// SPDX-License-Identifier: MIT
#include "calib/projector_pattern.h"

namespace translume::calib {

ProjectorChessboard ProjectorChessboard::Centered(cv::Size size, int cols, int rows, int sq) {
  ProjectorChessboard b;
  b.projector_size = size;
  b.cols = cols;
  b.rows = rows;
  b.square_px = sq;
  b.origin = {(size.width - (cols + 1) * sq) / 2, (size.height - (rows + 1) * sq) / 2};
  return b;
}

std::string ProjectorChessboard::Validate() const {
  if (cols < 3 || rows < 3 || cols == rows) return "needs at least 3x3 inner corners, cols != rows";
  if (square_px < 4) return "squares must be at least 4 projector pixels";
  if (origin.x < square_px || origin.y < square_px ||
      origin.x + (cols + 2) * square_px > projector_size.width ||
      origin.y + (rows + 2) * square_px > projector_size.height)
    return "the board and its one-square white border must fit in the projector image";
  return "";
}

std::vector<cv::Point2f> ProjectorChessboard::Corners() const {
  std::vector<cv::Point2f> c;
  for (int j = 0; j < rows; ++j)
    for (int i = 0; i < cols; ++i)
      c.emplace_back(float(origin.x + (i + 1) * square_px - 0.5),
                     float(origin.y + (j + 1) * square_px - 0.5));
  return c;
}

int ProjectorChessboard::ValueAtPixel(int x, int y) const {
  const int fx = x - origin.x, fy = y - origin.y;
  const int a = fx >= 0 ? fx / square_px : -1 - (-fx - 1) / square_px;
  const int b = fy >= 0 ? fy / square_px : -1 - (-fy - 1) / square_px;
  if (a < -1 || b < -1 || a > cols + 1 || b > rows + 1) return 0;   // beyond the border
  if (a == -1 || b == -1 || a == cols + 1 || b == rows + 1) return 1;  // white border
  return (a + b) & 1;
}

cv::Mat ProjectorChessboard::MakeImage() const {
  cv::Mat img(projector_size, CV_8UC1);
  for (int y = 0; y < img.rows; ++y)
    for (int x = 0; x < img.cols; ++x) img.at<uint8_t>(y, x) = ValueAtPixel(x, y) ? 255 : 0;
  return img;
}

}  // namespace translume::calib
