// SPDX-License-Identifier: MIT
// translume: acquire heterogeneous translucent materials from photographs (Wang et al. 2008).
#include <CLI/CLI.hpp>
#include <cstdio>
#include <filesystem>
#include <cstring>
#include <new>
#include <opencv2/core/utility.hpp>
#include <opencv2/core/utils/logger.hpp>
#include <exception>
#include <string>
#include <vector>

#include "solver/memory.h"
#include "solver/status.h"
#include "solver/threads.h"
#include "tools/commands.h"

namespace {

struct Command {
  const char* name;
  int (*run)(int, char**);
  const char* help;
  std::vector<std::string> (*subcommands)() = nullptr;  // named in error lines: "translume calibrate white: error: ..."
};

const Command kCommands[] = {
    {"demo", translume::RunDemo, "Run the main job on the embedded default sample"},
    {"acquire", translume::RunAcquire, "From a capture folder of photos to a material (the pipeline)"},
    {"simulate-capture", translume::RunSimulateCapture, "Write a simulated capture folder of a material"},
    {"patterns", translume::RunPatterns, "Write the projector images that light NxN regions of the sample"},
    {"synth", translume::RunSynth, "Write a synthetic material volume (.vdb)"},
    {"forward", translume::RunForward, "Simulate the front-face radiance of a material under a light"},
    {"simulate", translume::RunSimulate, "Simulate node-space data of a material (no photos): a dataset"},
    {"solve", translume::RunSolve, "Recover kappa and mu from a dataset (the inverse problem)"},
    {"evaluate", translume::RunEvaluate, "Held-out relighting and parameter errors of a recovery"},
    {"calibrate", translume::RunCalibrate, "Calibrate camera, projector, response, white balance",
     translume::CalibrateSubcommands},
    {"hdr", translume::RunHdr, "Merge an exposure stack into a linear HDR image (.exr)"},
    {"bench", translume::RunBench, "Benchmarks: bench forward, recovery, exposure-times, patterns",
     translume::BenchSubcommands},
    {"render", translume::RunRender, "Render a material on a shape (polygrid diffusion, Section 5)"},
    {"edit", translume::RunEdit, "Edit a material: scale/add kappa, mu per channel, in a mask and depth range"},
    {"info", translume::RunInfo, "Version, build, backends, threads, memory estimates"},
};

void PrintUsage(FILE* out) {
  std::fprintf(out,
               "translume %s: heterogeneous translucent materials from photographs\n\n"
               "usage: translume COMMAND [options]   (translume COMMAND --help for its options)\n\n"
               "commands:\n",
               TRANSLUME_VERSION);
  for (const Command& c : kCommands) std::fprintf(out, "  %-17s %s\n", c.name, c.help);
  std::fprintf(out, "\nEvery command takes --threads N. Docs: README.md and docs/.\n");
}

// "calibrate white" for `translume calibrate --threads 2 white ...`: the command and its
// subcommand, where the first argument after the command's options names one.
std::string ShownName(const Command& c, int argc, char** argv) {
  for (int k = 2; k < argc; ++k) {
    const std::string arg = argv[k];
    if (arg == "--threads") {
      ++k;  // and its value
      continue;
    }
    if (arg.rfind("--threads=", 0) == 0) continue;
    if (c.subcommands)
      for (const std::string& sub : c.subcommands())
        if (sub == arg) return std::string(c.name) + " " + sub;
    break;
  }
  return c.name;
}

}  // namespace

int main(int argc, char** argv) {
  translume::UsePassiveOpenMpByDefault(argv);
  translume::KeepFreedMemoryForReuse();
  // OpenCV's own log lines ("[ERROR:0@0.029] ... Can't open file") would come before ours,
  // which name the file and the problem.
  cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_SILENT);
  // OpenCV's thread pool (calibration, HDR) follows --threads and TRANSLUME_THREADS too.
  translume::AddThreadCountListener([](int threads) { cv::setNumThreads(threads); });
  if (const std::string err = translume::InitThreadsFromEnvironment(); !err.empty()) {
    std::fprintf(stderr, "translume: error: %s\n", err.c_str());
    return 1;
  }
  if (argc < 2 || !std::strcmp(argv[1], "--help") || !std::strcmp(argv[1], "-h") ||
      !std::strcmp(argv[1], "help")) {
    PrintUsage(stdout);
    return argc < 2 ? 2 : 0;
  }
  if (!std::strcmp(argv[1], "--version")) {
    std::printf("translume %s\n", TRANSLUME_VERSION);
    return 0;
  }
  for (const Command& c : kCommands) {
    if (std::strcmp(argv[1], c.name) != 0) continue;
    const std::string shown = ShownName(c, argc, argv);
    const char* name = shown.c_str();
    try {
      return c.run(argc - 1, argv + 1);
    } catch (const CLI::ParseError& e) {
      std::fprintf(stderr, "translume %s: %s (see translume %s --help)\n", name, e.what(),
                   name);
      return 2;
    } catch (const translume::InputError& e) {
      std::fprintf(stderr, "translume %s: error: %s\n", name, e.what());
      return 1;
    } catch (const translume::Interrupted& e) {
      std::fprintf(stderr, "translume %s: interrupted: %s\n", name, e.what());
      return translume::kInterruptedExit;
    } catch (const std::filesystem::filesystem_error& e) {
      // "filesystem error: OPERATION: REASON [PATH]" -> "PATH: OPERATION: REASON", the file first.
      std::string what = e.what();
      if (what.rfind("filesystem error: ", 0) == 0) what.erase(0, 18);
      if (const size_t bracket = what.find(" ["); bracket != std::string::npos) what.resize(bracket);
      std::fprintf(stderr, "translume %s: error: %s: %s\n", name,
                   e.path1().empty() ? "(a path)" : e.path1().c_str(), what.c_str());
      return 1;
    } catch (const std::bad_alloc&) {
      std::fprintf(stderr, "translume %s: error: out of memory: the grid or the images are too large "
                   "for this machine (translume info --grid NXxNYxNZ estimates what a grid needs)\n", name);
      return 1;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "translume %s: error: %s\n", name, e.what());
      return 1;
    }
  }
  std::fprintf(stderr, "translume: unknown command '%s' (see translume --help)\n", argv[1]);
  return 2;
}
