// SPDX-License-Identifier: MIT
#include "solver/threads.h"

#include <omp.h>

#include <unistd.h>

#include <cstdlib>

namespace translume {

void SetNumThreads(int n) {
  if (n > 0) omp_set_num_threads(n);
}

int NumThreads() { return omp_get_max_threads(); }

void InitThreadsFromEnvironment() {
  if (const char* env = std::getenv("TRANSLUME_THREADS")) SetNumThreads(std::atoi(env));
}

void UsePassiveOpenMpByDefault(char** argv) {
  if (std::getenv("OMP_WAIT_POLICY") || std::getenv("GOMP_SPINCOUNT")) return;
  setenv("OMP_WAIT_POLICY", "passive", 1);
  execv("/proc/self/exe", argv);
  // No /proc: go on with the runtime's default policy.
}

}  // namespace translume
