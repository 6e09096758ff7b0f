// SPDX-License-Identifier: MIT
#pragma once

#include <cstdint>
#include <string>

namespace translume {

// Loops over fewer values (grid nodes) than this run on one thread (the OpenMP `if` clause of
// every parallel loop in the solver): opening a parallel region costs a few microseconds
// with spinning threads and tens with sleeping ones (OMP_WAIT_POLICY=passive, our default:
// ~75 us on the 2-core VM), more than one pass over that many nodes takes on one core.
// docs/solver.md, "Threads", has the measurements.
inline constexpr int64_t kParallelNodes = 100000;

// Threads used by every multithreaded loop (OpenMP). Default: TRANSLUME_THREADS if set, else
// OMP_NUM_THREADS if set, else the number of hardware threads. `translume --threads N` sets it.
void SetNumThreads(int n);
int NumThreads();
// Other thread pools that must follow SetNumThreads (OpenCV's, for calibration and HDR): called
// now with NumThreads(), and again on every change. The translume binary registers OpenCV's.
void AddThreadCountListener(void (*listener)(int threads));
// Called once at start-up: applies TRANSLUME_THREADS; returns "" or what is wrong with it.
std::string InitThreadsFromEnvironment();

// Called first in an executable's main(): unless OMP_WAIT_POLICY or GOMP_SPINCOUNT is set,
// sets OMP_WAIT_POLICY=passive (idle OpenMP threads sleep at once instead of spinning) and
// re-executes the program (/proc/self/exe, same arguments), since the OpenMP runtime reads its
// environment when it loads, before main. Returns only if that was not needed or failed. Why:
// where other processes (or llvmpipe's threads) compete for the cores, spinning barriers made
// two-thread solves 100-250x slower (docs/solver.md, "Threads").
void UsePassiveOpenMpByDefault(char** argv);

}  // namespace translume
