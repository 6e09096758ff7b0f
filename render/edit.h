// SPDX-License-Identifier: MIT
#pragma once

#include <array>
#include <string>

#include "solver/image.h"
#include "solver/material.h"

namespace translume {

// Material editing (Wang et al. 2008, Section 5.4) on the block material, in the chosen channels:
//   v' = v + m (s v + a - v)     for v = kappa and mu separately,
// with s the multiplier, a the added constant, and m the mask weight at the node: the pattern
// mask's luminance (0.2126 R + 0.7152 G + 0.0722 B, clamped to [0, 1]) stretched over the x-y
// face (nearest pixel), times 1 inside the depth range k in [depth_begin, depth_end] and 0
// outside. The result must stay positive and finite.
struct EditOptions {
  double scale_kappa = 1, scale_mu = 1;
  double add_kappa = 0, add_mu = 0;
  int depth_begin = 0, depth_end = -1;  // node layers, inclusive; -1: to the deepest layer
  std::array<bool, 3> channels{true, true, true};  // R, G, B


  std::string Validate() const;
  // Parses "kappa=2" / "mu=0.5" into the scale (add = false) or add fields; repeated terms
  // compose (scales multiply, additions add up). Throws InputError.
  void ParseTerm(const std::string& text, bool add);
  // Parses "A:B" (node layers, 0 <= A <= B, inclusive) into the depth range. Throws InputError.
  void ParseDepth(const std::string& text);
  // Parses a set of channel letters ("r", "gb", "rgb"; case-insensitive, each at most once)
  // into channels. Throws InputError.
  void ParseChannels(const std::string& text);
};

// Throws InputError if an edited value is not positive and finite.
Material EditMaterial(const Material& material, const EditOptions& options,
                      const Image* mask = nullptr);

}  // namespace translume
