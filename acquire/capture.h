// SPDX-License-Identifier: MIT
#pragma once

#include <array>
#include <optional>
#include <string>
#include <vector>

#include "calib/shutter.h"
#include "solver/grid.h"
#include "solver/light.h"

namespace translume::acquire {

// A capture folder, format v1 (docs/capture.md, "Capture folder"): CAPTURE/capture.json names
// the sample, the recovery grid, the calibration (photos or finished calibration files) and
// one exposure stack per illumination condition. Paths in the file are relative to the folder;
// the parsed spec holds them resolved (folder / path).
//
// Sample frame (mm): origin at the front face's corner that images as node (0, 0, 0), x along
// node index i, y along j, z into the sample (SPEC section 2); the front face is z = 0.
struct CaptureSpec {
  std::string dir;   // the capture folder
  std::string file;  // dir/capture.json
  Setup setup = Setup::kBack;
  std::array<double, 3> size_mm{};  // sample extent along x, y, z: (n - 1) h per axis
  GridShape grid;                   // recovery grid (from spacing_mm or grid)
  double spacing_mm = 0;
  double eta = 1.3;
  double C = 0;  // from eta unless given
  // Image positions (pixels, OpenCV convention) of the front face's corners, in the order
  // sample (0, 0), (X, 0), (X, Y), (0, Y); empty: found automatically in the images.
  std::vector<std::array<double, 2>> face_corners_px;
  // The corners above are only near the face's (capture.json {"near": [...]}, clicked by hand,
  // within a few pixels): refined in the photos as automatic ones are.
  bool face_corners_near = false;
  // The lens's blur on the photos of the sample, a Gaussian sigma in pixels (0..5), which
  // spreads the face's outline into the dark surround (docs/capture.md, "Mapping"); empty:
  // "auto", read off the face's outline in the photos (EstimateOutlineBlur).
  std::optional<double> camera_blur_px;

  // Calibration: each either a finished file (`*_file`) or what to compute it from.
  struct Camera {
    std::string file;               // OpenCV YAML of `translume calibrate camera`
    std::string photos, board;      // or: board photos folder and board specification
  } camera;
  struct Projector {
    std::string file;               // OpenCV YAML of `translume calibrate projector`
    std::string planes, board;      // or: plane photo pairs folder, printed board
    std::string pattern = "11x7:64";
    std::string projector_size = "1024x768";
    bool rear = false;              // rear projection (default: true in the back-lit setup)
    bool present() const { return !file.empty() || !planes.empty(); }
  } projector;
  struct Response {
    std::string file;                 // OpenCV YAML of `translume calibrate response`
    std::vector<std::string> stacks;  // or: stacks of static scenes
    bool linear = false;              // "linear": 16-bit, float or RAW photos need none
  } response;
  struct White {
    std::string file;                 // OpenCV YAML of `translume calibrate white`
    std::string white, black;         // or: stacks (or .exr) of the reference under projector
                                      // white and black
    std::vector<std::array<double, 2>> patch;  // its 4 image corners (pixels)
    std::array<double, 3> albedo{};   // the patch's RGB albedo
    // The reference covers the lit face's outline in the photos (a white card in the front
    // face's place front-lit; back-lit, a thin diffuser in the back face's place): its image,
    // minus its black, relative to the patch's mean, is each lit-face node's share of the
    // projector's irradiance (its fall-off), and multiplies the patterns' q.
    bool flat_field = false;
  } white;
  std::string black;  // optional: stack of the sample under projector black, subtracted
  // Optional: a stack (or HDR .exr) of an evenly lit, featureless field filling the camera's view
  // through the same lens, aperture and focus (the lens's vignetting): every HDR image the
  // capture's photos make is divided by it, normalised to its mean.
  std::string camera_flat;
  // The camera's black level left in linear photos (16-bit or float files that were not
  // black-subtracted), fraction of full scale, RGB; subtracted from every photo of every stack
  // (calib::MergeOptions::sensor_black). 0: none.
  std::array<double, 3> sensor_black{};
  // How the photos' exposure times are read (docs/capture.md, "Exposure times"): "auto" (the
  // response fit, or the linear stacks' brightness steps, decides), "labelled" or "apex".
  calib::ShutterTimes exposure_times = calib::ShutterTimes::kAuto;

  struct Condition {
    std::string name;
    std::string stack;     // exposure stack folder
    std::string pattern;   // projector image (q through the projector calibration), or
    std::string light;     // a light spec on the lit face (solver/light.h), q taken as given;
                           // an image: file relative to the capture folder (Light())
    // A validation condition: not fitted; the solve stops on it (RecoveryOptions::
    // validation_every) and keeps its best iterate.
    bool validation = false;
    // The parsed light spec, its image: path resolved against the capture folder `dir`.
    LightSpec Light(const std::string& dir) const;
  };
  std::vector<Condition> conditions;
};

// Reads and validates DIR/capture.json (`path` may name the folder or the file). Throws
// InputError "FILE: FIELD: problem" on: unknown format, unknown or mistyped fields, a setup
// other than back|front, non-positive sizes, neither or both of spacing_mm and grid, a spacing
// (given or from the grid) that SpacingProblem refuses, more than 10^6 nodes on an axis, a grid
// of other than whole numbers or that does not match the size, eta and C both given, corners
// not 4 pairs, a missing folder or file (or one of the other kind), a board or projector
// pattern and size that do not parse, a condition with neither or both of pattern and light,
// pattern conditions without a projector calibration, duplicate condition names; and
// "FILE: problem" when the file is a folder or not JSON (a number out of a double's range too).
CaptureSpec ReadCapture(const std::string& path);

// The JSON text of a spec, paths relative to spec.dir (what ReadCapture reads back).
std::string CaptureJson(const CaptureSpec& spec);

}  // namespace translume::acquire
