// SPDX-License-Identifier: MIT
#pragma once

#include <string>

namespace translume::calib {

// How the exposure times of a capture's photos (EXIF ExposureTime or exposures.json) are read.
// Cameras label shutter speeds with rounded numbers of the APEX series t = 2^-(k/3) s (third
// stops; some cameras half stops, t = 2^-(k/2) s): a camera set to "1/30" exposes 1/32 s,
// "1/15" 1/16 s, "15" 16 s, "0.3" 0.315 s, and writes the label into EXIF. Merged with the
// labels, a stack's exposures next in time brighten up to 7 % more or less than their times say
// (docs/capture.md, "Exposure times").
enum class ShutterTimes {
  kAuto,      // whichever of the two below the photos agree with (calibration decides)
  kLabelled,  // the times as given
  kApex,      // each standard label replaced by its APEX time (ApexSeconds)
};

// "auto", "labelled", "apex"; throws CalibError naming `what` (a flag or a file) otherwise.
ShutterTimes ParseShutterTimes(const std::string& text, const std::string& what);
const char* ToString(ShutterTimes times);
// For messages: "read as APEX shutter speeds (1/30 as 1/32 s)", "as labelled" ("auto" for kAuto).
const char* Describe(ShutterTimes times);

// The APEX time of a standard shutter-speed label within 0.5 % of `seconds` (1/8000 s .. 30 s in
// third stops; 1/6000, 1/3000, 1/1500, 1/750, 1/350, 1/180, 1/90, 1/45, 1/3, 0.7, 1.5, 3, 11
// and 22 from the half-stop series): 1/30 -> 1/32, 1/125 -> 1/128, 1/10 -> 0.0992, 30 -> 32.
// Any other time (0.03125, 0.0417) is returned unchanged.
double ApexSeconds(double seconds);

// A time written as a decimal number of seconds ("0.5", "15") or as cameras show shutter speeds
// ("1/30"); 0 if it is neither (also "0x10", "inf", "1/0").
double SecondsFromText(const std::string& text);

// The inverse: the label a camera shows for an APEX time within 0.5 % (1/32 -> 1/30, 16 -> 15),
// else `seconds` unchanged. Simulated captures write their times so.
double ShutterLabel(double seconds);

}  // namespace translume::calib
