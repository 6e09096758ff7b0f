// SPDX-License-Identifier: MIT
#pragma once

#include <array>
#include <string>
#include <vector>

#include "solver/grid.h"
#include "solver/material.h"
#include "solver/multigrid.h"

namespace translume {

// Where a diffusion solve runs: `cpu` (OpenMP, float or double) or `gl` (OpenGL compute
// shaders in a headless context, float; see gl_solver.h).
enum class Backend { kCpu, kGl };
// Throws InputError naming `flag` on anything but cpu | gl.
Backend ParseBackend(const std::string& text, const char* flag = "--backend");
const char* BackendName(Backend backend);  // "cpu", "gl"

enum class Precision { kFloat, kDouble };
Precision ParsePrecision(const std::string& text);

struct ForwardOptions {
  Setup setup = Setup::kBack;
  Backend backend = Backend::kCpu;
  Precision precision = Precision::kDouble;
  MultigridOptions multigrid;
  bool side_faces = false;  // also the side faces' radiance (ForwardResult::sides)
};

// One RGB light pattern on the lit face: q[c][i + nx * j], c = R, G, B.
using FacePattern = std::array<std::vector<float>, 3>;
FacePattern GreyPattern(const std::vector<float>& q);

// Per channel, the four side faces' values (ForwardResult::sides).
using SideFaces = std::array<std::array<std::vector<float>, 4>, 3>;

struct ForwardResult {
  // Front-face outgoing radiance L = (phi - q) / (2 pi) at nodes (i, j, 0), SPEC section 3,
  // per channel, nx*ny values (i + nx * j).
  FacePattern radiance;
  // With ForwardOptions::side_faces: the four side faces' outgoing radiance, per channel, in
  // the order x = 0, x = X (ny*nz values, j + ny * k), y = 0, y = Y (nx*nz values, i + nx * k):
  // L = (phi - q) / (2 pi) as on the front face, q the light on the lit face's row (k of
  // LitFaceK) and 0 elsewhere. What a camera that sees a side face photographs there.
  SideFaces sides;
  std::array<SolveSummary, 3> summaries;
};

// Solves the forward problem of SPEC section 3 for every channel of `material` under light q
// on the lit face of `options.setup`, and returns the front-face radiance.
ForwardResult SolveForward(const Material& material, const FacePattern& q,
                           const ForwardOptions& options);

// SolveForward for several lights. The gl backend solves all lights of a channel as one batch
// (GlMultigridSolver::SolveBatch: one dispatch per step for all of them); the cpu backend
// solves them one after another.
std::vector<ForwardResult> SolveForwardBatch(const Material& material,
                                             const std::vector<FacePattern>& lights,
                                             const ForwardOptions& options);

}  // namespace translume
