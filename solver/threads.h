// SPDX-License-Identifier: MIT
#pragma once

namespace translume {

// Threads used by every multithreaded loop (OpenMP). Default: TRANSLUME_THREADS if set, else
// OMP_NUM_THREADS if set, else the number of hardware threads. `translume --threads N` sets it.
void SetNumThreads(int n);
int NumThreads();
// Called once at start-up: applies TRANSLUME_THREADS.
void InitThreadsFromEnvironment();

}  // namespace translume
