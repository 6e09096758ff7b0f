// SPDX-License-Identifier: MIT
#include "calib/bench_exposure_times.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fmt/format.h>
#include <fmt/ranges.h>
#include <nlohmann/json.hpp>
#include <sstream>

#include "calib/error.h"
#include "calib/hdr.h"
#include "calib/synthetic_rig.h"

namespace translume::calib {
namespace {

struct NamedBracket {
  const char* name;
  std::vector<double> labels;
};

const std::vector<NamedBracket>& Brackets() {
  static const std::vector<NamedBracket> brackets = {
      {"full", {1 / 15., 1 / 8., 1 / 4., 1 / 2., 1, 2, 4, 8, 15}},
      {"fast", {1 / 1000., 1 / 500., 1 / 250., 1 / 125., 1 / 60., 1 / 30., 1 / 15., 1 / 8., 1 / 4.}},
      {"thirds", {1 / 100., 1 / 60., 1 / 40., 1 / 25., 1 / 15., 1 / 10., 1 / 6., 1 / 4., 0.4}},
      {"halves", {1 / 1500., 1 / 750., 1 / 350., 1 / 180., 1 / 90., 1 / 45.}},
  };
  return brackets;
}

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + long(v.size() / 2), v.end());
  return v[v.size() / 2];
}

double Quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[size_t(q * double(v.size() - 1))];
}

// Relative errors of a merge against the truth after one scale per channel (the median ratio),
// over pixels valid in all three channels.
std::vector<double> RelativeErrors(const cv::Mat& truth, const HdrImage& h) {
  std::vector<double> ratio[3];
  for (int y = 0; y < truth.rows; ++y)
    for (int x = 0; x < truth.cols; ++x) {
      if (h.flags.at<cv::Vec3b>(y, x) != cv::Vec3b(kHdrOk, kHdrOk, kHdrOk)) continue;
      for (int c = 0; c < 3; ++c)
        ratio[c].push_back(double(h.radiance.at<cv::Vec3f>(y, x)[c]) / truth.at<cv::Vec3f>(y, x)[c]);
    }
  std::vector<double> err;
  for (int c = 0; c < 3; ++c) {
    const double scale = Median(ratio[c]);
    for (double r : ratio[c]) err.push_back(std::abs(r / scale - 1));
  }
  return err;
}

ExposureStack StackOf(const std::vector<cv::Mat>& photos, const std::vector<double>& labels) {
  ExposureStack s;
  s.dir = "bench";
  for (size_t j = 0; j < photos.size(); ++j) s.exposures.push_back({fmt::format("e{}.png", j), photos[j], labels[j]});
  return s;
}

// `stack` with the times the camera exposed, read as given.
ExposureStack WithSeconds(ExposureStack stack, const std::vector<double>& seconds) {
  for (size_t j = 0; j < seconds.size(); ++j) stack.exposures[j].seconds = seconds[j];
  return stack;
}

template <typename F>
double Seconds(F&& f) {
  const auto start = std::chrono::steady_clock::now();
  f();
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

struct CaseResult {
  bool right = false, decisive = false, right_black = false;
  double error_auto = 0, error_labelled = 0, error_apex = 0, error_true = 0, p95_auto = 0, error_black = -1;
  double seconds_auto = 0, seconds_forced = 0;
};

// One scene: the brightest value fills 80 % of full scale in the shortest photo, the darkest 2 %
// in the longest.
CaseResult RunCase(int bits, const std::vector<double>& labels, bool apex_camera, double offset, cv::Size size,
                   uint64_t seed) {
  std::vector<double> exposed = labels;
  if (apex_camera)
    for (double& t : exposed) t = ApexSeconds(t);
  const auto [shortest, longest] = std::minmax_element(exposed.begin(), exposed.end());
  const double decades = std::log10(*longest / *shortest * 0.8 / 0.02);
  const cv::Mat truth = SyntheticHdrScene(size, decades, seed) * (0.8 / *shortest);
  StackOptions so;
  so.bits = bits;
  so.seed = seed * 2;
  so.offset = bits == 8 ? 0 : offset;
  const SyntheticResponse response;
  const ExposureStack stack = StackOf(SyntheticRig::RenderExposureStack(truth, exposed, response, so), labels);
  const ShutterTimes camera = apex_camera ? ShutterTimes::kApex : ShutterTimes::kLabelled;
  CaseResult r;
  auto merge = [&](ShutterTimes times, const ResponseCurve* curve) {
    MergeOptions mo;
    mo.shutter = times;
    return MergeHdr(stack, curve, nullptr, mo);
  };
  auto error = [&](const HdrImage& h) { return Median(RelativeErrors(truth, h)); };
  // The merge with the times the camera exposed (8-bit: through a curve fitted to such times).
  auto true_error = [&](const ResponseCurve* curve) {
    MergeOptions mo;
    mo.shutter = ShutterTimes::kLabelled;
    return error(MergeHdr(WithSeconds(stack, exposed), curve, nullptr, mo));
  };
  if (bits == 8) {
    so.seed = seed * 2 + 1;
    const ExposureStack calibration =
        StackOf(SyntheticRig::RenderExposureStack(SyntheticHdrScene(size, decades, seed + 1000) * (0.8 / *shortest),
                                                  exposed, response, so), labels);
    ResponseCurve curve, labelled;
    r.seconds_auto = Seconds([&] { curve = CalibrateResponse({calibration}); });
    ResponseOptions ro;
    ro.shutter = ShutterTimes::kLabelled;
    r.seconds_forced = Seconds([&] { labelled = CalibrateResponse({calibration}, ro); });
    ro.shutter = ShutterTimes::kApex;
    const ResponseCurve apex = CalibrateResponse({calibration}, ro);
    ro.shutter = ShutterTimes::kLabelled;
    const ResponseCurve true_curve = CalibrateResponse({WithSeconds(calibration, exposed)}, ro);
    r.right = curve.shutter == camera;
    r.decisive = curve.other_fit_rms > 0 &&
                 std::min(curve.fit_rms, curve.other_fit_rms) < 0.98 * std::max(curve.fit_rms, curve.other_fit_rms);
    const HdrImage h = merge(ShutterTimes::kAuto, &curve);
    const std::vector<double> e = RelativeErrors(truth, h);
    r.error_auto = Median(e);
    r.p95_auto = Quantile(e, 0.95);
    r.error_labelled = error(merge(ShutterTimes::kLabelled, &labelled));
    r.error_apex = error(merge(ShutterTimes::kApex, &apex));
    r.error_true = true_error(&true_curve);
    return r;
  }
  so.seed = seed * 2 + 1;
  const ExposureStack black = StackOf(
      SyntheticRig::RenderExposureStack(cv::Mat::zeros(truth.size(), CV_32FC3), exposed, response, so), labels);
  r.right_black = ChooseShutterTimes(stack, &black).times == camera;
  r.error_black = Median(RelativeErrors(truth, MergeHdr(stack, nullptr, &black)));
  const ShutterChoice choice = ChooseShutterTimes(stack);
  r.right = choice.times == camera;
  r.decisive = choice.decisive;
  HdrImage h;
  r.seconds_auto = Seconds([&] { h = merge(ShutterTimes::kAuto, nullptr); });
  HdrImage labelled;
  r.seconds_forced = Seconds([&] { labelled = merge(ShutterTimes::kLabelled, nullptr); });
  const std::vector<double> e = RelativeErrors(truth, h);
  r.error_auto = Median(e);
  r.p95_auto = Quantile(e, 0.95);
  r.error_labelled = error(labelled);
  r.error_apex = error(merge(ShutterTimes::kApex, nullptr));
  r.error_true = true_error(nullptr);
  return r;
}

}  // namespace

std::vector<std::string> ExposureTimesBracketNames() {
  std::vector<std::string> names;
  for (const NamedBracket& b : Brackets()) names.push_back(b.name);
  return names;
}

std::vector<double> ExposureTimesBracket(const std::string& name) {
  for (const NamedBracket& b : Brackets())
    if (name == b.name) return b.labels;
  if (name.find(':') == std::string::npos)
    throw CalibError(fmt::format("bracket '{}': not one of {} nor times joined by ':' (1/60:1/30:1/15)", name,
                                 fmt::join(ExposureTimesBracketNames(), ", ")));
  std::vector<double> labels;
  std::stringstream in(name);
  for (std::string part; std::getline(in, part, ':');) {
    const double t = SecondsFromText(part);
    if (!(t > 0)) throw CalibError(fmt::format("bracket '{}': '{}' is no exposure time (seconds or 1/N)", name, part));
    labels.push_back(t);
  }
  std::vector<double> sorted = labels;
  std::sort(sorted.begin(), sorted.end());
  if (labels.size() < 2 || std::adjacent_find(sorted.begin(), sorted.end()) != sorted.end())
    throw CalibError(fmt::format("bracket '{}': needs two or more different times", name));
  return labels;
}

std::string ExposureTimesBenchOptions::Validate() const {
  if (bits.empty() || brackets.empty() || cameras.empty() || offsets.empty())
    return "--bits, --brackets, --cameras and --offsets need one value or more";
  for (int b : bits)
    if (b != 8 && b != 16) return fmt::format("--bits: {} is neither 8 nor 16", b);
  for (const std::string& c : cameras)
    if (c != "apex" && c != "exact") return fmt::format("--cameras: '{}' is neither apex nor exact", c);
  for (double o : offsets)
    if (!(o >= 0 && o < 0.5)) return fmt::format("--offsets: {} is not within [0, 0.5)", o);
  for (const std::string& b : brackets) {
    try {
      ExposureTimesBracket(b);
    } catch (const CalibError& e) {
      return std::string("--brackets: ") + e.what();
    }
  }
  if (seeds < 1) return "--seeds must be >= 1";
  if (size.width < 64 || size.height < 64) return "--size must be at least 64x64";
  return "";
}

std::vector<ExposureTimesBenchRow> RunExposureTimesBench(const ExposureTimesBenchOptions& o,
                                                         const std::function<void(const std::string&)>& progress) {
  if (std::string why = o.Validate(); !why.empty()) throw CalibError("bench exposure-times: " + why);
  std::vector<std::vector<double>> labels;
  for (const std::string& b : o.brackets) labels.push_back(ExposureTimesBracket(b));
  std::vector<ExposureTimesBenchRow> rows;
  for (int bits : o.bits)
    for (size_t b = 0; b < o.brackets.size(); ++b)
      for (const std::string& camera : o.cameras)
        for (double offset : o.offsets) {
          if (bits == 8 && offset != o.offsets.front()) continue;  // 8-bit: no offset rows
          ExposureTimesBenchRow row;
          row.bits = bits;
          row.bracket = o.brackets[b];
          row.camera = camera;
          row.offset = bits == 8 ? 0 : offset;
          std::vector<double> ea, el, ex, et, p95, sa, sf, eb;
          for (int s = 0; s < o.seeds; ++s) {
            const CaseResult r = RunCase(bits, labels[b], camera == "apex", row.offset, o.size, uint64_t(11 + s));
            ++row.cases;
            row.right += r.right;
            row.decisive += r.decisive;
            row.right_black += r.right_black;
            eb.push_back(r.error_black);
            ea.push_back(r.error_auto);
            el.push_back(r.error_labelled);
            ex.push_back(r.error_apex);
            et.push_back(r.error_true);
            p95.push_back(r.p95_auto);
            sa.push_back(r.seconds_auto);
            sf.push_back(r.seconds_forced);
          }
          row.error_auto = Median(ea);
          row.error_labelled = Median(el);
          row.error_apex = Median(ex);
          row.error_true = Median(et);
          row.p95_auto = Median(p95);
          row.seconds_auto = Median(sa);
          row.seconds_forced = Median(sf);
          row.error_black = bits == 8 ? -1 : Median(eb);
          if (progress)
            progress(fmt::format("{}-bit {} {} camera, offset {:g}: auto right {} of {}", bits, row.bracket, camera,
                                 row.offset, row.right, row.cases));
          rows.push_back(row);
        }
  return rows;
}

std::string ExposureTimesBenchTable(const std::vector<ExposureTimesBenchRow>& rows) {
  std::string s = fmt::format("{:>4} {:>8} {:>6} {:>6} {:>7} {:>8}  {:>8} {:>8} {:>8} {:>8} {:>8}  {:>7} {:>8}  {:>9} "
                              "{:>9} {:>6}\n",
                              "bits", "bracket", "camera", "offset", "right", "decisive", "auto %", "label %",
                              "apex %", "true %", "p95 %", "+black", "black %", "auto s", "forced s", "ratio");
  for (const ExposureTimesBenchRow& r : rows)
    s += fmt::format("{:>4} {:>8} {:>6} {:>6g} {:>7} {:>8}  {:>8.3f} {:>8.3f} {:>8.3f} {:>8.3f} {:>8.3f}  {:>7} {:>8}  "
                     "{:>9.4f} {:>9.4f} {:>6.2f}\n",
                     r.bits, r.bracket, r.camera, r.offset, fmt::format("{}/{}", r.right, r.cases),
                     fmt::format("{}/{}", r.decisive, r.cases), 100 * r.error_auto, 100 * r.error_labelled,
                     100 * r.error_apex, 100 * r.error_true, 100 * r.p95_auto,
                     r.bits == 8 ? std::string("-") : fmt::format("{}/{}", r.right_black, r.cases),
                     r.bits == 8 ? std::string("-") : fmt::format("{:.3f}", 100 * r.error_black), r.seconds_auto,
                     r.seconds_forced, r.seconds_forced > 0 ? r.seconds_auto / r.seconds_forced : 0.0);
  s += "(right: auto read the times as the camera exposed them; errors: median relative error of the merged\n"
       " radiance after one scale per channel, valid pixels, read as auto chose / as labelled / as APEX / with\n"
       " the true times; +black / black %: linear rows, auto right and its error with a black stack given,\n"
       " subtracted exposure by exposure; auto s / forced s: the response fit (8-bit) or the merge (linear)\n"
       " under auto and forced as labelled, medians, timed alternately in this run)";
  return s;
}

std::string ExposureTimesBenchJson(const std::vector<ExposureTimesBenchRow>& rows) {
  nlohmann::json j = nlohmann::json::array();
  for (const ExposureTimesBenchRow& r : rows)
    j.push_back({{"bits", r.bits}, {"bracket", r.bracket}, {"camera", r.camera}, {"offset", r.offset},
                 {"cases", r.cases}, {"right", r.right}, {"decisive", r.decisive},
                 {"error_auto", r.error_auto}, {"error_labelled", r.error_labelled}, {"error_apex", r.error_apex},
                 {"error_true", r.error_true}, {"p95_auto", r.p95_auto}, {"error_black", r.error_black},
                 {"right_black", r.right_black}, {"seconds_auto", r.seconds_auto},
                 {"seconds_forced", r.seconds_forced}});
  return j.dump(2);
}

}  // namespace translume::calib
