// SPDX-License-Identifier: MIT
#include <algorithm>
#include <cctype>
#include <cstdio>
#include <fmt/format.h>

#include "solver/status.h"
#include "solver/threads.h"
#include "tools/commands.h"

namespace translume {

void AddCommonOptions(CLI::App& app) {
  app.add_option_function<int>("--threads", [](int n) { SetNumThreads(n); },
                               "Threads to use (default: TRANSLUME_THREADS, OMP_NUM_THREADS "
                               "or all hardware threads)")
      ->check(CLI::PositiveNumber);
}

std::string Extension(const std::string& path) {
  const auto slash = path.find_last_of('/');
  const auto dot = path.rfind('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
  std::string ext = path.substr(dot);
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  return ext;
}

void RequireExtension(const std::string& path, std::initializer_list<const char*> exts,
                      const char* flag) {
  const std::string e = Extension(path);
  std::string names;
  for (const char* x : exts) {
    if (e == x) return;
    names += (names.empty() ? "" : " or ") + std::string(x);
  }
  throw InputError(fmt::format("{} {}: the output must end in {}", flag, path, names));
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
