// SPDX-License-Identifier: MIT
#pragma once

#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <string>

namespace translume {

// `text` with control characters (a NUL quoted from a damaged file ended the printed message
// there) written as \xNN; newlines and tabs kept.
inline std::string Printable(const std::string& text) {
  std::string out;
  for (const char ch : text) {
    const unsigned char c = static_cast<unsigned char>(ch);
    if ((c < 0x20 && c != '\n' && c != '\t') || c == 0x7f) {
      const char* hex = "0123456789abcdef";
      out += "\\x";
      out += hex[c >> 4];
      out += hex[c & 15];
    } else {
      out += ch;
    }
  }
  return out;
}

// "Bad input": a file, flag or value that a user supplied is wrong. The message is one line
// that names the file (or flag) and the problem; the binary prints it and exits non-zero.
// Text quoted from a file may hold anything: the message is kept Printable.
class InputError : public std::runtime_error {
 public:
  explicit InputError(const std::string& message) : std::runtime_error(Printable(message)) {}
  explicit InputError(const char* message) : InputError(std::string(message)) {}
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
