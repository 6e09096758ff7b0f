// SPDX-License-Identifier: MIT
// Helpers shared by the calib tests (header-only; test sources only).
#pragma once

#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cmath>
#include <filesystem>
#include <functional>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "calib/board.h"
#include "calib/error.h"
#include "calib/synthetic_rig.h"

namespace translume::calib {

// a and b have the same size, type and every element bit for bit (as a calibration file that
// stores doubles with 17 significant digits must give back).
inline void ExpectSameMat(const cv::Mat& a, const cv::Mat& b, const std::string& what) {
  ASSERT_EQ(a.size(), b.size()) << what;
  ASSERT_EQ(a.type(), b.type()) << what;
  EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0) << what << ":\n" << a << "\nread back as\n" << b;
}

// The message of the CalibError that f throws, or "(no error)".
inline std::string CalibErrorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const CalibError& e) {
    return e.what();
  }
  return "(no error)";
}

// The default rig with a 4096 x 3072 camera (4x the pixels per side, the same view), its focal
// length times `zoom`.
inline SyntheticRig LargeCameraRig(double zoom = 1) {
  SyntheticRig rig = SyntheticRig::Default();
  const double k = 4;
  rig.camera.size = {4096, 3072};
  rig.camera.K = {zoom * k * rig.camera.K(0, 0), 0, k * (rig.camera.K(0, 2) + 0.5) - 0.5,
                  0, zoom * k * rig.camera.K(1, 1), k * (rig.camera.K(1, 2) + 0.5) - 0.5, 0, 0, 1};
  return rig;
}

// RMS over `found` of the distance to the nearest `truth` corner (px).
inline double CornerRmsToTruth(const std::vector<cv::Point2f>& found, const std::vector<cv::Point2d>& truth);

// FindChessboardGrid on `photo` with its reduced search and with a full-size one: both find
// every corner, and the reduced search's RMS from `truth` is below `bound` and no more than the
// full-size search's plus `slack` (px). Prints both.
inline void ExpectReducedSearchAccurate(const cv::Mat& photo, int cols, int rows,
                                        const std::vector<cv::Point2d>& truth, double bound,
                                        double slack = 0) {
  const auto reduced = FindChessboardGrid(photo, cols, rows);
  const auto full = FindChessboardGrid(photo, cols, rows, 1 << 30);
  ASSERT_EQ(reduced.size(), truth.size());
  ASSERT_EQ(full.size(), truth.size());
  const double r = CornerRmsToTruth(reduced, truth), f = CornerRmsToTruth(full, truth);
  std::printf("corner RMS against the truth: reduced search %.3f px, full-size search %.3f px\n", r, f);
  EXPECT_LT(r, bound);
  EXPECT_LE(r, f + slack);
}

// RMS over `found` of the distance to the nearest `truth` corner (px).
inline double CornerRmsToTruth(const std::vector<cv::Point2f>& found, const std::vector<cv::Point2d>& truth) {
  double sum = 0;
  for (const cv::Point2f& f : found) {
    double nearest = 1e30;
    for (const cv::Point2d& t : truth) nearest = std::min(nearest, cv::norm(cv::Point2d(f) - t));
    sum += nearest * nearest;
  }
  return std::sqrt(sum / double(found.size()));
}

// A file name in the temporary folder, with this process's id so that test runs from several
// checkouts at once do not share it.
inline std::string TempPath(const std::string& name) {
  return (std::filesystem::temp_directory_path() / (std::to_string(getpid()) + "_" + name)).string();
}

}  // namespace translume::calib
