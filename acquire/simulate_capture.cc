// SPDX-License-Identifier: MIT
#include "acquire/simulate_capture.h"

#include <fmt/format.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "acquire/capture.h"
#include "calib/board.h"
#include "calib/hdr.h"
#include "calib/parallel.h"
#include "calib/projector_pattern.h"
#include "solver/atomic_file.h"
#include "solver/json_file.h"
#include "solver/light.h"
#include "solver/material_io.h"
#include "solver/simulate.h"
#include "solver/status.h"

namespace translume::acquire {
namespace {

namespace fs = std::filesystem;
constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180;

cv::Matx33d Rotation(double rx, double ry, double rz) {
  cv::Matx33d a, b, c;
  cv::Rodrigues(cv::Vec3d(rx, 0, 0), a);
  cv::Rodrigues(cv::Vec3d(0, ry, 0), b);
  cv::Rodrigues(cv::Vec3d(0, 0, rz), c);
  return a * b * c;
}

// projector_from_camera for a projector at camera-frame point P aimed at camera-frame point c,
// its image rows running along the camera's (image y down).
calib::Pose AimedProjector(const cv::Vec3d& P, const cv::Vec3d& c) {
  const cv::Vec3d z = cv::normalize(c - P);
  cv::Vec3d y = cv::Vec3d(0, 1, 0) - z[1] * z;
  y = cv::normalize(y);
  const cv::Vec3d x = y.cross(z);
  calib::Pose camera_from_projector;
  camera_from_projector.R = cv::Matx33d(x[0], y[0], z[0], x[1], y[1], z[1], x[2], y[2], z[2]);
  camera_from_projector.t = P;
  return camera_from_projector.Inverse();
}

struct Geometry {
  GridShape grid;
  double h, X, Y, Z;
};

Geometry Geom(const GridShape& g, double h) {
  return {g, h, double(g.nx - 1) * h, double(g.ny - 1) * h, double(g.nz - 1) * h};
}

// Places camera and projector for `setup` given the intrinsics already in `r` and a camera
// distance factor; the projector's focal length is chosen so the lit face spans ~60 % of its
// width.
void PlaceRig(CaptureRig* r, const Geometry& g, Setup setup, double distance_scale,
              const cv::Vec3d& tilt_deg, bool keep_projector_K) {
  const double D = distance_scale * r->camera.K(0, 0) * g.X / (0.6 * r->camera.size.width);
  r->camera_from_sample.R = Rotation(tilt_deg[0] * kDeg, tilt_deg[1] * kDeg, tilt_deg[2] * kDeg);
  r->camera_from_sample.t =
      cv::Vec3d(0.01 * D, -0.005 * D, D) - r->camera_from_sample.R * cv::Vec3d(g.X / 2, g.Y / 2, 0);
  const double z_lit = setup == Setup::kBack ? g.Z : 0.0;
  const cv::Vec3d c = r->camera_from_sample.Apply({g.X / 2, g.Y / 2, z_lit});
  cv::Vec3d P;
  if (setup == Setup::kFront) {
    P = cv::Vec3d(0.3 * D, -0.05 * D, 0);
  } else {
    const cv::Vec3d behind = r->camera_from_sample.R * cv::Vec3d(0, 0, 1);
    P = c + 1.1 * D * behind + cv::Vec3d(0.04 * D, 0.02 * D, 0);
  }
  r->projector_from_camera = AimedProjector(P, c);
  if (!keep_projector_K) {
    const double f = 0.6 * r->projector.size.width * cv::norm(c - P) / g.X;
    r->projector.K = {f, 0, (r->projector.size.width - 1) / 2.0, 0, f,
                      (r->projector.size.height - 1) / 2.0, 0, 0, 1};
  }
}

calib::SyntheticRig ToSyntheticRig(const CaptureRig& r) {
  calib::SyntheticRig s;
  s.camera = {r.camera.size, r.camera.K, r.camera.dist};
  s.projector = {r.projector.size, r.projector.K, r.projector.dist};
  s.projector_from_camera = r.projector_from_camera;
  return s;
}

// Where a ray from o along d enters the block [0, X] x [0, Y] x [0, Z] (the slab method): the
// face (0: x = 0, 1: x = X, 2: y = 0, 3: y = Y, 4: z = 0, the front face, 5: z = Z) and the
// point, or -1 where it misses.
int EnterBlock(const Geometry& g, const cv::Vec3d& o, const cv::Vec3d& d, cv::Vec3d* at) {
  const double hi[3] = {g.X, g.Y, g.Z};
  double t_in = -std::numeric_limits<double>::infinity(), t_out = std::numeric_limits<double>::infinity();
  int face = -1;
  for (int a = 0; a < 3; ++a) {
    if (std::abs(d[a]) < 1e-15) {
      if (o[a] < 0 || o[a] > hi[a]) return -1;
      continue;
    }
    const double t0 = -o[a] / d[a], t1 = (hi[a] - o[a]) / d[a];
    if (std::min(t0, t1) > t_in) {
      t_in = std::min(t0, t1);
      face = 2 * a + (t1 < t0 ? 1 : 0);
    }
    t_out = std::min(t_out, std::max(t0, t1));
  }
  if (face < 0 || !(t_in < t_out) || t_in <= 0) return -1;
  *at = o + t_in * d;
  return face;
}

// Linear RGB image of the front face of the sample (or of the plane z = plane_z) through the
// lens's vignetting: shade(x, y) (mm, sample frame) inside the face grown by margin_mm on every
// side, 0 (a dark room) outside; every pixel the mean of samples x samples rays spread over it.
// With side_shade (margin 0 and plane_z 0 only), the block itself: rays that enter it through a
// side face take side_shade(face, u, z) there (face 0..3 as EnterBlock's; u = y on x = 0 and
// x = X, x on y = 0 and y = Y), those through the front face shade(x, y).
cv::Mat RenderFace(const CaptureRig& rig, const calib::SyntheticRig& srig, const Geometry& g,
                   const std::function<cv::Vec3d(double, double)>& shade, int samples = 3, double margin_mm = 0,
                   double plane_z = 0, const std::function<cv::Vec3d(int, double, double)>& side_shade = {}) {
  CV_Assert(!side_shade || (margin_mm == 0 && plane_z == 0));
  const cv::Mat& rays = srig.CameraRays();
  const calib::Pose sample_from_camera = rig.camera_from_sample.Inverse();
  const cv::Vec3d o = sample_from_camera.t;  // camera centre in the sample frame
  cv::Mat img(rig.camera.size, CV_32FC3);
  cv::parallel_for_(cv::Range(0, img.rows), [&](const cv::Range& rr) {
    for (int y = rr.start; y < rr.end; ++y)
      for (int x = 0; x < img.cols; ++x) {
        const cv::Vec2d r00 = rays.at<cv::Vec2d>(y, x), r10 = rays.at<cv::Vec2d>(y, x + 1);
        const cv::Vec2d r01 = rays.at<cv::Vec2d>(y + 1, x), r11 = rays.at<cv::Vec2d>(y + 1, x + 1);
        cv::Vec3d sum(0, 0, 0);
        for (int b = 0; b < samples; ++b)
          for (int a = 0; a < samples; ++a) {
            const double fa = (a + 0.5) / samples, fb = (b + 0.5) / samples;
            const cv::Vec2d q = (1 - fb) * ((1 - fa) * r00 + fa * r10) + fb * ((1 - fa) * r01 + fa * r11);
            const cv::Vec3d d = sample_from_camera.R * cv::Vec3d(q[0], q[1], 1.0);
            if (side_shade) {
              cv::Vec3d at;
              const int face = EnterBlock(g, o, d, &at);
              if (face == 4) sum += shade(at[0], at[1]);
              else if (face >= 0 && face < 4) sum += side_shade(face, face < 2 ? at[1] : at[0], at[2]);
              continue;
            }
            if (std::abs(d[2]) < 1e-12) continue;
            const double s = (plane_z - o[2]) / d[2];
            if (s <= 0) continue;
            const double sx = o[0] + s * d[0], sy = o[1] + s * d[1];
            if (sx < -margin_mm || sy < -margin_mm || sx > g.X + margin_mm || sy > g.Y + margin_mm) continue;
            sum += shade(sx, sy);
          }
        const cv::Vec3d v = sum / double(samples * samples);
        img.at<cv::Vec3f>(y, x) = cv::Vec3f(float(v[0]), float(v[1]), float(v[2]));
      }
  });
  if (rig.sample_blur_px > 0) cv::GaussianBlur(img, img, cv::Size(0, 0), rig.sample_blur_px);
  if (rig.camera_vignetting < 1) {
    const cv::Mat v = RadialFalloff(rig.camera, rig.camera_vignetting);
    for (int y = 0; y < img.rows; ++y)
      for (int x = 0; x < img.cols; ++x) img.at<cv::Vec3f>(y, x) *= v.at<float>(y, x);
  }
  return img;
}

// The white patch: the face's corners pulled 15 % towards its centre, so the patch spans
// [kPatchInset, 1 - kPatchInset] of the face's width and height.
constexpr double kPatchInset = 0.075;

// Bilinear interpolation of a node field (nx * ny, i + nx j) of the face at (x, y) mm.
double FaceBilinear(const std::vector<float>& f, const GridShape& s, double hf, double x, double y) {
  const double u = std::clamp(x / hf, 0.0, double(s.nx - 1)), v = std::clamp(y / hf, 0.0, double(s.ny - 1));
  const int64_t i = std::min(int64_t(u), s.nx - 2), j = std::min(int64_t(v), s.ny - 2);
  const double a = u - double(i), b = v - double(j);
  auto at = [&](int64_t ii, int64_t jj) { return double(f[size_t(ii + s.nx * jj)]); };
  return (1 - b) * ((1 - a) * at(i, j) + a * at(i + 1, j)) + b * ((1 - a) * at(i, j + 1) + a * at(i + 1, j + 1));
}

// Mean of a fine face field over coarse node (i, j)'s dual box (K fine cells per coarse cell,
// K even: the box's edges are fine nodes): the trapezoid rule over the fine nodes in the box,
// exact for the bilinear interpolant. This is what a node stands for in the finite-volume
// model, and what a camera measures over the node's area.
double DualBoxMean(const std::vector<float>& fine, const GridShape& fs, int K, int64_t i, int64_t j) {
  auto axis = [&](int64_t n, int64_t count, std::vector<std::pair<int64_t, double>>* w) {
    const int64_t lo = std::max<int64_t>(0, n * K - K / 2), hi = std::min<int64_t>(count - 1, n * K + K / 2);
    for (int64_t f = lo; f <= hi; ++f) w->emplace_back(f, (f == lo || f == hi) && K % 2 == 0 ? 0.5 : 1.0);
  };
  std::vector<std::pair<int64_t, double>> wx, wy;
  axis(i, fs.nx, &wx);
  axis(j, fs.ny, &wy);
  double sum = 0, wsum = 0;
  for (const auto& [fj, b] : wy)
    for (const auto& [fi, a] : wx) {
      sum += a * b * fine[size_t(fi + fs.nx * fj)];
      wsum += a * b;
    }
  return sum / wsum;
}

// Writes an exposure stack folder: tNN.png and exposures.json.
int WriteStack(const std::string& dir, const std::vector<cv::Mat>& photos, const std::vector<double>& times) {
  fs::create_directories(dir);
  nlohmann::json j;
  for (size_t k = 0; k < photos.size(); ++k) j[fmt::format("t{:02d}.png", k)] = times[k];
  // The PNG encoder is serial: photos in parallel.
  calib::ParallelFor(int(photos.size()), [&](int k) {
    calib::WritePhoto((fs::path(dir) / fmt::format("t{:02d}.png", k)).string(), photos[size_t(k)]);
  });
  std::ofstream((fs::path(dir) / "exposures.json").string()) << j.dump(2) << "\n";
  return int(photos.size());
}

std::vector<double> Exposures(double t0, int n) {
  std::vector<double> t;
  for (int k = 0; k < n; ++k) t.push_back(t0 * std::pow(2.0, k));
  return t;
}

}  // namespace

CaptureRig DefaultCaptureRig(const GridShape& grid, double h, Setup setup) {
  CaptureRig r;
  r.camera.size = {1024, 768};
  r.camera.K = {3000.0, 0, 515.3, 0, 3001.5, 380.7, 0, 0, 1};
  r.camera.dist = {-0.12, 0.09, 0.0004, -0.0003, 0.0};
  r.projector.size = {1024, 768};
  r.projector.dist = {0.03, -0.01, 0.0, 0.0, 0.0};
  r.noise.read_noise = 0.0005;
  r.noise.shot_noise = 0.0001;
  PlaceRig(&r, Geom(grid, h), setup, 1.0, {4.0, -3.0, 1.5}, false);
  return r;
}

CaptureRig ReadCaptureRig(const std::string& path, const GridShape& grid, double h, Setup setup) {
  const nlohmann::json j = ReadJsonFile(path, " the rig file");
  CaptureRig r = DefaultCaptureRig(grid, h, setup);
  auto fail = [&](const std::string& field, const std::string& why) {
    throw InputError(fmt::format("{}: {}: {}", path, field, why));
  };
  auto numbers = [&](const nlohmann::json& v, const std::string& field, size_t n) {
    if (!v.is_array() || v.size() != n) fail(field, fmt::format("expected {} numbers", n));
    std::vector<double> out;
    for (const auto& x : v) {
      if (!x.is_number()) fail(field, fmt::format("expected {} numbers", n));
      out.push_back(x.get<double>());
    }
    return out;
  };
  auto device = [&](const char* key, DeviceIntrinsics* d) {
    if (!j.contains(key)) return false;
    const auto& o = j[key];
    for (const auto& [k, v] : o.items())
      if (k != "size" && k != "K" && k != "dist") fail(std::string(key) + "." + k, "unknown field");
    if (o.contains("size")) {
      const auto s = numbers(o["size"], std::string(key) + ".size", 2);
      if (s[0] < 64 || s[1] < 64) fail(std::string(key) + ".size", "at least 64x64");
      d->size = {int(s[0]), int(s[1])};
    }
    if (o.contains("K")) {
      const auto k = numbers(o["K"], std::string(key) + ".K", 9);
      d->K = cv::Matx33d(k.data());
    }
    if (o.contains("dist")) {
      const auto k = numbers(o["dist"], std::string(key) + ".dist", 5);
      for (int i = 0; i < 5; ++i) d->dist[i] = k[size_t(i)];
    }
    return o.contains("K");
  };
  for (const auto& [k, v] : j.items())
    if (k != "camera" && k != "projector" && k != "distance_scale" && k != "tilt_deg" &&
        k != "camera_gain" && k != "projector_black" && k != "bits" && k != "read_noise" &&
        k != "shot_noise" && k != "black_offset" && k != "shutter_labels" && k != "projector_falloff" &&
        k != "camera_vignetting" && k != "sample_blur_px" && k != "comment")
      fail(k, "unknown field");
  device("camera", &r.camera);
  const bool projector_K = device("projector", &r.projector);
  double scale = 1.0;
  cv::Vec3d tilt(4.0, -3.0, 1.5);
  if (j.contains("distance_scale")) {
    if (!j["distance_scale"].is_number() || !(j["distance_scale"].get<double>() > 0))
      fail("distance_scale", "expected a positive number");
    scale = j["distance_scale"].get<double>();
  }
  if (j.contains("tilt_deg")) {
    const auto t = numbers(j["tilt_deg"], "tilt_deg", 3);
    tilt = {t[0], t[1], t[2]};
  }
  if (j.contains("camera_gain")) {
    const auto g = numbers(j["camera_gain"], "camera_gain", 3);
    for (double x : g)
      if (!(x > 0)) fail("camera_gain", "must be positive");
    r.camera_gain = {g[0], g[1], g[2]};
  }
  if (j.contains("projector_black")) {
    if (!j["projector_black"].is_number()) fail("projector_black", "expected a number");
    r.projector_black = j["projector_black"].get<double>();
    if (!(r.projector_black >= 0 && r.projector_black < 0.1)) fail("projector_black", "must be in [0, 0.1)");
  }
  for (const char* k : {"projector_falloff", "camera_vignetting"})
    if (j.contains(k)) {
      if (!j[k].is_number() || !(j[k].get<double>() > 0 && j[k].get<double>() <= 1))
        fail(k, "expected a number in (0, 1]");
      (std::string(k) == "projector_falloff" ? r.projector_falloff : r.camera_vignetting) = j[k].get<double>();
    }
  if (j.contains("sample_blur_px")) {
    const double blur = j["sample_blur_px"].is_number() ? j["sample_blur_px"].get<double>() : -1;
    if (!(blur >= 0 && blur <= 5)) fail("sample_blur_px", "expected a number in [0, 5]");
    r.sample_blur_px = blur;
  }
  if (j.contains("bits")) {
    if (!j["bits"].is_number_integer() || (j["bits"] != 8 && j["bits"] != 16)) fail("bits", "expected 8 or 16");
    r.bits = j["bits"].get<int>();
  }
  for (const char* k : {"read_noise", "shot_noise"})
    if (j.contains(k)) {
      if (!j[k].is_number() || !(j[k].get<double>() >= 0)) fail(k, "expected a number >= 0");
      (std::string(k) == "read_noise" ? r.noise.read_noise : r.noise.shot_noise) = j[k].get<double>();
    }
  if (j.contains("black_offset")) {
    if (!j["black_offset"].is_number() || !(j["black_offset"].get<double>() >= 0 && j["black_offset"].get<double>() < 0.5))
      fail("black_offset", "expected a number in [0, 0.5)");
    r.noise.offset = j["black_offset"].get<double>();
  }
  if (j.contains("shutter_labels")) {
    if (!j["shutter_labels"].is_boolean()) fail("shutter_labels", "expected true or false");
    r.shutter_labels = j["shutter_labels"].get<bool>();
  }
  PlaceRig(&r, Geom(grid, h), setup, scale, tilt, projector_K);
  return r;
}

cv::Mat RadialFalloff(const DeviceIntrinsics& device, double at_corner) {
  const cv::Size size = device.size;
  const double cx = device.K(0, 2), cy = device.K(1, 2);
  double far2 = 0;
  for (double x : {0.0, double(size.width)})
    for (double y : {0.0, double(size.height)}) far2 = std::max(far2, (x - cx) * (x - cx) + (y - cy) * (y - cy));
  cv::Mat f(size, CV_32FC1);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      const double dx = x + 0.5 - cx, dy = y + 0.5 - cy;
      f.at<float>(y, x) = float(1 - (1 - at_corner) * (dx * dx + dy * dy) / far2);
    }
  return f;
}

std::string SimulateCaptureOptions::Validate() const {
  if (lights < 1 || lights > 8) return fmt::format("lights must be 1x1 to 8x8, got {}x{}", lights, lights);
  if (oversample < 2 || oversample > 8 || oversample % 2) return fmt::format("oversample must be 2, 4, 6 or 8, got {}", oversample);
  if (holdout < 0 || holdout > kMaxHoldout)
    return fmt::format("holdout must be within 0..{}, got {}", kMaxHoldout, holdout);
  if (validation < 0 || validation > 64) return fmt::format("validation must be within 0..64, got {}", validation);
  if (exposures < 2 || exposures > 16) return fmt::format("exposures must be in [2, 16], got {}", exposures);
  if (camera_views < 5) return "camera_views must be >= 5";
  if (planes < 4) return "planes must be >= 4";
  if (!(tolerance > 0 && tolerance < 1e-3)) return "tolerance must be in (0, 1e-3)";
  return "";
}

std::string SimulateCaptureSummary::BriefReport() const {
  return fmt::format("{} conditions, {} photos, {:.1f} s", conditions, photos, seconds);
}

SimulateCaptureSummary SimulateCapture(const Material& material, const CaptureRig& rig,
                                       const SimulateCaptureOptions& o, const std::string& dir,
                                       const std::function<void(const std::string&)>& progress_fn) {
  if (std::string why = o.Validate(); !why.empty()) throw InputError("simulate-capture: " + why);
  if (fs::exists(dir) && !(fs::is_directory(dir) && fs::is_empty(dir)) &&
      !(o.replace_simulated && fs::is_directory(dir) && fs::exists(fs::path(dir) / "truth/material.vdb")))
    throw InputError(fmt::format("{}: exists and is not empty (a new capture folder is written)", dir));
  const auto t_start = std::chrono::steady_clock::now();
  auto elapsed = [&] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  };
  auto progress = [&](const std::string& s) {
    if (progress_fn) progress_fn(fmt::format("{} ({:.1f} s)", s, elapsed()));
    if (o.stop && o.stop()) throw Interrupted(fmt::format("stopped after \"{}\"; {} was not written", s, dir));
  };
  // Everything goes into a temporary sibling folder, renamed at the end.
  SimulateCaptureSummary sum;
  WriteFolderAtomically(dir, [&](const std::string& tmp_dir) {
    const fs::path tmp(tmp_dir);
    for (const char* sub : {"calib/camera", "calib/planes", "patterns", "truth"})
      fs::create_directories(tmp / sub);
    const Geometry g = Geom(material.shape, material.spacing_mm);
    const calib::SyntheticRig srig = ToSyntheticRig(rig);
    // Photographs a linear radiance image at `times` (the rig's response and noise, `bits` deep)
    // and writes the stack to `dir`; returns the number of photos.
    auto shoot = [&](const std::string& dir_out, const cv::Mat& radiance, const std::vector<double>& times,
                     int bits, uint64_t seed) {
      calib::StackOptions so = rig.noise;
      so.bits = bits;
      so.seed = seed;
      std::vector<double> written = times;
      if (rig.shutter_labels)
        for (double& t : written) t = calib::ShutterLabel(t);
      return WriteStack(dir_out, calib::SyntheticRig::RenderExposureStack(radiance, times, rig.response, so), written);
    };
    // n times one stop apart from t0 (rounded to a power of two with shutter labels).
    auto exposures = [&](double t0, int n) {
      return Exposures(rig.shutter_labels ? std::exp2(std::round(std::log2(t0))) : t0, n);
    };
    const double D = rig.camera_from_sample.t[2];

    // Camera calibration photos: a small chessboard sized to the sample.
    const double square = std::max(0.5, std::round(g.X / 12 * 10) / 10);
    const calib::BoardSpec board = calib::BoardSpec::Parse(fmt::format("chessboard:9x6:{}", square));
    calib::PhotoOptions po;
    po.blur_sigma_px = rig.blur_sigma_px;
    int k = 0;
    for (const calib::Pose& p : srig.BoardPoses(board, o.camera_views, 1.2 * D, o.seed)) {
      po.seed = o.seed * 1000 + uint64_t(k);
      calib::WriteImage8((tmp / "calib/camera" / fmt::format("board{:02d}.png", k++)).string(),
                         srig.RenderBoard(board, p, po));
      ++sum.photos;
    }
    if (k < o.camera_views) throw InputError("simulate-capture: the rig cannot see the calibration board");
    progress(fmt::format("camera calibration: {} board photos", k));

    // Projector calibration: plane pairs (board photo, projected chessboard photo).
    const int pattern_square = std::max(8, int(0.55 * rig.projector.size.width / 13));
    const calib::ProjectorChessboard pattern =
        calib::ProjectorChessboard::Centered(rig.projector.size, 11, 7, pattern_square);
    k = 0;
    for (const calib::Pose& p : srig.PlanePoses(pattern, o.planes, D, o.seed + 7, &board)) {
      po.seed = o.seed * 2000 + uint64_t(k);
      const fs::path base = tmp / "calib/planes" / fmt::format("plane{:02d}", k++);
      calib::WriteImage8(base.string() + "_board.png", srig.RenderBoard(board, p, po));
      po.seed += 500;
      calib::WriteImage8(base.string() + "_pattern.png", srig.RenderProjectedChessboard(p, pattern, po));
      sum.photos += 2;
    }
    if (k < o.planes) throw InputError("simulate-capture: the rig cannot see the projector's pattern on planes");
    progress(fmt::format("projector calibration: {} plane pairs", k));

    // Response: two stacks of a static scene with smooth gradients over 4 decades.
    std::vector<std::string> response_stacks;
    const std::vector<double> rtimes = exposures(1.0 / 64, 10);
    for (int s = 0; s < 2; ++s) {
      cv::Mat scene(rig.camera.size, CV_32FC3);
      for (int y = 0; y < scene.rows; ++y)
        for (int x = 0; x < scene.cols; ++x) {
          const double u = double(x) / scene.cols, v = double(y) / scene.rows;
          const double base = std::pow(10.0, -4 + 4.3 * (s ? v : u)) * (0.6 + 0.4 * (s ? u : v));
          scene.at<cv::Vec3f>(y, x) = cv::Vec3f(float(base * 40), float(base * 48), float(base * 36));
        }
      const std::string d = (tmp / "calib/response" / fmt::format("s{}", s + 1)).string();
      sum.photos += shoot(d, scene, rtimes, 8, o.seed * 3000 + uint64_t(s));
      response_stacks.push_back(d);
    }
    progress("camera response: 2 stacks");

    // The measurement: region patterns, forward solves on the refined grid, photos.
    const int K = o.oversample;
    const Material fine = RefineMaterial(material, K);
    const GridShape& fs_ = fine.shape;
    const double hf = fine.spacing_mm;
    const int N = o.lights;
    const int M = N * N;               // region conditions (fitted)
    const int P = M + o.validation;    // and validation spots: photographed conditions
    // Condition m's name: regions "00".., validation spots "v00"..
    const auto name = [&](int m) { return m < M ? fmt::format("{:02d}", m) : fmt::format("v{:02d}", m - M); };
    std::vector<cv::Mat> patterns;
    std::vector<FacePattern> fine_q;
    // What the projector's light does on the face: its images through its fall-off.
    const cv::Mat falloff = RadialFalloff(rig.projector, rig.projector_falloff);
    std::vector<cv::Mat> images = RegionPatterns(rig.projector, rig.projector_from_camera, rig.camera_from_sample,
                                                 SampleSize(g.grid, g.h), o.setup, N);
    if (o.validation > 0)
      for (cv::Mat& p : SpotPatterns(rig.projector, rig.projector_from_camera, rig.camera_from_sample,
                                     SampleSize(g.grid, g.h), o.setup,
                                     ValidationSpots(SampleSize(g.grid, g.h), o.validation)))
        images.push_back(std::move(p));
    for (int m = 0; m < P; ++m) {
      const cv::Mat& p = images[size_t(m)];
      calib::WriteImage8((tmp / "patterns" / (name(m) + ".png")).string(), p);
      cv::Mat pf;
      p.convertTo(pf, CV_32F, 1.0 / 255);
      patterns.push_back(pf.mul(falloff));
      fine_q.push_back(GreyPattern(ProjectPatternOnFace(patterns.back(), rig.projector, rig.projector_from_camera,
                                                        rig.camera_from_sample, fs_, hf, o.setup, 4)));
    }
    fine_q.push_back(GreyPattern(ProjectPatternOnFace(falloff, rig.projector, rig.projector_from_camera,
                                                      rig.camera_from_sample, fs_, hf, o.setup, 4)));
    MultigridOptions mg;
    mg.tolerance = o.tolerance;
    mg.max_iterations = 300;
    std::vector<SideFaces> fine_sides;  // what a camera that sees a side face photographs there
    const std::vector<FacePattern> fine_L = RenderFrontFace(fine, o.setup, fine_q, mg, Backend::kCpu, 0, &fine_sides);
    progress(fmt::format("{} forward solves on the {} grid ({}x finer)", fine_q.size(),
                         fs_.ToString(), K));
    // Camera sensitivity (aperture, ISO): the brightest diffuse radiance reaches 80 % of full
    // scale in a 1/30 s exposure, the shortest of the stack (as in the paper: 1/30 s and up).
    double brightest = 0;
    for (int m = 0; m < P; ++m)
      for (int c = 0; c < 3; ++c)
        for (float v : fine_L[size_t(m)][size_t(c)]) brightest = std::max(brightest, rig.camera_gain[c] * v);
    const cv::Vec3d gain = rig.camera_gain * (0.8 * 30 / brightest);
    const std::vector<double> mtimes = exposures(1.0 / 30, o.exposures);

    // White calibration: a white card (albedo 0.9) where the sample goes, projector white and
    // black; its patch corners are the face's corners pulled 15 % towards the centre. It covers
    // the face and a margin of 10 % of its width (capture.json's white.flat_field) in the lit
    // face's place (back-lit: a diffuser there, the projector behind it), and takes the lit face's
    // irradiance (with a fall-off; beyond the face, the border's).
    const double albedo = 0.9;
    const cv::Vec3d white_radiance = gain * (albedo / kPi);
    // Stacks from 10 % of full scale for the brightest channel, one stop apart.
    const double wmax = std::max({white_radiance[0], white_radiance[1], white_radiance[2]});
    const std::vector<double> wtimes = exposures(0.1 / wmax, 5),
                              btimes = exposures(0.1 / (wmax * std::max(rig.projector_black, 1e-6)), 5);
    for (int s = 0; s < 2; ++s) {
      const double q = s == 0 ? 1.0 : rig.projector_black;
      const cv::Mat img = RenderFace(rig, srig, g, [&](double x, double y) {
        return rig.projector_falloff < 1 ? white_radiance * (q * FaceBilinear(fine_q[size_t(P)][0], fs_, hf, x, y))
                                         : white_radiance * q;
      }, 3, 0.1 * g.X, LitFaceZ(g.grid, g.h, o.setup));
      sum.photos += shoot((tmp / (s == 0 ? "calib/white" : "calib/white_black")).string(), img,
                          s ? btimes : wtimes, rig.bits, o.seed * 4000 + uint64_t(s));
    }
    std::vector<cv::Point3d> patch3;
    for (const auto& c : FrontFaceCorners(g.grid, g.h))
      patch3.emplace_back(kPatchInset * g.X + (1 - 2 * kPatchInset) * c.x, kPatchInset * g.Y + (1 - 2 * kPatchInset) * c.y,
                          LitFaceZ(g.grid, g.h, o.setup));
    std::vector<cv::Point3d> patch_cam, corner_cam;
    for (const auto& p : patch3) {
      const cv::Vec3d x = rig.camera_from_sample.Apply({p.x, p.y, p.z});
      patch_cam.emplace_back(x[0], x[1], x[2]);
    }
    for (const auto& p : FrontFaceCorners(g.grid, g.h)) {
      const cv::Vec3d x = rig.camera_from_sample.Apply({p.x, p.y, p.z});
      corner_cam.emplace_back(x[0], x[1], x[2]);
    }
    const auto patch_px = rig.camera.Project(patch_cam), corners_px = rig.camera.Project(corner_cam);
    progress("white and black reference stacks");
    // A lens with vignetting: a camera flat (an evenly lit field filling the view, through the
    // lens), from 10 % of full scale at the principal point.
    if (rig.camera_vignetting < 1) {
      const cv::Mat v = RadialFalloff(rig.camera, rig.camera_vignetting);
      cv::Mat field;
      cv::merge(std::vector<cv::Mat>{v, v, v}, field);
      sum.photos += shoot((tmp / "calib/camera_flat").string(), field, exposures(0.1, 4), rig.bits,
                          o.seed * 4000 + 7);
    }

    // Surface reflection of directly lit front-face points (front-lit setup only): masked out
    // by the acquisition, but it is what the camera sees there (and it saturates).
    const double surface_albedo = 0.2;
    // (phi - q) / (2 pi) models the light leaving unlit points; at lit points it can fall below
    // 0 (phi < q where the light leaks away), which photographed a front-lit region black
    // around a bright core, and the front-lit black frame black along the face's border (the
    // projector's black level lights every point) while the condition photos kept that negative
    // part: their difference lost 17-89 % of the border nodes' signal. The photos take it
    // clamped at 0 per fine node (a lit point shows at least its surface reflection), so that
    // condition minus black frame is the truth's L wherever the condition does not light.
    std::vector<FacePattern> photo_L = fine_L;
    for (FacePattern& pattern : photo_L)
      for (auto& channel : pattern)
        for (float& v : channel) v = std::max(v, 0.0f);
    for (SideFaces& sides : fine_sides)
      for (auto& channel : sides)
        for (auto& face : channel)
          for (float& v : face) v = std::max(v, 0.0f);
    // A side face's field as a face of (u, z) nodes: u along y on x = 0 and x = X, along x on
    // y = 0 and y = Y.
    const GridShape side_shape[2] = {{fs_.ny, fs_.nz, 1}, {fs_.nx, fs_.nz, 1}};
    const auto side_shade = [&](int m, double black_scale) {
      return [&, m, black_scale](int face, double u, double z) {
        const GridShape& shape = side_shape[face / 2];
        cv::Vec3d v;
        for (int c = 0; c < 3; ++c) {
          double L = black_scale * FaceBilinear(fine_sides[size_t(P)][size_t(c)][size_t(face)], shape, hf, u, z);
          if (m >= 0) L += FaceBilinear(fine_sides[size_t(m)][size_t(c)][size_t(face)], shape, hf, u, z);
          v[c] = gain[c] * L;
        }
        return v;
      };
    };
    auto photo = [&](int m, double black_scale) {
      return RenderFace(rig, srig, g, [&](double x, double y) {
        cv::Vec3d v;
        for (int c = 0; c < 3; ++c) {
          double L = black_scale * FaceBilinear(photo_L[size_t(P)][size_t(c)], fs_, hf, x, y);
          if (m >= 0) L += FaceBilinear(photo_L[size_t(m)][size_t(c)], fs_, hf, x, y);
          if (o.setup == Setup::kFront) {
            double qf = black_scale * FaceBilinear(fine_q[size_t(P)][0], fs_, hf, x, y);
            if (m >= 0) qf += FaceBilinear(fine_q[size_t(m)][0], fs_, hf, x, y);
            L += surface_albedo * qf / kPi;
          }
          v[c] = gain[c] * L;
        }
        return v;
      }, 3, 0, 0, side_shade(m, black_scale));
    };
    CaptureSpec spec;
    spec.dir = tmp.string();
    for (int m = 0; m < P; ++m) {
      const std::string d = (tmp / "lighting" / name(m)).string();
      sum.photos += shoot(d, photo(m, rig.projector_black), mtimes, rig.bits, o.seed * 5000 + uint64_t(m));
      CaptureSpec::Condition c{name(m), d, (tmp / "patterns" / (name(m) + ".png")).string(), ""};
      c.validation = m >= M;
      spec.conditions.push_back(c);
    }
    sum.photos += shoot((tmp / "lighting/black").string(), photo(-1, rig.projector_black), mtimes, rig.bits,
                        o.seed * 5000 + 999);
    // The sample under projector white, as `translume patterns --photo` takes it to place the
    // regions: its brightest pixel at 80 % of full scale in the shortest photo.
    const cv::Mat lit = photo(-1, 1.0);
    double peak = 0;
    cv::minMaxLoc(lit.reshape(1), nullptr, &peak);
    sum.photos += shoot((tmp / "calib/sample_lit").string(), lit, exposures(0.8 / peak, o.exposures), rig.bits,
                        o.seed * 5000 + 998);
    progress(fmt::format("{} exposure stacks of {} photos ({:.3g} s to {:.3g} s)", P + 1,
                         o.exposures, mtimes.front(), mtimes.back()));

    // q's unit is the irradiance that the white patch receives (what the white calibration ties
    // the photos to): with a fall-off, the truth's q and L are scaled by the patch's mean.
    double patch_irradiance = 1;
    if (rig.projector_falloff < 1) {
      double sum = 0;
      int64_t n = 0;
      for (int64_t j = 0; j < fs_.ny; ++j)
        for (int64_t i = 0; i < fs_.nx; ++i) {
          const double x = double(i) * hf, y = double(j) * hf;
          if (x < kPatchInset * g.X || x > (1 - kPatchInset) * g.X || y < kPatchInset * g.Y ||
              y > (1 - kPatchInset) * g.Y)
            continue;
          sum += fine_q[size_t(P)][0][size_t(i + fs_.nx * j)];
          ++n;
        }
      patch_irradiance = sum / double(n);
    }
    // Ground truth: the material, the simulator's node-space data and held-out spots.
    WriteMaterial((tmp / "truth/material.vdb").string(), material);
    Dataset truth;
    truth.shape = g.grid;
    truth.spacing_mm = g.h;
    truth.C = material.C;
    truth.setup = o.setup;
    for (int m = 0; m < M; ++m) {
      DatasetCondition c;
      c.name = fmt::format("{:02d}", m);
      c.q = GreyPattern(ProjectPatternOnFace(patterns[size_t(m)], rig.projector, rig.projector_from_camera,
                                             rig.camera_from_sample, g.grid, g.h, o.setup, 8));
      for (auto& channel : c.q)
        for (float& v : channel) v = float(v / patch_irradiance);
      for (int ch = 0; ch < 3; ++ch) {
        c.L[size_t(ch)].resize(size_t(g.grid.face_size()));
        for (int64_t j = 0; j < g.grid.ny; ++j)
          for (int64_t i = 0; i < g.grid.nx; ++i)
            c.L[size_t(ch)][size_t(i + g.grid.nx * j)] =
                float(DualBoxMean(fine_L[size_t(m)][size_t(ch)], fs_, K, i, j) / patch_irradiance);
      }
      c.mask = MeasurementMask(g.grid, o.setup, c.q);
      truth.conditions.push_back(c);
    }
    WriteDataset((tmp / "truth/dataset").string(), truth);
    if (o.holdout > 0) {
      SimulateOptions so;  // no training lights: the training truth is the photos' own, above
      so.setup = o.setup;
      so.oversample = K;
      so.holdout = o.holdout;
      so.seed = o.seed;
      so.tolerance = o.tolerance;
      WriteDataset((tmp / "truth/dataset/holdout").string(), SimulateDataset(material, so).holdout);
    }
    progress(fmt::format("ground truth: truth/material.vdb, truth/dataset ({} held-out spots)", o.holdout));

    spec.setup = o.setup;
    spec.size_mm = {g.X, g.Y, g.Z};
    spec.grid = g.grid;
    spec.spacing_mm = g.h;
    spec.eta = material.eta;
    spec.C = material.C;
    if (!o.auto_corners)
      for (const auto& p : corners_px) spec.face_corners_px.push_back({p.x, p.y});
    spec.camera.photos = (tmp / "calib/camera").string();
    spec.camera.board = board.ToString();
    spec.projector.planes = (tmp / "calib/planes").string();
    spec.projector.board = board.ToString();
    spec.projector.pattern = fmt::format("11x7:{}", pattern_square);
    spec.projector.projector_size = fmt::format("{}x{}", rig.projector.size.width, rig.projector.size.height);
    spec.projector.rear = o.setup == Setup::kBack;
    spec.response.linear = rig.bits == 16;
    if (rig.bits != 16) spec.response.stacks = response_stacks;
    spec.white.white = (tmp / "calib/white").string();
    spec.white.black = (tmp / "calib/white_black").string();
    for (const auto& p : patch_px) spec.white.patch.push_back({p.x, p.y});
    spec.white.flat_field = true;
    spec.white.albedo = {albedo, albedo, albedo};
    spec.black = (tmp / "lighting/black").string();
    if (rig.camera_vignetting < 1) spec.camera_flat = (tmp / "calib/camera_flat").string();
    // As a camera's raw metadata states it; 8-bit photos carry it through their response.
    if (rig.bits == 16) spec.sensor_black.fill(rig.noise.offset);
    std::ofstream(tmp / "capture.json") << CaptureJson(spec);
    sum.conditions = P;
  });
  sum.capture_json = (fs::path(dir).lexically_normal() / "capture.json").string();
  sum.seconds = elapsed();
  return sum;
}

}  // namespace translume::acquire
