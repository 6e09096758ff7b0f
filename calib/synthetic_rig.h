// SPDX-License-Identifier: MIT
#pragma once

#include <cstdint>
#include <functional>
#include <opencv2/core.hpp>
#include <vector>

#include "calib/board.h"
#include "calib/projector_pattern.h"

namespace translume::calib {

// A pinhole device with OpenCV's 5-coefficient lens distortion (k1, k2, p1, p2, k3).
// Pixel convention: pixel centres at integer coordinates, (0, 0) the top-left pixel's centre.
struct DeviceModel {
  cv::Size size{1024, 768};  // pixels
  cv::Matx33d K = cv::Matx33d::eye();
  cv::Vec<double, 5> dist{0, 0, 0, 0, 0};

  // Pixel positions of points given in the device frame (mm, z forward).
  std::vector<cv::Point2d> Project(const std::vector<cv::Point3d>& points) const;
};

// Rigid transform x_to = R x_from + t (mm).
struct Pose {
  cv::Matx33d R = cv::Matx33d::eye();
  cv::Vec3d t{0, 0, 0};
  cv::Vec3d Apply(const cv::Vec3d& x) const { return R * x + t; }
  Pose Inverse() const;
  // Composition: (a_from_b * b_from_c) is a_from_c.
  Pose operator*(const Pose& b) const { return {R * b.R, R * b.t + t}; }
  // From a Rodrigues rotation vector (radians) and a translation.
  static Pose FromRodrigues(const cv::Vec3d& rvec, const cv::Vec3d& t);
};

// Camera response for synthetic 8-bit photos: code = round(255 f(x)), x linear in [0, 1].
// f(x) = ((x + a)^g - a^g) / ((1 + a)^g - a^g) per channel (a = toe), a monotone gamma-like curve.
struct SyntheticResponse {
  cv::Vec3d gamma{1 / 2.0, 1 / 2.2, 1 / 2.4};  // R, G, B
  double toe = 0.01;
  double Apply(double x, int channel) const;
};

// Options for one rendered photo.
struct PhotoOptions {
  int supersample = 5;          // N x N jittered samples per pixel (box filter antialiasing),
                                // where the pixel's corners and centre differ
  double blur_sigma_px = 0.5;   // Gaussian optical blur after sampling (0: none)
  double noise_sigma = 1.0;     // Gaussian noise, 8-bit codes
  double white_level = 215.0;   // 8-bit code of a white (albedo 1 under full light) surface
  double background = 0.25;     // albedo outside the board / plane
  double ambient = 0.05;        // projected photos: room light relative to projector white
  uint64_t seed = 1;
};

// Options for a rendered exposure stack.
struct StackOptions {
  int bits = 8;                 // 8: through `response`; 16: linear codes
  double read_noise = 0.0005;   // std of additive noise, linear units of full scale
  double shot_noise = 0.0001;   // variance per unit linear signal (Poisson-like)
  double offset = 0;            // sensor black level left in the codes, fraction of full scale
  uint64_t seed = 1;
};

// A linear radiance image (CV_32FC3, RGB) spanning `decades` below 1 per second: a log ramp along
// x with per-channel offsets and 40 random constant 12x12 patches (the 8-bit merge and response
// tests' scene and `bench exposure-times`'). Deterministic for a seed.
cv::Mat SyntheticHdrScene(cv::Size size, double decades, uint64_t seed);

// A ColorChecker-like chart: 4 rows x 6 columns of square patches on a black frame.
struct SyntheticChart {
  double patch_mm = 40.0, gap_mm = 8.0;
  // Linear RGB albedos, row-major (24 patches).
  std::vector<cv::Vec3d> albedo;
  static SyntheticChart ColorChecker();  // approximate ColorChecker 2005 linear sRGB albedos
  cv::Size2d SizeMm() const;
  // Albedo at chart point (x, y) mm (origin at the chart's top-left corner).
  cv::Vec3d AlbedoAt(double x, double y) const;
  // Centre of patch k in chart mm.
  cv::Point2d PatchCenter(int k) const;
};

// A camera + projector rig with known geometry that renders the photos a real capture would
// take. All poses in mm; the camera frame is the world frame.
class SyntheticRig {
 public:
  DeviceModel camera;
  DeviceModel projector;
  Pose projector_from_camera;

  // The default rig: 1024x768 camera (f = 1200 px, moderate barrel distortion), 1024x768
  // projector (f = 1500 px, principal point shifted down as in DLP lens shift), projector
  // 150 mm right of the camera, turned to look at the camera's axis at ~500 mm.
  static SyntheticRig Default();

  // `n` board poses (camera_from_board) at about distance_mm, tilted up to ~35 degrees,
  // keeping the board in view; deterministic for a seed.
  std::vector<Pose> BoardPoses(const BoardSpec& board, int n, double distance_mm,
                               uint64_t seed) const;
  // `n` plane poses (camera_from_plane) facing the camera at about distance_mm on which the
  // projector's pattern lands fully inside the camera view. Plane frame: z = 0 on the plane.
  // With `board`, the plane frame is the board's frame and the printed board (with its
  // margin) is in view too.
  std::vector<Pose> PlanePoses(const ProjectorChessboard& pattern, int n, double distance_mm,
                               uint64_t seed, const BoardSpec* board = nullptr) const;

  // A grey 8-bit photo of a printed board (white albedo 0.9, black 0.05) at camera_from_board
  // under uniform light.
  cv::Mat RenderBoard(const BoardSpec& board, const Pose& camera_from_board,
                      const PhotoOptions& o = {}) const;
  // A grey 8-bit photo of a white plane (albedo 0.9) at camera_from_plane lit by the projector
  // showing `pattern` (plus o.ambient room light). pattern.projector_size must be
  // projector.size.
  cv::Mat RenderProjectedChessboard(const Pose& camera_from_plane,
                                    const ProjectorChessboard& pattern,
                                    const PhotoOptions& o = {}) const;
  // The same for any 8-bit grey projector image (projector.size; 255 = full white; each
  // projector pixel a sharp square, as on a DLP).
  cv::Mat RenderProjectedImage(const Pose& camera_from_plane, const cv::Mat& projector_image,
                               const PhotoOptions& o = {}) const;
  // Where the ray of projector pixel `p` (continuous, OpenCV convention) meets the plane
  // z = 0 of camera_from_plane, in the camera frame (mm); false when it misses.
  bool ProjectorPixelOnPlane(const Pose& camera_from_plane, const cv::Point2d& p,
                             cv::Vec3d* camera_xyz) const;
  // Linear camera radiance (CV_32FC3, RGB) of the chart at camera_from_chart lit by projector
  // full white of uniform per-channel irradiance `projector_rgb` (a flat field) where the
  // projector reaches: L = albedo * projector_rgb / pi, times `camera_gain` per channel (the
  // camera's unknown per-channel sensitivity). Outside the chart: black. The gains that
  // WhiteBalance should find are 1 / (camera_gain * projector_rgb).
  cv::Mat RenderChartRadiance(const SyntheticChart& chart, const Pose& camera_from_chart,
                              const cv::Vec3d& projector_rgb, const cv::Vec3d& camera_gain,
                              int supersample = 4) const;

  // Photos of a linear radiance image (CV_32FC3, RGB) at exposure times `seconds`: linear
  // signal x = radiance * t, noise, clipped to [0, 1]; 8-bit codes through `response` or
  // 16-bit linear codes. Returns CV_8UC3 or CV_16UC3 images, RGB order.
  static std::vector<cv::Mat> RenderExposureStack(const cv::Mat& radiance,
                                                  const std::vector<double>& seconds,
                                                  const SyntheticResponse& response,
                                                  const StackOptions& o = {});

  // Normalised camera ray directions (x/z, y/z) at the corners of every pixel: a
  // (H+1) x (W+1) CV_64FC2 map, entry (j, i) at pixel position (i - 0.5, j - 0.5). Cached.
  const cv::Mat& CameraRays() const;

 private:
  // Renders a plane photo: value(plane point, camera point) in linear albedo*light units.
  cv::Mat RenderPlane(const Pose& camera_from_plane, const PhotoOptions& o,
                      const std::function<double(const cv::Vec3d& plane_xyz,
                                                 const cv::Vec3d& camera_xyz)>& shade) const;
  mutable cv::Mat rays_;
};

}  // namespace translume::calib
