// SPDX-License-Identifier: MIT
#pragma once

#include <string>
#include <vector>

#include "solver/forward.h"
#include "solver/grid.h"

namespace translume {

// One illumination condition of a node-space dataset (docs/formats.md, "Dataset").
//   q:    incoming light on the lit face, per RGB channel, nx*ny values, q[c][i + nx * j] is
//         node (i, j) of the lit face (k = nz - 1 back-lit, k = 0 front-lit).
//   L:    measured front-face radiance (k = 0), same layout; L = (phi - q_front) / (2 pi).
//   mask: nx*ny weights, 1 = measured, 0 = ignore (values in [0, 1] act as weights).
struct DatasetCondition {
  std::string name;
  FacePattern q, L;
  std::vector<float> mask;
};

// A node-space dataset: what the inverse problem fits (SPEC section 4). Grid, spacing and C
// describe the recovery grid; every image is one value per front/lit-face node.
struct Dataset {
  GridShape shape;
  double spacing_mm = 0.5;
  double C = 0;
  Setup setup = Setup::kBack;
  std::vector<DatasetCondition> conditions;

  // The largest boundary parameter C accepted (C is about 30 for a refractive index of 3).
  static constexpr double kMaxC = 1000;
  // Empty if usable, else the broken constraint (sizes, finiteness, mask range, q >= 0, spacing
  // within SpacingProblem's range, 1 <= C <= kMaxC, light in some condition's q, measured
  // light in every channel; a single dark condition is allowed).
  std::string Validate() const;
};

// a and b agree to 1e-6 relative: the same spacing or C, as read back from files.
bool NearlyEqual(double a, double b);

// "" when `other` (a held-out or validation dataset) poses its conditions on the same problem
// as `training`: the same grid, spacing and C (relative 1e-6), and with same_setup the same lit
// face; otherwise what differs, as "its grid G, spacing S mm and C c differ from the training
// dataset's ..." (with same_setup also the setups).
std::string DifferentProblem(const Dataset& other, const Dataset& training, bool same_setup);

// A condition name that is also safe as part of a file name: 1-100 characters of
// [A-Za-z0-9_.-], not "." or "..".
bool IsSafeConditionName(const std::string& name);

// Reads DIR/dataset.json (`path` may name the folder or the json file). Image paths are relative
// to the folder. Throws InputError naming the file and the field on anything wrong: unknown
// format, missing or mistyped fields, grid < 2 nodes per axis, an unknown setup, duplicate
// condition names, missing images, wrong image size or channel count (q, L: 3 channels; mask:
// 1), non-finite values, negative q, mask outside [0, 1], and whatever Dataset::Validate refuses.
Dataset ReadDataset(const std::string& path);
// The folder of a dataset named as ReadDataset takes it: `path` itself, or the json file's
// folder ("." for a bare file name).
std::string DatasetFolder(const std::string& path);

// Writes `dir`/dataset.json and the EXR images q_NAME.exr, L_NAME.exr, mask_NAME.exr (the mask
// only where it is not all 1). Every file is written atomically. Throws InputError on I/O
// failure or if dataset.Validate() fails.
void WriteDataset(const std::string& dir, const Dataset& dataset);

}  // namespace translume
