// SPDX-License-Identifier: MIT
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "calib/board.h"
#include "calib/camera_calib.h"
#include "calib/projector_pattern.h"

namespace translume::calib {

// One pose of a flat plane seen by the calibrated camera (docs/capture.md):
//  board_photo    the printed board lying on the plane (gives the plane's pose),
//  pattern_photo  the projector showing the chessboard pattern on a white part of the same
//                 plane, the plane not moved in between.
struct PlaneView {
  std::string name;
  cv::Mat board_photo;    // 8-bit grey or BGR
  cv::Mat pattern_photo;  // 8-bit grey or BGR
};

struct ProjectorCalibOptions {
  int min_planes = 4;
  double outlier_factor = 3.0;   // drop planes whose projector RMS > factor * median ...
  double outlier_min_px = 0.5;   // ... and > this
  bool fix_k3 = true;            // projector distortion: k1, k2 (and p1, p2 unless zero_tangent)
  bool zero_tangent = true;
  // Rear projection (the back-lit setup): the projector lights the plane (a thin diffusing
  // screen) from the side opposite the camera, so the camera sees the projected pattern
  // mirrored left-right; each detected row of corners is reversed to match the projector's.
  bool rear_projection = false;
  // The calibration is refused when its reprojection RMS (the projector fit's or either stereo
  // one's) exceeds this: good planes give ~0.1-1 px, while planes taken as front projection
  // that were rear projected (or the reverse) give ~10 px or more.
  double max_rms_px = 3.0;
  std::string Validate() const;
};

// Projector intrinsics (an inverse camera: K, distortion in OpenCV's model, projector pixels)
// and the rigid pose x_projector = R x_camera + T (mm).
struct ProjectorCalibration {
  cv::Size projector_size;
  cv::Matx33d K;
  cv::Mat dist;                 // 1x5 CV_64F
  cv::Mat std_intrinsics;       // 1-sigma of fx, fy, cx, cy, ...
  cv::Matx33d R;                // projector_from_camera rotation
  cv::Vec3d T;                  // projector_from_camera translation, mm
  double projector_rms = 0;     // px, projector intrinsics fit
  double stereo_camera_rms = 0;     // px, pose fit, camera corners
  double stereo_projector_rms = 0;  // px, pose fit, projector corners
  std::vector<std::string> used_planes;
  std::vector<cv::Vec2d> per_plane_errors;  // stereo RMS per plane (camera, projector), px
  std::vector<std::string> dropped;         // "NAME: reason"
  std::string BriefReport() const;
};

// Corners of the projected pattern on one plane, in the plane's frame (mm, z = 0): camera
// corners of the pattern, undistorted, their rays intersected with the plane z = 0 of
// camera_from_plane (R, t).
std::vector<cv::Point3f> CornersOnPlane(const CameraCalibration& camera,
                                        const std::vector<cv::Point2f>& camera_corners,
                                        const cv::Matx33d& R, const cv::Vec3d& t);

// Plane-based projector calibration (Falcao et al. 2008, as in Wang et al. 2008): per plane,
// the plane pose from the printed board (solvePnP with the calibrated camera), the projected
// corners in plane coordinates; then calibrateCamera for the projector with the pattern's
// projector-pixel corners, and stereoCalibrate with both intrinsics fixed for the pose.
// Planes missing a photo, where either board is not found, or whose projector RMS is an
// outlier, are dropped and listed. Throws CalibError when photos differ in size from the camera calibration, fewer
// than min_planes planes remain, or the reprojection RMS exceeds max_rms_px (with a hint on
// rear projection).
ProjectorCalibration CalibrateProjector(const CameraCalibration& camera, const BoardSpec& board,
                                        const ProjectorChessboard& pattern,
                                        const std::vector<PlaneView>& planes,
                                        const ProjectorCalibOptions& options = {});

// OpenCV FileStorage YAML: projector_matrix, projector_distortion, projector_width,
// projector_height, R, T (projector_from_camera, mm), projector_rms, stereo_camera_rms,
// stereo_projector_rms, per_plane_errors, planes, dropped_planes, pattern; plus the camera's
// camera_matrix, distortion_coefficients, image_width, image_height.
void WriteProjectorCalibration(const std::string& path, const ProjectorCalibration& p,
                               const CameraCalibration& camera, const std::string& pattern);
// Reads the projector's fields back (not the camera's or the pattern); throws CalibError naming
// the file when it cannot be read, lacks projector_matrix, projector_distortion, R or T, or holds
// unusable values (IntrinsicsProblem, a size that is not positive, R no rotation, T not finite).
ProjectorCalibration ReadProjectorCalibration(const std::string& path);

// R and T hold for the camera intrinsics the projector was calibrated through, which its file
// keeps. Where those differ from `camera`'s by more than 2 % (fx, fy; cx, cy against the image
// width) or in image size: "PATH was calibrated through another camera calibration (fx A
// against B px)"; else "" (also for a file that keeps none).
std::string CameraMismatch(const CameraCalibration& camera, const std::string& projector_path);

}  // namespace translume::calib
