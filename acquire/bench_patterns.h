// SPDX-License-Identifier: MIT
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "solver/grid.h"

namespace translume::acquire {

// `translume bench patterns`: how closely `translume patterns` lights what the true rig lights.
// Each case simulates a capture of a marble block through the default rig or `rig_file` (simulate-capture
// with the fewest conditions and `seed`: its board, plane, white-card and sample-lit photos),
// calibrates it as acquire does, and makes the N x N region patterns (MakeRegionPatterns) from
// the sample's true face corners, from the corners found (and refined) in the photo of the
// sample under projector white (calib/sample_lit), and from corners given kNearOffsetPx off the
// true ones (as if clicked by hand) refined in that photo; the reference is the true rig's
// patterns (RegionPatterns on the simulator's own intrinsics and poses).
// How far off the true corners the bench's near corners are given (px, each in its own direction).
constexpr double kNearOffsetPx = 3.5;

struct PatternsBenchOptions {
  std::vector<Setup> setups = {Setup::kBack, Setup::kFront};
  int seeds = 3;   // cases per setup (seeds 1..seeds)
  int lights = 4;  // N: N x N regions
  std::string rig_file = "default";  // or a rig file (.json, ReadCaptureRig: docs/capture.md)
  std::string Validate() const;  // "" or the broken constraint, named as the flag
};

struct PatternsBenchRow {
  Setup setup = Setup::kBack;
  int seed = 1;
  int regions = 0;
  double camera_rms_px = 0, projector_rms_px = 0;  // the calibrations' reprojection RMS
  // From the true corners / from the corners found in the photo: the worst and the median
  // region's intersection over union with the true pattern, and the mean edge shift, projector
  // pixels: the pixels lit in one pattern only over the true regions' outline length.
  double iou_min = 0, iou_median = 0, edge_px = 0;
  double photo_iou_min = 0, photo_iou_median = 0, photo_edge_px = 0;
  double photo_corner_px = 0;  // the found and refined corners' largest distance from the true ones
  double photo_found_corner_px = 0;  // the same before the refinement
  double near_corner_px = 0, near_iou_min = 0, near_iou_median = 0, near_edge_px = 0;  // from near corners
  double pose_rms_px = 0;      // the sample pose's RMS against the true corners
  double capture_seconds = 0, calibration_seconds = 0, pattern_seconds = 0;
};

std::vector<PatternsBenchRow> RunPatternsBench(const PatternsBenchOptions& options,
                                               const std::function<void(const std::string&)>& progress = {});
std::string PatternsBenchTable(const std::vector<PatternsBenchRow>& rows);
std::string PatternsBenchJson(const std::vector<PatternsBenchRow>& rows);

}  // namespace translume::acquire
