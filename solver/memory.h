// SPDX-License-Identifier: MIT
#pragma once

#include <cstdint>
#include <string>

#include "solver/forward.h"
#include "solver/grid.h"

namespace translume {

struct MemoryEstimate {
  int64_t forward_bytes = 0;   // one forward solve, all channels in turn
  int64_t recovery_bytes = 0;  // a recovery with `conditions` lights, channels concurrently
};

// Upper-bound estimates of the memory a forward solve or a cpu recovery adds to the process,
// from the data structures' sizes (the multigrid hierarchy is counted as 4/3 of the finest
// level, the bound for semi-coarsening in two axes) and, for the optimiser's working vectors,
// a measured count with a margin: with 16 conditions a recovery's estimate is 5.0 kB per node
// (Wax I: 1.3 GB; Marble: 6.6 GB), 1.1-1.2x the peak measured on the cpu backend (a gl
// recovery needs less on the host).
// `optimizer_vectors`: how many vectors of all 6N log-parameters (doubles) the optimiser keeps;
// 72 is the default L-BFGS's (RecoveryMemoryBytes in recover.h counts them for other options).
MemoryEstimate EstimateMemory(const GridShape& shape, int conditions, Precision precision,
                              int optimizer_vectors = 72);

// The memory this process may still take: the least of MemAvailable (/proc/meminfo) and what its
// cgroups allow (CgroupAvailableBytes); -1 if neither is known. In a container /proc/meminfo
// shows the host's memory, so the cgroup's limit is the one the OOM killer enforces.
int64_t AvailableMemoryBytes();
// Both figures behind it, read once (-1 where unknown); bytes is the least of the known ones.
struct AvailableMemory {
  int64_t bytes = -1, meminfo_bytes = -1, cgroup_bytes = -1;
};
AvailableMemory ReadAvailableMemory();

// What the memory limits of a cgroup and its ancestors still allow: for each with a limit,
// limit - usage + inactive_file (page cache the kernel reclaims before it kills), the least of
// them; -1 where none sets a limit. Reads the cgroup v2 files (memory.max, memory.current,
// memory.stat) under `root` or `root`/unified, and the v1 memory controller's
// (memory.limit_in_bytes, memory.usage_in_bytes, memory.stat's total_inactive_file) under
// `root`/memory; v1 limits of 2^62 bytes or more mean "none". `proc_self_cgroup`: the text of
// /proc/self/cgroup ("id:controllers:path" lines). Directories that do not exist are skipped, so
// that a container which mounts its own cgroup at `root` is read there.
int64_t CgroupAvailableBytes(const std::string& proc_self_cgroup, const std::string& root = "/sys/fs/cgroup");

// Throws InputError if `bytes` exceeds the available memory, naming `what` and the estimate, then
// `hint` (a way to need less).
void CheckFitsInMemory(int64_t bytes, const std::string& what, const std::string& hint = "");

std::string FormatBytes(int64_t bytes);

// The process's resident set and its peak since the start or the last ResetPeakResidentSet,
// in bytes (Linux: VmRSS, VmHWM of /proc/self/status); -1 where unknown.
int64_t ResidentSetBytes();
int64_t PeakResidentSetBytes();
// Hands free heap memory back to the system (glibc's malloc_trim), so that memory freed
// earlier cannot hide what comes next, then resets the peak to the current resident set
// (/proc/self/clear_refs); false where the kernel does not allow it.
bool ResetPeakResidentSet();
// Hands the free heap memory of every thread's arena back to the system (glibc's malloc_trim;
// a no-op without glibc): after work in other threads, whose arenas the next allocations of
// this thread cannot reuse.
void ReleaseFreedMemory();

// Makes glibc's malloc keep freed memory for reuse: large blocks come from the heap instead of
// fresh mappings, and up to 1 GiB of free memory stays at the heap's top. A recovery's optimiser
// (Ceres' L-BFGS and Wolfe line search, one per channel) allocates and frees vectors of 2 N
// doubles (4 MB on the Wax I grid; 6 N with `bench recovery --joint-optimizer`) several times per
// iteration; with glibc's defaults many of them are fresh mappings
// whose pages fault in again, which took ~30 % of an iteration on a 96x96x16 cpu recovery
// (docs/benchmarks.md, "The optimiser's page faults"). Process-wide and idempotent: call it at
// start-up, before other threads run; the translume binaries do. A no-op without glibc.
void KeepFreedMemoryForReuse();

}  // namespace translume
