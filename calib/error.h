// SPDX-License-Identifier: MIT
#pragma once

#include <stdexcept>
#include <string>

namespace translume::calib {

// Bad input to calibration or HDR merging: an unreadable file, a board that is not found, too
// few usable views, a missing exposure time. The message is one line that names the file (or
// option) and the problem; callers print it as is.
class CalibError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace translume::calib
