// SPDX-License-Identifier: MIT
#include "solver/threads.h"

#include <omp.h>

#include <unistd.h>

#include <cstdlib>
#include <string>
#include <vector>

namespace translume {

namespace {
std::vector<void (*)(int)>& Listeners() {
  static std::vector<void (*)(int)> listeners;
  return listeners;
}
}  // namespace

void SetNumThreads(int n) {
  if (n <= 0) return;
  omp_set_num_threads(n);
  for (auto* listener : Listeners()) listener(n);
}

void AddThreadCountListener(void (*listener)(int threads)) {
  Listeners().push_back(listener);
  listener(NumThreads());
}

int NumThreads() { return omp_get_max_threads(); }

std::string InitThreadsFromEnvironment() {
  const char* env = std::getenv("TRANSLUME_THREADS");
  if (!env || !*env) return "";
  char* end = nullptr;
  const long n = std::strtol(env, &end, 10);
  if (*end != '\0' || n < 1 || n > 4096)
    return std::string("TRANSLUME_THREADS=") + env + ": expected a whole number of threads, 1..4096";
  SetNumThreads(int(n));
  return "";
}

void UsePassiveOpenMpByDefault(char** argv) {
  if (std::getenv("OMP_WAIT_POLICY") || std::getenv("GOMP_SPINCOUNT")) return;
  setenv("OMP_WAIT_POLICY", "passive", 1);
  execv("/proc/self/exe", argv);
  // No /proc: go on with the runtime's default policy.
}

}  // namespace translume
