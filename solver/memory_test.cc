// SPDX-License-Identifier: MIT
#include "solver/memory.h"

#include <gtest/gtest.h>
#include <sys/resource.h>

#include <cstring>
#include <memory>

namespace translume {
namespace {

int64_t MinorFaults() {
  rusage u{};
  getrusage(RUSAGE_THREAD, &u);
  return u.ru_minflt;
}

// Allocates, fills and frees a block of `bytes` `rounds` times; returns the page faults taken.
int64_t FaultsOfLargeBlocks(size_t bytes, int rounds) {
  const int64_t before = MinorFaults();
  for (int r = 0; r < rounds; ++r) {
    std::unique_ptr<char[]> block(new char[bytes]);
    std::memset(block.get(), r + 1, bytes);
    volatile char sink = block[bytes / 2];
    (void)sink;
  }
  return MinorFaults() - before;
}

// What the optimiser's vectors need (memory.h): a freed large block's pages serve the next
// block of that size, so that only the first allocation faults its pages in. (With glibc's
// defaults a 64 MiB block is a fresh mapping every time: ~16k faults per round.)
TEST(Memory, FreedLargeBlocksAreReusedWithoutPageFaults) {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  GTEST_SKIP() << "the sanitizer's allocator replaces glibc's malloc";
#endif
  KeepFreedMemoryForReuse();
  KeepFreedMemoryForReuse();  // idempotent
  constexpr size_t kBytes = size_t(64) << 20;
  constexpr int64_t kPages = int64_t(kBytes / 4096);
  FaultsOfLargeBlocks(kBytes, 1);  // the heap grows once
  const int64_t faults = FaultsOfLargeBlocks(kBytes, 8);
#if defined(__GLIBC__)
  EXPECT_LT(faults, kPages / 10) << "8 rounds of " << kPages << " pages";
#else
  (void)faults;
#endif
}

TEST(Memory, FormatBytesPicksTheUnit) {
  EXPECT_EQ(FormatBytes(512), "0.5 KiB");
  EXPECT_EQ(FormatBytes(int64_t(3) << 20), "3.0 MiB");
  EXPECT_EQ(FormatBytes(int64_t(5) << 30), "5.00 GiB");
}

}  // namespace
}  // namespace translume
