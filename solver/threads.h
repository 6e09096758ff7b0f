// SPDX-License-Identifier: MIT
#pragma once

namespace translume {

// Threads used by every multithreaded loop (OpenMP). Default: TRANSLUME_THREADS if set, else
// OMP_NUM_THREADS if set, else the number of hardware threads. `translume --threads N` sets it.
void SetNumThreads(int n);
int NumThreads();
// Called once at start-up: applies TRANSLUME_THREADS.
void InitThreadsFromEnvironment();

// Called first in an executable's main(): unless OMP_WAIT_POLICY or GOMP_SPINCOUNT is set,
// sets OMP_WAIT_POLICY=passive (idle OpenMP threads sleep at once instead of spinning) and
// re-executes the program (/proc/self/exe, same arguments), since the OpenMP runtime reads its
// environment when it loads, before main. Returns only if that was not needed or failed. Why:
// where other processes (or llvmpipe's threads) compete for the cores, spinning barriers made
// two-thread solves 100-250x slower (docs/solver.md, "Threads").
void UsePassiveOpenMpByDefault(char** argv);

}  // namespace translume
