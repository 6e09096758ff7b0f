// SPDX-License-Identifier: MIT
#pragma once

#include <cstdint>
#include <string>

namespace translume {

// Node grid of SPEC section 2: nx * ny * nz nodes, node (i, j, k) at (i h, j h, k h) mm.
// x = image column, y = image row, z = depth (k = 0 is the front face the camera sees).
// Linear index i + nx * (j + ny * k): x fastest. Always 64-bit.
struct GridShape {
  int64_t nx = 0, ny = 0, nz = 0;

  int64_t size() const { return nx * ny * nz; }
  int64_t face_size() const { return nx * ny; }
  int64_t index(int64_t i, int64_t j, int64_t k) const { return i + nx * (j + ny * k); }
  int64_t n(int axis) const { return axis == 0 ? nx : axis == 1 ? ny : nz; }
  bool operator==(const GridShape&) const = default;
  std::string ToString() const {
    return std::to_string(nx) + "x" + std::to_string(ny) + "x" + std::to_string(nz);
  }
};

// The node spacings h accepted anywhere (mm): from a micrometre to a metre. Outside that range
// a sample's grid, its memory estimate or the solver's matrices overflow or underflow.
inline constexpr double kMinSpacingMm = 1e-3, kMaxSpacingMm = 1e3;
// "" if spacing_mm is a finite spacing within [kMinSpacingMm, kMaxSpacingMm], else the problem
// ("must be within 0.001..1000 mm, got 1e-50").
std::string SpacingProblem(double spacing_mm);

// The most nodes along one axis accepted anywhere. The paper's largest grid is 256x256x20; with
// this bound a grid's node count cannot overflow int64 (larger grids then fail the memory
// check, not an overflow).
inline constexpr int64_t kMaxGridAxis = 65536;

// Parses "NXxNYxNZ" (e.g. "130x53x37"), every dimension within 2..kMaxGridAxis; throws
// InputError naming `what` on bad input.
GridShape ParseGridShape(const std::string& text, const std::string& what);

// Which face the projector lights (SPEC section 2).
enum class Setup { kBack, kFront };
// Throws InputError naming `flag` (the command line's option) on anything but back | front.
Setup ParseSetup(const std::string& text, const char* flag = "--setup");
const char* SetupName(Setup setup);
// Depth index k of the lit face: nz - 1 in the back-lit setup, 0 in the front-lit one.
inline int64_t LitFaceK(Setup setup, const GridShape& shape) {
  return setup == Setup::kBack ? shape.nz - 1 : 0;
}

}  // namespace translume
