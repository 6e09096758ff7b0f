// SPDX-License-Identifier: MIT
#include <cstdio>

#include "solver/threads.h"
#include "tools/commands.h"

namespace translume {

void AddCommonOptions(CLI::App& app) {
  app.add_option_function<int>("--threads", [](int n) { SetNumThreads(n); },
                               "Threads to use (default: TRANSLUME_THREADS, OMP_NUM_THREADS "
                               "or all hardware threads)")
      ->check(CLI::PositiveNumber);
}

bool ParseOrHelp(CLI::App& app, int argc, char** argv) {
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp&) {
    std::fputs(app.help().c_str(), stdout);
    return true;
  }
  return false;
}

}  // namespace translume
