// SPDX-License-Identifier: MIT
#pragma once

#include <CLI/CLI.hpp>
#include <string>

#include "solver/recover.h"

namespace translume {

// The optimiser flags shared by `solve` and `acquire`.
struct RecoveryFlags {
  RecoveryOptions options;
  std::string optimizer = "lbfgs", regularizer = "tk1", backend = "cpu";
  // The parsed options; throws InputError "--flag: problem" (a flag of `app`, the command's, that
  // the problem names) or "COMMAND: problem" when invalid, and checks that a gl context exists
  // for --backend gl.
  RecoveryOptions Options(const CLI::App& app, const char* command) const;
};
void AddRecoveryFlags(CLI::App& app, RecoveryFlags* flags);
// --validation-every, --validation-patience and --validation-margin (RecoveryOptions'
// validation_*), for `solve` and `acquire` (through AddRecoveryFlags) and `bench recovery`.
void AddValidationFlags(CLI::App& app, RecoveryOptions* options);
// --solve-tolerance (RecoveryOptions::solve_tolerance), for the same three commands.
void AddSolveToleranceFlag(CLI::App& app, RecoveryOptions* options);

// CheckFitsInMemory (solver/memory.h) for a recovery with these options; where a lower
// --lbfgs-rank would need less, the error says how much.
void CheckRecoveryFitsInMemory(const GridShape& shape, int conditions, const RecoveryOptions& options,
                               const std::string& what);

// "12.3 s", "4.5 min", "1.2 h".
std::string FormatSeconds(double seconds);

// The time left if every remaining iteration up to `max_iterations` runs, "<= 1.2 min" (an upper
// bound: the fit may stop sooner), from the mean iteration time since the first report (so the
// homogeneous fit before it does not count); "?" at the first report.
class TimeLeft {
 public:
  std::string operator()(const IterationReport& report, int max_iterations);

 private:
  double first_seconds_ = -1;
  int first_iteration_ = 0;
};

}  // namespace translume
