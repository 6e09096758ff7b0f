// SPDX-License-Identifier: MIT
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "solver/dataset.h"
#include "solver/light.h"
#include "solver/material.h"
#include "solver/multigrid.h"

namespace translume {

// The material on a grid K times finer per axis: (n - 1) K + 1 nodes per axis (RefineShape),
// spacing h / K, kappa and mu trilinearly interpolated between the original nodes (which it
// keeps exactly).
Material RefineMaterial(const Material& material, int K);
GridShape RefineShape(const GridShape& shape, int K);

// Front-face radiance of `material` under each light pattern (L = (phi - q_front) / (2 pi),
// SPEC section 3), solved on the material's own grid. cpu: conditions in parallel threads, one
// solver each; gl: batches of up to 16 conditions per solve, in turn on the calling thread (the
// one that owns the GL context). max_at_once > 0 caps the solvers held at once (threads on
// cpu, the batch on gl), and with them the memory (solver/memory.h's forward bytes each).
// With `sides`, it also receives the side faces' radiance under each light (ForwardResult::sides).
std::vector<FacePattern> RenderFrontFace(const Material& material, Setup setup,
                                         const std::vector<FacePattern>& lights,
                                         const MultigridOptions& multigrid,
                                         Backend backend = Backend::kCpu, int max_at_once = 0,
                                         std::vector<SideFaces>* sides = nullptr);

// What a camera measures of each front-face node under each light: RenderFrontFace's radiance
// averaged over the nodes' face boxes (MeasureFace, solver/face_measurement.h). This is what
// datasets hold and what the objective fits.
std::vector<FacePattern> RenderMeasured(const Material& material, Setup setup,
                                        const std::vector<FacePattern>& lights,
                                        const MultigridOptions& multigrid,
                                        Backend backend = Backend::kCpu, int max_at_once = 0);

// Front-lit mask: 0 at every front-face node within `margin` nodes (Chebyshev distance) of a
// node with q > 0 in any channel, 1 elsewhere. All 1 for the back-lit setup.
std::vector<float> MeasurementMask(const GridShape& shape, Setup setup, const FacePattern& q,
                                   int margin = 2);

// The most held-out conditions a simulation writes: as many as the most training lights
// (RegionLights' 64x64). Each is a forward solve; far more were a typo (2^31 allocated 28 GB).
inline constexpr int kMaxHoldout = 4096;

struct SimulateOptions {
  std::vector<LightSpec> lights;  // the training conditions (e.g. RegionLights("4x4")); none: holdout only
  Setup setup = Setup::kBack;
  double noise = 0;         // relative Gaussian noise sigma per pixel and channel (0.01 = 1 %), <= 1
  int oversample = 2;       // forward solves on a grid this many times finer per axis: 1, 2, 4, 6, 8
  int holdout = 0;          // extra held-out conditions: random spots on the lit face, <= kMaxHoldout
  // Validation conditions (RecoveryOptions::validation_every): random spots as the held-out
  // ones, drawn after them (the same seed gives the same training and held-out data with or
  // without them), <= kMaxHoldout.
  int validation = 0;
  uint64_t seed = 1;        // noise and holdout spot positions
  double tolerance = 1e-9;  // relative residual of every forward solve
  int mask_margin = 2;      // front-lit: nodes masked around the lit region
  Backend backend = Backend::kCpu;  // where the forward solves run

  std::string Validate() const;
};

struct SimulatedData {
  Dataset training;  // no conditions when options.lights is empty
  Dataset holdout;  // no conditions when options.holdout == 0
  std::vector<LightSpec> holdout_lights;
  Dataset validation;  // no conditions when options.validation == 0
  std::vector<LightSpec> validation_lights;
};

// Simulates a capture of `material` (the recovery grid): forward solves on the refined grid
// (RefineMaterial with options.oversample), front-face radiance averaged over each recovery
// node's face box as a camera measures it (BoxMeansOfFineFace, solver/face_measurement.h), then
// noise. q in the dataset is the light rasterised on the
// recovery grid. Holdout and validation spots have random centres on the lit face and radius 3 h.
SimulatedData SimulateDataset(const Material& material, const SimulateOptions& options);

}  // namespace translume
