// SPDX-License-Identifier: MIT
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "calib/board.h"

namespace translume::calib {

// A named 8-bit photo (grey or BGR).
struct NamedImage {
  std::string name;  // file name, used in reports and errors
  cv::Mat image;
};

struct CameraCalibOptions {
  int min_views = 5;             // fewer usable views is an error
  double outlier_factor = 3.0;   // a view whose RMS > outlier_factor * median RMS ...
  double outlier_min_px = 0.25;  // ... and > this many pixels is dropped (then recalibrated)
  bool fix_k3 = true;            // estimate k1, k2, p1, p2 only (k3 = 0)
  std::string Validate() const;  // empty when valid
};

// Intrinsics of one device in OpenCV's model: K = [fx 0 cx; 0 fy cy; 0 0 1] (pixels),
// distortion (k1, k2, p1, p2, k3).
struct CameraCalibration {
  cv::Size image_size;
  cv::Matx33d K;
  cv::Mat dist;                          // 1x5 CV_64F
  cv::Mat std_intrinsics;                // 1-sigma of fx, fy, cx, cy, k1, k2, p1, p2, k3 (...)
  double rms = 0;                        // px, over all corners of the used views
  std::vector<std::string> used_views;
  std::vector<double> per_view_errors;   // px RMS, one per used view
  std::vector<cv::Vec3d> rvecs, tvecs;   // camera_from_board per used view
  std::vector<std::string> dropped;      // "NAME: reason" per dropped view
  std::string BriefReport() const;
};

// Zhang's calibration from photos of `board`. Views where the board is not found, or whose
// reprojection RMS is an outlier, are dropped and listed in `dropped`. Throws CalibError when
// photos differ in size (naming the file) or fewer than min_views views remain.
CameraCalibration CalibrateCamera(const BoardSpec& board, const std::vector<NamedImage>& views,
                                  const CameraCalibOptions& options = {});

// OpenCV FileStorage YAML: camera_matrix, distortion_coefficients, image_width, image_height,
// rms, per_view_errors, std_intrinsics, views, dropped_views, board.
void WriteCameraCalibration(const std::string& path, const CameraCalibration& c,
                            const std::string& board);
// Reads camera_matrix, distortion_coefficients, image_width/height (and rms, per_view_errors,
// std_intrinsics, views, dropped_views where present) back; rvecs/tvecs are not stored. Throws
// CalibError naming the file when it cannot be read, lacks a field or holds intrinsics that
// IntrinsicsProblem refuses.
CameraCalibration ReadCameraCalibration(const std::string& path);

// "" when K and dist are usable intrinsics (every number finite, fx and fy positive), else the
// problem, naming the fields `matrix` and `distortion` ("camera_matrix: fx is 0, must be positive").
std::string IntrinsicsProblem(const cv::Matx33d& K, const cv::Mat& dist, const std::string& matrix,
                              const std::string& distortion);

}  // namespace translume::calib
