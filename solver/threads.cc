// SPDX-License-Identifier: MIT
#include "solver/threads.h"

#include <omp.h>

#include <cstdlib>

namespace translume {

void SetNumThreads(int n) {
  if (n > 0) omp_set_num_threads(n);
}

int NumThreads() { return omp_get_max_threads(); }

void InitThreadsFromEnvironment() {
  if (const char* env = std::getenv("TRANSLUME_THREADS")) SetNumThreads(std::atoi(env));
}

}  // namespace translume
