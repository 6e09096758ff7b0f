// SPDX-License-Identifier: MIT
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

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
// size, bit depth or colour (grey and colour files mixed), a file cannot be decoded, or the
// folder holds fewer than 2 images.
ExposureStack ReadExposureStack(const std::string& dir);

// Camera response of an 8-bit camera: lut is 256x1 CV_32FC3 (R, G, B), lut(z) = relative
// linear exposure (irradiance * seconds) that gives code z, normalised per channel so that
// lut(128) = 1. (Channel ratios are therefore arbitrary; the white balance fixes them.)
struct ResponseCurve {
  cv::Mat lut;
  std::string Validate() const;  // empty when monotone, positive and finite
};

struct ResponseOptions {
  int samples_per_stack = 600;  // pixel positions per stack, stratified by intensity
  double smoothness = 30.0;     // lambda of Debevec & Malik's second-derivative term
  uint64_t seed = 1;
  std::string Validate() const;
};

// Debevec & Malik 1997: solves for g = ln(lut) per channel from one or more 8-bit stacks by
// weighted least squares (hat weights, clipped codes 0..2 and 253..255 excluded) with a
// smoothness prior. Throws CalibError when a stack is not 8-bit, the data do not constrain
// the curve, or the fitted curve does not rise over the codes the data cover (the photos do not
// brighten with their exposure times).
ResponseCurve CalibrateResponse(const std::vector<ExposureStack>& stacks,
                                const ResponseOptions& options = {});

// OpenCV FileStorage YAML with `response` (256x1, 3 channels RGB) and `channels: RGB`.
void WriteResponse(const std::string& path, const ResponseCurve& curve);
ResponseCurve ReadResponse(const std::string& path);

struct MergeOptions {
  int low_code = 3;             // 8-bit: codes <= low_code are under-exposed
  int high_code = 250;          // 8-bit: codes >= high_code are saturated
  double low_linear = 0.0005;   // linear inputs: values <= this fraction of full scale are
                                // under-exposed
  double high_linear = 0.97;    // linear inputs: values >= this fraction are saturated
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
  // times (over 200 samples or more; shutter speeds as cameras label them, 1/8 for 0.133 s,
  // are up to 7 % off): a sentence naming the stack, both photos and the ratios; else "".
  std::string time_warning;
  std::string BriefReport() const;
};

// Merges a stack: each exposure is linearised (8-bit through `response`, required; 16-bit and
// float as is), the black stack's exposure of the same time (if given) is subtracted, and
//   E = sum_j w_j x_j / sum_j w_j t_j
// over the samples that are neither saturated nor under-exposed in their channel (w: a hat
// over the valid code range, so long exposures weigh more: the estimate is noise-optimal for
// shot noise). A channel saturated in every exposure is +inf and flagged; one under-exposed in
// every exposure takes the longest exposure's value (>= 0) and is flagged. Throws CalibError
// naming the stack and both photos when two exposures next in time contradict their times: the
// median ratio of their linear values, over samples well inside the valid range in both, more
// than 2x off the ratio of their times (pairs with fewer than 50 such samples are not judged).
HdrImage MergeHdr(const ExposureStack& stack, const ResponseCurve* response,
                  const ExposureStack* black = nullptr, const MergeOptions& options = {});

// A linear HDR image from `path`: an image file read as is (ReadLinearRgb), or a stack folder
// merged with MergeHdr (`response` for 8-bit stacks, may be null otherwise).
cv::Mat ReadHdrOrStack(const std::string& path, const ResponseCurve* response);

}  // namespace translume::calib
