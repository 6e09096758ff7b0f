// SPDX-License-Identifier: MIT
#include "solver/memory.h"

#include <gtest/gtest.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>

#include "solver/forward.h"
#include "solver/light.h"
#include "solver/status.h"

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

// The forward estimate (which `forward` and `bench forward` check against the available
// memory) bounds the peak a forward solve adds, and is not loose. The material already exists
// here, so the peak lacks its 24 bytes per node of the estimate (`translume forward`, which
// loads it, took 137 bytes per node in float on 128x128x20 .. 256x256x40, where the estimate
// counted 132 before it counted the CG iterate as double; docs/benchmarks.md, "The recovery's
// memory estimate").
class ForwardPeak : public ::testing::TestWithParam<Precision> {};

TEST_P(ForwardPeak, StaysWithinTheEstimate) {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  GTEST_SKIP() << "the sanitizer's allocator and shadow memory change the resident set";
#endif
  const Precision precision = GetParam();
  const GridShape shape{96, 96, 24};
  const Material m = Material::Constant(shape, 0.5, {0.3f, 0.2f, 0.1f}, {0.01f, 0.02f, 0.05f});
  const FacePattern q = GreyPattern(RasterizeLight(LightSpec::Parse("uniform"), shape, 0.5));
  if (!ResetPeakResidentSet()) GTEST_SKIP() << "cannot reset the peak resident set (/proc/self/clear_refs)";
  const int64_t before = ResidentSetBytes();
  ASSERT_GT(before, 0);
  ForwardOptions o;
  o.precision = precision;
  const ForwardResult r = SolveForward(m, q, o);
  const double used = double(PeakResidentSetBytes() - before);
  const double estimate = double(EstimateMemory(shape, 1, precision).forward_bytes);
  std::printf("peak %s above the start, estimate %s (%.2f)\n", FormatBytes(int64_t(used)).c_str(),
              FormatBytes(int64_t(estimate)).c_str(), used / estimate);
  EXPECT_TRUE(r.summaries[0].converged);
  EXPECT_LE(used, estimate);
  EXPECT_GE(used, 0.6 * estimate);
}

INSTANTIATE_TEST_SUITE_P(Memory, ForwardPeak, ::testing::Values(Precision::kFloat, Precision::kDouble),
                         [](const ::testing::TestParamInfo<Precision>& p) {
                           return std::string(p.param == Precision::kFloat ? "Float" : "Double");
                         });

TEST(Memory, TooLargeNamesWhatTheEstimateAndTheHint) {
  if (AvailableMemoryBytes() < 0) GTEST_SKIP() << "no MemAvailable in /proc/meminfo";
  EXPECT_NO_THROW(CheckFitsInMemory(1 << 20, "a small thing"));
  try {
    CheckFitsInMemory(int64_t(1) << 60, "a huge thing", " (try less)");
    ADD_FAILURE() << "an exabyte fits";
  } catch (const InputError& e) {
    const std::string m = e.what();
    EXPECT_EQ(m.rfind("a huge thing needs about 1073741824.00 GiB of memory, but only ", 0), 0u) << m;
    EXPECT_TRUE(m.ends_with(" is available (try less)")) << m;
  }
}

// A cgroup tree as the kernel shows it, written under a temporary root.
class FakeCgroups {
 public:
  FakeCgroups() : root_(std::filesystem::path(::testing::TempDir()) / ("cgroups_" + std::to_string(::getpid()))) {
    std::filesystem::remove_all(root_);
  }
  ~FakeCgroups() { std::filesystem::remove_all(root_); }
  void Write(const std::string& file, const std::string& text) const {
    const std::filesystem::path p = root_ / file;
    std::filesystem::create_directories(p.parent_path());
    std::ofstream(p) << text;
  }
  std::string root() const { return root_.string(); }

 private:
  std::filesystem::path root_;
};

// In a container /proc/meminfo shows the host's memory; the cgroup's limit is what the OOM
// killer enforces, so it bounds the available memory (limit - usage + inactive file pages,
// the least over the cgroup and its ancestors).
TEST(Memory, CgroupLimitsBoundTheAvailableMemory) {
  {  // v2: the parent's limit is tighter than the leaf's.
    FakeCgroups fs;
    fs.Write("a/b/memory.max", "1000000\n");
    fs.Write("a/b/memory.current", "400000\n");
    fs.Write("a/b/memory.stat", "anon 300000\nfile 100000\ninactive_file 100000\nactive_file 0\n");
    fs.Write("a/memory.max", "500000\n");
    fs.Write("a/memory.current", "420000\n");
    fs.Write("a/memory.stat", "inactive_file 30000\n");
    fs.Write("memory.current", "9000000\n");  // the root has no memory.max
    EXPECT_EQ(CgroupAvailableBytes("0::/a/b\n", fs.root()), 110000);
    fs.Write("a/memory.max", "max\n");
    EXPECT_EQ(CgroupAvailableBytes("0::/a/b\n", fs.root()), 700000);
    EXPECT_EQ(CgroupAvailableBytes("0::/a/b/\n", fs.root()), 700000);
    fs.Write("a/b/memory.max", "max\n");
    EXPECT_EQ(CgroupAvailableBytes("0::/a/b\n", fs.root()), -1);
  }
  {  // v1 memory controller (beside other controllers and a v2 hierarchy: hybrid).
    FakeCgroups fs;
    const std::string self = "5:cpu,cpuacct:/job\n4:memory:/job\n0::/job\n";
    fs.Write("memory/job/memory.limit_in_bytes", "9223372036854771712\n");  // no limit
    fs.Write("memory/job/memory.usage_in_bytes", "500000\n");
    fs.Write("memory/job/memory.stat", "cache 300000\ninactive_file 1\ntotal_inactive_file 250000\n");
    fs.Write("memory/memory.limit_in_bytes", "9223372036854771712\n");
    EXPECT_EQ(CgroupAvailableBytes(self, fs.root()), -1);
    fs.Write("memory/job/memory.limit_in_bytes", "2000000\n");
    EXPECT_EQ(CgroupAvailableBytes(self, fs.root()), 1750000);
    // A v2 limit in the hybrid's unified hierarchy counts too.
    fs.Write("unified/job/memory.max", "600000\n");
    fs.Write("unified/job/memory.current", "100000\n");
    EXPECT_EQ(CgroupAvailableBytes(self, fs.root()), 500000);
    // Usage above the limit (before reclaim) means nothing is left, not a negative amount.
    fs.Write("memory/job/memory.usage_in_bytes", "3000000\n");
    EXPECT_EQ(CgroupAvailableBytes(self, fs.root()), 0);
  }
  {  // A container that mounts its own cgroup at the root while /proc/self/cgroup names the
     // host's path: the path's directories do not exist, the root's files are read.
    FakeCgroups fs;
    fs.Write("memory/memory.limit_in_bytes", "8000000\n");
    fs.Write("memory/memory.usage_in_bytes", "1000000\n");
    EXPECT_EQ(CgroupAvailableBytes("4:memory:/docker/0123abcd\n", fs.root()), 7000000);
  }
  {  // Nothing there, or nothing readable.
    FakeCgroups fs;
    EXPECT_EQ(CgroupAvailableBytes("0::/\n", fs.root()), -1);
    EXPECT_EQ(CgroupAvailableBytes("", fs.root()), -1);
    EXPECT_EQ(CgroupAvailableBytes("garbage\n", fs.root()), -1);
  }
  // This machine: the available memory is known, the least of the two figures.
  const AvailableMemory a = ReadAvailableMemory();
  EXPECT_GT(a.meminfo_bytes, 0);
  EXPECT_EQ(a.bytes, a.cgroup_bytes < 0 ? a.meminfo_bytes : std::min(a.meminfo_bytes, a.cgroup_bytes));
  EXPECT_GT(AvailableMemoryBytes(), 0);
}

TEST(Memory, FormatBytesPicksTheUnit) {
  EXPECT_EQ(FormatBytes(512), "0.5 KiB");
  EXPECT_EQ(FormatBytes(int64_t(3) << 20), "3.0 MiB");
  EXPECT_EQ(FormatBytes(int64_t(5) << 30), "5.00 GiB");
}

}  // namespace
}  // namespace translume
