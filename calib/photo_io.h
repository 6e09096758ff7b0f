// SPDX-License-Identifier: MIT
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "calib/camera_calib.h"
#include "calib/projector_calib.h"
#include "calib/projector_pattern.h"

namespace translume::calib {

// An 8-bit grey version of any photo (8-bit, 16-bit, float, RAW; see ReadRgbImage).
cv::Mat ReadGray8(const std::string& path);

// Every photo in `dir` (IsPhotoFile: hidden files skipped), sorted by name, as 8-bit grey;
// names are the paths. Throws CalibError when `dir` is not a folder or holds no photo.
std::vector<NamedImage> ReadPhotoFolder(const std::string& dir);

// Plane photos for CalibrateProjector: NAME_board.EXT and NAME_pattern.EXT pairs in one folder
// (the suffixes in any case). A plane missing one photo has it empty (CalibrateProjector drops
// it). Throws CalibError naming the file for a photo of another name.
std::vector<PlaneView> ReadPlaneFolder(const std::string& dir);

// "COLSxROWS:SQUARE_PX" centred on a projector of size "WIDTHxHEIGHT". Throws CalibError naming
// the option (pattern_name / size_name: the command line's flags, or a file's fields) on
// malformed text or an invalid board.
ProjectorChessboard ParseProjectorChessboard(const std::string& pattern, const std::string& size,
                                             const std::string& pattern_name = "--pattern",
                                             const std::string& size_name = "--projector-size");

}  // namespace translume::calib
