// SPDX-License-Identifier: MIT
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "solver/material.h"

namespace translume {

// Synthetic materials with physically plausible values: kappa = 1 / (3 (sigma_a + sigma_s'))
// and mu = sigma_a from the measured coefficients of Jensen et al. 2001 (Table 2), blended and
// scaled into kappa in ~0.05-0.5 mm and mu in ~0.001-0.1 /mm.
//   homogeneous  one material (marble-like) everywhere
//   layered      three layers along depth z (a thin skin-like top layer, marble, an apple-like
//                base)
//   marble       marble-like host with dark, absorbing veins from 3-D turbulence noise
//   inclusions   a wax-like host with buried blobs of a more absorbing material
//   wax          smooth low-frequency variation of kappa and mu
//   wax1, wax2, stone: the paper's samples (Wang et al. 2008, Table II) at their grid sizes
//   (130x53x37, 140x75x48, 128x128x41); `marble` defaults to the paper's 256x256x20.
struct SynthOptions {
  std::string preset = "marble";
  GridShape shape;  // {0,0,0}: the preset's default grid
  double spacing_mm = 0.5;
  uint64_t seed = 1;
  double eta = 1.3;
};

std::vector<std::string> SynthPresetNames();
GridShape DefaultSynthShape(const std::string& preset);
// Throws InputError on an unknown preset or bad options.
Material SynthesizeMaterial(const SynthOptions& options);

}  // namespace translume
