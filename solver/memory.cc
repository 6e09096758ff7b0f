// SPDX-License-Identifier: MIT
#include "solver/memory.h"

#include <fmt/format.h>

#include <algorithm>
#include <fstream>
#if defined(__GLIBC__)
#include <malloc.h>
#endif
#include <sstream>

#include "solver/status.h"

namespace translume {

MemoryEstimate EstimateMemory(const GridShape& shape, int conditions, Precision precision, int optimizer_vectors) {
  const double n = double(shape.size());
  const double t = precision == Precision::kDouble ? 8 : 4;
  // Per level: kappa, mu, cx, cy, cz, diag, the smoother's copy of the stencil in its own
  // layout (4 arrays), lu_inv, b, x, transfer temporaries (~2).
  const double hierarchy = 15 * t * n * 4.0 / 3.0;
  // Finest level extras: CG vectors r, p, q; the caller's kappa, mu, b, phi; the CG iterate,
  // double in both precisions (docs/solver.md).
  const double solve = hierarchy + 7 * t * n + 8 * n;
  const double material = 6 * 4 * n;  // RGB kappa and mu, float
  MemoryEstimate e;
  e.forward_bytes = int64_t(solve + material);
  // Recovery. Per channel (three run concurrently): one solver, the forward and adjoint fields
  // of every condition (kept for warm starts and the gradient), kappa, mu and their gradients
  // (4 vectors of N doubles). The optimiser: `optimizer_vectors` vectors of all 6N
  // log-parameters. Plus 16 MiB whatever the grid (threads, the dataset's face images, small
  // levels; ~5 measured).
  const double per_channel = solve + 2.0 * conditions * t * n + 4 * 8 * n;
  const double optimizer = double(optimizer_vectors) * 6 * 8 * n;
  e.recovery_bytes = int64_t(3 * per_channel + optimizer + material) + (int64_t(16) << 20);
  return e;
}

namespace {

std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return in ? s.str() : std::string();
}

// The number after `key` on the line that starts with `key` (then ':' or ' '), -1 if none.
// Units are the caller's ("MemAvailable:  123 kB" gives 123).
int64_t KeyedNumber(const std::string& text, const std::string& key) {
  std::istringstream lines(text);
  std::string line;
  while (std::getline(lines, line)) {
    if (line.size() > key.size() && line.rfind(key, 0) == 0 &&
        (line[key.size()] == ':' || line[key.size()] == ' ')) {
      std::istringstream s(line.substr(key.size() + 1));
      int64_t v = -1;
      return s >> v ? v : -1;
    }
  }
  return -1;
}

// A file that holds one number, or "max" (-1), or nothing readable (-1).
int64_t FileNumber(const std::string& path) {
  std::istringstream s(ReadFile(path));
  int64_t v = -1;
  return s >> v ? v : -1;
}

// The lesser of two amounts where -1 means unknown.
int64_t LeastKnown(int64_t a, int64_t b) { return a < 0 ? b : b < 0 ? a : std::min(a, b); }

struct CgroupFiles {
  const char* limit;
  const char* usage;
  const char* inactive_file;  // key in memory.stat
};

// limit - usage + inactive file pages for `dir`, -1 without a limit.
int64_t CgroupDirAvailable(const std::string& dir, const CgroupFiles& f) {
  const int64_t limit = FileNumber(dir + "/" + f.limit);
  if (limit < 0 || limit >= (int64_t(1) << 62)) return -1;
  const int64_t usage = std::max<int64_t>(FileNumber(dir + "/" + f.usage), 0);
  const int64_t inactive = std::max<int64_t>(KeyedNumber(ReadFile(dir + "/memory.stat"), f.inactive_file), 0);
  return std::max<int64_t>(limit - usage + inactive, 0);
}

// The least over `path` and its ancestors under `base`; -1 where none has a limit.
int64_t CgroupPathAvailable(const std::string& base, std::string path, const CgroupFiles& f) {
  int64_t least = -1;
  while (true) {
    while (path.size() > 1 && path.back() == '/') path.pop_back();
    least = LeastKnown(least, CgroupDirAvailable(base + (path == "/" ? "" : path), f));
    if (path.empty() || path == "/") break;
    const size_t slash = path.rfind('/');
    path = slash == std::string::npos || slash == 0 ? "/" : path.substr(0, slash);
  }
  return least;
}

}  // namespace

int64_t CgroupAvailableBytes(const std::string& proc_self_cgroup, const std::string& root) {
  static constexpr CgroupFiles kV1{"memory.limit_in_bytes", "memory.usage_in_bytes", "total_inactive_file"};
  static constexpr CgroupFiles kV2{"memory.max", "memory.current", "inactive_file"};
  int64_t least = -1;
  const auto keep = [&](int64_t a) { least = LeastKnown(least, a); };
  std::istringstream lines(proc_self_cgroup);
  std::string line;
  while (std::getline(lines, line)) {
    const size_t c1 = line.find(':');
    const size_t c2 = c1 == std::string::npos ? c1 : line.find(':', c1 + 1);
    if (c2 == std::string::npos) continue;
    const std::string path = line.substr(c2 + 1);
    if (c2 == c1 + 1) {  // "0::/path": the v2 hierarchy
      keep(CgroupPathAvailable(root, path, kV2));
      keep(CgroupPathAvailable(root + "/unified", path, kV2));
      continue;
    }
    std::istringstream controllers(line.substr(c1 + 1, c2 - c1 - 1));
    std::string controller;
    while (std::getline(controllers, controller, ','))
      if (controller == "memory") keep(CgroupPathAvailable(root + "/memory", path, kV1));
  }
  return least;
}

AvailableMemory ReadAvailableMemory() {
  AvailableMemory a;
  const int64_t kb = KeyedNumber(ReadFile("/proc/meminfo"), "MemAvailable");
  a.meminfo_bytes = kb < 0 ? -1 : kb * 1024;
  a.cgroup_bytes = CgroupAvailableBytes(ReadFile("/proc/self/cgroup"));
  a.bytes = LeastKnown(a.meminfo_bytes, a.cgroup_bytes);
  return a;
}

int64_t AvailableMemoryBytes() { return ReadAvailableMemory().bytes; }

void CheckFitsInMemory(int64_t bytes, const std::string& what, const std::string& hint) {
  const int64_t avail = AvailableMemoryBytes();
  if (avail > 0 && bytes > avail) {
    throw InputError(fmt::format("{} needs about {} of memory, but only {} is available{}",
                                 what, FormatBytes(bytes), FormatBytes(avail), hint));
  }
}

namespace {

int64_t ProcStatusBytes(const std::string& field) {
  const int64_t kb = KeyedNumber(ReadFile("/proc/self/status"), field);
  return kb < 0 ? -1 : kb * 1024;
}

}  // namespace

int64_t ResidentSetBytes() { return ProcStatusBytes("VmRSS"); }
int64_t PeakResidentSetBytes() { return ProcStatusBytes("VmHWM"); }

void ReleaseFreedMemory() {
#if defined(__GLIBC__)
  malloc_trim(0);
#endif
}

bool ResetPeakResidentSet() {
  ReleaseFreedMemory();
  std::ofstream clear("/proc/self/clear_refs");
  clear << "5";
  clear.flush();
  return bool(clear);
}

std::string FormatBytes(int64_t bytes) {
  const double b = double(bytes);
  if (b >= 1024.0 * 1024 * 1024) return fmt::format("{:.2f} GiB", b / (1024.0 * 1024 * 1024));
  if (b >= 1024.0 * 1024) return fmt::format("{:.1f} MiB", b / (1024.0 * 1024));
  return fmt::format("{:.1f} KiB", b / 1024.0);
}

void KeepFreedMemoryForReuse() {
#if defined(__GLIBC__)
  // M_MMAP_MAX 0: no block gets its own mapping (glibc still maps where the heap cannot grow).
  // Setting either value also ends glibc's dynamic adjustment of both thresholds.
  mallopt(M_MMAP_MAX, 0);
  mallopt(M_TRIM_THRESHOLD, 1 << 30);
#endif
}

}  // namespace translume
