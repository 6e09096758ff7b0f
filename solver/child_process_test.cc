// SPDX-License-Identifier: MIT
#include "solver/child_process.h"

#include <gtest/gtest.h>
#include <sys/resource.h>

#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <new>
#include <unistd.h>

#include "solver/memory.h"
#include "solver/status.h"

namespace translume {
namespace {

TEST(ChildProcess, ReturnsWhatTheWorkReturned) {
  std::string expected(20 << 20, '\0');  // far more than a pipe holds
  for (size_t i = 0; i < expected.size(); ++i) expected[i] = char(i * 2654435761u >> 24);
  const pid_t parent = getpid();
  EXPECT_EQ(RunInChildProcess([&] { return expected; }), expected);
  EXPECT_EQ(RunInChildProcess([&] { return std::to_string(getpid() != parent); }), "1");
  EXPECT_EQ(RunInChildProcess([] { return std::string(); }), "");
}

TEST(ChildProcess, RethrowsTheWorksExceptions) {
  EXPECT_THROW(RunInChildProcess([]() -> std::string { throw std::bad_alloc(); }), std::bad_alloc);
  try {
    RunInChildProcess([]() -> std::string { throw InputError("a.vdb: broken"); });
    ADD_FAILURE() << "no InputError";
  } catch (const InputError& e) {
    EXPECT_STREQ(e.what(), "a.vdb: broken");
  }
  try {
    RunInChildProcess([]() -> std::string { throw std::logic_error("odd"); });
    ADD_FAILURE() << "no runtime_error";
  } catch (const InputError&) {
    ADD_FAILURE() << "an InputError for a logic_error";
  } catch (const std::runtime_error& e) {
    EXPECT_STREQ(e.what(), "odd");
  }
}

TEST(ChildProcess, ACrashEndsTheChildNotTheCaller) {
  try {
    RunInChildProcess([]() -> std::string {
      std::fprintf(stderr, "some noise\nmalloc(): invalid size (unsorted)\n");
      std::abort();
    });
    ADD_FAILURE() << "no ChildCrashed";
  } catch (const ChildCrashed& e) {
    EXPECT_STREQ(e.what(), "was killed by signal 6 (Aborted): malloc(): invalid size (unsorted)");
  }
  try {
    RunInChildProcess([]() -> std::string {
      std::raise(SIGKILL);  // as the OOM killer would
      return "";
    });
    ADD_FAILURE() << "no ChildCrashed";
  } catch (const ChildCrashed& e) {
    EXPECT_STREQ(e.what(), "was killed by signal 9 (Killed)");
  }
  try {
    RunInChildProcess([]() -> std::string { _exit(3); });
    ADD_FAILURE() << "no ChildCrashed";
  } catch (const ChildCrashed& e) {
    EXPECT_STREQ(e.what(), "exited with status 3");
  }
}

// The child may take what is available now, not more: a damaged length fails there as
// std::bad_alloc instead of growing until the OOM killer chooses a process.
TEST(ChildProcess, TheChildsAddressSpaceIsLimitedToAvailableMemory) {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  GTEST_SKIP() << "no limit under AddressSanitizer and ThreadSanitizer (they reserve terabytes)";
#endif
  const int64_t available = AvailableMemoryBytes();
  if (available <= 0) GTEST_SKIP() << "no MemAvailable in /proc/meminfo";
  long pages = 0;
  std::ifstream("/proc/self/statm") >> pages;
  const double own = double(pages) * double(sysconf(_SC_PAGESIZE));
  const std::string limit = RunInChildProcess([] {
    rlimit r{};
    getrlimit(RLIMIT_AS, &r);
    return r.rlim_cur == RLIM_INFINITY ? std::string("unlimited") : std::to_string(double(r.rlim_cur));
  });
  ASSERT_NE(limit, "unlimited");
  EXPECT_GT(std::stod(limit), own + 0.5 * double(available));
  EXPECT_LT(std::stod(limit), own + 1.5 * double(available) + double(1 << 30));
}

}  // namespace
}  // namespace translume
