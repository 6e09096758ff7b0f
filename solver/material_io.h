// SPDX-License-Identifier: MIT
#pragma once

#include <string>

#include "solver/material.h"

namespace translume {

// The material file (OpenVDB, .vdb):
//   grids   kappa   Vec3f, mm, RGB in x/y/z of the vector
//           mu      Vec3f, 1/mm
//           density float, mean over RGB of sigma_t' = 1 / (3 kappa)   (for viewers, written only)
//           albedo  Vec3f, 1 - 3 kappa mu                               (for viewers, written only)
//   every grid: linear transform with voxel size h (mm), voxel (i, j, k) = node (i, j, k), all
//   nx*ny*nz voxels active, nothing outside.
//   file metadata  C (float), eta (float), translume_format (string "material/1").
// Writes to a temporary name beside `path` and renames, so a failure leaves nothing behind.
void WriteMaterial(const std::string& path, const Material& material);

// Reads and validates a material file. Throws InputError naming the file and the problem on a
// missing grid, mismatched shapes or transforms, non-finite or non-positive values, missing or
// unknown file metadata.
Material ReadMaterial(const std::string& path);

// For tests of the rejection paths only: writes a deliberately broken material file, so that no
// other translation unit has to include OpenVDB.
enum class MaterialCorruption {
  kMissingMu, kMissingC, kUnknownMetadata, kShapeMismatch, kNegativeKappa, kNanMu,
  kWrongGridType, kMissingVoxel, kWrongFormat, kRotated, kMirrored,
  kHugeTiles,  // valid, but a 4096^3 grid of active tiles: far more than memory holds densely
  kNoChecksum  // not corrupt: a file as written before the checksum trailer (still read)
};
void WriteCorruptMaterialForTest(const std::string& path, const Material& material,
                                 MaterialCorruption corruption);

}  // namespace translume
