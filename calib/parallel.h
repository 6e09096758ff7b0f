// SPDX-License-Identifier: MIT
#pragma once

#include <algorithm>
#include <exception>
#include <opencv2/core/utility.hpp>
#include <vector>

namespace translume::calib {

// Runs body(i) for every i in [0, n) on OpenCV's threads (photos decode, encode and detect
// boards one per thread). If any call throws, rethrows the exception of the lowest such i once
// all have finished.
template <typename F>
void ParallelFor(int n, F&& body) {
  std::vector<std::exception_ptr> errors(size_t(std::max(n, 0)));
  cv::parallel_for_(cv::Range(0, std::max(n, 0)), [&](const cv::Range& r) {
    for (int i = r.start; i < r.end; ++i) {
      try {
        body(i);
      } catch (...) {
        errors[size_t(i)] = std::current_exception();
      }
    }
  });
  for (const std::exception_ptr& e : errors)
    if (e) std::rethrow_exception(e);
}

}  // namespace translume::calib
