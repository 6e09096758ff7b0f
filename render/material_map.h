// SPDX-License-Identifier: MIT
#pragma once

#include <array>
#include <string>

#include "render/diffusion.h"
#include "solver/material.h"

namespace translume {

// How an acquired block material covers an object (Section 5, after Chen et al. 2004): as a
// shell. A node's surface point is the boundary node it was reached from (Polygrid::source);
// its (u, v) are that node's polycube-face coordinates times the mean boundary spacing (mm),
// its depth the distance to it (mm). The material node (u / h, v / h, depth / h) is sampled
// trilinearly; u and v tile (wrap) or clamp; below the block's depth the core repeats the
// deepest layer (k = nz - 1).
struct ShellMappingOptions {
  bool tile = true;
  double scale = 1.0;  // surface mm per material mm (> 1 stretches the material)

  std::string Validate() const;
};

NodeMaterial MapShellMaterial(const Polygrid& pg, const Material& material,
                              const ShellMappingOptions& options);

// Materials for every level of a hierarchy (finest first) from the finest level's: each coarser
// level averages its children (RestrictPolygrid), as in Section 5.3.
std::vector<NodeMaterial> RestrictMaterialHierarchy(const std::vector<Polygrid>& levels,
                                                    NodeMaterial finest);

// One constant material everywhere.
NodeMaterial ConstantNodeMaterial(const Polygrid& pg, const std::array<float, 3>& kappa,
                                  const std::array<float, 3>& mu);

// Procedural materials evaluated at the node positions (mm):
//   marble  a marble-like host with absorbing veins from a sum of sines of position
//   layers  a skin-like top layer 1 mm deep over a marble-like core
// Throws InputError on an unknown name.
NodeMaterial ProceduralNodeMaterial(const Polygrid& pg, const std::string& name);

// A material named without a file: "procedural:NAME" (ProceduralNodeMaterial) or
// "homogeneous:KAPPA,MU" (mm, 1/mm, grey, both > 0). IsNamedNodeMaterial: spec has one of the
// two prefixes; NamedNodeMaterial throws InputError naming spec where it is not one.
bool IsNamedNodeMaterial(const std::string& spec);
NodeMaterial NamedNodeMaterial(const Polygrid& pg, const std::string& spec);

}  // namespace translume
