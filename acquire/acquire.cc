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

AcquireReport Acquire(const CaptureSpec& cap, const std::string& out, const AcquireOptions& o,
                      const std::function<void(const std::string&)>& progress_fn,
                      const RecoveryCallback& iteration) {
  if (std::string why = o.Validate(); !why.empty()) throw InputError("acquire: " + why);
  AcquireReport rep;
  rep.work_dir = WorkDir(out);
  rep.material = out;
  const fs::path work(rep.work_dir);
  fs::create_directories(work);
  StageLog log((work / "stages.json").string(), o.force);
  bool solving = false;
  auto progress = [&](const std::string& s) {
    // A line that ends in "..." announces work, and a stop comes before it, unprinted; the others
    // report work done, and are printed before a stop.
    std::string what = s;
    constexpr std::string_view kWarning = "warning: ";
    if (what.rfind(kWarning, 0) == 0) rep.warnings.push_back(what.substr(kWarning.size()));
    const bool announces = what.size() >= 3 && what.compare(what.size() - 3, 3, "...") == 0;
    if (!announces && progress_fn) progress_fn(s);
    if (!solving && o.stop && o.stop()) {
      if (announces) what.erase(what.find_last_not_of(". ") + 1);
      throw StageInterrupted(fmt::format("stopped {} \"{}\"", announces ? "before" : "after", what), rep.work_dir);
    }
    if (announces && progress_fn) progress_fn(s);
  };
  auto t0 = Clock::now();
  auto stage_done = [&](const std::string& name) {
    const auto now = Clock::now();
    rep.stage_seconds.emplace_back(name, std::chrono::duration<double>(now - t0).count());
    t0 = now;
  };
  const GridShape& g = cap.grid;
  const double h = cap.spacing_mm;

  // 1. Calibration.
  bool computed = false;  // in the current stage (else: reused from the work folder or files)
  calib::CameraCalibration camera;
  const std::string camera_yml = (work / "camera.yml").string();
  if (!cap.camera.file.empty()) {
    camera = calib::ReadCameraCalibration(cap.camera.file);
  } else {
    const std::string sig = Signature({cap.camera.photos}, cap.camera.board);
    if (log.Done("camera", sig, {camera_yml})) {
      camera = calib::ReadCameraCalibration(camera_yml);
    } else {
      progress(fmt::format("calibrating the camera from {} ...", cap.camera.photos));
      const calib::BoardSpec board = calib::BoardSpec::Parse(cap.camera.board);
      camera = calib::CalibrateCamera(board, calib::ReadPhotoFolder(cap.camera.photos));
      WriteAtomically(camera_yml, [&](const std::string& tmp) {
        calib::WriteCameraCalibration(tmp, camera, cap.camera.board);
      });
      log.Record("camera", sig);
      computed = true;
    }
  }
  rep.camera_rms_px = camera.rms;
  progress(fmt::format("camera: {}", camera.BriefReport()));
  for (const std::string& d : camera.dropped) progress(fmt::format("  dropped {}", d));
  const DeviceIntrinsics cam = DeviceIntrinsics::From(camera.image_size, camera.K, camera.dist);

  std::optional<calib::ProjectorCalibration> projector;
  if (!cap.projector.file.empty()) {
    projector = calib::ReadProjectorCalibration(cap.projector.file);
    if (std::string why = calib::CameraMismatch(camera, cap.projector.file); !why.empty())
      throw InputError(fmt::format("{}: projector: {}", cap.file, why));
  } else if (!cap.projector.planes.empty()) {
    const std::string yml = (work / "projector.yml").string();
    const std::string sig = Signature({cap.projector.planes, camera_yml},
                                      cap.projector.board + cap.projector.pattern +
                                      cap.projector.projector_size + (cap.projector.rear ? "r" : ""));
    if (log.Done("projector", sig, {yml})) {
      projector = calib::ReadProjectorCalibration(yml);
    } else {
      progress(fmt::format("calibrating the projector from {} ...", cap.projector.planes));
      calib::ProjectorCalibOptions po;
      po.rear_projection = cap.projector.rear;
      projector = calib::CalibrateProjector(
          camera, calib::BoardSpec::Parse(cap.projector.board),
          calib::ParseProjectorChessboard(cap.projector.pattern, cap.projector.projector_size),
          calib::ReadPlaneFolder(cap.projector.planes), po);
      WriteAtomically(yml, [&](const std::string& tmp) {
        calib::WriteProjectorCalibration(tmp, *projector, camera,
                                         cap.projector.pattern + " on " + cap.projector.projector_size);
      });
      log.Record("projector", sig);
      computed = true;
    }
    progress(fmt::format("projector: {}", projector->BriefReport()));
    for (const std::string& d : projector->dropped) progress(fmt::format("  dropped {}", d));
  }
  if (projector) rep.projector_rms_px = projector->stereo_projector_rms;

  std::optional<calib::ResponseCurve> response;
  if (!cap.response.file.empty()) {
    response = calib::ReadResponse(cap.response.file);
  } else if (!cap.response.stacks.empty()) {
    const std::string yml = (work / "response.yml").string();
    const std::string sig = Signature(cap.response.stacks, calib::ToString(cap.exposure_times));
    if (log.Done("response", sig, {yml})) {
      response = calib::ReadResponse(yml);
    } else {
      progress("calibrating the camera response ...");
      std::vector<calib::ExposureStack> stacks;
      for (const auto& d : cap.response.stacks) stacks.push_back(calib::ReadExposureStack(d));
      calib::ResponseOptions ro;
      ro.shutter = cap.exposure_times;
      response = calib::CalibrateResponse(stacks, ro);
      if (response->other_fit_rms > 0 || response->shutter == calib::ShutterTimes::kApex)
        progress("response: " + response->ShutterReport());
      WriteAtomically(yml, [&](const std::string& tmp) { calib::WriteResponse(tmp, *response); });
      log.Record("response", sig);
      computed = true;
    }
  }
  const calib::ResponseCurve* curve = response ? &*response : nullptr;
  // The file the curve came from: stages that merge stacks depend on it.
  const std::string response_file = !cap.response.file.empty() ? cap.response.file : (work / "response.yml").string();
  // How every stack's exposure times are read: one reading for the whole capture, so that no
  // stack's scale differs from another's by a label's rounding.
  calib::MergeOptions merge_options;
  merge_options.shutter = cap.exposure_times;
  merge_options.sensor_black = {cap.sensor_black[0], cap.sensor_black[1], cap.sensor_black[2]};
  // Stages whose merges the sensor black level changes depend on it.
  const std::string black_sig = cap.sensor_black == std::array<double, 3>{}
                                    ? ""
                                    : fmt::format(" sensor_black {}", nlohmann::json(cap.sensor_black).dump());
  std::string merge_sig;  // how every stack is merged: set below, once the times' reading is known
  if (merge_options.shutter == calib::ShutterTimes::kAuto && curve) merge_options.shutter = curve->shutter;
  if (merge_options.shutter == calib::ShutterTimes::kAuto) {
    // Linear photos: their brightness steps decide, pooled over the white and lighting stacks
    // until every pair of times that tells the readings apart has been judged.
    std::vector<std::string> judged;
    if (fs::is_directory(cap.white.white)) judged.push_back(cap.white.white);
    for (const auto& c : cap.conditions) judged.push_back(c.stack);
    const std::string txt = (work / "exposure_times.txt").string();
    const std::string sig = Signature(judged, black_sig);
    std::string reading;
    if (log.Done("exposure_times", sig, {txt})) {
      std::ifstream(txt) >> reading;
    } else {
      calib::ShutterJudge judge(merge_options);
      for (const std::string& d : judged) {
        const calib::ExposureStack stack = calib::ReadExposureStack(d);
        if (stack.IsEightBit()) continue;  // refused in the merge, which names the response
        judge.Add(stack);
        if (judge.Decisive()) break;
      }
      const calib::ShutterChoice choice = judge.Choice();
      reading = calib::ToString(choice.times);
      if (choice.pairs > 0) progress(choice.BriefReport());
      WriteAtomically(txt, [&](const std::string& tmp) {
        std::ofstream(tmp) << reading << "\n" << choice.BriefReport() << "\n";
      });
      log.Record("exposure_times", sig);
    }
    merge_options.shutter = calib::ParseShutterTimes(reading, txt);
  }
  const std::string times_sig = calib::ToString(merge_options.shutter);
  rep.exposure_times = times_sig;
  merge_sig = times_sig + black_sig;

  // An HDR image or a stack merged here, its time warning shown.
  auto read_hdr = [&](const std::string& path) {
    calib::HdrReadInfo info;
    cv::Mat img = calib::ReadHdrOrStack(path, curve, merge_options, &info);
    if (!info.time_warning.empty()) progress("warning: " + info.time_warning);
    return img;
  };

  // The lens's vignetting: every HDR image is divided by the camera flat, normalised to its mean
  // (a constant factor that the white gains take back).
  cv::Mat camera_flat;
  if (!cap.camera_flat.empty()) {
    const std::string exr = (work / "camera_flat.exr").string();
    const std::string sig = Signature({cap.camera_flat, response_file}, merge_sig);
    if (log.Done("camera_flat", sig, {exr})) {
      camera_flat = calib::ReadLinearRgb(exr);
    } else {
      progress("camera flat ...");
      try {
        const cv::Mat merged = read_hdr(cap.camera_flat);
        if (merged.size() != camera.image_size)
          throw calib::CalibError(fmt::format("{}: images are {}x{} but the camera calibration is {}x{}",
                                              cap.camera_flat, merged.cols, merged.rows, camera.image_size.width,
                                              camera.image_size.height));
        camera_flat = calib::NormalizedCameraFlat(merged, cap.camera_flat);
      } catch (const calib::CalibError& e) {
        throw InputError(fmt::format("{}: camera_flat: {}", cap.file, e.what()));
      }
      WriteAtomically(exr, [&](const std::string& tmp) { calib::WriteExr(tmp, camera_flat); });
      log.Record("camera_flat", sig);
      computed = true;
    }
  }
  // An HDR image of the capture's photos through the camera flat (+inf stays +inf); its size is
  // checked first.
  auto flatten = [&](const cv::Mat& img) {
    if (camera_flat.empty() || img.empty()) return img;
    TL_CHECK(img.size() == camera_flat.size());
    cv::Mat out;
    cv::divide(img, camera_flat, out);
    return out;
  };

  calib::WhiteBalance white;
  const std::string flat_exr = (work / "flat_field.exr").string();
  if (!cap.white.file.empty()) {
    white = calib::ReadWhiteBalance(cap.white.file);
    const bool flat = !cap.camera_flat.empty();
    if (white.camera_flat != flat)
      progress(fmt::format("warning: {}: its white reference was {}divided by a camera flat, this capture's images "
                           "are{}: the gains may be off by the vignetting over its patch (calibrate white {})",
                           cap.white.file, white.camera_flat ? "" : "not ", flat ? "" : " not",
                           flat ? "--camera-flat " + cap.camera_flat : "without --camera-flat"));
    if (white.sensor_black != merge_options.sensor_black)
      progress(fmt::format("warning: {}: its stacks were merged with a sensor black level of {:g},{:g},{:g}, this "
                           "capture's with {:g},{:g},{:g}: the gains may be off by its offset (calibrate white "
                           "--sensor-black)", cap.white.file, white.sensor_black[0], white.sensor_black[1],
                           white.sensor_black[2], cap.sensor_black[0], cap.sensor_black[1], cap.sensor_black[2]));
    if (!white.exposure_times.empty() && white.exposure_times != times_sig)
      progress(fmt::format("warning: {}: its white stack's exposure times were read {}, this capture's are read {}: "
                           "the gains may be off by up to 7 % (calibrate white --exposure-times {})",
                           cap.white.file, white.exposure_times, times_sig, times_sig));
  } else {
    const std::string yml = (work / "white.yml").string();
    const std::string sig = Signature({cap.white.white, cap.white.black, response_file, cap.camera_flat},
                                      fmt::format("{}{}{}{}", nlohmann::json(cap.white.patch).dump(),
                                                  nlohmann::json(cap.white.albedo).dump(), merge_sig,
                                                  cap.white.flat_field ? " flat_field" : ""));
    std::vector<std::string> outputs{yml};
    if (cap.white.flat_field) outputs.push_back(flat_exr);
    if (log.Done("white", sig, outputs)) {
      white = calib::ReadWhiteBalance(yml);
    } else {
      progress("white balance ...");
      cv::Mat w = read_hdr(cap.white.white);
      cv::Mat b = cap.white.black.empty() ? cv::Mat() : read_hdr(cap.white.black);
      for (const auto& [img, path] : {std::pair<const cv::Mat&, const std::string&>{w, cap.white.white},
                                      std::pair<const cv::Mat&, const std::string&>{b, cap.white.black}})
        if (!img.empty() && img.size() != camera.image_size)
          throw InputError(fmt::format("{}: images are {}x{} but the camera calibration is {}x{}", path, img.cols,
                                       img.rows, camera.image_size.width, camera.image_size.height));
      w = flatten(w);
      b = flatten(b);
      std::vector<cv::Point2f> patch;
      for (const auto& p : cap.white.patch) patch.emplace_back(float(p[0]), float(p[1]));
      try {
        white = calib::WhiteFromPatch(w, b, patch, {cap.white.albedo[0], cap.white.albedo[1], cap.white.albedo[2]});
        if (fs::is_directory(cap.white.white)) white.exposure_times = times_sig;
        white.sensor_black = merge_options.sensor_black;
        white.camera_flat = !camera_flat.empty();
      } catch (const calib::CalibError& e) {
        throw InputError(fmt::format("{}: white: {}", cap.file, e.what()));
      }
      WriteAtomically(yml, [&](const std::string& tmp) {
        calib::WriteWhiteBalance(tmp, white, b.empty() ? cv::Vec3d() : cv::Vec3d(cv::mean(b).val), cap.white.black);
      });
      if (cap.white.flat_field) {
        // The reference's irradiance in q units (1 where the patch's falls) per channel: its
        // radiance gains x (white - black) over albedo / pi.
        const cv::Mat diff = b.empty() ? w : cv::Mat(w - b);
        cv::Scalar scale;
        for (int k = 0; k < 3; ++k) scale[k] = white.gains[k] * CV_PI / cap.white.albedo[size_t(k)];
        cv::Mat flat;
        cv::multiply(diff, scale, flat);
        WriteAtomically(flat_exr, [&](const std::string& tmp) { calib::WriteExr(tmp, flat); });
      }
      log.Record("white", sig);
      computed = true;
    }
  }
  for (int c = 0; c < 3; ++c) rep.white_gains[size_t(c)] = white.gains[c];
  if (!computed) rep.reused.push_back("calibration");
  computed = false;
  stage_done("calibration");

  // 2. HDR.
  const fs::path hdr_dir = work / "hdr";
  // key: the stage log's; exr: where the merged image is kept.
  auto merge = [&](const std::string& key, const fs::path& exr_path, const std::string& stack) {
    const std::string exr = exr_path.string();
    const std::string sig = Signature({stack, response_file}, merge_sig);
    if (log.Done(key, sig, {exr})) return flatten(calib::ReadLinearRgb(exr));
    const calib::ExposureStack s = calib::ReadExposureStack(stack);
    if (s.Size() != camera.image_size)
      throw InputError(fmt::format("{}: photos are {}x{} but the camera calibration is {}x{}", stack,
                                   s.Size().width, s.Size().height, camera.image_size.width,
                                   camera.image_size.height));
    if (s.IsEightBit() && !curve)
      throw InputError(fmt::format("{}: 8-bit photos need a camera response (capture.json: response)", stack));
    const calib::HdrImage hdr = calib::MergeHdr(s, s.IsEightBit() ? curve : nullptr, nullptr, merge_options);
    if (!hdr.time_warning.empty()) progress("warning: " + hdr.time_warning);
    WriteAtomically(exr, [&](const std::string& tmp) { calib::WriteExr(tmp, hdr.radiance); });
    log.Record(key, sig);
    computed = true;
    return flatten(hdr.radiance);
  };
  std::vector<cv::Mat> hdr;
  for (size_t m = 0; m < cap.conditions.size(); ++m) {
    const std::string& name = cap.conditions[m].name;
    hdr.push_back(merge("hdr:" + name, hdr_dir / (name + ".exr"), cap.conditions[m].stack));
    progress(fmt::format("hdr {}/{}: {}", m + 1, cap.conditions.size(), cap.conditions[m].stack));
  }
  // Outside hdr/, whose files are named after the conditions (one may be called "black").
  const cv::Mat black = cap.black.empty() ? cv::Mat() : merge("black_hdr", work / "black.exr", cap.black);
  if (!computed) rep.reused.push_back("hdr");
  stage_done("hdr");

  // 3. Pose.
  std::vector<cv::Point2d> corners;
  bool outline_unrefined = false;  // corners found: the outline's, its sides not refined
  if (!cap.face_corners_px.empty()) {
    for (const auto& p : cap.face_corners_px) corners.emplace_back(p[0], p[1]);
  } else {
    // Saturated pixels (+inf) stay +inf, the brightest (DetectFaceCorners): a front-lit region
    // saturates where its own condition lights it, and those pixels are the face's too. The
    // fitted conditions only: together they light the whole face, and a validation spot adds
    // nothing but a saturated disc (front-lit: corners 0.31 px off instead of 0.26).
    cv::Mat sum = cv::Mat::zeros(camera.image_size, CV_32FC3);
    for (size_t m = 0; m < hdr.size(); ++m) {
      if (cap.conditions[m].validation) continue;
      cv::Mat known = hdr[m].clone();
      cv::patchNaNs(known, 0);
      for (auto it = known.begin<cv::Vec3f>(); it != known.end<cv::Vec3f>(); ++it)
        for (int c = 0; c < 3; ++c)
          if ((*it)[c] == -std::numeric_limits<float>::infinity()) (*it)[c] = 0;
      sum += known;
    }
    // Where the camera sees side faces too, the sides of the outline found do not refine; the
    // outline itself is a start for the block's outline fit below.
    std::vector<cv::Point2d> outline;
    corners = DetectFaceCorners(sum, &cam, &outline);
    if (corners.empty()) {
      corners = outline;
      outline_unrefined = true;
    }
    if (corners.empty())
      throw InputError(fmt::format("{}: face_corners_px is \"auto\" but no four-sided sample was "
                                   "found in the images; give the corners", cap.file));
    progress(fmt::format("found the {}: {}", outline_unrefined ? "sample's outline" : "front face's corners",
                         CornerList(corners)));
  }
  // The black level, subtracted from every condition: saturated (+inf) samples of it, which do
  // not occur in practice, count as 0 so that they cannot hide a condition's own saturation.
  cv::Mat black_level = black.clone();
  for (auto it = black_level.begin<cv::Vec3f>(); it != black_level.end<cv::Vec3f>(); ++it)
    for (int k = 0; k < 3; ++k)
      if (!std::isfinite((*it)[k])) (*it)[k] = 0;
  calib::Pose camera_from_sample = EstimateSamplePose(cam, corners, g, h, cap.file + ": face_corners_px",
                                                      &rep.pose_rms_px, !cap.face_corners_px.empty());
  // The lens's blur: given, or read off the outline in the fitted conditions less the black
  // (front-lit, each condition saturates where it lights the face, and their sum everywhere).
  std::vector<cv::Mat> lit;
  for (size_t m = 0; m < hdr.size(); ++m)
    if (!cap.conditions[m].validation) lit.push_back(hdr[m]);
  std::string blur_said;
  const auto estimate_blur = [&] {
    const OutlineBlur b = EstimateOutlineBlur(lit, cam, camera_from_sample, g, h, 3.0, black_level);
    rep.camera_blur_px = b.sigma_px;
    rep.camera_blur_profiles = b.profiles;
    blur_said = b.positions == 0
                    ? fmt::format("{}: camera_blur_px is \"auto\" but the face's outline is too short in the photos, "
                                  "or too near their border, for profiles across it; taking the lens as sharp (give "
                                  "camera_blur_px)", cap.file)
                : b.profiles == 0
                    ? fmt::format("{}: camera_blur_px is \"auto\" but the face's outline shows nowhere unsaturated "
                                  "in the photos; taking the lens as sharp (give camera_blur_px)", cap.file)
                    : fmt::format("the lens's blur on the sample's photos: sigma {:.2f} px (from {} profiles across "
                                  "the face's outline; residual {:.2g} against {:.2g} for a sharp lens)",
                                  b.sigma_px, b.profiles, b.rms, b.rms_sharp);
  };
  // A camera beside the projector (the paper's front-lit rig) may see side faces of the block:
  // the front face's edges next to them do not show, and the outline is the block's.
  const std::array<double, 3> size = SampleSize(g, h);
  const bool exact = !cap.face_corners_px.empty() && !cap.face_corners_near;
  const CornerSource source = exact ? CornerSource::kExact
                              : cap.face_corners_near ? CornerSource::kNear : CornerSource::kFound;
  const OutlineFitNeed need =
      NeedsBlockOutlineFit(cam, camera_from_sample, size, source, rep.pose_rms_px, outline_unrefined);
  OutlineChoice choice;  // use_fit: the block's outline fit placed the corners (or checked exact ones)
  std::string shows;     // the side faces seen
  if (need.needed) {
    choice = ChooseBlockOutline(lit, cam, size, camera_from_sample, corners, cap.camera_blur_px.value_or(1.0), need,
                                black_level);
    const char* names[4] = {"x = 0", "x = X", "y = 0", "y = Y"};
    for (int f = 0; f < 4; ++f)
      if (choice.side_px[size_t(f)] > kSideFaceShowsPx)
        shows += fmt::format("{}{} ({:.1f} px wide)", shows.empty() ? "" : ", ", names[f], choice.side_px[size_t(f)]);
    if (!choice.size_hint.empty())
      progress(fmt::format("warning: {}: sample_mm may be off: {}, and a block of that width fits the outline in "
                           "the photos better; the pose is fitted to the face's four corners", cap.file,
                           choice.size_hint));
    else if (!choice.use_fit)
      progress(choice.settled ? "the block's outline shows no side face; refining the face's four corners"
                       : "the block's outline fit did not settle; refining the face's four corners instead");
    if (shows.empty()) shows = "none";
  }
  if (choice.use_fit) {
    const BlockOutlineFit& fit = choice.fit;
    const bool settled = choice.settled;
    progress(fmt::format("the pose is fitted to the block's outline; side faces the camera sees besides the front "
                         "face: {}", shows));
    double moved = 0;
    for (size_t k = 0; k < fit.corners.size(); ++k) moved = std::max(moved, cv::norm(fit.corners[k] - corners[k]));
    if (!settled) {
      if (!exact)
        throw InputError(fmt::format("{}: the sample's outline is not a face's: the camera sees side faces of the "
                                     "block ({}), and the block's outline fit did not settle (docs/capture.md, "
                                     "\"Side faces\"); give face_corners_px as measured", cap.file, shows));
      progress("the block's outline fit did not settle; face_corners_px are used as given, unchecked");
    } else if (exact) {
      if (moved > 1)
        progress(fmt::format("warning: {}: face_corners_px lie up to {:.1f} px from the block's outline fitted in "
                             "the photos (its front corners: {}); give them as {{\"near\": [...]}} to have them "
                             "refined, or \"auto\"", cap.file, moved, CornerList(fit.corners)));
    } else {
      corners = fit.corners;
      camera_from_sample = fit.camera_from_sample;
      rep.pose_rms_px = fit.rms_px;
      rep.face_corners = "refined";
      rep.face_corners_edge_points = fit.edge_points;
      progress(fmt::format("fitted the block's outline on {} edge points of {} sides (RMS {:.2f} px) through a lens "
                           "blur of {:.2f} px (the front corners moved up to {:.2f} px): {}", fit.edge_points,
                           fit.sides, fit.rms_px, fit.blur_px, moved, CornerList(corners)));
    }
    if (cap.camera_blur_px) {
      rep.camera_blur_px = *cap.camera_blur_px;
    } else if (settled) {
      rep.camera_blur_px = fit.blur_px;
      rep.camera_blur_profiles = fit.edge_points;
      blur_said = fmt::format("the lens's blur on the sample's photos: sigma {:.2f} px (from the block's outline)",
                              fit.blur_px);
    } else {
      estimate_blur();
    }
  } else {
    if (cap.camera_blur_px) rep.camera_blur_px = *cap.camera_blur_px;
    else estimate_blur();
    // Corners found automatically or given near the face, refined against every fitted
    // condition's photo through the blur (RefineFaceCorners; corners given near it first with
    // the edges let within kNearCornerReachPx of them); then the pose, and the blur read again
    // along the new outline. Corners given as exact are checked (the usual pass, the near ones
    // where it moves them by more than a pixel or fails), and left as they are.
    int points = 0;
    double refine_blur = 0;
    const auto refine = [&](bool near) {
      const std::vector<cv::Point2d> refined = RefineFaceCornersWithin(
          lit, cam, corners, rep.camera_blur_px, near ? kNearCornerReachPx : 0, black_level, &points, &refine_blur);
      double moved = 0;
      for (size_t k = 0; k < refined.size(); ++k) moved = std::max(moved, cv::norm(refined[k] - corners[k]));
      return std::make_pair(refined, moved);
    };
    if (cap.face_corners_px.empty() || cap.face_corners_near) {
      const auto [refined, moved] = refine(cap.face_corners_near);
      rep.face_corners = cap.face_corners_near ? "near" : "found";
      if (refined.empty()) {
        progress(fmt::format("the face's corners were not refined: too few profiles across a side show an "
                             "unsaturated edge; keeping the {} ones", cap.face_corners_near ? "given" : "found"));
      } else {
        rep.face_corners = "refined";
        rep.face_corners_edge_points = points;
        corners = refined;
        camera_from_sample = EstimateSamplePose(cam, corners, g, h, cap.file + ": face_corners_px", &rep.pose_rms_px);
        // Where the pose's outline misses the face's (sample_mm off), the blur the refinement
        // found on the face's own edges, not one read across the pose's outline.
        if (!cap.camera_blur_px && rep.pose_rms_px > 1 && refine_blur > 0) {
          rep.camera_blur_px = refine_blur;
          rep.camera_blur_profiles = points;
          blur_said = fmt::format("the lens's blur on the sample's photos: sigma {:.2f} px (from the face's edges; the "
                                  "pose misses the corners by {:.2f} px RMS)", refine_blur, rep.pose_rms_px);
        } else if (!cap.camera_blur_px) {
          estimate_blur();
        }
        progress(fmt::format("refined the corners on {} edge points through a lens blur of {:.2f} px (moved up to "
                             "{:.2f} px): {}", points, refine_blur, moved, CornerList(corners)));
      }
    } else if (const auto [close, close_moved] = refine(false); close.empty() || close_moved > 1) {
      // Off by more than a pixel, or by more than the usual pass reaches: the near passes.
      const auto [refined, moved] = refine(true);
      if (!refined.empty() && moved > 1)
        progress(fmt::format("warning: {}: face_corners_px lie up to {:.1f} px from the face's outline in the "
                             "photos (refined: {}); give them as {{\"near\": [...]}} to have them refined, or "
                             "\"auto\"", cap.file, moved, CornerList(refined)));
    }
  }
  if (!blur_said.empty()) progress(blur_said);
  for (const auto& p : corners) rep.face_corners_px.push_back({p.x, p.y});
  stage_done("pose");

  // 4. Mapping.
  Dataset d;
  d.shape = g;
  d.spacing_mm = h;
  d.C = cap.C;
  d.setup = cap.setup;
  Dataset validation = d;  // the validation conditions (CaptureSpec::Condition::validation)
  const int64_t F = g.face_size();
  DeviceIntrinsics proj;
  calib::Pose projector_from_camera;
  if (projector) {
    proj = DeviceIntrinsics::From(projector->projector_size, projector->K, projector->dist);
    projector_from_camera.R = projector->R;
    projector_from_camera.t = projector->T;
  }
  // The projector's irradiance on each lit-face node relative to the white patch's (1 without
  // a flat field): the white reference's image read over the lit face's dual boxes, the mean
  // of its channels.
  // (Light-spec conditions take their q as given: without a pattern condition it is not read.)
  std::vector<float> irradiance(size_t(F), 1.0f);
  const bool patterns = std::any_of(cap.conditions.begin(), cap.conditions.end(),
                                    [](const CaptureSpec::Condition& c) { return !c.pattern.empty(); });
  if (cap.white.flat_field && patterns) {
    calib::Pose sample_from_lit_plane;  // (x, y, 0) -> (x, y, Z): the lit face as a front face
    sample_from_lit_plane.t = {0, 0, LitFaceZ(g, h, cap.setup)};
    const FaceSamples flat = ResampleFrontFace(calib::ReadLinearRgb(flat_exr), cam,
                                               camera_from_sample * sample_from_lit_plane, g, h, o.face_samples);
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
                                     cap.file, problem, f % g.nx, f / g.nx, cap.white.white));
      irradiance[size_t(f)] = v;
      lo = std::min(lo, v);
      hi = std::max(hi, v);
    }
    progress(fmt::format("flat field: the projector's irradiance on the lit face is {:.3f}-{:.3f} of the white "
                         "patch's", lo, hi));
    rep.flat_field = {lo, hi};
  }
  // The pixels across the face's outline also see the dark surround, and the lens's blur spreads
  // the outline further: the border nodes' means are divided by the face's coverage of their
  // samples, blurred as the lens blurs (ResampleFrontFace).
  const cv::Mat coverage = FaceCoverage(cam, camera_from_sample, g, h, rep.camera_blur_px);
  for (size_t m = 0; m < cap.conditions.size(); ++m) {
    const auto& c = cap.conditions[m];
    cv::Mat img = hdr[m];
    if (!black_level.empty()) img = hdr[m] - black_level;  // inf - finite stays inf (saturated)
    const FaceSamples fsm = ResampleFrontFace(img, cam, camera_from_sample, g, h, o.face_samples, &coverage);
    DatasetCondition dc;
    dc.name = c.name;
    if (!c.pattern.empty()) {
      cv::Mat pat = calib::ReadLinearRgb(c.pattern), grey;
      cv::cvtColor(pat, grey, cv::COLOR_RGB2GRAY);
      if (grey.size() != projector->projector_size)
        throw InputError(fmt::format("{}: pattern is {}x{} but the projector is {}x{}", c.pattern, grey.cols,
                                     grey.rows, projector->projector_size.width, projector->projector_size.height));
      std::vector<float> q = ProjectPatternOnFace(grey, proj, projector_from_camera, camera_from_sample, g, h, cap.setup);
      for (int64_t f = 0; f < F; ++f) q[size_t(f)] *= irradiance[size_t(f)];
      dc.q = GreyPattern(q);
    } else {
      dc.q = GreyPattern(RasterizeLightFile(c.Light(cap.dir), g, h));
    }
    dc.mask = MeasurementMask(g, cap.setup, dc.q, o.mask_margin);
    AcquireConditionReport cr;
    cr.name = c.name;
    cr.validation = c.validation;
    double brightest = 0;
    for (int64_t f = 0; f < F; ++f) {
      const bool valid = std::isfinite(fsm.value[0][size_t(f)]) && fsm.saturated[size_t(f)] == 0;
      if (fsm.saturated[size_t(f)] > 0) ++cr.saturated_nodes;
      for (int k = 0; k < 3; ++k) {
        const float v = valid ? float(white.gains[k] * fsm.value[size_t(k)][size_t(f)]) : 0.0f;
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
    rep.conditions.push_back(cr);
    (c.validation ? validation : d).conditions.push_back(std::move(dc));
  }
  if (std::string why = d.Validate(); !why.empty()) TL_CHECK_MSG(false, why);
  rep.dataset_dir = (work / "dataset").string();
  WriteFolderAtomically(rep.dataset_dir, [&](const std::string& tmp) {
    WriteDataset(tmp, d);
    if (!validation.conditions.empty()) WriteDataset((fs::path(tmp) / "validation").string(), validation);
  });
  progress(fmt::format("wrote the node-space dataset {}/dataset.json ({} conditions{}, grid {})",
                       rep.dataset_dir, d.conditions.size(),
                       validation.conditions.empty() ? "" : fmt::format(", {} in validation/", validation.conditions.size()),
                       g.ToString()));
  stage_done("mapping");

  // 5. Solve.
  nlohmann::json j;
  if (o.solve) {
    progress("solving for kappa and mu ...");
    solving = true;
    RecoveryState state;
    RecoveryOptions ro = o.recovery;
    if (!ro.stop) ro.stop = o.stop;  // the homogeneous fit and the level search
    rep.solve = Recover(d, ro, &state, iteration, &validation);
    const Material m = MaterialFromState(d, state, cap.eta);
    WriteMaterial(out, m);
    stage_done("solve");
    // Previews: measured | fitted | residual per condition, kappa and mu slices.
    const fs::path prev = work / "previews";
    fs::create_directories(prev);
    // Every condition in the capture's order, validation ones included (their E is the
    // validation error per condition; a fitted condition's is rep.solve's).
    std::vector<const DatasetCondition*> all;
    for (size_t c = 0, t = 0, v = 0; c < rep.conditions.size(); ++c)
      all.push_back(rep.conditions[c].validation ? &validation.conditions[v++] : &d.conditions[t++]);
    std::vector<FacePattern> q;
    for (const DatasetCondition* c : all) q.push_back(c->q);
    MultigridOptions mg;
    mg.tolerance = 1e-8;
    const auto fitted = RenderMeasured(m, d.setup, q, mg);
    for (size_t c = 0; c < all.size(); ++c) {
      rep.conditions[c].fit_error = RelightingError({fitted[c]}, {all[c]->L}, {all[c]->mask});
      const std::string p = (prev / fmt::format("fit_{}.png", all[c]->name)).string();
      WriteFitComparison(p, g, all[c]->L, fitted[c], all[c]->mask);
      rep.previews.push_back(p);
    }
    for (const auto& p : WriteMaterialSlices((prev / "material").string(), m)) rep.previews.push_back(p);
    WritePreviewIndex(prev / "index.html", rep, cap.file, g);
    rep.previews.push_back((prev / "index.html").string());
    stage_done("previews");
    j["solve"] = {{"termination", TerminationName(rep.solve.termination)},
                  {"message", rep.solve.message},
                  {"iterations", rep.solve.iterations},
                  {"solves", rep.solve.solves},
                  {"solve_tolerance", o.recovery.solve_tolerance},
                  {"fit_error", rep.solve.fit_error},
                  {"homogeneous_kappa", rep.solve.homogeneous_kappa},
                  {"homogeneous_mu", rep.solve.homogeneous_mu},
                  {"level_mu_factor", rep.solve.level_factor},
                  {"level_seconds", rep.solve.level_seconds},
                  {"validation_error", rep.solve.validation_error},
                  {"validation_iteration", rep.solve.validation_iteration}};
  }
  j["capture"] = cap.file;
  j["material"] = o.solve ? out : "";
  j["dataset"] = rep.dataset_dir;
  j["grid"] = {g.nx, g.ny, g.nz};
  j["spacing_mm"] = h;
  j["setup"] = SetupName(cap.setup);
  j["camera_rms_px"] = rep.camera_rms_px;
  j["projector_rms_px"] = rep.projector_rms_px;
  j["pose_rms_px"] = rep.pose_rms_px;
  j["face_corners_px"] = rep.face_corners_px;
  j["face_corners"] = rep.face_corners;
  j["face_corners_edge_points"] = rep.face_corners_edge_points;
  j["camera_blur_px"] = rep.camera_blur_px;
  j["camera_blur"] = cap.camera_blur_px ? "given" : "found";
  j["camera_blur_profiles"] = rep.camera_blur_profiles;
  j["white_gains"] = rep.white_gains;
  if (cap.white.flat_field && rep.flat_field[1] > 0) j["flat_field"] = rep.flat_field;
  j["exposure_times"] = rep.exposure_times;
  nlohmann::json st = nlohmann::json::object();
  for (const auto& [name, t] : rep.stage_seconds) st[name] = t;
  j["stage_seconds"] = st;
  j["reused"] = rep.reused;
  j["warnings"] = rep.warnings;
  nlohmann::json cs = nlohmann::json::array();
  for (const auto& c : rep.conditions)
    cs.push_back({{"name", c.name}, {"measured_nodes", c.measured_nodes}, {"saturated_nodes", c.saturated_nodes},
                  {"masked_nodes", c.masked_nodes}, {"q_sum", c.q_sum}, {"fit_error", c.fit_error},
                  {"validation", c.validation}});
  j["conditions"] = cs;
  j["previews"] = rep.previews;
  rep.report_json = (work / "report.json").string();
  WriteAtomically(rep.report_json, [&](const std::string& tmp) { std::ofstream(tmp) << j.dump(2) << "\n"; });
  return rep;
}

}  // namespace translume::acquire
