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

// Upper-bound estimates from the data structures' sizes (the multigrid hierarchy is counted
// as 4/3 of the finest level, the bound for semi-coarsening in two axes).
MemoryEstimate EstimateMemory(const GridShape& shape, int conditions, Precision precision);

// MemAvailable from /proc/meminfo; -1 if unknown.
int64_t AvailableMemoryBytes();

// Throws InputError if `bytes` exceeds the available memory, naming `what` and the estimate.
void CheckFitsInMemory(int64_t bytes, const std::string& what);

std::string FormatBytes(int64_t bytes);

}  // namespace translume
