// SPDX-License-Identifier: MIT
// translume-gpubench: `translume bench` (forward, recovery) and the gl platform report without
// file IO, so that it runs on a GPU machine with only a driver (tools/gpu_bundle.sh;
// docs/gpu.md).
#include <cstdio>
#include <cstring>
#include <exception>

#include "solver/gl_context.h"
#include "solver/memory.h"
#include "solver/status.h"
#include "solver/threads.h"
#include "tools/commands.h"

int main(int argc, char** argv) {
  translume::UsePassiveOpenMpByDefault(argv);
  translume::KeepFreedMemoryForReuse();
  if (const std::string err = translume::InitThreadsFromEnvironment(); !err.empty()) {
    std::fprintf(stderr, "translume: error: %s\n", err.c_str());
    return 1;
  }
  if (argc >= 2 && !std::strcmp(argv[1], "gl-info")) {
    try {
      std::printf("%s\n", translume::GlContext::Get().info().ToString().c_str());
      return 0;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "translume-gpubench: %s\n", e.what());
      return 1;
    }
  }
  if (argc < 2 || std::strcmp(argv[1], "bench") != 0) {
    std::fprintf(stderr, "usage: translume-gpubench gl-info | bench forward|recovery [options]\n");
    return 2;
  }
  try {
    CLI::App app{"translume-gpubench bench: the forward and recovery benchmarks of `translume bench`",
                 "translume-gpubench bench"};
    app.require_subcommand(1);
    translume::AddBenchForward(app);
    translume::AddBenchRecovery(app);
    translume::AddCommonOptions(app);
    translume::ParseOrHelp(app, argc - 1, argv + 1);
    return 0;
  } catch (const CLI::ParseError& e) {
    std::fprintf(stderr, "translume-gpubench: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "translume-gpubench: error: %s\n", e.what());
    return 1;
  }
}
