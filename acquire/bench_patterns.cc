// SPDX-License-Identifier: MIT
#include "acquire/bench_patterns.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>
#include <unistd.h>

#include "acquire/acquire.h"
#include "acquire/capture.h"
#include "acquire/face_mapping.h"
#include "acquire/patterns.h"
#include "acquire/simulate_capture.h"
#include "calib/hdr.h"
#include "solver/status.h"
#include "solver/synthetic.h"

namespace translume::acquire {
namespace {

namespace fs = std::filesystem;

double Since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

struct Agreement {
  double iou_min = 1, iou_median = 1, edge_px = 0;
};

// Each region's intersection over union with the truth; the edge shift is the pixels lit in one
// of the two patterns only over the length of the true regions' outlines.
Agreement Compare(const std::vector<cv::Mat>& ours, const std::vector<cv::Mat>& truth) {
  std::vector<double> iou;
  double differing = 0, outline = 0;
  for (size_t m = 0; m < truth.size(); ++m) {
    const double both = cv::countNonZero(ours[m] & truth[m]), either = cv::countNonZero(ours[m] | truth[m]);
    iou.push_back(either > 0 ? both / either : 0);
    differing += cv::countNonZero(ours[m] ^ truth[m]);
    std::vector<std::vector<cv::Point>> contours;
    cv::findContours(truth[m].clone(), contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_NONE);
    for (const auto& c : contours) outline += cv::arcLength(c, true);
  }
  Agreement a;
  std::sort(iou.begin(), iou.end());
  a.iou_min = iou.front();
  a.iou_median = iou[iou.size() / 2];
  a.edge_px = outline > 0 ? differing / outline : 0;
  return a;
}

PatternsBenchRow RunCase(Setup setup, int seed, int lights, const std::string& rig_file, const fs::path& dir,
                         const std::function<void(const std::string&)>& progress) {
  PatternsBenchRow row;
  row.setup = setup;
  row.seed = seed;
  row.regions = lights * lights;
  SynthOptions so;
  so.preset = "marble";
  so.shape = {24, 18, setup == Setup::kBack ? 6 : 10};
  const Material m = SynthesizeMaterial(so);
  const CaptureRig rig = rig_file == "default" ? DefaultCaptureRig(m.shape, m.spacing_mm, setup)
                                               : ReadCaptureRig(rig_file, m.shape, m.spacing_mm, setup);
  SimulateCaptureOptions sco;
  sco.setup = setup;
  // The fewest conditions a capture takes: front-lit, one region lighting the whole face would
  // mask every node (lit nodes and their margin are not measured).
  sco.lights = setup == Setup::kBack ? 1 : 2;
  sco.holdout = 0;
  sco.exposures = 6;
  sco.seed = uint64_t(seed);
  const fs::path capture = dir / "capture";
  auto start = std::chrono::steady_clock::now();
  SimulateCapture(m, rig, sco, capture.string());
  row.capture_seconds = Since(start);
  if (progress) progress(fmt::format("{} seed {}: capture simulated, calibrating", SetupName(setup), seed));
  AcquireOptions ao;
  ao.solve = false;
  const CaptureSpec spec = ReadCapture(capture.string());
  start = std::chrono::steady_clock::now();
  const AcquireReport report = Acquire(spec, (dir / "out" / "m.vdb").string(), ao);
  row.calibration_seconds = Since(start);
  row.camera_rms_px = report.camera_rms_px;
  row.projector_rms_px = report.projector_rms_px;

  PatternJob job;
  job.camera = calib::ReadCameraCalibration(report.work_dir + "/camera.yml");
  job.projector_file = report.work_dir + "/projector.yml";
  job.projector = calib::ReadProjectorCalibration(job.projector_file);
  job.size_mm = spec.size_mm;
  job.setup = setup;
  job.lights = lights;
  for (const auto& p : spec.face_corners_px) job.corners.emplace_back(p[0], p[1]);
  const std::vector<cv::Point2d> true_corners = job.corners;
  const std::vector<cv::Mat> truth = RegionPatterns(rig.projector, rig.projector_from_camera, rig.camera_from_sample,
                                                    SampleSize(m.shape, m.spacing_mm), setup, lights);
  start = std::chrono::steady_clock::now();
  const PatternSet from_corners = MakeRegionPatterns(job);
  row.pattern_seconds = Since(start);
  row.pose_rms_px = from_corners.pose_rms_px;
  const Agreement a = Compare(from_corners.images, truth);
  row.iou_min = a.iou_min;
  row.iou_median = a.iou_median;
  row.edge_px = a.edge_px;

  const calib::ResponseCurve response = calib::ReadResponse(report.work_dir + "/response.yml");
  job.corners.clear();
  job.photo = calib::ReadHdrOrStack((capture / "calib" / "sample_lit").string(), &response);
  const auto farthest = [&](const std::vector<cv::Point2d>& corners) {
    double d = 0;
    for (size_t k = 0; k < true_corners.size(); ++k) d = std::max(d, cv::norm(corners[k] - true_corners[k]));
    return d;
  };
  const PatternSet from_photo = MakeRegionPatterns(job);
  row.photo_corner_px = farthest(from_photo.corners);
  row.photo_found_corner_px = farthest(from_photo.unrefined_corners);
  const Agreement b = Compare(from_photo.images, truth);
  row.photo_iou_min = b.iou_min;
  row.photo_iou_median = b.iou_median;
  row.photo_edge_px = b.edge_px;

  // Corners clicked by hand: each kNearOffsetPx off in a direction of its own, per seed.
  for (size_t k = 0; k < true_corners.size(); ++k) {
    const double angle = 1.3 * seed + 2.1 * double(k);
    job.corners.push_back(true_corners[k] + kNearOffsetPx * cv::Point2d(std::cos(angle), std::sin(angle)));
  }
  const PatternSet from_near = MakeRegionPatterns(job);
  row.near_corner_px = farthest(from_near.corners);
  const Agreement c = Compare(from_near.images, truth);
  row.near_iou_min = c.iou_min;
  row.near_iou_median = c.iou_median;
  row.near_edge_px = c.edge_px;
  return row;
}

}  // namespace

std::string PatternsBenchOptions::Validate() const {
  if (setups.empty()) return "--setups needs a setup";
  if (seeds < 1 || seeds > 100) return "--seeds must be within 1..100";
  if (lights < 1 || lights > 16) return "--lights must be within 1..16";
  return "";
}

std::vector<PatternsBenchRow> RunPatternsBench(const PatternsBenchOptions& o,
                                               const std::function<void(const std::string&)>& progress) {
  if (std::string why = o.Validate(); !why.empty()) throw InputError("bench patterns: " + why);
  const fs::path root = fs::temp_directory_path() / fmt::format("translume_bench_patterns_{}", getpid());
  std::vector<PatternsBenchRow> rows;
  try {
    for (Setup setup : o.setups)
      for (int seed = 1; seed <= o.seeds; ++seed) {
        const fs::path dir = root / fmt::format("{}_{}", SetupName(setup), seed);
        fs::remove_all(dir);
        rows.push_back(RunCase(setup, seed, o.lights, o.rig_file, dir, progress));
        fs::remove_all(dir);
        const PatternsBenchRow& r = rows.back();
        if (progress)
          progress(fmt::format("{} seed {}: intersection over union {:.4f} from the corners, {:.4f} from the photo, "
                               "{:.4f} from near corners", SetupName(setup), seed, r.iou_min, r.photo_iou_min,
                               r.near_iou_min));
      }
  } catch (...) {
    std::error_code ec;
    fs::remove_all(root, ec);
    throw;
  }
  fs::remove_all(root);
  return rows;
}

std::string PatternsBenchTable(const std::vector<PatternsBenchRow>& rows) {
  std::string s = fmt::format("{:>6} {:>4} {:>7} {:>7} {:>7}  {:>7} {:>7} {:>7}  {:>6} {:>6} {:>7} {:>7} {:>7}  "
                              "{:>6} {:>7} {:>7}  {:>7} {:>7}\n",
                              "setup", "seed", "regions", "cam px", "proj px", "IoU min", "IoU med", "edge px",
                              "found", "corner", "IoU min", "IoU med", "edge px", "corner", "IoU min", "edge px",
                              "calib s", "ours ms");
  for (const PatternsBenchRow& r : rows)
    s += fmt::format("{:>6} {:>4} {:>7} {:>7.3f} {:>7.3f}  {:>7.4f} {:>7.4f} {:>7.3f}  {:>6.3f} {:>6.3f} {:>7.4f} "
                     "{:>7.4f} {:>7.3f}  {:>6.3f} {:>7.4f} {:>7.3f}  {:>7.1f} {:>7.1f}\n",
                     SetupName(r.setup), r.seed, r.regions, r.camera_rms_px, r.projector_rms_px, r.iou_min,
                     r.iou_median, r.edge_px, r.photo_found_corner_px, r.photo_corner_px, r.photo_iou_min,
                     r.photo_iou_median, r.photo_edge_px, r.near_corner_px, r.near_iou_min, r.near_edge_px,
                     r.calibration_seconds, 1e3 * r.pattern_seconds);
  s += fmt::format(
      "(each region's pattern against the true rig's: the worst and median intersection over union, and the\n"
      " edge shift in projector pixels (pixels lit in one only / the true outlines' length); first from the\n"
      " true face corners; then from the corners found in the photo of the sample lit (found: their largest\n"
      " distance from the true ones, camera px; corner: the same once refined in the photo); then from corners\n"
      " given {} px off the true ones and refined in the photo; cam px / proj px: the calibrations' RMS;\n"
      " calib s: acquire's calibration; ours ms: translume patterns' computation from the corners)", kNearOffsetPx);
  return s;
}

std::string PatternsBenchJson(const std::vector<PatternsBenchRow>& rows) {
  nlohmann::json j = nlohmann::json::array();
  for (const PatternsBenchRow& r : rows)
    j.push_back({{"setup", SetupName(r.setup)}, {"seed", r.seed}, {"regions", r.regions},
                 {"camera_rms_px", r.camera_rms_px}, {"projector_rms_px", r.projector_rms_px},
                 {"iou_min", r.iou_min}, {"iou_median", r.iou_median}, {"edge_px", r.edge_px},
                 {"photo_corner_px", r.photo_corner_px}, {"photo_found_corner_px", r.photo_found_corner_px},
                 {"near_corner_px", r.near_corner_px}, {"near_iou_min", r.near_iou_min},
                 {"near_iou_median", r.near_iou_median}, {"near_edge_px", r.near_edge_px},
                 {"photo_iou_min", r.photo_iou_min},
                 {"photo_iou_median", r.photo_iou_median}, {"photo_edge_px", r.photo_edge_px},
                 {"pose_rms_px", r.pose_rms_px}, {"capture_seconds", r.capture_seconds},
                 {"calibration_seconds", r.calibration_seconds}, {"pattern_seconds", r.pattern_seconds}});
  return j.dump(2);
}

}  // namespace translume::acquire
