// SPDX-License-Identifier: MIT
#pragma once

#include <array>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "calib/camera_calib.h"
#include "calib/projector_calib.h"
#include "solver/grid.h"

namespace translume::acquire {

// `translume patterns` (docs/capture.md, step 6): the projector images that light N x N regions
// of a real sample's lit face, and a few validation spots (ValidationSpots), from the rig's
// calibrations and the sample's place.
struct PatternJob {
  calib::CameraCalibration camera;
  calib::ProjectorCalibration projector;
  std::string projector_file;        // the projector calibration's file (CameraMismatch)
  std::array<double, 3> size_mm{};   // the block's extent X, Y, Z
  Setup setup = Setup::kBack;
  int lights = 4;                    // N
  int validation = 4;                // validation spots after the regions (ValidationSpots)
  // The front face's corners in the camera image (face_corners_px's order), or empty: found in
  // `photo` (linear RGB, CV_32FC3, the camera's size, +inf where saturated: the sample lit on a
  // dark background). Corners found in the photo, or given with it (then they may lie up to
  // kNearCornerReachPx off: clicked by hand), are refined in it (RefineFaceCornersWithin, the
  // lens's blur searched from 1 px), or, where the camera sees side faces, taken from the
  // block's outline (FitBlockOutline).
  std::vector<cv::Point2d> corners;
  cv::Mat photo;
  std::string corners_source = "the corners";  // names corners or photo in messages
};

struct PatternSet {
  std::vector<cv::Mat> images;     // CV_8UC1, 255 lit; region m = I + N J (RegionPatterns), then the spots
  std::vector<std::string> names;  // "00".."15"; "000".. from 11 x 11 regions on; spots "v00"..
  int validation = 0;              // the last this many are validation spots
  std::vector<cv::Point2d> corners;
  // With a photo: the corners before the refinement (found or given), how far it moved them at
  // most (px), and the lens's blur it found (sigma, px); refined false where it could not be
  // done (too few unsaturated edge points on a side), the corners then kept as they were.
  std::vector<cv::Point2d> unrefined_corners;
  bool refined = false;
  double refine_moved_px = 0, refine_blur_px = 0;
  bool outline_fit = false;  // the corners come from FitBlockOutline (NeedsBlockOutlineFit)
  bool side_faces = false;   // ... which shows side faces besides the front face
  double pose_rms_px = 0;
  bool face_inside_projector = true;
  int64_t fewest_pixels = 0, most_pixels = 0;
  std::vector<std::string> warnings;  // a pose that misses the corners, a face outside the image
};

// Throws InputError naming the problem: a projector calibrated through another camera
// calibration, no sample found in the photo, corners that are no convex quadrilateral or that
// the pose cannot fit (EstimateSamplePose), and RegionPatterns' refusals.
PatternSet MakeRegionPatterns(const PatternJob& job);

// "" where `dir` may take a new folder of patterns (missing or empty), else "DIR: is a file (...)"
// or "DIR: exists and is not empty (...)".
std::string PatternFolderProblem(const std::string& dir);

// Writes `dir` (which must not exist or be empty) atomically: NAME.png per region and
// conditions.json, the conditions list for capture.json (stacks lighting/NAME, patterns under
// the folder's own name). Throws InputError with PatternFolderProblem's message.
void WritePatternFolder(const PatternSet& set, const std::string& dir);

}  // namespace translume::acquire
