// SPDX-License-Identifier: MIT
#include "solver/memory.h"

#include <fmt/format.h>
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

int64_t AvailableMemoryBytes() {
  std::ifstream in("/proc/meminfo");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("MemAvailable:", 0) == 0) {
      std::istringstream s(line.substr(13));
      int64_t kb = 0;
      s >> kb;
      return kb * 1024;
    }
  }
  return -1;
}

void CheckFitsInMemory(int64_t bytes, const std::string& what, const std::string& hint) {
  const int64_t avail = AvailableMemoryBytes();
  if (avail > 0 && bytes > avail) {
    throw InputError(fmt::format("{} needs about {} of memory, but only {} is available{}",
                                 what, FormatBytes(bytes), FormatBytes(avail), hint));
  }
}

namespace {

int64_t ProcStatusBytes(const std::string& field) {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind(field + ":", 0) == 0) return std::stoll(line.substr(field.size() + 1)) * 1024;
  return -1;
}

}  // namespace

int64_t ResidentSetBytes() { return ProcStatusBytes("VmRSS"); }
int64_t PeakResidentSetBytes() { return ProcStatusBytes("VmHWM"); }

bool ResetPeakResidentSet() {
#if defined(__GLIBC__)
  malloc_trim(0);
#endif
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
