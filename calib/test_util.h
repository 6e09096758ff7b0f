// SPDX-License-Identifier: MIT
// Helpers shared by the calib tests (header-only; test sources only).
#pragma once

#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <functional>
#include <opencv2/core.hpp>
#include <string>

#include "calib/error.h"

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

// A file name in the temporary folder, with this process's id so that test runs from several
// checkouts at once do not share it.
inline std::string TempPath(const std::string& name) {
  return (std::filesystem::temp_directory_path() / (std::to_string(getpid()) + "_" + name)).string();
}

}  // namespace translume::calib
