// SPDX-License-Identifier: MIT
#pragma once

#include <functional>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "calib/shutter.h"

namespace translume::calib {

// `translume bench exposure-times`: how well the exposure times are read from synthetic stacks
// whose photos carry camera labels (docs/capture.md, "Exposure times"). Each case renders a
// scene through a camera that exposes either the labels' APEX times (1/30 as 1/32 s: what
// cameras do) or exactly the labels, at known truth, and reads it as `auto` decides, as
// labelled, as APEX and with the true times:
// - 8-bit: the response is fitted to one stack (CalibrateResponse) and another stack of the
//   same bracket merged through it;
// - linear (16-bit): the stack is judged (ChooseShutterTimes) and merged (MergeHdr).
struct ExposureTimesBenchOptions {
  std::vector<int> bits = {8, 16};
  // Named brackets (ExposureTimesBracketNames) or labels joined by ':' ("1/60:1/30:1/15").
  std::vector<std::string> brackets = {"full", "fast", "thirds", "halves"};
  std::vector<std::string> cameras = {"apex", "exact"};
  // Linear stacks only: a sensor black level left in the codes (fraction of full scale) and no
  // black stack to remove it; 8-bit codes carry theirs through the fitted response.
  std::vector<double> offsets = {0.0, 0.02};
  int seeds = 8;              // cases per row (scenes and noise); the row reports their medians
  cv::Size size{240, 160};    // pixels per photo
  std::string Validate() const;  // "" or the broken constraint, named as the flag
};

// The labels of a named bracket (full: 1/15 .. 15 s in full stops; fast: 1/1000 .. 1/4 s;
// thirds: 1/100 .. 0.4 s two thirds of a stop apart; halves: 1/1500 .. 1/45 s in the half-stop
// series) or of a ':'-joined list of times ("1/60", "0.3", "15"). Throws CalibError naming the
// bracket.
std::vector<double> ExposureTimesBracket(const std::string& name);
std::vector<std::string> ExposureTimesBracketNames();

struct ExposureTimesBenchRow {
  int bits = 8;
  std::string bracket, camera;  // camera: "apex" (exposes 2^-(k/3) s) or "exact"
  double offset = 0;
  int cases = 0;
  int right = 0;       // cases where auto read the times as the camera exposed them
  // Cases where the photos told the readings apart: 8-bit, the two fits' residuals differ by over
  // 2 %; linear, ShutterChoice::decisive.
  int decisive = 0;
  // Median over the cases of each merge's median relative error against the true radiance,
  // after one scale per channel, over pixels valid in every channel: read as auto chose, as
  // labelled, as APEX times, and with the times the camera exposed.
  double error_auto = 0, error_labelled = 0, error_apex = 0, error_true = 0;
  // The same at the 95th percentile, auto's reading.
  double p95_auto = 0;
  // Linear rows: read as auto chose with a black stack given (the same times, the sensor's black
  // level and noise, no light), subtracted exposure by exposure; how often auto was right then.
  // -1 for 8-bit rows.
  double error_black = -1;
  int right_black = 0;
  // Median seconds of the reading under auto and forced as labelled, timed alternately in the
  // same process: 8-bit the response fit (auto fits twice where labels are APEX-like), linear
  // the merge (auto judges the stack first).
  double seconds_auto = 0, seconds_forced = 0;
};

std::vector<ExposureTimesBenchRow> RunExposureTimesBench(
    const ExposureTimesBenchOptions& options, const std::function<void(const std::string&)>& progress = {});
std::string ExposureTimesBenchTable(const std::vector<ExposureTimesBenchRow>& rows);
std::string ExposureTimesBenchJson(const std::vector<ExposureTimesBenchRow>& rows);

}  // namespace translume::calib
