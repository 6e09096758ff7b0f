// SPDX-License-Identifier: MIT
// `translume bench exposure-times` and `bench patterns`: the capture side's benchmarks, which
// need the calib and acquire libraries (so they stay out of the self-contained GPU benchmark
// binary).
#include <cstdio>
#include <fmt/format.h>
#include <memory>
#include <string>
#include <vector>

#include "acquire/bench_patterns.h"
#include "calib/bench_exposure_times.h"
#include "solver/light.h"
#include "solver/status.h"
#include "solver/threads.h"
#include "tools/commands.h"

namespace translume {

void AddBenchExposureTimes(CLI::App& bench) {
  struct Flags {
    calib::ExposureTimesBenchOptions o;
    std::string size = "240x160";
    bool json = false;
  };
  auto f = std::make_shared<Flags>();
  auto* cmd = bench.add_subcommand(
      "exposure-times", "Exposure times read from camera labels (auto / as labelled / APEX) on synthetic stacks: "
                        "how often auto is right, and the merged radiance's error against the truth");
  cmd->fallthrough();
  calib::ExposureTimesBenchOptions& o = f->o;
  cmd->add_option("--bits", o.bits, "8 (response fit, then a merge) and/or 16 (linear merge)")
      ->delimiter(',')->capture_default_str();
  cmd->add_option("--brackets", o.brackets, "Named brackets (full: 1/15..15 s, fast: 1/1000..1/4 s, thirds: "
                                            "1/100..0.4 s, halves: 1/1500..1/45 s) or labels joined by ':' "
                                            "(1/60:1/30:1/15)")
      ->delimiter(',')->capture_default_str();
  cmd->add_option("--cameras", o.cameras, "apex: the camera exposes the labels' APEX times (1/30 as 1/32 s); "
                                          "exact: it exposes the labels")
      ->delimiter(',')->capture_default_str();
  cmd->add_option("--offsets", o.offsets, "16-bit: sensor black level left in the codes, fraction of full scale "
                                          "(no black stack)")
      ->delimiter(',')->capture_default_str();
  cmd->add_option("--seeds", o.seeds, "Scenes per row (medians over them)")->capture_default_str();
  cmd->add_option("--size", f->size, "Photo size WxH")->capture_default_str();
  cmd->add_flag("--json", f->json, "Print JSON instead of a table");
  cmd->callback([f] {
    calib::ExposureTimesBenchOptions o = f->o;
    int w = 0, h = 0;
    char end = 0;
    if (std::sscanf(f->size.c_str(), "%dx%d%c", &w, &h, &end) != 2)
      throw InputError("--size " + f->size + ": expected WxH, whole numbers of pixels");
    o.size = {w, h};
    if (std::string why = o.Validate(); !why.empty()) throw InputError("bench exposure-times: " + why);
    std::fprintf(stderr, "bench exposure-times: %d seeds per row, %dx%d photos, %d threads\n", o.seeds, w, h,
                 NumThreads());
    const auto rows = calib::RunExposureTimesBench(o, PrintBenchProgress);
    std::printf("%s\n", (f->json ? calib::ExposureTimesBenchJson(rows) : calib::ExposureTimesBenchTable(rows)).c_str());
  });
}

void AddBenchPatterns(CLI::App& bench) {
  struct Flags {
    acquire::PatternsBenchOptions o;
    std::vector<std::string> setups = {"back", "front"};
    std::string lights = "4x4";
    bool json = false;
  };
  auto f = std::make_shared<Flags>();
  auto* cmd = bench.add_subcommand(
      "patterns", "Region patterns (translume patterns) from simulated captures' calibrations against the true "
                  "rig's: intersection over union and edge shift, from true and from found face corners");
  cmd->fallthrough();
  cmd->add_option("--setups", f->setups, "Lit faces: back, front")->delimiter(',')->capture_default_str();
  cmd->add_option("--seeds", f->o.seeds, "Simulated captures per setup (seeds 1..N)")->capture_default_str();
  cmd->add_option("--lights", f->lights, "NxN regions of the lit face")->capture_default_str();
  cmd->add_option("--rig", f->o.rig_file, "default, or a rig file (.json, as simulate-capture's: your camera's and "
                                          "projector's intrinsics, distances, tilt)")->capture_default_str();
  cmd->add_flag("--json", f->json, "Print JSON instead of a table");
  cmd->callback([f] {
    acquire::PatternsBenchOptions o = f->o;
    o.setups.clear();
    for (const auto& s : f->setups) o.setups.push_back(ParseSetup(s, "--setups"));
    o.lights = RegionLights(f->lights).front().region_n;  // validates NxN
    if (std::string why = o.Validate(); !why.empty()) throw InputError("bench patterns: " + why);
    std::fprintf(stderr, "bench patterns: %d captures per setup, %dx%d regions, %d threads\n", o.seeds, o.lights,
                 o.lights, NumThreads());
    const auto rows = acquire::RunPatternsBench(o, PrintBenchProgress);
    std::printf("%s\n", (f->json ? acquire::PatternsBenchJson(rows) : acquire::PatternsBenchTable(rows)).c_str());
  });
}

}  // namespace translume
