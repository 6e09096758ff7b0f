// SPDX-License-Identifier: MIT
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace translume::calib {

// White balance and absolute scale of the camera against the projector.
//
// Model: the projector shows full white, which puts irradiance q = 1 (per channel, the solver's
// unit of incoming light) on the reference target. A Lambertian patch of albedo rho then has
// radiance rho q / pi = rho / pi. The camera's linear HDR value m (after black subtraction) is
// proportional to that radiance per channel, so the gains are
//   g_c = sum_k rho_kc m_kc / (pi sum_k m_kc^2)   (least squares over the reference patches),
// and g_c * (camera HDR - black HDR) is outgoing radiance L in the units of q (solver input).
struct WhiteBalance {
  cv::Vec3d gains{1, 1, 1};   // R, G, B
  cv::Vec3d residual{0, 0, 0};  // relative RMS misfit of the reference patches per channel
  int patches = 0;            // reference patches used
  std::string method;         // "colorchecker" or "patch"
  // How the white stack's exposure times were read ("labelled" or "apex"; calib/shutter.h), so
  // that the lighting stacks can be read alike; "" for an HDR image given as is.
  std::string exposure_times;
  // The sensor black level its stacks were merged with (MergeOptions::sensor_black), and whether
  // its HDR images were divided by a camera flat (NormalizedCameraFlat): a capture that treats
  // its photos otherwise gets gains off by that much.
  cv::Vec3d sensor_black{0, 0, 0};
  bool camera_flat = false;
  std::string BriefReport() const;
};

// Mean of the HDR inside a convex polygon (image pixels); throws CalibError when it holds
// saturated (+inf) or no pixels.
cv::Vec3d MeanInPolygon(const cv::Mat& hdr, const std::vector<cv::Point2f>& polygon);

// A white patch of known albedo (per channel) whose 4 image corners are given.
// white, black: CV_32FC3 linear HDR images (black may be empty: nothing subtracted). Throws
// CalibError when a corner lies outside the image (OpenCV convention: beyond -0.5 or size - 0.5)
// or the patch is not brighter under white than under black in some channel (both here and for
// the ColorChecker: the gains must be positive).
WhiteBalance WhiteFromPatch(const cv::Mat& white, const cv::Mat& black,
                            const std::vector<cv::Point2f>& corners, const cv::Vec3d& albedo);

// An X-Rite ColorChecker Classic (24 patches), found by OpenCV's mcc detector on a tone-mapped
// 8-bit version of `white`; patch values are means of the linear HDR over the central half of
// each patch; the chart orientation is the one whose 24 values best fit the known albedos;
// gains come from the 6 neutral patches (ColorCheckerLinearAlbedos()). Throws CalibError when
// no chart is found or a patch is saturated. *patch_values receives the 24 black-subtracted
// means (optional).
WhiteBalance WhiteFromColorChecker(const cv::Mat& white, const cv::Mat& black,
                                   std::vector<cv::Vec3d>* patch_values = nullptr);

// OpenCV FileStorage YAML: white_gains (1x3, RGB), residual, patches, method, and
// black_level_mean (RGB mean of the black HDR in camera units, 0 when none) and black_image
// (the black HDR's path, to subtract per pixel).
void WriteWhiteBalance(const std::string& path, const WhiteBalance& w,
                       const cv::Vec3d& black_mean, const std::string& black_image);
// Also sensor_black (1x3) and camera_flat (0 or 1) where set.
// Reads white_gains, residual, patches, method, exposure_times, sensor_black and camera_flat back
// (not the black level); throws CalibError
// naming the file when it cannot be read, lacks white_gains or a gain is not finite and positive.
WhiteBalance ReadWhiteBalance(const std::string& path);

}  // namespace translume::calib
