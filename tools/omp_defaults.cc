// SPDX-License-Identifier: MIT
// OpenMP's wait policy for every translume executable: passive (idle threads sleep at once)
// unless the user set OMP_WAIT_POLICY or GOMP_SPINCOUNT. libgomp reads its environment when it
// loads, before main, so this runs from the executable's .preinit_array, which the dynamic
// loader calls before any shared library's initialisers. Why: where other processes (or
// llvmpipe's threads, with --backend gl) compete for the cores, spinning barriers made
// two-thread solves 100-250x slower (docs/solver.md, "Threads"); on an idle machine passive
// costs a thread wake-up per parallel region. Linked as an object library (CMakeLists.txt:
// translume_omp_defaults), since nothing references it.
#include <cstdlib>

namespace {

void PassiveOpenMpByDefault(int, char**, char**) {
  if (!std::getenv("OMP_WAIT_POLICY") && !std::getenv("GOMP_SPINCOUNT"))
    setenv("OMP_WAIT_POLICY", "passive", 0);
}

__attribute__((section(".preinit_array"), used)) void (*const kPreinit)(int, char**, char**) =
    PassiveOpenMpByDefault;

}  // namespace
