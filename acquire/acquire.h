// SPDX-License-Identifier: MIT
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "acquire/capture.h"
#include "solver/recover.h"
#include "solver/status.h"

namespace translume::acquire {

// Acquire stopped between stages (AcquireOptions::stop): what() is the whole message; `where`
// its first part ("stopped before \"...\"" or "stopped after \"...\""), for callers that give
// other advice than a re-run of acquire.
class StageInterrupted : public Interrupted {
 public:
  StageInterrupted(const std::string& where, const std::string& work_dir)
      : Interrupted(where + "; the finished stages are in " + work_dir + " (a re-run reuses them)"),
        where(where) {}
  std::string where;
};

struct AcquireOptions {
  RecoveryOptions recovery;  // the solve (as `translume solve`)
  bool force = false;        // recompute calibration and HDR even when the work folder has them
  bool solve = true;         // false: stop after writing the node-space dataset
  int face_samples = 6;      // per axis, per node dual box, at least (ResampleFrontFace)
  int mask_margin = 2;       // front-lit: masked nodes around the directly lit ones
  // Polled at every progress line before the solve (between stages, per HDR stack): true stops
  // there with Interrupted (solver/status.h); the finished stages stay in the work folder for a
  // re-run. In the solve it is RecoveryOptions::stop (unless recovery.stop is set): the
  // homogeneous fit and the level search end there; the fit's iterations stop through the
  // iteration callback. Either way the material so far is written.
  std::function<bool()> stop;
  std::string Validate() const;
};

struct AcquireConditionReport {
  std::string name;
  int64_t measured_nodes = 0, saturated_nodes = 0, masked_nodes = 0;
  double q_sum = 0;            // sum of q over the lit face (light delivered, in nodes)
  double fit_error = -1;       // E of the fitted material on this condition
  bool validation = false;     // a validation condition (not fitted; fit_error is its validation E)
};

struct AcquireReport {
  std::string work_dir, dataset_dir, material, report_json;
  std::vector<std::pair<std::string, double>> stage_seconds;  // in order
  std::vector<std::string> reused;                            // stages taken from the work folder
  std::vector<std::string> warnings;  // the "warning: " lines of the log, without that prefix
  // pose_rms_px: the corners' reprojection RMS; where the pose was fitted to the block's outline
  // (a camera that sees side faces: FitBlockOutline), the edge points' RMS distance from it.
  double camera_rms_px = -1, projector_rms_px = -1, pose_rms_px = -1;
  std::vector<std::array<double, 2>> face_corners_px;
  // How they came: "given" (capture.json), "found" (on the summed conditions), "near" (given
  // near the face, capture.json {"near": ...}, left as given) or "refined" (found or given near,
  // then fitted through the lens's blur on face_corners_edge_points edge points;
  // RefineFaceCorners, or FitBlockOutline where the camera sees side faces).
  std::string face_corners = "given";
  int face_corners_edge_points = 0;
  // The lens's blur used for the face's coverage (Gaussian sigma, px): capture.json's, or found
  // from camera_blur_profiles profiles across the face's outline (0 profiles: given, or none
  // usable).
  double camera_blur_px = 0;
  int camera_blur_profiles = 0;
  std::array<double, 3> white_gains{};
  // white.flat_field: the lowest and highest irradiance on the lit face, relative to the patch's.
  std::array<float, 2> flat_field{};
  std::string exposure_times;  // how the photos' times were read: "labelled" or "apex"
  std::vector<AcquireConditionReport> conditions;
  RecoverySummary solve;
  std::vector<std::string> previews;
  std::string Table() const;  // the short end-of-run report
};

// The work folder of an output material: OUT.vdb -> OUT_work/ (calibration files, HDR images,
// the node-space dataset, previews, report.json).
std::string WorkDir(const std::string& output_vdb);

// From photos to material (docs/capture.md, "translume acquire"):
//  1. calibration: camera (Zhang), projector (planes; rear projection in the back-lit setup),
//     camera response (Debevec & Malik), white gains (white patch, projector black) - or the
//     finished files named by capture.json;
//  2. HDR: every condition's stack (and the sample's projector-black stack) merged;
//  3. pose: camera_from_sample from the front face's corners (given, or found in the images);
//  4. mapping: L = white gains * (HDR - black HDR) resampled onto the front-face nodes
//     (area-weighted), q from each projector pattern through the projector calibration (or
//     the light spec), masks (front-lit: lit nodes plus a margin; nodes on saturated pixels);
//     the node-space dataset written to WORK/dataset;
//  5. solve (Recover) -> `output_vdb`, WORK/report.json, WORK/previews/*.png (measured vs
//     fitted front face per condition, kappa and mu slices).
// Stages 1 and 2 reuse their results in the work folder when their inputs are unchanged (file
// names, sizes and times) unless options.force. Every output is written under a temporary name
// and renamed. Throws InputError naming the file and the problem for bad input.
AcquireReport Acquire(const CaptureSpec& capture, const std::string& output_vdb,
                      const AcquireOptions& options,
                      const std::function<void(const std::string&)>& progress = {},
                      const RecoveryCallback& iteration = {});

}  // namespace translume::acquire
