// SPDX-License-Identifier: MIT
#pragma once

#include <string>
#include <vector>

#include "solver/grid.h"
#include "solver/image.h"
#include "solver/forward.h"
#include "solver/light.h"
#include "solver/material.h"

namespace translume {

// The largest image ReadImage takes: 2^28 pixels (16384 x 16384; a 100 MP photo is 1e8) of at
// most 64 channels, and within the available memory as floats.
inline constexpr int64_t kMaxImagePixels = int64_t(1) << 28;
inline constexpr int kMaxImageChannels = 64;

// Reads any format OpenImageIO knows, converted to float (8/16-bit integers map to [0, 1]).
// Throws InputError naming the file on failure, and on an image larger than the above.
Image ReadImage(const std::string& path);

// Writes an image; the format follows the extension (.exr: float, .png: 8-bit after clamping to
// [0, 1]). Written under a temporary name and renamed. Throws InputError on failure.
void WriteImage(const std::string& path, const Image& image);

// q at the lit-face nodes for any light, reading the pattern file of `image:FILE` lights.
std::vector<float> RasterizeLightFile(const LightSpec& spec, const GridShape& shape, double h);

// Channel-separated planes (each width*height, row-major) to an interleaved image.
Image ImageFromPlanes(int width, int height, const std::vector<const float*>& planes);

// The residual panel of WriteFitComparison saturates at this fraction of the measured panel's
// brightest node.
inline constexpr float kResidualPreviewRange = 0.05f;

// An 8-bit preview of a fit to one condition (or of any rendering against a reference: evaluate's
// held-out previews pass the truth relit as `measured`), three panels of the face side by side (x right, y
// down, PreviewPixelsPerNode pixels per node, a 2-node black gap between panels):
//   measured  `measured` where mask > 0, black where masked: divided by top = the largest
//             measured value over the unmasked nodes and the three channels, clamped to [0, 1],
//             gamma 1/2.2;
//   fitted    `fitted` on the same scale;
//   residual  r = (fitted - measured) / top per unmasked node in the channel where |r| is
//             largest (so misfits of opposite sign in two channels do not cancel): black at 0,
//             red (fitted brighter) or blue (fitted darker) rising linearly to full at |r| =
//             kResidualPreviewRange (clamped); masked nodes mid-grey (neither red nor blue).
// So a misfit is seen where it lies (an edge misregistered, a region too dark), on one scale for
// every condition of a capture. Written under a temporary name and renamed.
void WriteFitComparison(const std::string& path, const GridShape& shape, const FacePattern& measured,
                        const FacePattern& fitted, const std::vector<float>& mask);

// Pixels per node along each axis of the node-space previews (nearest neighbour: a square block
// per node), so that a face of nx nodes is at least 256 pixels wide: ceil(256 / nx), at least 1.
int PreviewPixelsPerNode(int64_t nx);

// 8-bit PNG slices of kappa and mu at depths 0, nz/4, nz/2, 3nz/4 and nz-1 (x right, y down),
// PreviewPixelsPerNode pixels per node, RGB = channels, each channel on a log scale over its own
// spread in the whole volume: from its kPreviewQuantile quantile (0) to its 1 - kPreviewQuantile
// quantile (1), clamped, a range of at least a factor kPreviewMinRatio (material.h; a constant
// channel is mid-grey). So the structure shows whatever the channels' levels, a few extreme
// nodes, such as a recovery's corners, do not flatten the rest, and a variation of a few percent
// stays faint: PREFIX_kappa_kNN.png, PREFIX_mu_kNN.png. Returns the paths written,
// MaterialSlicePaths(prefix, material.shape).
std::vector<std::string> WriteMaterialSlices(const std::string& prefix, const Material& material);
// The paths WriteMaterialSlices writes for a material of this grid: kappa's, then mu's, each
// in the order of MaterialSliceDepths.
std::vector<std::string> MaterialSlicePaths(const std::string& prefix, const GridShape& shape);
// The depths k of those slices: 0, nz/4, nz/2, 3nz/4, nz-1 without repeats.
std::vector<int64_t> MaterialSliceDepths(const GridShape& shape);

}  // namespace translume
