// SPDX-License-Identifier: MIT
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "calib/shutter.h"

namespace translume::calib {

// One photo of an exposure stack. pixels: RGB order, CV_8UC3 (codes through the camera
// response), CV_16UC3 (linear codes, full scale 65535) or CV_32FC3 (linear, full scale 1).
struct Exposure {
  std::string path;
  cv::Mat pixels;
  double seconds = 0;  // exposure time
};

// Photos of one static scene at different exposure times, sorted by file name.
struct ExposureStack {
  std::string dir;
  std::vector<Exposure> exposures;
  bool IsEightBit() const { return !exposures.empty() && exposures[0].pixels.depth() == CV_8U; }
  cv::Size Size() const { return exposures.empty() ? cv::Size() : exposures[0].pixels.size(); }
};

// Whether an exposure's time is a shutter-speed label whose APEX time differs from it by more
// than 0.5 % (1/30, 1/15, 15, 0.3; not 1/8, 1/4, 2).
bool HasApexLabels(const ExposureStack& stack);
// The stack with each time read as `times` (kApex: ApexSeconds; kLabelled: as is). The pixels
// are shared, not copied. kAuto is a bug (throws std::logic_error).
ExposureStack WithShutterTimes(const ExposureStack& stack, ShutterTimes times);

// Whether a file in a photo folder or exposure stack is read as a photo: .png .jpg .jpeg .tif
// .tiff .bmp .exr or a camera RAW file (below), in any case, and not a hidden file (a name
// starting with '.', e.g. the ._IMG_0001.JPG that macOS leaves on FAT and exFAT cards).
bool IsPhotoFile(const std::string& path);

// Reads one image file through OpenImageIO as RGB (grey images are replicated, alpha dropped):
// 8-bit files stay CV_8UC3, 16-bit files become CV_16UC3, float/half files CV_32FC3. Camera RAW
// files (.cr2 .cr3 .nef .arw .dng .raf .orf .rw2 .pef .srw) are decoded linearly (no white
// balance, no auto brightness, linear colour space) to CV_16UC3. *exif_seconds receives the EXIF
// ExposureTime (0 when absent), *grey whether the file itself was grey (one or two channels).
// Throws CalibError "PATH: problem", also for a damaged JPEG (cut short or corrupt data) and a
// PNG cut short (no IEND chunk).
cv::Mat ReadRgbImage(const std::string& path, double* exif_seconds = nullptr, bool* grey = nullptr);

// Throws CalibError "NAME: image is WxH but K of WHOSE N photos are W2xH2" for the first photo
// whose size differs from the size most of them share, so that the odd photo is the one named
// whichever sorts first (WHOSE: "the stack's", "the folder's").
void RequireOneSize(const std::vector<std::string>& names, const std::vector<cv::Size>& sizes,
                    const std::string& whose);

// Writes a CV_32FC3 RGB image as an OpenEXR file (float). Throws CalibError on failure.
void WriteExr(const std::string& path, const cv::Mat& rgb);
// Writes an 8-bit grey (CV_8UC1) or RGB (CV_8UC3) image; format from the extension.
void WriteImage8(const std::string& path, const cv::Mat& image);
// Writes an 8-bit or 16-bit grey or RGB photo (16-bit: PNG or TIFF); format from the extension.
void WritePhoto(const std::string& path, const cv::Mat& image);
// Reads an image as linear float RGB (CV_32FC3; integer files scaled to [0, 1]).
cv::Mat ReadLinearRgb(const std::string& path);

// Reads every image in `dir` (sorted by name) with its exposure time: the EXIF ExposureTime
// when present, else the entry for the file name in `dir`/exposures.json ({"name": seconds}).
// Throws CalibError naming the file when a time is missing or not positive, images differ in
// size, bit depth or colour (grey and colour files mixed), a file cannot be decoded, the
// folder holds fewer than 2 images, or an entry of exposures.json names no photo in it.
ExposureStack ReadExposureStack(const std::string& dir);

// Camera response of an 8-bit camera: lut is 256x1 CV_32FC3 (R, G, B), lut(z) = relative
// linear exposure (irradiance * seconds) that gives code z, normalised per channel so that
// lut(128) = 1. (Channel ratios are therefore arbitrary; the white balance fixes them.)
struct ResponseCurve {
  cv::Mat lut;
  // How the exposure times of the stacks it was fitted to were read (never kAuto): stacks
  // merged through this curve read theirs the same way (MergeHdr).
  ShutterTimes shutter = ShutterTimes::kLabelled;
  // Fit residual: RMS over the data rows of ln(lut(z)) - ln E - ln t, hat-weighted, ln units
  // (0.01 = 1 %). Not stored in the file (0 after ReadResponse).
  double fit_rms = 0;
  // Under ShutterTimes::kAuto with APEX labels in the stacks: the other reading's fit_rms.
  double other_fit_rms = 0;
  std::string Validate() const;  // empty when monotone, positive and finite
  // "fitted to times as labelled" / "... read as APEX shutter speeds (fit residual 0.4 %, as
  // labelled 2.1 %)".
  std::string ShutterReport() const;
};

struct ResponseOptions {
  int samples_per_stack = 600;  // pixel positions per stack, stratified by intensity
  double smoothness = 30.0;     // lambda of Debevec & Malik's second-derivative term
  uint64_t seed = 1;
  // kAuto: where the stacks' times include APEX labels (HasApexLabels), the curve is fitted to
  // both readings, and the APEX one kept where its fit residual is over 2 % smaller. (Read both ways, an 8-bit
  // stack alone cannot fix its times' common exponent: Grossberg & Nayar's exponential
  // ambiguity. What decides is how evenly the photos' brightness steps follow the times.)
  ShutterTimes shutter = ShutterTimes::kAuto;
  std::string Validate() const;
};

// Debevec & Malik 1997: solves for g = ln(lut) per channel from one or more 8-bit stacks by
// weighted least squares (hat weights, clipped codes 0..2 and 253..255 excluded) with a
// smoothness prior, the stacks' times read as options.shutter says. Throws CalibError when a
// stack is not 8-bit, the data do not constrain the curve, or the fitted curve does not rise
// over the codes the data cover (the photos do not brighten with their exposure times).
ResponseCurve CalibrateResponse(const std::vector<ExposureStack>& stacks,
                                const ResponseOptions& options = {});

// OpenCV FileStorage YAML with `response` (256x1, 3 channels RGB), `channels: RGB` and
// `exposure_times: labelled|apex` (files without it: labelled).
void WriteResponse(const std::string& path, const ResponseCurve& curve);
ResponseCurve ReadResponse(const std::string& path);

// "" where each of a sensor black level's channels (fractions of full scale) lies in [0, 0.5);
// else "expected fractions of full scale in [0, 0.5)".
std::string SensorBlackProblem(const cv::Vec3d& sensor_black);

struct MergeOptions {
  int low_code = 3;             // 8-bit: codes <= low_code are under-exposed
  int high_code = 250;          // 8-bit: codes >= high_code are saturated
  double low_linear = 0.0005;   // linear inputs: values <= this fraction of full scale are
                                // under-exposed
  double high_linear = 0.97;    // linear inputs: values >= this fraction are saturated
  // Linear inputs: the camera's black level left in the photos (16-bit or float files that
  // were not black-subtracted), a fraction of full scale per channel (RGB), in [0, 0.5). It is
  // subtracted from every photo (and black-stack photo) before its time divides it; a value is
  // under-exposed at or below sensor_black + low_linear. 8-bit stacks take none (their
  // response curve holds their black level), nor do camera RAW files (decoded with theirs
  // removed): MergeHdr and ShutterJudge refuse one, and ReadHdrOrStack refuses one for an HDR
  // image (merged already).
  cv::Vec3d sensor_black{0, 0, 0};
  // How the stack's (and the black stack's) times are read. kAuto: 8-bit stacks as their
  // response was fitted (ResponseCurve::shutter); linear stacks as ChooseShutterTimes judges
  // this stack.
  ShutterTimes shutter = ShutterTimes::kAuto;
  std::string Validate() const;
};

// Per-pixel, per-channel sample state of a merged image.
enum HdrFlag : uint8_t { kHdrOk = 0, kHdrSaturated = 1, kHdrUnderexposed = 2 };

struct HdrImage {
  cv::Mat radiance;  // CV_32FC3 RGB: linear exposure per second (camera units); +inf where
                     // saturated in every exposure
  cv::Mat flags;     // CV_8UC3 HdrFlag per channel
  size_t saturated = 0, underexposed = 0;  // channel samples flagged
  // Where two exposures next in time brighten by a ratio more than 3 % off the ratio of their
  // times as read (over 200 samples or more; camera labels read as labelled are up to 7 % off):
  // a sentence naming the stack, both photos and the ratios; the same for linear photos too far
  // apart in time for that check, more than 2x off over their dimmer pixels (MergeHdr). Where two
  // exposures next in time share too few well-exposed samples for their times to be checked,
  // though each has 50 or more: a sentence saying so. Else "". (The first warning, shortest
  // exposures first; a later warning replaces a "not checked" note.)
  std::string time_warning;
  ShutterTimes shutter = ShutterTimes::kLabelled;  // how the times were read (never kAuto)
  std::string BriefReport() const;
};

// How the brightness steps of linear (16-bit, RAW or float) stacks agree with their times read
// either way: the RMS over exposure pairs next in time (with 200 samples or more well inside the
// valid range in both) of ln(measured ratio / time ratio), less their mean where three or more
// different pairs of times are judged. (A sensor black level left in the photos, with no black
// stack to remove it, lowers every step alike: 2 % of full scale by about 5 %, as much as tells
// 1/15 -> 1/8 from 1/16 -> 1/8. Two pairs cannot tell that from the times; three can.)
struct ShutterChoice {
  ShutterTimes times = ShutterTimes::kLabelled;
  double labelled_rms = 0, apex_rms = 0;  // ln units; 0 where not judged
  double step_bias = 0;                   // the mean removed from the chosen reading's steps, ln units
  int pairs = 0;                          // pairs judged
  bool decisive = false;                  // some judged pair tells the readings apart
  std::string BriefReport() const;        // "exposure times read as APEX shutter speeds: ..."
};

// Pools the pairs of one capture's linear stacks, which share one reading of their times. Add
// stacks until Decisive() (or none is left), then Choice(): kApex where some stack has APEX
// labels and the steps are off the APEX times by less than 0.8x their RMS off the labels;
// kLabelled otherwise (also where no pair could be judged). 8-bit stacks are refused
// (CalibError): their steps depend on the response, whose fit decides (ResponseOptions).
class ShutterJudge {
 public:
  explicit ShutterJudge(const MergeOptions& options = {}) : options_(options) {}
  void Add(const ExposureStack& stack, const ExposureStack* black = nullptr);
  // Some pair of labels whose ratio differs from their APEX times' ratio by over 0.5 % has been
  // seen, and every such pair has been judged in some stack. (Pairs off by one common factor,
  // 1/4000 -> 1/2000 as 1/4096 -> 1/2048, cannot tell the readings apart; yet the readings
  // differ in that stack's scale against the others', so the next stacks are needed.)
  bool Decisive() const;
  ShutterChoice Choice() const;

 private:
  struct Step {
    std::pair<double, double> key;  // labelled times (shorter, longer)
    double labelled = 0, apex = 0;  // ln(measured ratio / time ratio) read either way
  };
  MergeOptions options_;
  std::vector<Step> steps_;
  bool apex_labels_ = false;
  std::vector<std::pair<double, double>> telling_, judged_;  // labelled times (shorter, longer)
};

// One stack judged alone.
ShutterChoice ChooseShutterTimes(const ExposureStack& stack, const ExposureStack* black = nullptr,
                                 const MergeOptions& options = {});

// Merges a stack: each exposure is linearised (8-bit through `response`, required; 16-bit and
// float as is), the black stack's exposure of the same time (if given) is subtracted, and
//   E = sum_j w_j x_j / sum_j w_j t_j
// over the samples that are neither saturated nor under-exposed in their channel (w: a hat
// over the valid code range, so long exposures weigh more: the estimate is noise-optimal for
// shot noise). A channel saturated in every exposure is +inf and flagged; one under-exposed in
// every exposure takes the longest exposure's value (>= 0) and is flagged. Throws CalibError
// naming the stack and both photos when two exposures next in time contradict their times: the
// median ratio of their linear values, over samples well inside the valid range in both (0.1 of
// it in from either end), more than 2x off the ratio of their times. Linear pairs with fewer
// than 50 such samples, whose times are further apart than that window spans or whose photos
// each have 50 or more, are judged on 0.01 of the range in from either end, where a black level
// left in the photos also contradicts the times: time_warning then, not an error. Pairs left
// with fewer than 50 samples are not judged (time_warning says so where each photo has 50 or
// more).
HdrImage MergeHdr(const ExposureStack& stack, const ResponseCurve* response,
                  const ExposureStack* black = nullptr, const MergeOptions& options = {});

// A camera flat (the HDR image of an evenly lit, featureless field filling the view through the
// lens: its vignetting) divided by its mean per channel, for HDR images of the same camera to be
// divided by. Throws CalibError "PATH: saturated at pixel (x, y)" for a non-finite pixel and
// "PATH: dark at pixel (x, y)" for one under 0.1 of its channel's mean (the field does not fill
// the view evenly).
cv::Mat NormalizedCameraFlat(const cv::Mat& hdr, const std::string& path);

// What ReadHdrOrStack did with a stack folder (left as constructed for an image file).
struct HdrReadInfo {
  ShutterTimes shutter = ShutterTimes::kAuto;  // how a stack's times were read (HdrImage::shutter)
  std::string time_warning;                    // HdrImage::time_warning: "" or one sentence
};

// A linear HDR image from `path`: an image file read as is (ReadLinearRgb), or a stack folder
// merged with MergeHdr (`response` for 8-bit stacks, may be null otherwise). *info, where given,
// receives what the merge found; callers show its time_warning as a warning.
cv::Mat ReadHdrOrStack(const std::string& path, const ResponseCurve* response,
                       const MergeOptions& options = {}, HdrReadInfo* info = nullptr);

}  // namespace translume::calib
