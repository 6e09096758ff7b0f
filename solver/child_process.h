// SPDX-License-Identifier: MIT
#pragma once

#include <functional>
#include <stdexcept>
#include <string>

namespace translume {

// The child process of RunInChildProcess ended without finishing `work`: killed by a signal
// (a crash, an abort) or exited early. what() says how, with the last line it wrote to stderr.
class ChildCrashed : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Runs `work` in a forked child process and returns the bytes it returned. For reading
// untrusted files with a library that trusts them (OpenVDB): a crash, a failed assertion or a
// corrupted heap ends the child, not this process. In the child:
// - the address space is limited to its size now plus the memory available now (not under
//   AddressSanitizer, which reserves terabytes), so a damaged length that asks for gigabytes
//   fails there with std::bad_alloc instead of waking the OOM killer;
// - stderr goes to a temporary file, whose last line ChildCrashed quotes;
// - only the calling thread exists: `work` must not start threads or use a thread pool that
//   this process started (OpenMP, TBB), and must not need destructors of globals.
// An InputError or std::bad_alloc thrown by `work` is rethrown here as the same type; any other
// exception as std::runtime_error with its message. Throws ChildCrashed as above.
std::string RunInChildProcess(const std::function<std::string()>& work);

}  // namespace translume
