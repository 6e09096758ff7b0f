// SPDX-License-Identifier: MIT
#include "calib/hdr.h"

#include <fmt/format.h>

#include <Eigen/Sparse>
#include <OpenImageIO/imageio.h>
#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <atomic>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <tuple>
#include <map>
#include <optional>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <set>

#include "calib/error.h"
#include "calib/parallel.h"

namespace translume::calib {
namespace {

namespace fs = std::filesystem;

std::string Lower(std::string s) {
  for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

bool IsRaw(const std::string& path) {
  static const std::set<std::string> raw = {".cr2", ".cr3", ".nef", ".arw", ".dng",
                                            ".raf", ".orf", ".rw2", ".pef", ".srw"};
  return raw.count(Lower(fs::path(path).extension().string())) > 0;
}

// OpenImageIO's error text, first line only (our messages are one line).
std::string FirstLine(std::string s) {
  const size_t n = s.find('\n');
  if (n != std::string::npos) s.resize(n);
  return s.empty() ? "unknown error" : s;
}

// Whether a PNG file lacks its IEND chunk in its last 4 KiB (a copy cut short). Such a file is
// refused before decoding: OpenImageIO 2.4 leaves libpng's default error handler, which prints
// its own "libpng error:" line on stderr besides our one-line error.
bool PngCutShort(const std::string& path) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  const std::streamoff size = in.tellg();
  std::string bytes(8, '\0');
  in.seekg(0);
  if (size < 8 || !in.read(bytes.data(), 8) || bytes != "\x89PNG\r\n\x1a\n") return false;
  const std::streamoff tail = std::min<std::streamoff>(size, 4096);
  bytes.assign(size_t(tail), '\0');
  in.seekg(size - tail);
  in.read(bytes.data(), tail);
  // The chunk: length 0, type IEND, its fixed CRC.
  return bytes.find(std::string("\0\0\0\0IEND\xae\x42\x60\x82", 12)) == std::string::npos;
}

// Debevec & Malik's hat weight over the 8-bit codes.
double HatWeight(int z) { return z <= 127 ? z + 1.0 : 256.0 - z; }

// A stack's samples as linear values: codes (8-bit, 16-bit scaled to full scale 1, float) and
// their linearisation (8-bit through `response`).
// Linear stacks' values have MergeOptions::sensor_black subtracted.
struct Linearizer {
  const ResponseCurve* response = nullptr;
  bool eight = false;
  float full = 1.f;
  cv::Vec3d black{0, 0, 0};
  Linearizer(const ExposureStack& stack, const ResponseCurve* r, const MergeOptions& o)
      : response(r), eight(stack.IsEightBit()),
        full(!stack.exposures.empty() && stack.exposures[0].pixels.depth() == CV_16U ? 65535.f : 1.f),
        black(eight ? cv::Vec3d(0, 0, 0) : o.sensor_black) {}
  float Code(const cv::Mat& m, int y, int x, int c) const {
    switch (m.depth()) {
      case CV_8U: return m.at<cv::Vec3b>(y, x)[c];
      case CV_16U: return m.at<cv::Vec3w>(y, x)[c] / full;
      default: return m.at<cv::Vec3f>(y, x)[c];
    }
  }
  double Linear(float v, int c) const { return eight ? response->lut.at<cv::Vec3f>(int(v))[c] : v - black[c]; }
  // The lowest code that is not under-exposed is above this (`lo`: the options' low_code or
  // low_linear).
  double Low(double lo, int c) const { return lo + black[c]; }
};

// Per exposure of `stack`, the black stack's exposure of the same time (null without `black`).
// `given`: the stack as read from its folder (before WithShutterTimes), whose times messages quote.
std::vector<const Exposure*> MatchBlacks(const ExposureStack& stack, const ExposureStack* black,
                                         const ExposureStack& given) {
  std::vector<const Exposure*> blacks(stack.exposures.size(), nullptr);
  if (!black) return blacks;
  for (size_t j = 0; j < stack.exposures.size(); ++j) {
    const Exposure& e = stack.exposures[j];
    for (const Exposure& b : black->exposures)
      if (std::abs(b.seconds / e.seconds - 1) < 0.01) blacks[j] = &b;
    if (!blacks[j])
      throw CalibError(fmt::format("{}: the black stack {} has no photo at {:g} s", e.path, black->dir,
                                   given.exposures[j].seconds));
    if (blacks[j]->pixels.size() != e.pixels.size() || blacks[j]->pixels.depth() != e.pixels.depth())
      throw CalibError(fmt::format("{}: size or bit depth differs from {}", blacks[j]->path, e.path));
  }
  return blacks;
}

// The exposures' indices sorted by time, shortest first.
std::vector<size_t> TimeOrder(const ExposureStack& stack) {
  std::vector<size_t> order(stack.exposures.size());
  for (size_t j = 0; j < order.size(); ++j) order[j] = j;
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    return stack.exposures[a].seconds < stack.exposures[b].seconds;
  });
  return order;
}

// Two exposures next in time (indices into the stack, a the shorter) and how much brighter b is:
// the median ratio of their linear values (black subtracted) over samples well inside the valid
// range [lo, hi] in both (`inset` of the range in from either end; judged by a third exposure
// where one is well inside, MeasurePairRatio), on a grid of ~10^4 pixels.
// seen_a, seen_b: the grid's samples well inside the range in a, in b.
struct PairRatio {
  size_t k = 0;     // a's place in the time order (b's is k + 1)
  size_t a = 0, b = 0;
  double measured = 0;
  size_t samples = 0, seen_a = 0, seen_b = 0;
};

// Pairs with fewer samples are not judged at all (MergeHdr's 2x check) ...
constexpr size_t kMinPairSamples = 50;
// ... and pairs with fewer are not weighed against 3 % (the warning, ShutterJudge).
constexpr size_t kMinPairSamplesForPercent = 200;

// Channel c's codes "well inside" the valid range (lo, hi]: `inset` of it in from either end.
std::pair<double, double> WellInside(const Linearizer& lin, int c, double lo, double hi, double inset) {
  const double range = hi - lin.Low(lo, c);
  return {lin.Low(lo, c) + inset * range, hi - inset * range};
}

// The pair order[k], order[k + 1] (order: TimeOrder(stack)).
PairRatio MeasurePairRatio(const ExposureStack& stack, const Linearizer& lin,
                           const std::vector<const Exposure*>& blacks, const std::vector<size_t>& order, size_t k,
                           double lo, double hi, double inset) {
  const size_t a = order[k], b = order[k + 1];
  const cv::Size size = stack.Size();
  const int step = std::max(1, int(std::sqrt(double(size.area()) / 1e4)));
  double well_lo[3], well_hi[3], lin_lo[3], lin_hi[3];
  for (int c = 0; c < 3; ++c) {
    std::tie(well_lo[c], well_hi[c]) = WellInside(lin, c, lo, hi, inset);
    // The lowest and highest codes strictly inside, as linear values (8-bit codes are integers).
    lin_lo[c] = lin.Linear(float(lin.eight ? std::floor(well_lo[c]) + 1 : well_lo[c]), c);
    lin_hi[c] = lin.Linear(float(lin.eight ? std::ceil(well_hi[c]) - 1 : well_hi[c]), c);
  }
  // The samples are chosen by a third exposure where the stack has one: the one next shorter
  // than a, else the one next longer than b, whose value (times the ratio of the times) says
  // whether a's and b's lie well inside. Chosen by a's and b's own values, the ratio is biased:
  // in a dim photo the values just above the window's floor are there partly because their
  // noise is positive (a simulated projector-black stack, 8-bit, read noise 1 code: 1.93x for
  // 2x). The third exposure's noise is not a's or b's. Per pixel: where neither third exposure
  // is well inside (a pixel mid-range in a and b, in brackets more than a stop apart), a's and
  // b's own values choose; the window's ends, where the bias is, are seen by one of them.
  std::vector<size_t> judges;
  if (k > 0) judges.push_back(order[k - 1]);
  if (k + 2 < order.size()) judges.push_back(order[k + 2]);
  PairRatio p;
  p.k = k;
  p.a = a;
  p.b = b;
  std::vector<double> ratios, own_ratios;  // judged per pixel; chosen by a's and b's own values
  for (int y = 0; y < size.height; y += step)
    for (int x = 0; x < size.width; x += step)
      for (int c = 0; c < 3; ++c) {
        const float va = lin.Code(stack.exposures[a].pixels, y, x, c), vb = lin.Code(stack.exposures[b].pixels, y, x, c);
        const bool in_a = va > well_lo[c] && va < well_hi[c], in_b = vb > well_lo[c] && vb < well_hi[c];
        p.seen_a += in_a;
        p.seen_b += in_b;
        bool judged = false, chosen = false;
        for (size_t j : judges) {
          const Exposure& e = stack.exposures[j];
          const float vj = lin.Code(e.pixels, y, x, c);
          if (!(vj > well_lo[c] && vj < well_hi[c])) continue;
          const double per_second = lin.Linear(vj, c) / e.seconds;
          const double pa = per_second * stack.exposures[a].seconds, pb = per_second * stack.exposures[b].seconds;
          // Well inside by the judge; a and b themselves only not clipped.
          judged = true;
          chosen = pa > lin_lo[c] && pa < lin_hi[c] && pb > lin_lo[c] && pb < lin_hi[c] &&
                   va > lin.Low(lo, c) && va < hi && vb > lin.Low(lo, c) && vb < hi;
          break;
        }
        const bool take = judged ? chosen : in_a && in_b;
        if (!take && !(in_a && in_b)) continue;
        double xa = lin.Linear(va, c), xb = lin.Linear(vb, c);
        if (blacks[a]) xa -= lin.Linear(lin.Code(blacks[a]->pixels, y, x, c), c);
        if (blacks[b]) xb -= lin.Linear(lin.Code(blacks[b]->pixels, y, x, c), c);
        if (!(xa > 0 && xb > 0)) continue;
        if (take) ratios.push_back(xb / xa);
        if (in_a && in_b) own_ratios.push_back(xb / xa);
      }
  // Times that contradict the photos make the third exposures' predictions miss, and they reject
  // nearly every pixel: there the pair's own choice, for the 2x check.
  if (ratios.size() < kMinPairSamples && own_ratios.size() >= kMinPairSamples) ratios.swap(own_ratios);
  p.samples = ratios.size();
  if (!ratios.empty()) {
    std::nth_element(ratios.begin(), ratios.begin() + long(ratios.size() / 2), ratios.end());
    p.measured = ratios[ratios.size() / 2];
  }
  return p;
}

// MeasurePairRatio of every pair next in time, 0.1 of the range in from either end.
std::vector<PairRatio> MeasurePairRatios(const ExposureStack& stack, const Linearizer& lin,
                                         const std::vector<const Exposure*>& blacks, double lo, double hi) {
  const std::vector<size_t> order = TimeOrder(stack);
  std::vector<PairRatio> pairs;
  for (size_t k = 0; k + 1 < order.size(); ++k)
    pairs.push_back(MeasurePairRatio(stack, lin, blacks, order, k, lo, hi, 0.1));
  return pairs;
}

}  // namespace

bool HasApexLabels(const ExposureStack& stack) {
  for (const Exposure& e : stack.exposures)
    if (std::abs(ApexSeconds(e.seconds) / e.seconds - 1) > 0.005) return true;
  return false;
}

ExposureStack WithShutterTimes(const ExposureStack& stack, ShutterTimes times) {
  if (times == ShutterTimes::kAuto) throw std::logic_error("WithShutterTimes: kAuto must be decided first");
  ExposureStack s = stack;
  if (times == ShutterTimes::kApex)
    for (Exposure& e : s.exposures) e.seconds = ApexSeconds(e.seconds);
  return s;
}

bool IsPhotoFile(const std::string& path) {
  static const std::set<std::string> ext = {".png", ".tif", ".tiff", ".jpg", ".jpeg", ".bmp", ".exr"};
  const fs::path p(path);
  const std::string name = p.filename().string();
  return !name.empty() && name[0] != '.' && (ext.count(Lower(p.extension().string())) > 0 || IsRaw(path));
}

cv::Mat ReadRgbImage(const std::string& path, double* exif_seconds, bool* grey) {
  if (!fs::exists(path)) throw CalibError(path + ": no such file");
  std::error_code ec;
  if (fs::file_size(path, ec) == 0 && !ec) throw CalibError(path + ": empty file (0 bytes), not an image");
  if (PngCutShort(path)) throw CalibError(path + ": damaged image (a PNG cut short: no IEND chunk at its end)");
  OIIO::ImageSpec config;
  if (IsRaw(path)) {
    config.attribute("raw:use_camera_wb", 0);
    config.attribute("raw:auto_bright", 0);
    config.attribute("raw:ColorSpace", "sRGB-linear");
    config.attribute("raw:Exposure", 1.0f);
  }
  auto in = OIIO::ImageInput::open(path, &config);
  if (!in) throw CalibError(fmt::format("{}: cannot read image: {}", path, FirstLine(OIIO::geterror())));
  const OIIO::ImageSpec& spec = in->spec();
  if (exif_seconds) *exif_seconds = spec.get_float_attribute("ExposureTime", 0.0f);
  int depth = CV_32F;
  OIIO::TypeDesc type = OIIO::TypeDesc::FLOAT;
  if (spec.format == OIIO::TypeDesc::UINT8 && !IsRaw(path)) {
    depth = CV_8U;
    type = OIIO::TypeDesc::UINT8;
  } else if (spec.format != OIIO::TypeDesc::FLOAT && spec.format != OIIO::TypeDesc::HALF &&
             spec.format != OIIO::TypeDesc::DOUBLE) {
    depth = CV_16U;
    type = OIIO::TypeDesc::UINT16;
  }
  const int nch = spec.nchannels;
  if (spec.depth > 1)
    throw CalibError(fmt::format("{}: a volume ({}x{}x{} {}), not a photo", path, spec.width, spec.height,
                                 spec.depth, in->format_name()));
  if (nch < 1 || spec.width <= 0 || spec.height <= 0)
    throw CalibError(path + ": image has no pixels");
  // A header's size, not a camera's (a 100 MP photo is 1e8 pixels): far larger were damaged files.
  constexpr int64_t kMaxPhotoPixels = int64_t(1) << 28;
  if (int64_t(spec.width) * spec.height > kMaxPhotoPixels)
    throw CalibError(fmt::format("{}: a {}x{} image is larger than translume reads (at most {} pixels)",
                                 path, spec.width, spec.height, kMaxPhotoPixels));
  cv::Mat raw(spec.height, spec.width, CV_MAKETYPE(depth, std::min(nch, 4)));
  const bool ok = in->read_image(0, 0, 0, std::min(nch, 4), type, raw.data);
  if (!ok) throw CalibError(fmt::format("{}: cannot decode image: {}", path, FirstLine(in->geterror())));
  // OpenImageIO's JPEG reader reports libjpeg's warnings (a file cut short, corrupt data) only
  // as error text and fills the missing pixels with grey: such a photo would enter the merge.
  if (std::strcmp(in->format_name(), "jpeg") == 0)
    if (const std::string warning = in->geterror(); !warning.empty())
      throw CalibError(fmt::format("{}: damaged image (cut short or corrupt): {}", path, FirstLine(warning)));
  cv::Mat rgb;
  if (grey) *grey = raw.channels() <= 2;
  if (raw.channels() == 1) cv::cvtColor(raw, rgb, cv::COLOR_GRAY2RGB);
  else if (raw.channels() == 2) {
    std::vector<cv::Mat> ch;
    cv::split(raw, ch);
    cv::merge(std::vector<cv::Mat>{ch[0], ch[0], ch[0]}, rgb);
  } else if (raw.channels() == 4) cv::cvtColor(raw, rgb, cv::COLOR_RGBA2RGB);
  else rgb = raw;
  return rgb;
}

cv::Mat ReadLinearRgb(const std::string& path) {
  cv::Mat m = ReadRgbImage(path);
  if (m.depth() == CV_8U) m.convertTo(m, CV_32F, 1.0 / 255);
  else if (m.depth() == CV_16U) m.convertTo(m, CV_32F, 1.0 / 65535);
  return m;
}

namespace {

void WriteWithOiio(const std::string& path, const cv::Mat& image, OIIO::TypeDesc type) {
  const cv::Mat c = image.isContinuous() ? image : image.clone();
  auto out = OIIO::ImageOutput::create(path);
  if (!out) throw CalibError(fmt::format("{}: cannot write: {}", path, FirstLine(OIIO::geterror())));
  OIIO::ImageSpec spec(c.cols, c.rows, c.channels(), type);
  if (c.channels() == 3) spec.channelnames = {"R", "G", "B"};
  spec.attribute("png:compressionLevel", 1);  // photos: fast to write, barely larger
  if (!out->open(path, spec) || !out->write_image(type, c.data) || !out->close())
    throw CalibError(fmt::format("{}: cannot write: {}", path, FirstLine(out->geterror())));
}

}  // namespace

void WriteExr(const std::string& path, const cv::Mat& rgb) {
  CV_Assert(rgb.type() == CV_32FC3);
  WriteWithOiio(path, rgb, OIIO::TypeDesc::FLOAT);
}

void WriteImage8(const std::string& path, const cv::Mat& image) {
  CV_Assert(image.type() == CV_8UC1 || image.type() == CV_8UC3);
  WriteWithOiio(path, image, OIIO::TypeDesc::UINT8);
}

void WritePhoto(const std::string& path, const cv::Mat& image) {
  CV_Assert(image.depth() == CV_8U || image.depth() == CV_16U);
  WriteWithOiio(path, image, image.depth() == CV_8U ? OIIO::TypeDesc::UINT8 : OIIO::TypeDesc::UINT16);
}

void RequireOneSize(const std::vector<std::string>& names, const std::vector<cv::Size>& sizes,
                    const std::string& whose) {
  std::map<std::pair<int, int>, int> count;
  for (const cv::Size& s : sizes) ++count[{s.width, s.height}];
  const auto common = std::max_element(count.begin(), count.end(),
                                       [](const auto& a, const auto& b) { return a.second < b.second; });
  for (size_t i = 0; i < sizes.size(); ++i)
    if (std::pair(sizes[i].width, sizes[i].height) != common->first)
      throw CalibError(fmt::format("{}: image is {}x{} but {} of {} {} photos are {}x{}", names[i],
                                   sizes[i].width, sizes[i].height, common->second, whose, sizes.size(),
                                   common->first.first, common->first.second));
}

namespace {

// An exposures.json time: a number of seconds, or a string of one ("0.5") or of a shutter
// speed as cameras show it ("1/30"); 0 if it is neither.
double SecondsOf(const nlohmann::json& value) {
  if (value.is_number()) return value.get<double>();
  return value.is_string() ? SecondsFromText(value.get<std::string>()) : 0;
}

}  // namespace

ExposureStack ReadExposureStack(const std::string& dir) {
  if (!fs::is_directory(dir)) throw CalibError(dir + ": not a folder");
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.is_regular_file() && IsPhotoFile(e.path().string()))
      files.push_back(e.path());
  std::sort(files.begin(), files.end());
  if (files.size() < 2)
    throw CalibError(fmt::format("{}: an exposure stack needs at least 2 images, found {}", dir,
                                 files.size()));
  nlohmann::json times;
  const fs::path json_path = fs::path(dir) / "exposures.json";
  if (fs::exists(json_path)) {
    std::ifstream f(json_path);
    try {
      times = nlohmann::json::parse(f);
    } catch (const nlohmann::json::exception& e) {  // e.g. a number beyond a double (1e999)
      std::string why = e.what();  // as solver/json_file.cc words it: no "[json.exception.KIND.ID] "
      if (const size_t at = why.find("] "); why.rfind("[json.exception.", 0) == 0 && at != std::string::npos)
        why.erase(0, at + 2);
      throw CalibError(fmt::format("{}: not valid JSON: {}", json_path.string(), why));
    }
    if (!times.is_object())
      throw CalibError(json_path.string() + ": expected an object {\"file name\": seconds}");
  }
  ExposureStack s;
  s.dir = dir;
  // Decoded in parallel, then checked in order.
  std::vector<cv::Mat> pixels(files.size());
  std::vector<double> exifs(files.size(), 0.0);
  std::vector<char> grey(files.size(), 0);
  ParallelFor(int(files.size()), [&](int i) {
    bool g = false;
    pixels[size_t(i)] = ReadRgbImage(files[size_t(i)].string(), &exifs[size_t(i)], &g);
    grey[size_t(i)] = g;
  });
  {
    std::vector<std::string> names;
    std::vector<cv::Size> sizes;
    for (size_t i = 0; i < files.size(); ++i) {
      names.push_back(files[i].string());
      sizes.push_back(pixels[i].size());
    }
    RequireOneSize(names, sizes, "the stack's");
  }
  for (size_t i = 0; i < files.size(); ++i) {
    const fs::path& p = files[i];
    Exposure e;
    e.path = p.string();
    const double exif = exifs[i];
    e.pixels = std::move(pixels[i]);
    std::string name = p.filename().string();
    // An entry in exposures.json overrides EXIF (a camera that writes wrong times). Names match
    // in any case where none matches exactly (t00.png for T00.PNG).
    if (!times.contains(name))
      for (const auto& [key, value] : times.items())
        if (Lower(key) == Lower(name)) name = key;
    const bool listed = times.contains(name);
    if (listed) e.seconds = SecondsOf(times[name]);
    else if (exif > 0 && std::isfinite(exif)) e.seconds = exif;
    if (!(e.seconds > 0) || !std::isfinite(e.seconds)) {
      const std::string json = json_path.string();
      throw CalibError(fmt::format(
          "{}: no exposure time ({})", e.path,
          listed ? fmt::format("its entry \"{}\" in {} is not a positive number of seconds (or \"1/30\")", name, json)
          : exif != 0 ? fmt::format("its EXIF ExposureTime {} is unusable and {} has no entry \"{}\"", exif, json, name)
                      : fmt::format("no EXIF ExposureTime and no positive entry \"{}\" in {}", name, json)));
    }
    if (!s.exposures.empty()) {
      const Exposure& f = s.exposures[0];
      if (e.pixels.depth() != f.pixels.depth())
        throw CalibError(fmt::format("{}: bit depth differs from {}", e.path, f.path));
      if (grey[i] != grey[0])
        throw CalibError(fmt::format("{}: a {} photo in a stack whose first photo {} is {}", e.path,
                                     grey[i] ? "greyscale" : "colour", f.path, grey[0] ? "greyscale" : "colour"));
    }
    s.exposures.push_back(std::move(e));
  }
  // An entry that names no photo: a misspelt name whose photo then took its EXIF time silently,
  // or a photo moved away.
  for (const auto& [key, value] : times.items()) {
    bool found = false;
    for (const fs::path& p : files) found = found || Lower(p.filename().string()) == Lower(key);
    if (found) continue;
    const fs::path named = fs::path(dir) / key;
    throw CalibError(fmt::format("{}: the entry \"{}\" names no photo of the stack ({})", json_path.string(), key,
                                 fs::exists(named) ? "that file is not read as a photo: see its extension"
                                                   : fmt::format("the folder holds {} to {}", files.front().filename().string(),
                                                                 files.back().filename().string())));
  }
  return s;
}

std::string ResponseCurve::Validate() const {
  if (lut.rows != 256 || lut.cols != 1 || lut.type() != CV_32FC3)
    return "response must be 256x1 with 3 float channels";
  for (int z = 0; z < 256; ++z)
    for (int c = 0; c < 3; ++c) {
      const float v = lut.at<cv::Vec3f>(z)[c];
      if (!(v > 0) || !std::isfinite(v)) return fmt::format("response({}) is not positive", z);
      if (z > 0 && !(v > lut.at<cv::Vec3f>(z - 1)[c]))
        return fmt::format("response is not increasing at code {} (channel {})", z, c);
    }
  return "";
}

std::string ResponseOptions::Validate() const {
  if (samples_per_stack < 20) return "samples_per_stack (--samples) must be at least 20";
  if (!(smoothness > 0)) return "smoothness (--smoothness) must be positive";
  return "";
}

namespace {

// CalibrateResponse for one reading of the times (the stacks' seconds as they are).
ResponseCurve FitResponse(const std::vector<ExposureStack>& stacks, const ResponseOptions& o) {
  ResponseCurve curve;
  double residual2 = 0, weight2 = 0;
  curve.lut.create(256, 1, CV_32FC3);
  std::mt19937_64 rng(o.seed);
  std::string dirs;
  for (const ExposureStack& s : stacks) dirs += (dirs.empty() ? "" : ", ") + s.dir;
  for (int c = 0; c < 3; ++c) {
    // Sample positions, stratified by the code in the middle exposure so that the whole
    // curve is constrained.
    struct Sample {
      size_t stack;
      cv::Point p;
    };
    std::vector<Sample> samples;
    for (size_t si = 0; si < stacks.size(); ++si) {
      const ExposureStack& s = stacks[si];
      const cv::Mat& mid = s.exposures[s.exposures.size() / 2].pixels;
      constexpr int kBins = 32;
      std::vector<std::vector<cv::Point>> bins(kBins);
      for (int y = 0; y < mid.rows; y += 2)
        for (int x = 0; x < mid.cols; x += 2) bins[mid.at<cv::Vec3b>(y, x)[c] / 8].emplace_back(x, y);
      const size_t per_bin = size_t(o.samples_per_stack) / kBins + 1;
      for (auto& b : bins) {
        std::shuffle(b.begin(), b.end(), rng);
        for (size_t k = 0; k < std::min(per_bin, b.size()); ++k) samples.push_back({si, b[k]});
      }
    }
    // Unknowns: g(0..255), then ln E per sample. Rows: data, smoothness, g(128) = 0.
    using Triplet = Eigen::Triplet<double>;
    std::vector<Triplet> t;
    std::vector<double> rhs;
    int row = 0;
    double data_weight2 = 0;
    int used = 0;
    int lowest = 255, highest = 0;  // the codes that data rows cover
    for (size_t k = 0; k < samples.size(); ++k) {
      const ExposureStack& s = stacks[samples[k].stack];
      int valid = 0;
      for (const Exposure& e : s.exposures) {
        const int z = e.pixels.at<cv::Vec3b>(samples[k].p)[c];
        valid += (z > 2 && z < 253);
      }
      if (valid < 2) continue;
      const int col = 256 + used++;
      for (const Exposure& e : s.exposures) {
        const int z = e.pixels.at<cv::Vec3b>(samples[k].p)[c];
        if (z <= 2 || z >= 253) continue;
        lowest = std::min(lowest, z);
        highest = std::max(highest, z);
        const double w = HatWeight(z);
        t.emplace_back(row, z, w);
        t.emplace_back(row, col, -w);
        rhs.push_back(w * std::log(e.seconds));
        data_weight2 += w * w;
        ++row;
      }
    }
    const int data_rows = row;
    if (used < 10)
      throw CalibError("response: fewer than 10 pixels are well exposed in two or more photos; "
                       "use stacks with overlapping exposures");
    for (int z = 1; z < 255; ++z) {
      const double w = o.smoothness * HatWeight(z);
      t.emplace_back(row, z - 1, w);
      t.emplace_back(row, z, -2 * w);
      t.emplace_back(row, z + 1, w);
      rhs.push_back(0);
      ++row;
    }
    t.emplace_back(row, 128, 1e3);
    rhs.push_back(0);
    ++row;
    Eigen::SparseMatrix<double> A(row, 256 + used);
    A.setFromTriplets(t.begin(), t.end());
    const Eigen::Map<const Eigen::VectorXd> b(rhs.data(), Eigen::Index(rhs.size()));
    const Eigen::SparseMatrix<double> AtA = A.transpose() * A;
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(AtA);
    if (solver.info() != Eigen::Success) throw CalibError("response: the least-squares system is singular");
    const Eigen::VectorXd g = solver.solve(A.transpose() * b);
    const Eigen::VectorXd r = (A * g - b).head(data_rows);
    residual2 += r.squaredNorm();
    weight2 += data_weight2;
    // Where the data constrain the curve it must rise: photos that do not brighten with their
    // exposure times (one photo copied, times swapped or wrong) fit a curve that falls (by 20 %
    // and more in the copied-photo case). Noise may leave wiggles of a percent or so where few
    // samples fall: a fall of more than 5 % below the highest value so far is refused.
    double top = g[lowest];
    for (int z = lowest + 1; z <= highest; ++z) {
      if (g[z] < top - 0.05 || (z == highest && !(g[z] > g[lowest])))
        throw CalibError(fmt::format("response: the fitted curve falls at code {} ({} channel), within the "
                                     "codes the photos cover: the photos of {} do not brighten with their "
                                     "exposure times (check EXIF or exposures.json)", z, "RGB"[c], dirs));
      top = std::max(top, g[z]);
    }
    for (int z = 0; z < 256; ++z) curve.lut.at<cv::Vec3f>(z)[c] = float(std::exp(g[z]));
  }
  // Codes without data follow the smoothness prior; enforce monotonicity at the ends.
  for (int c = 0; c < 3; ++c)
    for (int z = 1; z < 256; ++z) {
      float& v = curve.lut.at<cv::Vec3f>(z)[c];
      v = std::max(v, std::nextafter(curve.lut.at<cv::Vec3f>(z - 1)[c], 1e30f));
    }
  curve.fit_rms = std::sqrt(residual2 / std::max(weight2, 1e-300));
  return curve;
}

}  // namespace

ResponseCurve CalibrateResponse(const std::vector<ExposureStack>& stacks,
                                const ResponseOptions& o) {
  if (std::string why = o.Validate(); !why.empty()) throw CalibError("response: " + why);
  if (stacks.empty()) throw CalibError("response: no exposure stacks");
  bool apex_labels = false;
  for (const ExposureStack& s : stacks) {
    if (s.exposures.size() < 2)
      throw CalibError(fmt::format("{}: an exposure stack needs at least 2 images", s.dir));
    if (!s.IsEightBit())
      throw CalibError(s.dir + ": the response curve is fitted to 8-bit stacks only; 16-bit and "
                       "RAW photos are linear and need none (in capture.json: \"response\": \"linear\")");
    for (const Exposure& e : s.exposures)
      if (e.pixels.type() != CV_8UC3 || e.pixels.size() != s.Size() || !(e.seconds > 0))
        throw CalibError(e.path + ": expected 8-bit RGB of the stack's size with a positive time");
    apex_labels = apex_labels || HasApexLabels(s);
  }
  auto fit = [&](ShutterTimes times) {
    std::vector<ExposureStack> read;
    for (const ExposureStack& s : stacks) read.push_back(WithShutterTimes(s, times));
    ResponseCurve curve = FitResponse(read, o);
    curve.shutter = times;
    return curve;
  };
  if (o.shutter != ShutterTimes::kAuto || !apex_labels)
    return fit(o.shutter == ShutterTimes::kAuto ? ShutterTimes::kLabelled : o.shutter);
  // Both readings; one that the photos contradict outright (the curve falls) loses.
  std::optional<ResponseCurve> labelled, apex;
  std::string labelled_error;
  try {
    labelled = fit(ShutterTimes::kLabelled);
  } catch (const CalibError& e) {
    labelled_error = e.what();
  }
  try {
    apex = fit(ShutterTimes::kApex);
  } catch (const CalibError&) {
  }
  if (!labelled && !apex) throw CalibError(labelled_error);
  if (!apex) return *labelled;
  if (!labelled) return *apex;
  // Within 2 % of each other the two readings fit alike (a short bracket whose labels are off
  // by one common factor): the labels stay.
  ResponseCurve& best = apex->fit_rms < 0.98 * labelled->fit_rms ? *apex : *labelled;
  best.other_fit_rms = (&best == &*apex ? labelled : apex)->fit_rms;
  return best;
}

std::string ResponseCurve::ShutterReport() const {
  const std::string how = Describe(shutter);
  if (!(other_fit_rms > 0)) return fmt::format("exposure times {}", how);
  return fmt::format("exposure times {}: fit residual {:.2f} %, {:.2f} % {}", how, 100 * fit_rms,
                     100 * other_fit_rms,
                     shutter == ShutterTimes::kApex ? "as labelled" : "read as APEX shutter speeds");
}

void WriteResponse(const std::string& path, const ResponseCurve& curve) {
  cv::FileStorage fs(path, cv::FileStorage::WRITE);
  if (!fs.isOpened()) throw CalibError(path + ": cannot open for writing");
  fs << "channels" << "RGB";
  fs << "response" << curve.lut;
  fs << "exposure_times" << ToString(curve.shutter);
}

ResponseCurve ReadResponse(const std::string& path) {
  if (!fs::exists(path)) throw CalibError(path + ": no such file");
  ResponseCurve c;
  try {
    cv::FileStorage f(path, cv::FileStorage::READ);
    if (!f.isOpened()) throw CalibError(path + ": cannot read");
    f["response"] >> c.lut;
    if (!f["exposure_times"].empty()) {
      std::string times;
      f["exposure_times"] >> times;
      if (times != "labelled" && times != "apex")
        throw CalibError(path + ": exposure_times must be \"labelled\" or \"apex\", not \"" + times + "\"");
      c.shutter = ParseShutterTimes(times, path);
    }
  } catch (const cv::Exception&) {
    throw CalibError(path + ": not an OpenCV YAML/XML file");
  }
  if (std::string why = c.Validate(); !why.empty()) throw CalibError(path + ": " + why);
  return c;
}

std::string SensorBlackProblem(const cv::Vec3d& sensor_black) {
  for (int c = 0; c < 3; ++c)
    if (!(sensor_black[c] >= 0 && sensor_black[c] < 0.5)) return "expected fractions of full scale in [0, 0.5)";
  return "";
}

std::string MergeOptions::Validate() const {
  if (low_code < 0 || high_code > 255 || high_code - low_code < 10)
    return "need 0 <= low_code (--low), high_code (--high) <= 255 and high_code - low_code >= 10";
  if (!(low_linear >= 0 && high_linear <= 1 && high_linear > low_linear))
    return "need 0 <= low_linear < high_linear <= 1";
  if (std::string why = SensorBlackProblem(sensor_black); !why.empty())
    return fmt::format("sensor_black {:g},{:g},{:g}: {}", sensor_black[0], sensor_black[1], sensor_black[2], why);
  return "";
}

std::string HdrImage::BriefReport() const {
  const size_t n = radiance.total() * 3;
  return fmt::format("{}x{} HDR; {} channel samples saturated in every exposure ({:.3f}%), {} "
                     "under-exposed in every exposure ({:.3f}%)",
                     radiance.cols, radiance.rows, saturated, 100.0 * saturated / std::max<size_t>(n, 1),
                     underexposed, 100.0 * underexposed / std::max<size_t>(n, 1));
}

// HdrImage::time_warning's threshold on a pair's brightness ratio against its time ratio.
constexpr double kTimeRatioWarning = 0.03;

namespace {

void CheckMergeInput(const ExposureStack& stack) {
  if (stack.exposures.size() < 2)
    throw CalibError(fmt::format("{}: an exposure stack needs at least 2 images", stack.dir));
  for (const Exposure& e : stack.exposures) {
    const Exposure& f = stack.exposures[0];
    if (e.pixels.size() != f.pixels.size() || e.pixels.type() != f.pixels.type())
      throw CalibError(fmt::format("{}: size or pixel type differs from {}", e.path, f.path));
    if (e.pixels.type() != CV_8UC3 && e.pixels.type() != CV_16UC3 && e.pixels.type() != CV_32FC3)
      throw CalibError(e.path + ": expected 3-channel 8-bit, 16-bit or float pixels");
    if (!(e.seconds > 0) || !std::isfinite(e.seconds))
      throw CalibError(e.path + ": exposure time must be positive");
  }
}

std::string FileName(const Exposure& e) { return fs::path(e.path).filename().string(); }

// A sensor black level is for linear files that keep it: not for camera RAW files.
void CheckSensorBlack(const ExposureStack& stack, const MergeOptions& o) {
  if (o.sensor_black == cv::Vec3d(0, 0, 0)) return;
  for (const Exposure& e : stack.exposures)
    if (IsRaw(e.path))
      throw CalibError(e.path + ": camera RAW files are decoded with their black level removed; a sensor black level "
                       "is for 16-bit or float files that keep it");
}

}  // namespace

std::string ShutterChoice::BriefReport() const {
  const std::string how = Describe(times);
  if (pairs == 0) return fmt::format("exposure times {}", how);
  if (!decisive)
    return fmt::format("exposure times {}: no well-exposed pair of photos tells the labels from APEX times ({} "
                       "pair{} judged; force a reading where you know it)", how, pairs, pairs == 1 ? "" : "s");
  std::string report = fmt::format("exposure times {}: brightness steps {:.2f} % RMS off the labels, {:.2f} % off "
                                   "the APEX times ({} pairs", how, 100 * labelled_rms, 100 * apex_rms, pairs);
  // A black level left in the photos lowers every step (an offset o makes (2x + o) / (x + o) < 2).
  if (std::abs(step_bias) > 0.01)
    report += fmt::format(", after their common {:+.1f} %: {}", 100 * (std::exp(step_bias) - 1),
                          step_bias < 0 ? "a black level left in the photos? Give it (sensor black) or a black stack"
                                        : "the photos brighten more than their times say");
  return report + ")";
}

void ShutterJudge::Add(const ExposureStack& stack, const ExposureStack* black) {
  if (std::string why = options_.Validate(); !why.empty()) throw CalibError("hdr merge: " + why);
  CheckMergeInput(stack);
  if (stack.IsEightBit())
    throw CalibError(stack.dir + ": the exposure times of 8-bit photos are judged by the response fit");
  CheckSensorBlack(stack, options_);
  if (!HasApexLabels(stack)) return;
  apex_labels_ = true;
  const ExposureStack apex = WithShutterTimes(stack, ShutterTimes::kApex);
  std::optional<ExposureStack> apex_black;
  if (black) apex_black = WithShutterTimes(*black, ShutterTimes::kApex);
  const std::vector<PairRatio> pairs =
      MeasurePairRatios(apex, Linearizer(apex, nullptr, options_), MatchBlacks(apex, apex_black ? &*apex_black : nullptr, stack),
                        options_.low_linear, options_.high_linear);
  for (const PairRatio& p : pairs) {
    const std::pair<double, double> key{stack.exposures[p.a].seconds, stack.exposures[p.b].seconds};
    const double labelled_ratio = key.second / key.first;
    const double apex_ratio = apex.exposures[p.b].seconds / apex.exposures[p.a].seconds;
    const bool telling = std::abs(apex_ratio / labelled_ratio - 1) > 0.005;
    if (telling && std::find(telling_.begin(), telling_.end(), key) == telling_.end()) telling_.push_back(key);
    if (p.samples < kMinPairSamplesForPercent) continue;
    if (telling && std::find(judged_.begin(), judged_.end(), key) == judged_.end()) judged_.push_back(key);
    steps_.push_back({key, std::log(p.measured / labelled_ratio), std::log(p.measured / apex_ratio)});
  }
}

bool ShutterJudge::Decisive() const { return !telling_.empty() && judged_.size() == telling_.size(); }

ShutterChoice ShutterJudge::Choice() const {
  ShutterChoice choice;
  if (!apex_labels_ || steps_.empty()) return choice;
  choice.decisive = !judged_.empty();
  choice.pairs = int(steps_.size());
  std::vector<std::pair<double, double>> keys;
  for (const Step& s : steps_)
    if (std::find(keys.begin(), keys.end(), s.key) == keys.end()) keys.push_back(s.key);
  double mean_labelled = 0, mean_apex = 0;
  if (keys.size() >= 3) {
    for (const Step& s : steps_) {
      mean_labelled += s.labelled / double(steps_.size());
      mean_apex += s.apex / double(steps_.size());
    }
  }
  double sum_labelled = 0, sum_apex = 0;
  for (const Step& s : steps_) {
    sum_labelled += (s.labelled - mean_labelled) * (s.labelled - mean_labelled);
    sum_apex += (s.apex - mean_apex) * (s.apex - mean_apex);
  }
  choice.labelled_rms = std::sqrt(sum_labelled / double(steps_.size()));
  choice.apex_rms = std::sqrt(sum_apex / double(steps_.size()));
  choice.step_bias = mean_labelled;
  if (choice.apex_rms < 0.8 * choice.labelled_rms) {
    choice.times = ShutterTimes::kApex;
    choice.step_bias = mean_apex;
  }
  return choice;
}

ShutterChoice ChooseShutterTimes(const ExposureStack& stack, const ExposureStack* black,
                                 const MergeOptions& options) {
  ShutterJudge judge(options);
  judge.Add(stack, black);
  return judge.Choice();
}

HdrImage MergeHdr(const ExposureStack& given_stack, const ResponseCurve* response,
                  const ExposureStack* given_black, const MergeOptions& o) {
  if (std::string why = o.Validate(); !why.empty()) throw CalibError("hdr merge: " + why);
  CheckMergeInput(given_stack);
  const bool eight = given_stack.IsEightBit();
  if (eight && !response)
    throw CalibError(given_stack.dir + ": 8-bit photos need a response curve (a file of translume calibrate "
                     "response: give it with --response)");
  if (eight) {
    if (std::string why = response->Validate(); !why.empty()) throw CalibError("response: " + why);
    if (o.sensor_black != cv::Vec3d(0, 0, 0))
      throw CalibError(given_stack.dir + ": a sensor black level applies to linear photos (16-bit, float); an 8-bit "
                       "camera's response curve holds its black level");
  }
  CheckSensorBlack(given_stack, o);
  ShutterTimes times = o.shutter;
  if (times == ShutterTimes::kAuto)
    times = eight ? response->shutter : ChooseShutterTimes(given_stack, given_black, o).times;
  const ExposureStack stack = WithShutterTimes(given_stack, times);
  std::optional<ExposureStack> black_read;
  if (given_black) black_read = WithShutterTimes(*given_black, times);
  const ExposureStack* black = black_read ? &*black_read : nullptr;
  const size_t P = stack.exposures.size();
  const std::vector<const Exposure*> blacks = MatchBlacks(stack, black, given_stack);
  const Linearizer lin(stack, response, o);
  auto code = [&](const cv::Mat& m, int y, int x, int c) { return lin.Code(m, y, x, c); };
  auto linear = [&](float v, int c) { return lin.Linear(v, c); };
  const std::vector<size_t> order = TimeOrder(stack);
  HdrImage h;
  h.shutter = times;
  const cv::Size size = stack.Size();
  h.radiance.create(size, CV_32FC3);
  h.flags.create(size, CV_8UC3);
  const double lo = eight ? o.low_code : o.low_linear, hi = eight ? o.high_code : o.high_linear;
  // Exposures next in time must brighten as their times say (swapped or wrong times, a copied
  // photo): the median ratio of their linear values within a factor of 2 of the ratio of their
  // times. Linear pairs too far apart for the window "well inside" (3.2 stops on 16-bit photos:
  // their times say so, or each photo sees the scene but they share too few samples) are judged
  // on 0.01 of the range in from either end instead (6.5 stops), with a warning for an error.
  // Pairs with fewer than 50 samples are not judged; where each photo sees the scene, the
  // warning says so. A warning about times that contradict replaces that note.
  // The window's ratio of linear values, its top over its bottom (the sensor black removed).
  double narrow_span = std::numeric_limits<double>::infinity();
  for (int c = 0; c < 3; ++c) {
    const auto [well_lo, well_hi] = WellInside(lin, c, lo, hi, 0.1);
    narrow_span = std::min(narrow_span, (well_hi - lin.black[c]) / (well_lo - lin.black[c]));
  }
  bool note_only = false;  // time_warning holds only a "not checked" note
  for (PairRatio p : MeasurePairRatios(stack, lin, blacks, lo, hi)) {
    const Exposure &ea = stack.exposures[p.a], &eb = stack.exposures[p.b];
    const double expected = eb.seconds / ea.seconds;
    const bool widen = p.samples < kMinPairSamples && !eight &&
                       (expected > narrow_span || (p.seen_a >= kMinPairSamples && p.seen_b >= kMinPairSamples));
    if (widen) p = MeasurePairRatio(stack, lin, blacks, order, p.k, lo, hi, 0.01);
    if (p.samples < kMinPairSamples) {
      if (p.seen_a >= kMinPairSamples && p.seen_b >= kMinPairSamples && h.time_warning.empty()) {
        note_only = true;
        h.time_warning = fmt::format(
            "{}: {} and {} share {} well-exposed samples of the ~10^4 compared (at least {} are needed): their times "
            "are not checked against their brightness (exposures closer in time would have them checked)", stack.dir, FileName(eb),
            FileName(ea), p.samples, kMinPairSamples);
      }
      continue;
    }
    const double off = p.measured / expected - 1;
    const bool may_warn = h.time_warning.empty() || note_only;
    const bool contradicts = p.measured > 2 * expected || p.measured < 0.5 * expected;
    if (widen) {
      // Its dark end also holds a black level left in the photos, which makes a short exposure
      // look as bright as the next: a warning here, not an error, and no 3 % judgement (the
      // window's edges bias it by read noise).
      if (contradicts && may_warn) {
        note_only = false;
        h.time_warning = fmt::format(
            "{}: {} ({:g} s) is {:.2f}x as bright as {} ({:g} s) over pixels dim in {}, but its exposure time is {:.2f}x "
            "as long: check the times (EXIF or exposures.json){}", stack.dir, FileName(eb), eb.seconds, p.measured,
            FileName(ea), ea.seconds, FileName(ea), expected,
            !given_black && o.sensor_black == cv::Vec3d(0, 0, 0)
                ? ", or give the black level left in the photos (sensor black, or a black stack)" : "");
      }
      continue;
    }
    if (std::abs(off) > kTimeRatioWarning && p.samples >= kMinPairSamplesForPercent && may_warn) {
      note_only = false;
      const std::string hint =
          times == ShutterTimes::kApex ? "read as APEX shutter speeds: are they true times? Then read them as labelled"
          : HasApexLabels(given_stack)
              ? "times as a camera labels them (1/30 for 1/32 s)? Use the true times, or read them as APEX shutter "
                "speeds"
              : "use the true times";
      // A black level left in the photos makes every step smaller ((2x + o) / (x + o) < 2).
      const std::string black_hint =
          off < 0 && !eight && !given_black && o.sensor_black == cv::Vec3d(0, 0, 0) ? "; or a black level left in the photos (give it as the sensor black, or a black stack)" : "";
      h.time_warning = fmt::format(
          "{}: {} is {:.3f}x as bright as {}, but its exposure time is {:.3f}x as long ({:+.1f} %): {}{} "
          "(docs/capture.md, \"Exposure times\")",
          stack.dir, FileName(eb), p.measured, FileName(ea), expected, 100 * off, hint, black_hint);
    }
    if (contradicts)
      throw CalibError(fmt::format("{}: {} ({:g} s) is {:.2f}x as bright as {} ({:g} s), but its exposure time is "
                                   "{:.2f}x as long: check the times (EXIF or exposures.json)", stack.dir,
                                   FileName(eb), eb.seconds, p.measured, FileName(ea), ea.seconds, expected));
  }
  std::atomic<size_t> saturated{0}, under{0};
  cv::parallel_for_(cv::Range(0, size.height), [&](const cv::Range& r) {
    size_t sat_local = 0, under_local = 0;
    for (int y = r.start; y < r.end; ++y)
      for (int x = 0; x < size.width; ++x)
        for (int c = 0; c < 3; ++c) {
          double num = 0, den = 0;
          for (size_t j = 0; j < P; ++j) {
            const Exposure& e = stack.exposures[j];
            const float v = code(e.pixels, y, x, c);
            const double low = lin.Low(lo, c);
            if (v <= low || v >= hi) continue;
            // Hat weight over the valid range, never quite 0 for a valid sample.
            const double u = (v - low) / (hi - low);
            const double w = std::max(1.0 - std::abs(2 * u - 1), 0.02);
            double xl = linear(v, c);
            if (blacks[j]) xl -= linear(code(blacks[j]->pixels, y, x, c), c);
            num += w * xl;
            den += w * e.seconds;
          }
          float value;
          uint8_t flag = kHdrOk;
          if (den > 0) {
            value = float(num / den);
          } else if (code(stack.exposures[order[0]].pixels, y, x, c) >= hi) {
            value = std::numeric_limits<float>::infinity();
            flag = kHdrSaturated;
            ++sat_local;
          } else {
            const size_t j = order[P - 1];
            double xl = linear(code(stack.exposures[j].pixels, y, x, c), c);
            if (blacks[j]) xl -= linear(code(blacks[j]->pixels, y, x, c), c);
            value = float(std::max(xl, 0.0) / stack.exposures[j].seconds);
            flag = kHdrUnderexposed;
            ++under_local;
          }
          h.radiance.at<cv::Vec3f>(y, x)[c] = value;
          h.flags.at<cv::Vec3b>(y, x)[c] = flag;
        }
    saturated += sat_local;
    under += under_local;
  });
  h.saturated = saturated;
  h.underexposed = under;
  return h;
}

cv::Mat NormalizedCameraFlat(const cv::Mat& hdr, const std::string& path) {
  CV_Assert(hdr.type() == CV_32FC3);
  auto fail = [&](const char* what, int x, int y) {
    throw CalibError(fmt::format("{}: {} at pixel ({}, {}): a camera flat must fill the view evenly, unsaturated",
                                 path, what, x, y));
  };
  for (int y = 0; y < hdr.rows; ++y)
    for (int x = 0; x < hdr.cols; ++x)
      for (int k = 0; k < 3; ++k)
        if (!std::isfinite(hdr.at<cv::Vec3f>(y, x)[k])) fail("saturated", x, y);
  const cv::Scalar mean = cv::mean(hdr);
  cv::Mat flat;
  cv::multiply(hdr, cv::Scalar(1 / std::max(mean[0], 1e-30), 1 / std::max(mean[1], 1e-30), 1 / std::max(mean[2], 1e-30)),
               flat);
  for (int y = 0; y < flat.rows; ++y)
    for (int x = 0; x < flat.cols; ++x)
      for (int k = 0; k < 3; ++k)
        if (!(flat.at<cv::Vec3f>(y, x)[k] > 0.1f)) fail("dark", x, y);
  return flat;
}

cv::Mat ReadHdrOrStack(const std::string& path, const ResponseCurve* response, const MergeOptions& options,
                       HdrReadInfo* info) {
  if (!fs::is_directory(path)) {
    if (options.sensor_black != cv::Vec3d(0, 0, 0))
      throw CalibError(path + ": an HDR image is merged already; give the sensor black level where it is merged "
                       "(translume hdr --sensor-black), or give the stack folder");
    return ReadLinearRgb(path);
  }
  HdrImage h = MergeHdr(ReadExposureStack(path), response, nullptr, options);
  if (info) {
    info->shutter = h.shutter;
    info->time_warning = h.time_warning;
  }
  return h.radiance;
}

}  // namespace translume::calib
