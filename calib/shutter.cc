// SPDX-License-Identifier: MIT
#include "calib/shutter.h"

#include <cmath>
#include <cstdlib>

#include "calib/error.h"

namespace translume::calib {
namespace {

// {label, stops below 1 s}: third stops k/3, then the half-stop labels k/2 that the third
// series does not use (1/6, 1/10, 1/20 and 6 s are third-stop labels there).
struct Label {
  double seconds;
  double stops;
};
const Label kLabels[] = {
    {30, -15 / 3.}, {25, -14 / 3.}, {20, -13 / 3.}, {15, -12 / 3.}, {13, -11 / 3.}, {10, -10 / 3.},
    {8, -9 / 3.}, {6, -8 / 3.}, {5, -7 / 3.}, {4, -6 / 3.}, {3.2, -5 / 3.}, {2.5, -4 / 3.}, {2, -3 / 3.},
    {1.6, -2 / 3.}, {1.3, -1 / 3.}, {1, 0}, {0.8, 1 / 3.}, {0.6, 2 / 3.}, {0.5, 3 / 3.}, {0.4, 4 / 3.},
    {0.3, 5 / 3.}, {1 / 4., 6 / 3.}, {1 / 5., 7 / 3.}, {1 / 6., 8 / 3.}, {1 / 8., 9 / 3.},
    {1 / 10., 10 / 3.}, {1 / 13., 11 / 3.}, {1 / 15., 12 / 3.}, {1 / 20., 13 / 3.}, {1 / 25., 14 / 3.},
    {1 / 30., 15 / 3.}, {1 / 40., 16 / 3.}, {1 / 50., 17 / 3.}, {1 / 60., 18 / 3.}, {1 / 80., 19 / 3.},
    {1 / 100., 20 / 3.}, {1 / 125., 21 / 3.}, {1 / 160., 22 / 3.}, {1 / 200., 23 / 3.},
    {1 / 250., 24 / 3.}, {1 / 320., 25 / 3.}, {1 / 400., 26 / 3.}, {1 / 500., 27 / 3.},
    {1 / 640., 28 / 3.}, {1 / 800., 29 / 3.}, {1 / 1000., 30 / 3.}, {1 / 1250., 31 / 3.},
    {1 / 1600., 32 / 3.}, {1 / 2000., 33 / 3.}, {1 / 2500., 34 / 3.}, {1 / 3200., 35 / 3.},
    {1 / 4000., 36 / 3.}, {1 / 5000., 37 / 3.}, {1 / 6400., 38 / 3.}, {1 / 8000., 39 / 3.},
    {22, -9 / 2.}, {11, -7 / 2.}, {3, -3 / 2.}, {1.5, -1 / 2.}, {0.7, 1 / 2.}, {1 / 3., 3 / 2.},
    {1 / 45., 11 / 2.}, {1 / 90., 13 / 2.}, {1 / 180., 15 / 2.}, {1 / 350., 17 / 2.},
    {1 / 750., 19 / 2.}, {1 / 1500., 21 / 2.}, {1 / 3000., 23 / 2.}, {1 / 6000., 25 / 2.},
};

}  // namespace

ShutterTimes ParseShutterTimes(const std::string& text, const std::string& what) {
  if (text == "auto") return ShutterTimes::kAuto;
  if (text == "labelled") return ShutterTimes::kLabelled;
  if (text == "apex") return ShutterTimes::kApex;
  throw CalibError(what + ": exposure times must be \"auto\", \"labelled\" or \"apex\", not \"" + text + "\"");
}

const char* ToString(ShutterTimes times) {
  switch (times) {
    case ShutterTimes::kAuto: return "auto";
    case ShutterTimes::kLabelled: return "labelled";
    case ShutterTimes::kApex: return "apex";
  }
  return "?";
}

const char* Describe(ShutterTimes times) {
  return times == ShutterTimes::kApex ? "read as APEX shutter speeds (1/30 as 1/32 s)"
         : times == ShutterTimes::kLabelled ? "as labelled"
                                            : "auto";
}

double ApexSeconds(double seconds) {
  for (const Label& l : kLabels)
    if (std::abs(seconds / l.seconds - 1) < 0.005) return std::exp2(-l.stops);
  return seconds;
}

double ShutterLabel(double seconds) {
  for (const Label& l : kLabels)
    if (std::abs(seconds / std::exp2(-l.stops) - 1) < 0.005) return l.seconds;
  return seconds;
}

double SecondsFromText(const std::string& text) {
  // Decimal only: strtod also takes "0x10", "inf" and "nan".
  if (text.find_first_not_of("0123456789.eE+-/ ") != std::string::npos) return 0;
  double den = 1;
  char* end = nullptr;
  const double num = std::strtod(text.c_str(), &end);
  if (end == text.c_str()) return 0;
  if (*end == '/') {
    const char* start = end + 1;
    den = std::strtod(start, &end);
    if (end == start) return 0;
  }
  if (*end != '\0' || !(den > 0)) return 0;
  return num / den;
}

}  // namespace translume::calib
