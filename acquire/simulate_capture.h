// SPDX-License-Identifier: MIT
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <string>

#include "acquire/face_mapping.h"
#include "calib/synthetic_rig.h"
#include "solver/dataset.h"
#include "solver/material.h"

namespace translume::acquire {

// The simulated acquisition rig: devices, where the sample sits, and the radiometry.
struct CaptureRig {
  DeviceIntrinsics camera, projector;
  calib::Pose projector_from_camera;
  calib::Pose camera_from_sample;
  // Linear camera value per second (full scale 1) for outgoing radiance 1 in q units, per
  // channel: the camera's unknown colour sensitivity that the white calibration recovers.
  cv::Vec3d camera_gain{0.8, 1.0, 0.65};
  double projector_black = 1e-3;  // q on the whole lit face while the projector shows black
  calib::SyntheticResponse response;
  int bits = 8;                   // photo bit depth: 8 (through `response`) or 16 (linear)
  calib::StackOptions noise;      // read and shot noise of the exposure stacks
  double blur_sigma_px = 0.5;     // optical blur of calibration photos
  // Exposures at APEX times (1/32 s, 1/16 s, ...: powers of two), written as a camera labels
  // them (1/30, 1/15; calib/shutter.h). Otherwise times as written (1/30 s, 1/15 s, 0.133 s).
  bool shutter_labels = false;
  // The projector's irradiance at its image's farthest corner relative to its principal point,
  // in (0, 1] (1: uniform; real projectors 0.7-0.9): 1 - (1 - f) r^2, r the distance from the
  // principal point over the farthest corner's (RadialFalloff). The patterns, the black
  // level and the white card are lit through it.
  double projector_falloff = 1.0;
  // The lens's relative illumination at the camera image's farthest corner, in (0, 1] (1: none;
  // lenses wide open 0.5-0.8, stopped down 0.8-0.95), falling alike: the sample, white,
  // sample-lit and camera-flat photos are taken through it (not the board photos). Below 1 the
  // capture has a camera flat (calib/camera_flat, capture.json's camera_flat).
  double camera_vignetting = 1.0;
  // The lens's blur on the photos of the sample, the white reference and the sample lit (not
  // the camera flat, an even field): a Gaussian of this sigma (pixels) over the rendered image.
  // The same lens as the board photos' blur_sigma_px by default; 0: none (the face's outline
  // one pixel sharp).
  double sample_blur_px = 0.5;
};

// 1 - (1 - at_corner) r^2 per pixel of a device's image (CV_32FC1, its size), r the distance of
// the pixel's centre from the principal point over the farthest image corner's: a projector's
// irradiance for a full-white image, or a lens's relative illumination.
cv::Mat RadialFalloff(const DeviceIntrinsics& device, double at_corner);

// A rig for a sample of `grid` and spacing h: a 1024x768 camera (f = 3000 px, mild barrel
// distortion) facing the front face, slightly tilted, so that the face spans ~60 % of the image
// width; a 1024x768 projector whose footprint spans the lit face in ~60 % of its width: beside
// the camera (front-lit) or behind the sample facing the camera (back-lit).
CaptureRig DefaultCaptureRig(const GridShape& grid, double h, Setup setup);

// Reads a rig file (JSON; docs/capture.md "Simulated captures"): any of camera / projector
// {size [w, h], K [9], dist [5]}, distance_scale, tilt_deg [3], camera_gain [3],
// projector_black, projector_falloff, camera_vignetting, sample_blur_px, bits, read_noise, shot_noise, black_offset, shutter_labels, over
// DefaultCaptureRig. Throws InputError.
CaptureRig ReadCaptureRig(const std::string& path, const GridShape& grid, double h, Setup setup);

struct SimulateCaptureOptions {
  Setup setup = Setup::kBack;
  int lights = 4;          // N x N region conditions on the lit face
  int oversample = 2;      // forward solves on a grid this many times finer per axis (>= 2)
  int holdout = 16;        // held-out spot conditions in the truth dataset
  // Validation spot conditions, photographed as the regions (patterns/vNN.png, lighting/vNN,
  // "validation": true in capture.json; ValidationSpots): the solve stops on them.
  int validation = 4;
  int exposures = 10;      // per stack, one stop apart
  int camera_views = 12;   // board photos for the camera calibration
  int planes = 8;          // plane pairs for the projector calibration
  bool auto_corners = false;  // capture.json asks acquire to find the face corners
  double tolerance = 1e-9;    // forward solves
  uint64_t seed = 1;
  // An existing `dir` that holds a simulated capture (truth/material.vdb) is replaced, once the
  // new one is complete (the demo's re-runs); otherwise `dir` must not exist or be empty.
  bool replace_simulated = false;
  // Polled at every progress line: true stops with Interrupted (solver/status.h), and nothing
  // is written (an existing `dir` is left as it was).
  std::function<bool()> stop;
  std::string Validate() const;
};

struct SimulateCaptureSummary {
  std::string capture_json;
  int conditions = 0, photos = 0;
  double seconds = 0;
  std::string BriefReport() const;
};

// Writes a complete capture folder `dir` (which must not exist or be empty, or see
// replace_simulated) of `material`
// (on the recovery grid) through `rig` (docs/capture.md): calib/camera (board photos),
// calib/planes (projector plane pairs), calib/response (two exposure stacks of a static
// gradient scene), calib/white and calib/white_black (a white card of albedo 0.9 where the
// sample goes, under projector white and black), patterns/NN.png (projector images lighting
// each region of the lit face), lighting/NN (the sample under each pattern) and lighting/black,
// capture.json; and the ground truth: truth/material.vdb, truth/dataset (the simulator's own
// node-space q and L on the recovery grid) and truth/dataset/holdout (held-out spots).
// The photos come from forward solves on the refined grid: front-face radiance seen through
// the camera model (supersampled pixels), dark background, projector black level, camera
// gains, exposure clipping, noise and the camera response. `progress` gets one line per stage.
SimulateCaptureSummary SimulateCapture(const Material& material, const CaptureRig& rig,
                                       const SimulateCaptureOptions& options, const std::string& dir,
                                       const std::function<void(const std::string&)>& progress = {});

}  // namespace translume::acquire
