// SPDX-License-Identifier: MIT
#pragma once

#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <string>

namespace translume {

// "Bad input": a file, flag or value that a user supplied is wrong. The message is one line
// that names the file (or flag) and the problem; the binary prints it and exits non-zero.
class InputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Thrown when a long computation is interrupted by the user (Ctrl-C).
class Interrupted : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

[[noreturn]] inline void CheckFailed(const char* expr, const char* file, int line,
                                     const std::string& msg) {
  std::fprintf(stderr, "translume: internal error (bug): CHECK(%s) failed at %s:%d %s\n", expr,
               file, line, msg.c_str());
  std::abort();
}

}  // namespace translume

// "Bug": an invariant of our own code is broken. Never used for user input.
#define TL_CHECK(cond)                                                        \
  do {                                                                        \
    if (!(cond)) ::translume::CheckFailed(#cond, __FILE__, __LINE__, "");     \
  } while (0)
#define TL_CHECK_MSG(cond, msg)                                               \
  do {                                                                        \
    if (!(cond)) ::translume::CheckFailed(#cond, __FILE__, __LINE__, (msg));  \
  } while (0)
