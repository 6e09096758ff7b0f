// SPDX-License-Identifier: MIT
#include "acquire/acquire.h"

#include <fmt/format.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string_view>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "acquire/face_mapping.h"
#include "calib/board.h"
#include "calib/camera_calib.h"
#include "calib/error.h"
#include "calib/hdr.h"
#include "calib/photo_io.h"
#include "calib/projector_calib.h"
#include "calib/white.h"
#include "solver/atomic_file.h"
#include "solver/dataset.h"
#include "solver/evaluate.h"
#include "solver/image_io.h"
#include "solver/light.h"
#include "solver/material_io.h"
#include "solver/simulate.h"
#include "solver/status.h"

namespace translume::acquire {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

// A stage's input signature: every file under the given paths with its size and time. Paths
// count in their canonical form, so that the same capture named relatively or absolutely (or
// through a link) is the same input.
std::string Signature(const std::vector<std::string>& paths, const std::string& extra = "") {
  std::string s = extra;
  auto add = [&](const fs::path& p) {
    std::error_code ec;
    const auto t = fs::last_write_time(p, ec).time_since_epoch().count();
    fs::path canonical = fs::weakly_canonical(p, ec);
    if (ec) canonical = p;
    s += fmt::format("{}:{}:{};", canonical.string(), fs::is_regular_file(p) ? fs::file_size(p) : 0, t);
  };
  for (const std::string& p : paths) {
    if (p.empty()) continue;
    if (fs::is_directory(p)) {
      std::vector<fs::path> files;
      for (const auto& e : fs::recursive_directory_iterator(p))
        if (e.is_regular_file()) files.push_back(e.path());
      std::sort(files.begin(), files.end());
      for (const auto& f : files) add(f);
    } else {
      add(p);
    }
  }
  return fmt::format("{:016x}", std::hash<std::string>{}(s));
}

// The work folder's record of finished stages: {"stage": signature}.
class StageLog {
 public:
  StageLog(std::string path, bool force) : path_(std::move(path)), force_(force) {
    std::ifstream in(path_);
    if (in) {
      try {
        log_ = nlohmann::json::parse(in);
      } catch (const std::exception&) {
        log_ = nlohmann::json::object();
      }
    }
    if (!log_.is_object()) log_ = nlohmann::json::object();
  }
  bool Done(const std::string& stage, const std::string& sig, const std::vector<std::string>& outputs) const {
    if (force_ || !log_.contains(stage) || log_[stage] != sig) return false;
    for (const auto& o : outputs)
      if (!fs::exists(o)) return false;
    return true;
  }
  void Record(const std::string& stage, const std::string& sig) {
    log_[stage] = sig;
    WriteAtomically(path_, [&](const std::string& tmp) { std::ofstream(tmp) << log_.dump(2) << "\n"; });
  }

 private:
  std::string path_;
  bool force_;
  nlohmann::json log_;
};

// "(x0, y0) (x1, y1) ..." (px, two decimals), for the log's lines about corners.
std::string CornerList(const std::vector<cv::Point2d>& corners) {
  std::string list;
  for (const cv::Point2d& c : corners) list += fmt::format("{}({:.2f}, {:.2f})", list.empty() ? "" : " ", c.x, c.y);
  return list;
}

// Text for an HTML page: & < > " escaped.
std::string Html(const std::string& text) {
  std::string out;
  for (char ch : text) {
    switch (ch) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      default: out += ch;
    }
  }
  return out;
}

// previews/index.html: one page with the run's summary, every condition's fit preview beside its
// numbers, and the material's slices (kappa and mu by depth); links relative to the folder, so
// that it can be copied or archived whole.
void WritePreviewIndex(const fs::path& path, const AcquireReport& rep, const std::string& capture,
                       const GridShape& shape) {
  std::string h = "<!doctype html>\n<html><head><meta charset=\"utf-8\">\n<title>translume acquire: " +
                  Html(fs::path(rep.material).filename().string()) + "</title>\n"
                  "<style>body{font-family:sans-serif;background:#1e1e1e;color:#ddd;margin:1.5em}"
                  "img{image-rendering:pixelated;max-width:100%}td,th{padding:2px 10px;text-align:left;"
                  "vertical-align:middle;white-space:nowrap}th{color:#aaa;font-weight:normal}code{color:#fc9}"
                  "</style></head><body>\n";
  h += "<h1>" + Html(rep.material) + "</h1>\n";
  h += "<p>capture <code>" + Html(capture) + "</code>; " + Html(rep.solve.BriefReport()) + "</p>\n";
  h += "<h2>Conditions</h2>\n<p>measured | fitted (one brightness scale) | residual: fitted less measured, "
       "in the channel that misses most, relative to the brightest measured node; black: exact, "
       "<span style=\"color:#f42\">red"
       "</span>: the fit brighter, <span style=\"color:#47f\">blue</span>: darker, full colour at " +
       fmt::format("{:g}", 100 * kResidualPreviewRange) + " %; grey: masked nodes (docs/capture.md).</p>\n"
       "<table>\n<tr><th>condition</th><th>measured</th><th>saturated</th><th>masked</th><th>E</th><th></th></tr>\n";
  for (const auto& c : rep.conditions)
    h += fmt::format("<tr><td>{}{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td><img src=\"{}\" "
                     "alt=\"{}\"></td></tr>\n", Html(c.name), c.validation ? " (validation)" : "",
                     c.measured_nodes, c.saturated_nodes, c.masked_nodes,
                     c.fit_error < 0 ? std::string("-") : fmt::format("{:.3e}", c.fit_error),
                     Html("fit_" + c.name + ".png"), Html(c.name));
  h += "</table>\n<h2>Material</h2>\n<p>Each channel on a log scale from its 0.5 % to its 99.5 % value "
       "(<code>translume info</code> prints them); depth 0 is the front face's layer (the one the camera "
       "sees).</p>\n<table>\n";
  const std::vector<std::string> slices = MaterialSlicePaths("material", shape);  // kappa's, then mu's
  const std::vector<int64_t> depths = MaterialSliceDepths(shape);
  for (size_t q = 0; q < 2; ++q) {
    h += fmt::format("<tr><th>{}</th>", q == 0 ? "kappa" : "mu");
    for (size_t k = 0; k < depths.size(); ++k) {
      const std::string name = Html(slices[q * depths.size() + k]);
      h += fmt::format("<td>depth {}<br><img src=\"{}\" alt=\"{}\" width=\"256\"></td>", depths[k], name, name);
    }
    h += "</tr>\n";
  }
  h += "</table>\n</body></html>\n";
  WriteAtomically(path.string(), [&](const std::string& tmp) {
    std::ofstream f(tmp);
    f << h;
    if (!f) throw InputError(fmt::format("{}: cannot write", path.string()));
  });
}

}  // namespace

std::string AcquireOptions::Validate() const {
  if (face_samples < 1 || face_samples > 32) return "face_samples must be in [1, 32]";
  if (mask_margin < 0) return "mask_margin must be >= 0";
  return recovery.Validate();
}

std::string WorkDir(const std::string& output_vdb) {
  return fs::path(output_vdb).replace_extension("").string() + "_work";
}

std::string AcquireReport::Table() const {
  std::string s = "stage                seconds\n";
  for (const auto& [name, t] : stage_seconds)
    s += fmt::format("  {:<18} {:8.1f}{}\n", name, t,
                     std::find(reused.begin(), reused.end(), name) != reused.end() ? "  (reused)" : "");
  s += fmt::format("calibration: camera RMS {:.3f} px, projector RMS {}, sample pose RMS {:.3f} px (corners {}), "
                   "lens blur {:.2f} px{}, white gains {:.4g} {:.4g} {:.4g}, exposure times {}\n", camera_rms_px,
                   projector_rms_px < 0 ? std::string("-") : fmt::format("{:.3f} px", projector_rms_px),
                   pose_rms_px, face_corners, camera_blur_px, camera_blur_profiles > 0 ? " (found)" : "",
                   white_gains[0], white_gains[1], white_gains[2],
                   exposure_times.empty() ? "-" : calib::Describe(calib::ParseShutterTimes(exposure_times, "report")));
  s += "condition  measured  saturated  masked   fit error (validation: not fitted)\n";
  for (const auto& c : conditions)
    s += fmt::format("  {:<8} {:8d} {:10d} {:7d}   {}{}\n", c.name, c.measured_nodes, c.saturated_nodes,
                     c.masked_nodes, c.fit_error < 0 ? std::string("-") : fmt::format("{:.3e}", c.fit_error),
                     c.validation ? "  validation" : "");
  if (solve.validation_checks > 0)
    s += fmt::format("validation: the result is iteration {}'s iterate of {} (validation E {:.3e}, {} checks, "
                     "{:.1f} s)\n", solve.validation_iteration, solve.iterations, solve.validation_error,
                     solve.validation_checks, solve.validation_seconds);
  return s;
}

namespace {

// One run of Acquire: the capture, the options, the work folder's stage log and the report, with
// one method per stage (acquire.h's list), called in that order. Each stage leaves what later
// stages read in the members under its heading.
class AcquireRun {
 public:
  AcquireRun(const CaptureSpec& cap, const std::string& out, const AcquireOptions& o,
             const std::function<void(const std::string&)>& progress_fn)
      : cap_(cap), out_(out), o_(o), progress_fn_(progress_fn), work_(MadeWorkDir(out)),
        log_((work_ / "stages.json").string(), o.force), g_(cap.grid), h_(cap.spacing_mm) {
    rep_.work_dir = work_.string();
    rep_.material = out;
  }

  // 1. Calibration: camera, projector, response, the exposure times' reading, camera flat,
  // white balance; each from capture.json's file, the work folder, or computed.
  void Calibrate();
  // 2. HDR: every condition's stack and the projector-black stack merged, through the camera flat.
  void MergeStacks();
  // 3. Pose: the front face's corners (given, or found and refined), camera_from_sample and the
  // lens's blur.
  void FitPose();
  // 4. Mapping: L, q and masks per condition; the node-space dataset written.
  void MapOntoGrid();
  // 5. Solve, the material written, and the previews.
  void Solve(const RecoveryCallback& iteration);
  // report.json; returns the report (moved out: the last call).
  AcquireReport WriteReport();

 private:
  static fs::path MadeWorkDir(const std::string& out) {
    const fs::path work(WorkDir(out));
    fs::create_directories(work);
    return work;
  }
  void Progress(const std::string& s);
  void StageDone(const std::string& name);

  void CalibrateCamera();
  void CalibrateProjector();
  void CalibrateResponse();
  void ReadExposureTimes();
  void MergeCameraFlat();
  void CalibrateWhite();
  // An HDR image or a stack merged here, its time warning shown.
  cv::Mat ReadHdr(const std::string& path);
  // An HDR image of the capture's photos through the camera flat (+inf stays +inf).
  cv::Mat Flatten(const cv::Mat& img) const;
  // A stack merged (or its earlier merge reused; key: the stage log's, exr_path: where it is
  // kept), through the camera flat.
  cv::Mat Merge(const std::string& key, const fs::path& exr_path, const std::string& stack);

  // Corners found on the fitted conditions' sum; returns whether they are the outline's, its
  // sides not refined.
  bool FindCorners();
  // The lens's blur read off the pose's outline into the report; returns the log's line.
  std::string EstimateBlur(const std::vector<cv::Mat>& lit);
  // The pose, corners and blur from the block's outline fit (ChooseBlockOutline's choice.use_fit);
  // exact: corners given as measured, only checked.
  void UseBlockOutline(const OutlineChoice& choice, const std::string& shows, bool exact,
                       const std::vector<cv::Mat>& lit, std::string* blur_said);
  void RefineCorners(const std::vector<cv::Mat>& lit, std::string* blur_said);
  // The projector's irradiance on each lit-face node relative to the white patch's (1 without a
  // flat field).
  std::vector<float> LitFaceIrradiance();

  const CaptureSpec& cap_;
  const std::string& out_;
  const AcquireOptions& o_;
  const std::function<void(const std::string&)>& progress_fn_;
  AcquireReport rep_;
  const fs::path work_;
  StageLog log_;
  const GridShape g_;
  const double h_;
  bool solving_ = false;   // in the solve: stops go through RecoveryOptions::stop
  bool computed_ = false;  // in the current stage (else: reused from the work folder or files)
  Clock::time_point t0_ = Clock::now();
  nlohmann::json solve_json_;  // report.json's "solve"

  // Calibration.
  calib::CameraCalibration camera_;
  DeviceIntrinsics cam_;
  std::string camera_yml_;
  std::optional<calib::ProjectorCalibration> projector_;
  std::optional<calib::ResponseCurve> response_;
  std::string response_file_;  // the file the curve came from: stages that merge stacks depend on it
  // How every stack's exposure times are read: one reading for the whole capture, so that no
  // stack's scale differs from another's by a label's rounding.
  calib::MergeOptions merge_options_;
  std::string black_sig_;  // the sensor black level, for stages whose merges it changes
  std::string times_sig_;  // the times' reading
  std::string merge_sig_;  // how every stack is merged
  cv::Mat camera_flat_;    // normalised to its mean; empty: none
  calib::WhiteBalance white_;
  std::string flat_exr_;

  // HDR.
  std::vector<cv::Mat> hdr_;  // per condition, through the camera flat
  cv::Mat black_;             // the projector-black merge (empty: none)

  // Pose.
  cv::Mat black_level_;  // black_ with saturated samples as 0
  std::vector<cv::Point2d> corners_;
  calib::Pose camera_from_sample_;

  // Mapping.
  Dataset d_;
  Dataset validation_;  // the validation conditions (CaptureSpec::Condition::validation)
};

void AcquireRun::Progress(const std::string& s) {
  // A line that ends in "..." announces work, and a stop comes before it, unprinted; the others
  // report work done, and are printed before a stop.
  std::string what = s;
  constexpr std::string_view kWarning = "warning: ";
  if (what.rfind(kWarning, 0) == 0) rep_.warnings.push_back(what.substr(kWarning.size()));
  const bool announces = what.size() >= 3 && what.compare(what.size() - 3, 3, "...") == 0;
  if (!announces && progress_fn_) progress_fn_(s);
  if (!solving_ && o_.stop && o_.stop()) {
    if (announces) what.erase(what.find_last_not_of(". ") + 1);
    throw StageInterrupted(fmt::format("stopped {} \"{}\"", announces ? "before" : "after", what), rep_.work_dir);
  }
  if (announces && progress_fn_) progress_fn_(s);
}

void AcquireRun::StageDone(const std::string& name) {
  const auto now = Clock::now();
  rep_.stage_seconds.emplace_back(name, std::chrono::duration<double>(now - t0_).count());
  t0_ = now;
}

void AcquireRun::Calibrate() {
  CalibrateCamera();
  CalibrateProjector();
  CalibrateResponse();
  ReadExposureTimes();
  MergeCameraFlat();
  CalibrateWhite();
  for (int c = 0; c < 3; ++c) rep_.white_gains[size_t(c)] = white_.gains[c];
  if (!computed_) rep_.reused.push_back("calibration");
  computed_ = false;
  StageDone("calibration");
}

void AcquireRun::CalibrateCamera() {
  camera_yml_ = (work_ / "camera.yml").string();
  if (!cap_.camera.file.empty()) {
    camera_ = calib::ReadCameraCalibration(cap_.camera.file);
  } else {
    const std::string sig = Signature({cap_.camera.photos}, cap_.camera.board);
    if (log_.Done("camera", sig, {camera_yml_})) {
      camera_ = calib::ReadCameraCalibration(camera_yml_);
    } else {
      Progress(fmt::format("calibrating the camera from {} ...", cap_.camera.photos));
      const calib::BoardSpec board = calib::BoardSpec::Parse(cap_.camera.board);
      camera_ = calib::CalibrateCamera(board, calib::ReadPhotoFolder(cap_.camera.photos));
      WriteAtomically(camera_yml_, [&](const std::string& tmp) {
        calib::WriteCameraCalibration(tmp, camera_, cap_.camera.board);
      });
      log_.Record("camera", sig);
      computed_ = true;
    }
  }
  rep_.camera_rms_px = camera_.rms;
  Progress(fmt::format("camera: {}", camera_.BriefReport()));
  for (const std::string& d : camera_.dropped) Progress(fmt::format("  dropped {}", d));
  cam_ = DeviceIntrinsics::From(camera_.image_size, camera_.K, camera_.dist);
}

void AcquireRun::CalibrateProjector() {
  if (!cap_.projector.file.empty()) {
    projector_ = calib::ReadProjectorCalibration(cap_.projector.file);
    if (std::string why = calib::CameraMismatch(camera_, cap_.projector.file); !why.empty())
      throw InputError(fmt::format("{}: projector: {}", cap_.file, why));
  } else if (!cap_.projector.planes.empty()) {
    const std::string yml = (work_ / "projector.yml").string();
    const std::string sig = Signature({cap_.projector.planes, camera_yml_},
                                      cap_.projector.board + cap_.projector.pattern +
                                      cap_.projector.projector_size + (cap_.projector.rear ? "r" : ""));
    if (log_.Done("projector", sig, {yml})) {
      projector_ = calib::ReadProjectorCalibration(yml);
    } else {
      Progress(fmt::format("calibrating the projector from {} ...", cap_.projector.planes));
      calib::ProjectorCalibOptions po;
      po.rear_projection = cap_.projector.rear;
      projector_ = calib::CalibrateProjector(
          camera_, calib::BoardSpec::Parse(cap_.projector.board),
          calib::ParseProjectorChessboard(cap_.projector.pattern, cap_.projector.projector_size),
          calib::ReadPlaneFolder(cap_.projector.planes), po);
      WriteAtomically(yml, [&](const std::string& tmp) {
        calib::WriteProjectorCalibration(tmp, *projector_, camera_,
                                         cap_.projector.pattern + " on " + cap_.projector.projector_size);
      });
      log_.Record("projector", sig);
      computed_ = true;
    }
    Progress(fmt::format("projector: {}", projector_->BriefReport()));
    for (const std::string& d : projector_->dropped) Progress(fmt::format("  dropped {}", d));
  }
  if (projector_) rep_.projector_rms_px = projector_->stereo_projector_rms;
}

void AcquireRun::CalibrateResponse() {
  if (!cap_.response.file.empty()) {
    response_ = calib::ReadResponse(cap_.response.file);
  } else if (!cap_.response.stacks.empty()) {
    const std::string yml = (work_ / "response.yml").string();
    const std::string sig = Signature(cap_.response.stacks, calib::ToString(cap_.exposure_times));
    if (log_.Done("response", sig, {yml})) {
      response_ = calib::ReadResponse(yml);
    } else {
      Progress("calibrating the camera response ...");
      std::vector<calib::ExposureStack> stacks;
      for (const auto& d : cap_.response.stacks) stacks.push_back(calib::ReadExposureStack(d));
      calib::ResponseOptions ro;
      ro.shutter = cap_.exposure_times;
      response_ = calib::CalibrateResponse(stacks, ro);
      if (response_->other_fit_rms > 0 || response_->shutter == calib::ShutterTimes::kApex)
        Progress("response: " + response_->ShutterReport());
      WriteAtomically(yml, [&](const std::string& tmp) { calib::WriteResponse(tmp, *response_); });
      log_.Record("response", sig);
      computed_ = true;
    }
  }
  response_file_ = !cap_.response.file.empty() ? cap_.response.file : (work_ / "response.yml").string();
}

void AcquireRun::ReadExposureTimes() {
  merge_options_.shutter = cap_.exposure_times;
  merge_options_.sensor_black = {cap_.sensor_black[0], cap_.sensor_black[1], cap_.sensor_black[2]};
  black_sig_ = cap_.sensor_black == std::array<double, 3>{}
                   ? ""
                   : fmt::format(" sensor_black {}", nlohmann::json(cap_.sensor_black).dump());
  if (merge_options_.shutter == calib::ShutterTimes::kAuto && response_) merge_options_.shutter = response_->shutter;
  if (merge_options_.shutter == calib::ShutterTimes::kAuto) {
    // Linear photos: their brightness steps decide, pooled over the white and lighting stacks
    // until every pair of times that tells the readings apart has been judged.
    std::vector<std::string> judged;
    if (fs::is_directory(cap_.white.white)) judged.push_back(cap_.white.white);
    for (const auto& c : cap_.conditions) judged.push_back(c.stack);
    const std::string txt = (work_ / "exposure_times.txt").string();
    const std::string sig = Signature(judged, black_sig_);
    std::string reading;
    if (log_.Done("exposure_times", sig, {txt})) {
      std::ifstream(txt) >> reading;
    } else {
      calib::ShutterJudge judge(merge_options_);
      for (const std::string& d : judged) {
        const calib::ExposureStack stack = calib::ReadExposureStack(d);
        if (stack.IsEightBit()) continue;  // refused in the merge, which names the response
        judge.Add(stack);
        if (judge.Decisive()) break;
      }
      const calib::ShutterChoice choice = judge.Choice();
      reading = calib::ToString(choice.times);
      if (choice.pairs > 0) Progress(choice.BriefReport());
      WriteAtomically(txt, [&](const std::string& tmp) {
        std::ofstream(tmp) << reading << "\n" << choice.BriefReport() << "\n";
      });
      log_.Record("exposure_times", sig);
    }
    merge_options_.shutter = calib::ParseShutterTimes(reading, txt);
  }
  times_sig_ = calib::ToString(merge_options_.shutter);
  rep_.exposure_times = times_sig_;
  merge_sig_ = times_sig_ + black_sig_;
}

cv::Mat AcquireRun::ReadHdr(const std::string& path) {
  calib::HdrReadInfo info;
  cv::Mat img = calib::ReadHdrOrStack(path, response_ ? &*response_ : nullptr, merge_options_, &info);
  if (!info.time_warning.empty()) Progress("warning: " + info.time_warning);
  return img;
}

// The lens's vignetting: every HDR image is divided by the camera flat, normalised to its mean
// (a constant factor that the white gains take back).
void AcquireRun::MergeCameraFlat() {
  if (cap_.camera_flat.empty()) return;
  const std::string exr = (work_ / "camera_flat.exr").string();
  const std::string sig = Signature({cap_.camera_flat, response_file_}, merge_sig_);
  if (log_.Done("camera_flat", sig, {exr})) {
    camera_flat_ = calib::ReadLinearRgb(exr);
    return;
  }
  Progress("camera flat ...");
  try {
    const cv::Mat merged = ReadHdr(cap_.camera_flat);
    if (merged.size() != camera_.image_size)
      throw calib::CalibError(fmt::format("{}: images are {}x{} but the camera calibration is {}x{}",
                                          cap_.camera_flat, merged.cols, merged.rows, camera_.image_size.width,
                                          camera_.image_size.height));
    camera_flat_ = calib::NormalizedCameraFlat(merged, cap_.camera_flat);
  } catch (const calib::CalibError& e) {
    throw InputError(fmt::format("{}: camera_flat: {}", cap_.file, e.what()));
  }
  WriteAtomically(exr, [&](const std::string& tmp) { calib::WriteExr(tmp, camera_flat_); });
  log_.Record("camera_flat", sig);
  computed_ = true;
}

cv::Mat AcquireRun::Flatten(const cv::Mat& img) const {
  if (camera_flat_.empty() || img.empty()) return img;
  TL_CHECK(img.size() == camera_flat_.size());
  cv::Mat out;
  cv::divide(img, camera_flat_, out);
  return out;
}

void AcquireRun::CalibrateWhite() {
  flat_exr_ = (work_ / "flat_field.exr").string();
  if (!cap_.white.file.empty()) {
    white_ = calib::ReadWhiteBalance(cap_.white.file);
    const bool flat = !cap_.camera_flat.empty();
    if (white_.camera_flat != flat)
      Progress(fmt::format("warning: {}: its white reference was {}divided by a camera flat, this capture's images "
                           "are{}: the gains may be off by the vignetting over its patch (calibrate white {})",
                           cap_.white.file, white_.camera_flat ? "" : "not ", flat ? "" : " not",
                           flat ? "--camera-flat " + cap_.camera_flat : "without --camera-flat"));
    if (white_.sensor_black != merge_options_.sensor_black)
      Progress(fmt::format("warning: {}: its stacks were merged with a sensor black level of {:g},{:g},{:g}, this "
                           "capture's with {:g},{:g},{:g}: the gains may be off by its offset (calibrate white "
                           "--sensor-black)", cap_.white.file, white_.sensor_black[0], white_.sensor_black[1],
                           white_.sensor_black[2], cap_.sensor_black[0], cap_.sensor_black[1], cap_.sensor_black[2]));
    if (!white_.exposure_times.empty() && white_.exposure_times != times_sig_)
      Progress(fmt::format("warning: {}: its white stack's exposure times were read {}, this capture's are read {}: "
                           "the gains may be off by up to 7 % (calibrate white --exposure-times {})",
                           cap_.white.file, white_.exposure_times, times_sig_, times_sig_));
    return;
  }
  const std::string yml = (work_ / "white.yml").string();
  const std::string sig = Signature({cap_.white.white, cap_.white.black, response_file_, cap_.camera_flat},
                                    fmt::format("{}{}{}{}", nlohmann::json(cap_.white.patch).dump(),
                                                nlohmann::json(cap_.white.albedo).dump(), merge_sig_,
                                                cap_.white.flat_field ? " flat_field" : ""));
  std::vector<std::string> outputs{yml};
  if (cap_.white.flat_field) outputs.push_back(flat_exr_);
  if (log_.Done("white", sig, outputs)) {
    white_ = calib::ReadWhiteBalance(yml);
    return;
  }
  Progress("white balance ...");
  cv::Mat w = ReadHdr(cap_.white.white);
  cv::Mat b = cap_.white.black.empty() ? cv::Mat() : ReadHdr(cap_.white.black);
  for (const auto& [img, path] : {std::pair<const cv::Mat&, const std::string&>{w, cap_.white.white},
                                  std::pair<const cv::Mat&, const std::string&>{b, cap_.white.black}})
    if (!img.empty() && img.size() != camera_.image_size)
      throw InputError(fmt::format("{}: images are {}x{} but the camera calibration is {}x{}", path, img.cols,
                                   img.rows, camera_.image_size.width, camera_.image_size.height));
  w = Flatten(w);
  b = Flatten(b);
  std::vector<cv::Point2f> patch;
  for (const auto& p : cap_.white.patch) patch.emplace_back(float(p[0]), float(p[1]));
  try {
    white_ = calib::WhiteFromPatch(w, b, patch, {cap_.white.albedo[0], cap_.white.albedo[1], cap_.white.albedo[2]});
    if (fs::is_directory(cap_.white.white)) white_.exposure_times = times_sig_;
    white_.sensor_black = merge_options_.sensor_black;
    white_.camera_flat = !camera_flat_.empty();
  } catch (const calib::CalibError& e) {
    throw InputError(fmt::format("{}: white: {}", cap_.file, e.what()));
  }
  WriteAtomically(yml, [&](const std::string& tmp) {
    calib::WriteWhiteBalance(tmp, white_, b.empty() ? cv::Vec3d() : cv::Vec3d(cv::mean(b).val), cap_.white.black);
  });
  if (cap_.white.flat_field) {
    // The reference's irradiance in q units (1 where the patch's falls) per channel: its
    // radiance gains x (white - black) over albedo / pi.
    const cv::Mat diff = b.empty() ? w : cv::Mat(w - b);
    cv::Scalar scale;
    for (int k = 0; k < 3; ++k) scale[k] = white_.gains[k] * CV_PI / cap_.white.albedo[size_t(k)];
    cv::Mat flat;
    cv::multiply(diff, scale, flat);
    WriteAtomically(flat_exr_, [&](const std::string& tmp) { calib::WriteExr(tmp, flat); });
  }
  log_.Record("white", sig);
  computed_ = true;
}

cv::Mat AcquireRun::Merge(const std::string& key, const fs::path& exr_path, const std::string& stack) {
  const std::string exr = exr_path.string();
  const std::string sig = Signature({stack, response_file_}, merge_sig_);
  if (log_.Done(key, sig, {exr})) return Flatten(calib::ReadLinearRgb(exr));
  const calib::ExposureStack s = calib::ReadExposureStack(stack);
  if (s.Size() != camera_.image_size)
    throw InputError(fmt::format("{}: photos are {}x{} but the camera calibration is {}x{}", stack,
                                 s.Size().width, s.Size().height, camera_.image_size.width,
                                 camera_.image_size.height));
  if (s.IsEightBit() && !response_)
    throw InputError(fmt::format("{}: 8-bit photos need a camera response (capture.json: response)", stack));
  const calib::HdrImage hdr =
      calib::MergeHdr(s, s.IsEightBit() ? &*response_ : nullptr, nullptr, merge_options_);
  if (!hdr.time_warning.empty()) Progress("warning: " + hdr.time_warning);
  WriteAtomically(exr, [&](const std::string& tmp) { calib::WriteExr(tmp, hdr.radiance); });
  log_.Record(key, sig);
  computed_ = true;
  return Flatten(hdr.radiance);
}

void AcquireRun::MergeStacks() {
  const fs::path hdr_dir = work_ / "hdr";
  for (size_t m = 0; m < cap_.conditions.size(); ++m) {
    const std::string& name = cap_.conditions[m].name;
    hdr_.push_back(Merge("hdr:" + name, hdr_dir / (name + ".exr"), cap_.conditions[m].stack));
    Progress(fmt::format("hdr {}/{}: {}", m + 1, cap_.conditions.size(), cap_.conditions[m].stack));
  }
  // Outside hdr/, whose files are named after the conditions (one may be called "black").
  if (!cap_.black.empty()) black_ = Merge("black_hdr", work_ / "black.exr", cap_.black);
  if (!computed_) rep_.reused.push_back("hdr");
  StageDone("hdr");
}

bool AcquireRun::FindCorners() {
  // Saturated pixels (+inf) stay +inf, the brightest (DetectFaceCorners): a front-lit region
  // saturates where its own condition lights it, and those pixels are the face's too. The
  // fitted conditions only: together they light the whole face, and a validation spot adds
  // nothing but a saturated disc (front-lit: corners 0.31 px off instead of 0.26).
  cv::Mat sum = cv::Mat::zeros(camera_.image_size, CV_32FC3);
  for (size_t m = 0; m < hdr_.size(); ++m) {
    if (cap_.conditions[m].validation) continue;
    cv::Mat known = hdr_[m].clone();
    cv::patchNaNs(known, 0);
    for (auto it = known.begin<cv::Vec3f>(); it != known.end<cv::Vec3f>(); ++it)
      for (int c = 0; c < 3; ++c)
        if ((*it)[c] == -std::numeric_limits<float>::infinity()) (*it)[c] = 0;
    sum += known;
  }
  // Where the camera sees side faces too, the sides of the outline found do not refine; the
  // outline itself is a start for the block's outline fit.
  std::vector<cv::Point2d> outline;
  bool outline_unrefined = false;
  corners_ = DetectFaceCorners(sum, &cam_, &outline);
  if (corners_.empty()) {
    corners_ = outline;
    outline_unrefined = true;
  }
  if (corners_.empty())
    throw InputError(fmt::format("{}: face_corners_px is \"auto\" but no four-sided sample was "
                                 "found in the images; give the corners", cap_.file));
  Progress(fmt::format("found the {}: {}", outline_unrefined ? "sample's outline" : "front face's corners",
                       CornerList(corners_)));
  return outline_unrefined;
}

std::string AcquireRun::EstimateBlur(const std::vector<cv::Mat>& lit) {
  const OutlineBlur b = EstimateOutlineBlur(lit, cam_, camera_from_sample_, g_, h_, 3.0, black_level_);
  rep_.camera_blur_px = b.sigma_px;
  rep_.camera_blur_profiles = b.profiles;
  return b.positions == 0
             ? fmt::format("{}: camera_blur_px is \"auto\" but the face's outline is too short in the photos, "
                           "or too near their border, for profiles across it; taking the lens as sharp (give "
                           "camera_blur_px)", cap_.file)
         : b.profiles == 0
             ? fmt::format("{}: camera_blur_px is \"auto\" but the face's outline shows nowhere unsaturated "
                           "in the photos; taking the lens as sharp (give camera_blur_px)", cap_.file)
             : fmt::format("the lens's blur on the sample's photos: sigma {:.2f} px (from {} profiles across "
                           "the face's outline; residual {:.2g} against {:.2g} for a sharp lens)",
                           b.sigma_px, b.profiles, b.rms, b.rms_sharp);
}

void AcquireRun::FitPose() {
  bool outline_unrefined = false;  // corners found: the outline's, its sides not refined
  if (!cap_.face_corners_px.empty()) {
    for (const auto& p : cap_.face_corners_px) corners_.emplace_back(p[0], p[1]);
  } else {
    outline_unrefined = FindCorners();
  }
  // The black level, subtracted from every condition: saturated (+inf) samples of it, which do
  // not occur in practice, count as 0 so that they cannot hide a condition's own saturation.
  black_level_ = black_.clone();
  for (auto it = black_level_.begin<cv::Vec3f>(); it != black_level_.end<cv::Vec3f>(); ++it)
    for (int k = 0; k < 3; ++k)
      if (!std::isfinite((*it)[k])) (*it)[k] = 0;
  camera_from_sample_ = EstimateSamplePose(cam_, corners_, g_, h_, cap_.file + ": face_corners_px",
                                           &rep_.pose_rms_px, !cap_.face_corners_px.empty());
  // The lens's blur: given, or read off the outline in the fitted conditions less the black
  // (front-lit, each condition saturates where it lights the face, and their sum everywhere).
  std::vector<cv::Mat> lit;
  for (size_t m = 0; m < hdr_.size(); ++m)
    if (!cap_.conditions[m].validation) lit.push_back(hdr_[m]);
  std::string blur_said;
  // A camera beside the projector (the paper's front-lit rig) may see side faces of the block:
  // the front face's edges next to them do not show, and the outline is the block's.
  const std::array<double, 3> size = SampleSize(g_, h_);
  const bool exact = !cap_.face_corners_px.empty() && !cap_.face_corners_near;
  const CornerSource source = exact ? CornerSource::kExact
                              : cap_.face_corners_near ? CornerSource::kNear : CornerSource::kFound;
  const OutlineFitNeed need =
      NeedsBlockOutlineFit(cam_, camera_from_sample_, size, source, rep_.pose_rms_px, outline_unrefined);
  OutlineChoice choice;  // use_fit: the block's outline fit placed the corners (or checked exact ones)
  std::string shows;     // the side faces seen
  if (need.needed) {
    choice = ChooseBlockOutline(lit, cam_, size, camera_from_sample_, corners_, cap_.camera_blur_px.value_or(1.0),
                                need, black_level_);
    const char* names[4] = {"x = 0", "x = X", "y = 0", "y = Y"};
    for (int f = 0; f < 4; ++f)
      if (choice.side_px[size_t(f)] > kSideFaceShowsPx)
        shows += fmt::format("{}{} ({:.1f} px wide)", shows.empty() ? "" : ", ", names[f], choice.side_px[size_t(f)]);
    if (!choice.size_hint.empty())
      Progress(fmt::format("warning: {}: sample_mm may be off: {}, and a block of that width fits the outline in "
                           "the photos better; the pose is fitted to the face's four corners", cap_.file,
                           choice.size_hint));
    else if (!choice.use_fit)
      Progress(choice.settled ? "the block's outline shows no side face; refining the face's four corners"
                              : "the block's outline fit did not settle; refining the face's four corners instead");
    if (shows.empty()) shows = "none";
  }
  if (choice.use_fit) {
    UseBlockOutline(choice, shows, exact, lit, &blur_said);
  } else {
    if (cap_.camera_blur_px) rep_.camera_blur_px = *cap_.camera_blur_px;
    else blur_said = EstimateBlur(lit);
    RefineCorners(lit, &blur_said);
  }
  if (!blur_said.empty()) Progress(blur_said);
  for (const auto& p : corners_) rep_.face_corners_px.push_back({p.x, p.y});
  StageDone("pose");
}

void AcquireRun::UseBlockOutline(const OutlineChoice& choice, const std::string& shows, bool exact,
                                 const std::vector<cv::Mat>& lit, std::string* blur_said) {
  const BlockOutlineFit& fit = choice.fit;
  const bool settled = choice.settled;
  Progress(fmt::format("the pose is fitted to the block's outline; side faces the camera sees besides the front "
                       "face: {}", shows));
  double moved = 0;
  for (size_t k = 0; k < fit.corners.size(); ++k) moved = std::max(moved, cv::norm(fit.corners[k] - corners_[k]));
  if (!settled) {
    if (!exact)
      throw InputError(fmt::format("{}: the sample's outline is not a face's: the camera sees side faces of the "
                                   "block ({}), and the block's outline fit did not settle (docs/capture.md, "
                                   "\"Side faces\"); give face_corners_px as measured", cap_.file, shows));
    Progress("the block's outline fit did not settle; face_corners_px are used as given, unchecked");
  } else if (exact) {
    if (moved > 1)
      Progress(fmt::format("warning: {}: face_corners_px lie up to {:.1f} px from the block's outline fitted in "
                           "the photos (its front corners: {}); give them as {{\"near\": [...]}} to have them "
                           "refined, or \"auto\"", cap_.file, moved, CornerList(fit.corners)));
  } else {
    corners_ = fit.corners;
    camera_from_sample_ = fit.camera_from_sample;
    rep_.pose_rms_px = fit.rms_px;
    rep_.face_corners = "refined";
    rep_.face_corners_edge_points = fit.edge_points;
    Progress(fmt::format("fitted the block's outline on {} edge points of {} sides (RMS {:.2f} px) through a lens "
                         "blur of {:.2f} px (the front corners moved up to {:.2f} px): {}", fit.edge_points,
                         fit.sides, fit.rms_px, fit.blur_px, moved, CornerList(corners_)));
  }
  if (cap_.camera_blur_px) {
    rep_.camera_blur_px = *cap_.camera_blur_px;
  } else if (settled) {
    rep_.camera_blur_px = fit.blur_px;
    rep_.camera_blur_profiles = fit.edge_points;
    *blur_said = fmt::format("the lens's blur on the sample's photos: sigma {:.2f} px (from the block's outline)",
                             fit.blur_px);
  } else {
    *blur_said = EstimateBlur(lit);
  }
}

// Corners found automatically or given near the face, refined against every fitted condition's
// photo through the blur (RefineFaceCorners; corners given near it first with the edges let
// within kNearCornerReachPx of them); then the pose, and the blur read again along the new
// outline. Corners given as exact are checked (the usual pass, the near ones where it moves them
// by more than a pixel or fails), and left as they are.
void AcquireRun::RefineCorners(const std::vector<cv::Mat>& lit, std::string* blur_said) {
  int points = 0;
  double refine_blur = 0;
  const auto refine = [&](bool near) {
    const std::vector<cv::Point2d> refined = RefineFaceCornersWithin(
        lit, cam_, corners_, rep_.camera_blur_px, near ? kNearCornerReachPx : 0, black_level_, &points, &refine_blur);
    double moved = 0;
    for (size_t k = 0; k < refined.size(); ++k) moved = std::max(moved, cv::norm(refined[k] - corners_[k]));
    return std::make_pair(refined, moved);
  };
  if (cap_.face_corners_px.empty() || cap_.face_corners_near) {
    const auto [refined, moved] = refine(cap_.face_corners_near);
    rep_.face_corners = cap_.face_corners_near ? "near" : "found";
    if (refined.empty()) {
      Progress(fmt::format("the face's corners were not refined: too few profiles across a side show an "
                           "unsaturated edge; keeping the {} ones", cap_.face_corners_near ? "given" : "found"));
      return;
    }
    rep_.face_corners = "refined";
    rep_.face_corners_edge_points = points;
    corners_ = refined;
    camera_from_sample_ = EstimateSamplePose(cam_, corners_, g_, h_, cap_.file + ": face_corners_px", &rep_.pose_rms_px);
    // Where the pose's outline misses the face's (sample_mm off), the blur the refinement found on
    // the face's own edges, not one read across the pose's outline.
    if (!cap_.camera_blur_px && rep_.pose_rms_px > 1 && refine_blur > 0) {
      rep_.camera_blur_px = refine_blur;
      rep_.camera_blur_profiles = points;
      *blur_said = fmt::format("the lens's blur on the sample's photos: sigma {:.2f} px (from the face's edges; the "
                               "pose misses the corners by {:.2f} px RMS)", refine_blur, rep_.pose_rms_px);
    } else if (!cap_.camera_blur_px) {
      *blur_said = EstimateBlur(lit);
    }
    Progress(fmt::format("refined the corners on {} edge points through a lens blur of {:.2f} px (moved up to "
                         "{:.2f} px): {}", points, refine_blur, moved, CornerList(corners_)));
  } else if (const auto [close, close_moved] = refine(false); close.empty() || close_moved > 1) {
    // Off by more than a pixel, or by more than the usual pass reaches: the near passes.
    const auto [refined, moved] = refine(true);
    if (!refined.empty() && moved > 1)
      Progress(fmt::format("warning: {}: face_corners_px lie up to {:.1f} px from the face's outline in the "
                           "photos (refined: {}); give them as {{\"near\": [...]}} to have them refined, or "
                           "\"auto\"", cap_.file, moved, CornerList(refined)));
  }
}

// The white reference's image read over the lit face's dual boxes, the mean of its channels.
// (Light-spec conditions take their q as given: without a pattern condition it is not read.)
std::vector<float> AcquireRun::LitFaceIrradiance() {
  const int64_t F = g_.face_size();
  std::vector<float> irradiance(size_t(F), 1.0f);
  const bool patterns = std::any_of(cap_.conditions.begin(), cap_.conditions.end(),
                                    [](const CaptureSpec::Condition& c) { return !c.pattern.empty(); });
  if (!cap_.white.flat_field || !patterns) return irradiance;
  calib::Pose sample_from_lit_plane;  // (x, y, 0) -> (x, y, Z): the lit face as a front face
  sample_from_lit_plane.t = {0, 0, LitFaceZ(g_, h_, cap_.setup)};
  const FaceSamples flat = ResampleFrontFace(calib::ReadLinearRgb(flat_exr_), cam_,
                                             camera_from_sample_ * sample_from_lit_plane, g_, h_, o_.face_samples);
  float lo = std::numeric_limits<float>::infinity(), hi = 0;
  for (int64_t f = 0; f < F; ++f) {
    const float v = (flat.value[0][size_t(f)] + flat.value[1][size_t(f)] + flat.value[2][size_t(f)]) / 3;
    const char* problem = flat.saturated[size_t(f)] > 0 ? "is saturated"
                          : !std::isfinite(v)            ? "has no value"
                          : !(v > 0.05f)                 ? "is dark"
                                                         : nullptr;
    if (problem)
      throw InputError(fmt::format("{}: white.flat_field: the white reference's image {} at lit-face node ({}, {}) "
                                   "({}): it must cover the whole lit face, unsaturated",
                                   cap_.file, problem, f % g_.nx, f / g_.nx, cap_.white.white));
    irradiance[size_t(f)] = v;
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  Progress(fmt::format("flat field: the projector's irradiance on the lit face is {:.3f}-{:.3f} of the white "
                       "patch's", lo, hi));
  rep_.flat_field = {lo, hi};
  return irradiance;
}

void AcquireRun::MapOntoGrid() {
  d_.shape = g_;
  d_.spacing_mm = h_;
  d_.C = cap_.C;
  d_.setup = cap_.setup;
  validation_ = d_;
  const int64_t F = g_.face_size();
  DeviceIntrinsics proj;
  calib::Pose projector_from_camera;
  if (projector_) {
    proj = DeviceIntrinsics::From(projector_->projector_size, projector_->K, projector_->dist);
    projector_from_camera.R = projector_->R;
    projector_from_camera.t = projector_->T;
  }
  const std::vector<float> irradiance = LitFaceIrradiance();
  // The pixels across the face's outline also see the dark surround, and the lens's blur spreads
  // the outline further: the border nodes' means are divided by the face's coverage of their
  // samples, blurred as the lens blurs (ResampleFrontFace).
  const cv::Mat coverage = FaceCoverage(cam_, camera_from_sample_, g_, h_, rep_.camera_blur_px);
  for (size_t m = 0; m < cap_.conditions.size(); ++m) {
    const auto& c = cap_.conditions[m];
    cv::Mat img = hdr_[m];
    if (!black_level_.empty()) img = hdr_[m] - black_level_;  // inf - finite stays inf (saturated)
    const FaceSamples fsm = ResampleFrontFace(img, cam_, camera_from_sample_, g_, h_, o_.face_samples, &coverage);
    DatasetCondition dc;
    dc.name = c.name;
    if (!c.pattern.empty()) {
      cv::Mat pat = calib::ReadLinearRgb(c.pattern), grey;
      cv::cvtColor(pat, grey, cv::COLOR_RGB2GRAY);
      if (grey.size() != projector_->projector_size)
        throw InputError(fmt::format("{}: pattern is {}x{} but the projector is {}x{}", c.pattern, grey.cols,
                                     grey.rows, projector_->projector_size.width, projector_->projector_size.height));
      std::vector<float> q =
          ProjectPatternOnFace(grey, proj, projector_from_camera, camera_from_sample_, g_, h_, cap_.setup);
      for (int64_t f = 0; f < F; ++f) q[size_t(f)] *= irradiance[size_t(f)];
      dc.q = GreyPattern(q);
    } else {
      dc.q = GreyPattern(RasterizeLightFile(c.Light(cap_.dir), g_, h_));
    }
    dc.mask = MeasurementMask(g_, cap_.setup, dc.q, o_.mask_margin);
    AcquireConditionReport cr;
    cr.name = c.name;
    cr.validation = c.validation;
    double brightest = 0;
    for (int64_t f = 0; f < F; ++f) {
      const bool valid = std::isfinite(fsm.value[0][size_t(f)]) && fsm.saturated[size_t(f)] == 0;
      if (fsm.saturated[size_t(f)] > 0) ++cr.saturated_nodes;
      for (int k = 0; k < 3; ++k) {
        const float v = valid ? float(white_.gains[k] * fsm.value[size_t(k)][size_t(f)]) : 0.0f;
        dc.L[size_t(k)].push_back(v);
        if (dc.mask[size_t(f)] > 0) brightest = std::max(brightest, double(v));
      }
      if (!valid) dc.mask[size_t(f)] = 0;
      if (dc.mask[size_t(f)] > 0) ++cr.measured_nodes;
      else ++cr.masked_nodes;
      cr.q_sum += dc.q[0][size_t(f)];
    }
    if (cr.saturated_nodes == F)
      throw InputError(fmt::format("{}: the sample is saturated in every exposure (add shorter exposures)", c.stack));
    if (cr.measured_nodes == 0)
      throw InputError(fmt::format("{}: no usable front-face node (all masked or saturated)", c.stack));
    if (!(brightest > 0))
      throw InputError(fmt::format("{}: the sample is black in every exposure (add longer exposures, or "
                                   "check that the projector lights it)", c.stack));
    if (!(cr.q_sum > 0))
      throw InputError(fmt::format("{}: the condition puts no light on the lit face ({} misses the sample)",
                                   c.stack, c.pattern.empty() ? c.light : c.pattern));
    // Negative values after black subtraction are noise around zero.
    for (auto& ch : dc.L)
      for (float& v : ch) v = std::max(v, 0.0f);
    rep_.conditions.push_back(cr);
    (c.validation ? validation_ : d_).conditions.push_back(std::move(dc));
  }
  if (std::string why = d_.Validate(); !why.empty()) TL_CHECK_MSG(false, why);
  rep_.dataset_dir = (work_ / "dataset").string();
  WriteFolderAtomically(rep_.dataset_dir, [&](const std::string& tmp) {
    WriteDataset(tmp, d_);
    if (!validation_.conditions.empty()) WriteDataset((fs::path(tmp) / "validation").string(), validation_);
  });
  Progress(fmt::format("wrote the node-space dataset {}/dataset.json ({} conditions{}, grid {})",
                       rep_.dataset_dir, d_.conditions.size(),
                       validation_.conditions.empty() ? ""
                                                      : fmt::format(", {} in validation/", validation_.conditions.size()),
                       g_.ToString()));
  StageDone("mapping");
}

void AcquireRun::Solve(const RecoveryCallback& iteration) {
  Progress("solving for kappa and mu ...");
  solving_ = true;
  RecoveryState state;
  RecoveryOptions ro = o_.recovery;
  if (!ro.stop) ro.stop = o_.stop;  // the homogeneous fit and the level search
  rep_.solve = Recover(d_, ro, &state, iteration, &validation_);
  const Material m = MaterialFromState(d_, state, cap_.eta);
  WriteMaterial(out_, m);
  StageDone("solve");
  // Previews: measured | fitted | residual per condition, kappa and mu slices.
  const fs::path prev = work_ / "previews";
  fs::create_directories(prev);
  // Every condition in the capture's order, validation ones included (their E is the
  // validation error per condition; a fitted condition's is rep_.solve's).
  std::vector<const DatasetCondition*> all;
  for (size_t c = 0, t = 0, v = 0; c < rep_.conditions.size(); ++c)
    all.push_back(rep_.conditions[c].validation ? &validation_.conditions[v++] : &d_.conditions[t++]);
  std::vector<FacePattern> q;
  for (const DatasetCondition* c : all) q.push_back(c->q);
  MultigridOptions mg;
  mg.tolerance = 1e-8;
  const auto fitted = RenderMeasured(m, d_.setup, q, mg);
  for (size_t c = 0; c < all.size(); ++c) {
    rep_.conditions[c].fit_error = RelightingError({fitted[c]}, {all[c]->L}, {all[c]->mask});
    const std::string p = (prev / fmt::format("fit_{}.png", all[c]->name)).string();
    WriteFitComparison(p, g_, all[c]->L, fitted[c], all[c]->mask);
    rep_.previews.push_back(p);
  }
  for (const auto& p : WriteMaterialSlices((prev / "material").string(), m)) rep_.previews.push_back(p);
  WritePreviewIndex(prev / "index.html", rep_, cap_.file, g_);
  rep_.previews.push_back((prev / "index.html").string());
  StageDone("previews");
  solve_json_ = {{"termination", TerminationName(rep_.solve.termination)},
                 {"message", rep_.solve.message},
                 {"iterations", rep_.solve.iterations},
                 {"solves", rep_.solve.solves},
                 {"solve_tolerance", o_.recovery.solve_tolerance},
                 {"fit_error", rep_.solve.fit_error},
                 {"homogeneous_kappa", rep_.solve.homogeneous_kappa},
                 {"homogeneous_mu", rep_.solve.homogeneous_mu},
                 {"level_mu_factor", rep_.solve.level_factor},
                 {"level_seconds", rep_.solve.level_seconds},
                 {"validation_error", rep_.solve.validation_error},
                 {"validation_iteration", rep_.solve.validation_iteration}};
}

AcquireReport AcquireRun::WriteReport() {
  nlohmann::json j;
  if (!solve_json_.is_null()) j["solve"] = solve_json_;
  j["capture"] = cap_.file;
  j["material"] = o_.solve ? out_ : "";
  j["dataset"] = rep_.dataset_dir;
  j["grid"] = {g_.nx, g_.ny, g_.nz};
  j["spacing_mm"] = h_;
  j["setup"] = SetupName(cap_.setup);
  j["camera_rms_px"] = rep_.camera_rms_px;
  j["projector_rms_px"] = rep_.projector_rms_px;
  j["pose_rms_px"] = rep_.pose_rms_px;
  j["face_corners_px"] = rep_.face_corners_px;
  j["face_corners"] = rep_.face_corners;
  j["face_corners_edge_points"] = rep_.face_corners_edge_points;
  j["camera_blur_px"] = rep_.camera_blur_px;
  j["camera_blur"] = cap_.camera_blur_px ? "given" : "found";
  j["camera_blur_profiles"] = rep_.camera_blur_profiles;
  j["white_gains"] = rep_.white_gains;
  if (cap_.white.flat_field && rep_.flat_field[1] > 0) j["flat_field"] = rep_.flat_field;
  j["exposure_times"] = rep_.exposure_times;
  nlohmann::json st = nlohmann::json::object();
  for (const auto& [name, t] : rep_.stage_seconds) st[name] = t;
  j["stage_seconds"] = st;
  j["reused"] = rep_.reused;
  j["warnings"] = rep_.warnings;
  nlohmann::json cs = nlohmann::json::array();
  for (const auto& c : rep_.conditions)
    cs.push_back({{"name", c.name}, {"measured_nodes", c.measured_nodes}, {"saturated_nodes", c.saturated_nodes},
                  {"masked_nodes", c.masked_nodes}, {"q_sum", c.q_sum}, {"fit_error", c.fit_error},
                  {"validation", c.validation}});
  j["conditions"] = cs;
  j["previews"] = rep_.previews;
  rep_.report_json = (work_ / "report.json").string();
  WriteAtomically(rep_.report_json, [&](const std::string& tmp) { std::ofstream(tmp) << j.dump(2) << "\n"; });
  return std::move(rep_);
}

}  // namespace

AcquireReport Acquire(const CaptureSpec& cap, const std::string& out, const AcquireOptions& o,
                      const std::function<void(const std::string&)>& progress,
                      const RecoveryCallback& iteration) {
  if (std::string why = o.Validate(); !why.empty()) throw InputError("acquire: " + why);
  AcquireRun run(cap, out, o, progress);
  run.Calibrate();
  run.MergeStacks();
  run.FitPose();
  run.MapOntoGrid();
  if (o.solve) run.Solve(iteration);
  return run.WriteReport();
}

}  // namespace translume::acquire
