// SPDX-License-Identifier: MIT
#include "calib/synthetic_rig.h"

#include <algorithm>
#include <cmath>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <random>

#include "calib/colorchecker.h"

namespace translume::calib {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;

// Applies OpenCV's 5-coefficient distortion to normalised coordinates.
cv::Point2d Distort(const cv::Vec<double, 5>& d, double x, double y) {
  const double r2 = x * x + y * y;
  const double radial = 1 + r2 * (d[0] + r2 * (d[1] + r2 * d[4]));
  return {x * radial + 2 * d[2] * x * y + d[3] * (r2 + 2 * x * x),
          y * radial + d[2] * (r2 + 2 * y * y) + 2 * d[3] * x * y};
}

cv::Point2d ToPixel(const DeviceModel& m, const cv::Vec3d& X) {
  const cv::Point2d n = Distort(m.dist, X[0] / X[2], X[1] / X[2]);
  return {m.K(0, 0) * n.x + m.K(0, 1) * n.y + m.K(0, 2), m.K(1, 1) * n.y + m.K(1, 2)};
}

cv::Matx33d RotX(double a) {
  return {1, 0, 0, 0, std::cos(a), -std::sin(a), 0, std::sin(a), std::cos(a)};
}
cv::Matx33d RotY(double a) {
  return {std::cos(a), 0, std::sin(a), 0, 1, 0, -std::sin(a), 0, std::cos(a)};
}
cv::Matx33d RotZ(double a) {
  return {std::cos(a), -std::sin(a), 0, std::sin(a), std::cos(a), 0, 0, 0, 1};
}

// A hash of (x, y, k) to [0, 1): per-pixel jitter of the supersamples (stratified sampling
// without the structured aliasing of a regular grid).
double Jitter(int x, int y, int k) {
  uint64_t h = uint64_t(x) * 0x9E3779B97F4A7C15ull ^ uint64_t(y) * 0xC2B2AE3D27D4EB4Full ^
               uint64_t(k) * 0x165667B19E3779F9ull;
  h ^= h >> 29;
  h *= 0xBF58476D1CE4E5B9ull;
  h ^= h >> 32;
  return double(h >> 11) * (1.0 / 9007199254740992.0);
}

bool Inside(const cv::Size& s, const cv::Point2d& p, double margin) {
  return p.x >= margin && p.y >= margin && p.x <= s.width - 1 - margin &&
         p.y <= s.height - 1 - margin;
}

}  // namespace

std::vector<cv::Point2d> DeviceModel::Project(const std::vector<cv::Point3d>& points) const {
  std::vector<cv::Point2d> out;
  out.reserve(points.size());
  for (const auto& p : points) out.push_back(ToPixel(*this, cv::Vec3d(p.x, p.y, p.z)));
  return out;
}

bool SyntheticRig::ProjectorPixelOnPlane(const Pose& camera_from_plane, const cv::Point2d& p,
                                         cv::Vec3d* X) const {
  std::vector<cv::Point2d> in{p}, out;
  cv::undistortPoints(in, out, projector.K, projector.dist, cv::noArray(), cv::noArray(),
                      cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 100, 1e-12));
  const Pose camera_from_projector = projector_from_camera.Inverse();
  const cv::Vec3d C = camera_from_projector.t;
  const cv::Vec3d d = camera_from_projector.R * cv::Vec3d(out[0].x, out[0].y, 1.0);
  const cv::Vec3d n(camera_from_plane.R(0, 2), camera_from_plane.R(1, 2), camera_from_plane.R(2, 2));
  const double den = n.dot(d);
  if (std::abs(den) < 1e-9) return false;
  const double s = n.dot(camera_from_plane.t - C) / den;
  if (s <= 0) return false;
  *X = C + s * d;
  return true;
}

Pose Pose::Inverse() const { return {R.t(), -(R.t() * t)}; }

Pose Pose::FromRodrigues(const cv::Vec3d& rvec, const cv::Vec3d& t) {
  Pose p;
  cv::Rodrigues(rvec, p.R);
  p.t = t;
  return p;
}

double SyntheticResponse::Apply(double x, int c) const {
  x = std::clamp(x, 0.0, 1.0);
  const double g = gamma[c];
  return (std::pow(x + toe, g) - std::pow(toe, g)) / (std::pow(1 + toe, g) - std::pow(toe, g));
}

SyntheticChart SyntheticChart::ColorChecker() {
  SyntheticChart c;
  c.albedo = ColorCheckerLinearAlbedos();
  return c;
}

cv::Size2d SyntheticChart::SizeMm() const {
  return {6 * patch_mm + 7 * gap_mm, 4 * patch_mm + 5 * gap_mm};
}

cv::Point2d SyntheticChart::PatchCenter(int k) const {
  const int i = k % 6, j = k / 6;
  return {gap_mm + i * (patch_mm + gap_mm) + patch_mm / 2,
          gap_mm + j * (patch_mm + gap_mm) + patch_mm / 2};
}

cv::Vec3d SyntheticChart::AlbedoAt(double x, double y) const {
  const double pitch = patch_mm + gap_mm;
  const double u = x - gap_mm, v = y - gap_mm;
  const cv::Vec3d frame(0.03, 0.03, 0.03);
  if (u < 0 || v < 0) return frame;
  const int i = int(u / pitch), j = int(v / pitch);
  if (i > 5 || j > 3) return frame;
  if (u - i * pitch >= patch_mm || v - j * pitch >= patch_mm) return frame;
  return albedo[size_t(j * 6 + i)];
}

SyntheticRig SyntheticRig::Default() {
  SyntheticRig r;
  r.camera.size = {1024, 768};
  r.camera.K = {1200.0, 0, 515.3, 0, 1201.5, 380.7, 0, 0, 1};
  r.camera.dist = {-0.12, 0.09, 0.0004, -0.0003, 0.0};
  r.projector.size = {1024, 768};
  r.projector.K = {1500.0, 0, 520.0, 0, 1500.0, 600.0, 0, 0, 1};
  r.projector.dist = {0.03, -0.01, 0.0, 0.0, 0.0};
  // Projector 150 mm right of the camera; its image centre aimed at (0, 0, 500) mm.
  const cv::Vec3d C(150, 0, 0);
  const cv::Vec3d d = r.projector.K.inv() * cv::Vec3d(512, 384, 1);
  const double pitch = std::atan2(d[1], d[2]);
  const double yaw = std::atan2(-C[0], 500.0 - C[2]);
  const cv::Matx33d camera_from_projector = RotY(yaw) * RotX(pitch) * RotZ(0.5 * kDeg);
  r.projector_from_camera.R = camera_from_projector.t();
  r.projector_from_camera.t = -(camera_from_projector.t() * C);
  return r;
}

std::vector<Pose> SyntheticRig::BoardPoses(const BoardSpec& board, int n, double distance_mm,
                                           uint64_t seed) const {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  const cv::Rect2d a = board.SquaresArea();
  const double m = board.square_mm;  // white margin
  const cv::Vec3d centre(a.x + a.width / 2, a.y + a.height / 2, 0);
  std::vector<Pose> poses;
  for (int attempt = 0; int(poses.size()) < n && attempt < 1000 * n; ++attempt) {
    // Alternate strong tilts about x and y so that the focal length is well constrained.
    const int k = int(poses.size());
    const double big = (20 + 15 * std::abs(U(rng))) * kDeg * ((k & 2) ? -1 : 1);
    const double rx = (k & 1) ? big : 10 * kDeg * U(rng);
    const double ry = (k & 1) ? 10 * kDeg * U(rng) : big;
    Pose p;
    p.R = RotX(rx) * RotY(ry) * RotZ(10 * kDeg * U(rng));
    const double z = distance_mm * (1 + 0.15 * U(rng));
    const cv::Vec3d target(0.12 * z * U(rng), 0.08 * z * U(rng), z);
    p.t = target - p.R * centre;
    bool ok = true;
    for (double x : {a.x - m, a.x + a.width + m})
      for (double y : {a.y - m, a.y + a.height + m}) {
        const cv::Vec3d X = p.Apply({x, y, 0});
        ok = ok && X[2] > 0 && Inside(camera.size, ToPixel(camera, X), 4);
      }
    if (ok) poses.push_back(p);
  }
  return poses;
}

std::vector<Pose> SyntheticRig::PlanePoses(const ProjectorChessboard& pattern, int n,
                                           double distance_mm, uint64_t seed,
                                           const BoardSpec* board) const {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  const int s = pattern.square_px;
  const cv::Point2f c0(float(pattern.origin.x - s), float(pattern.origin.y - s));
  const cv::Point2f c1(float(pattern.origin.x + (pattern.cols + 2) * s),
                       float(pattern.origin.y + (pattern.rows + 2) * s));
  std::vector<Pose> poses;
  for (int attempt = 0; int(poses.size()) < n && attempt < 1000 * n; ++attempt) {
    const int k = int(poses.size());
    const double big = (15 + 15 * std::abs(U(rng))) * kDeg * ((k & 2) ? -1 : 1);
    Pose p;
    p.R = RotX((k & 1) ? big : 8 * kDeg * U(rng)) * RotY((k & 1) ? 8 * kDeg * U(rng) : big);
    p.t = cv::Vec3d(20 * U(rng), 20 * U(rng), distance_mm * (1 + 0.2 * U(rng)));
    bool ok = true;
    if (board) {
      const cv::Rect2d a = board->SquaresArea();
      const double m = board->square_mm;
      p.t -= p.R * cv::Vec3d(a.x + a.width / 2, a.y + a.height / 2, 0);
      for (double x : {a.x - m, a.x + a.width + m})
        for (double y : {a.y - m, a.y + a.height + m}) {
          const cv::Vec3d X = p.Apply({x, y, 0});
          ok = ok && X[2] > 0 && Inside(camera.size, ToPixel(camera, X), 4);
        }
    }
    for (float x : {c0.x, c1.x})
      for (float y : {c0.y, c1.y}) {
        cv::Vec3d X;
        ok = ok && ProjectorPixelOnPlane(p, {x, y}, &X) &&
             Inside(camera.size, ToPixel(camera, X), 8);
      }
    if (ok) poses.push_back(p);
  }
  return poses;
}

const cv::Mat& SyntheticRig::CameraRays() const {
  if (!rays_.empty() && rays_.rows == camera.size.height + 1 && rays_.cols == camera.size.width + 1)
    return rays_;
  const int W = camera.size.width + 1, H = camera.size.height + 1;
  rays_.create(H, W, CV_64FC2);
  const cv::Matx33d& K = camera.K;
  cv::parallel_for_(cv::Range(0, H), [&](const cv::Range& r) {
    for (int j = r.start; j < r.end; ++j)
      for (int i = 0; i < W; ++i) {
        // Distorted normalised coordinates, then fixed-point iteration of the inverse of
        // Distort() to full double precision.
        const double yd = (j - 0.5 - K(1, 2)) / K(1, 1);
        const double xd = (i - 0.5 - K(0, 2) - K(0, 1) * yd) / K(0, 0);
        double x = xd, y = yd;
        for (int it = 0; it < 100; ++it) {
          const cv::Point2d f = Distort(camera.dist, x, y);
          const double nx = x + (xd - f.x), ny = y + (yd - f.y);
          const bool done = std::abs(nx - x) + std::abs(ny - y) < 1e-15;
          x = nx;
          y = ny;
          if (done) break;
        }
        rays_.at<cv::Vec2d>(j, i) = cv::Vec2d(x, y);
      }
  });
  return rays_;
}

cv::Mat SyntheticRig::RenderPlane(
    const Pose& pose, const PhotoOptions& o,
    const std::function<double(const cv::Vec3d&, const cv::Vec3d&)>& shade) const {
  const cv::Mat& rays = CameraRays();
  const int N = std::max(1, o.supersample);
  const cv::Vec3d nrm(pose.R(0, 2), pose.R(1, 2), pose.R(2, 2));
  const double nt = nrm.dot(pose.t);
  const cv::Matx33d Rt = pose.R.t();
  cv::Mat img(camera.size, CV_64F);
  cv::parallel_for_(cv::Range(0, camera.size.height), [&](const cv::Range& r) {
    for (int y = r.start; y < r.end; ++y)
      for (int x = 0; x < camera.size.width; ++x) {
        const cv::Vec2d r00 = rays.at<cv::Vec2d>(y, x), r10 = rays.at<cv::Vec2d>(y, x + 1);
        const cv::Vec2d r01 = rays.at<cv::Vec2d>(y + 1, x), r11 = rays.at<cv::Vec2d>(y + 1, x + 1);
        // Shade at pixel position (fa, fb) in [0, 1]^2 (bilinear ray between the corners).
        auto at = [&](double fa, double fb) {
          const cv::Vec2d q = (1 - fb) * ((1 - fa) * r00 + fa * r10) + fb * ((1 - fa) * r01 + fa * r11);
          const cv::Vec3d d(q[0], q[1], 1.0);
          const double den = nrm.dot(d);
          const double s = std::abs(den) > 1e-12 ? nt / den : -1;
          if (s <= 0) return o.background;
          const cv::Vec3d X = s * d;
          return shade(Rt * (X - pose.t), X);
        };
        // Scenes are piecewise constant with features far larger than a pixel: a pixel whose
        // corners and centre agree is flat; only the others are supersampled.
        const double c0 = at(0.5, 0.5);
        if (at(0, 0) == c0 && at(1, 0) == c0 && at(0, 1) == c0 && at(1, 1) == c0) {
          img.at<double>(y, x) = c0;
          continue;
        }
        double sum = 0;
        for (int b = 0; b < N; ++b)
          for (int a = 0; a < N; ++a)
            sum += at((a + Jitter(x, y, 2 * (b * N + a))) / N, (b + Jitter(x, y, 2 * (b * N + a) + 1)) / N);
        img.at<double>(y, x) = sum / (N * N);
      }
  });
  if (o.blur_sigma_px > 0) cv::GaussianBlur(img, img, cv::Size(0, 0), o.blur_sigma_px);
  cv::Mat noise(img.size(), CV_64F);
  cv::RNG rng(o.seed);
  rng.fill(noise, cv::RNG::NORMAL, 0.0, o.noise_sigma);
  cv::Mat out;
  cv::Mat(img * o.white_level + noise).convertTo(out, CV_8U);
  return out;
}

cv::Mat SyntheticRig::RenderBoard(const BoardSpec& board, const Pose& pose,
                                  const PhotoOptions& o) const {
  const cv::Rect2d a = board.SquaresArea();
  const double m = board.square_mm;
  board.IsWhite(0, 0);  // builds the ChArUco texture before the parallel loop
  return RenderPlane(pose, o, [&](const cv::Vec3d& p, const cv::Vec3d&) {
    if (p[0] < a.x - m || p[1] < a.y - m || p[0] > a.x + a.width + m || p[1] > a.y + a.height + m)
      return o.background;
    return board.IsWhite(p[0], p[1]) ? 0.9 : 0.05;
  });
}

cv::Mat SyntheticRig::RenderProjectedChessboard(const Pose& pose, const ProjectorChessboard& pat,
                                                const PhotoOptions& o) const {
  return RenderProjectedImage(pose, pat.MakeImage(), o);
}

cv::Mat SyntheticRig::RenderProjectedImage(const Pose& pose, const cv::Mat& image,
                                           const PhotoOptions& o) const {
  CV_Assert(image.type() == CV_8UC1 && image.size() == projector.size);
  return RenderPlane(pose, o, [&](const cv::Vec3d&, const cv::Vec3d& X) {
    const cv::Vec3d Xp = projector_from_camera.Apply(X);
    double light = o.ambient;
    if (Xp[2] > 0) {
      const cv::Point2d q = ToPixel(projector, Xp);
      const int px = int(std::floor(q.x + 0.5)), py = int(std::floor(q.y + 0.5));
      if (px >= 0 && py >= 0 && px < projector.size.width && py < projector.size.height)
        light += image.at<uint8_t>(py, px) / 255.0;
    }
    return 0.9 * light;
  });
}

cv::Mat SyntheticRig::RenderChartRadiance(const SyntheticChart& chart, const Pose& pose,
                                          const cv::Vec3d& projector_rgb,
                                          const cv::Vec3d& camera_gain, int supersample) const {
  const cv::Mat& rays = CameraRays();
  const int N = std::max(1, supersample);
  const cv::Vec3d nrm(pose.R(0, 2), pose.R(1, 2), pose.R(2, 2));
  const cv::Size2d size = chart.SizeMm();
  cv::Mat img(camera.size, CV_32FC3, cv::Scalar::all(0));
  cv::parallel_for_(cv::Range(0, camera.size.height), [&](const cv::Range& r) {
    for (int y = r.start; y < r.end; ++y)
      for (int x = 0; x < camera.size.width; ++x) {
        cv::Vec3d sum(0, 0, 0);
        for (int b = 0; b < N; ++b)
          for (int a = 0; a < N; ++a) {
            const double fa = (a + 0.5) / N, fb = (b + 0.5) / N;
            const cv::Vec2d q = (1 - fb) * ((1 - fa) * rays.at<cv::Vec2d>(y, x) +
                                            fa * rays.at<cv::Vec2d>(y, x + 1)) +
                                fb * ((1 - fa) * rays.at<cv::Vec2d>(y + 1, x) +
                                      fa * rays.at<cv::Vec2d>(y + 1, x + 1));
            const cv::Vec3d d(q[0], q[1], 1.0);
            const double s = nrm.dot(pose.t) / nrm.dot(d);
            if (!(s > 0)) continue;
            const cv::Vec3d X = s * d;
            const cv::Vec3d p = pose.R.t() * (X - pose.t);
            if (p[0] < 0 || p[1] < 0 || p[0] > size.width || p[1] > size.height) continue;
            const cv::Vec3d Xp = projector_from_camera.Apply(X);
            if (Xp[2] <= 0 || !Inside(projector.size, ToPixel(projector, Xp), 0)) continue;
            const cv::Vec3d alb = chart.AlbedoAt(p[0], p[1]);
            for (int c = 0; c < 3; ++c) sum[c] += alb[c] * projector_rgb[c] / kPi * camera_gain[c];
          }
        img.at<cv::Vec3f>(y, x) = cv::Vec3f(sum / double(N * N));
      }
  });
  return img;
}

std::vector<cv::Mat> SyntheticRig::RenderExposureStack(const cv::Mat& radiance,
                                                       const std::vector<double>& seconds,
                                                       const SyntheticResponse& response,
                                                       const StackOptions& o) {
  CV_Assert(radiance.type() == CV_32FC3);
  // 8-bit codes through a table of the response over 2^16 linear levels (far finer than a
  // code step anywhere on the curve).
  constexpr int kLevels = 65536;
  std::vector<uint8_t> lut;
  if (o.bits == 8) {
    lut.resize(3 * kLevels);
    for (int c = 0; c < 3; ++c)
      for (int i = 0; i < kLevels; ++i)
        lut[size_t(c * kLevels + i)] = uint8_t(std::lround(255 * response.Apply(double(i) / (kLevels - 1), c)));
  }
  std::vector<cv::Mat> out;
  for (size_t e = 0; e < seconds.size(); ++e) {
    const double t = seconds[e];
    cv::Mat img(radiance.size(), o.bits == 8 ? CV_8UC3 : CV_16UC3);
    // Rows in parallel, each with its own generator seeded from (seed, exposure, row): OpenCV's
    // multiply-with-carry generator and ziggurat normals, a row's worth at a time, and the
    // row's arithmetic as OpenCV's vectorised array operations (a per-value
    // std::normal_distribution and scalar code took most of simulate-capture's time).
    const int width = 3 * radiance.cols;
    cv::parallel_for_(cv::Range(0, radiance.rows), [&](const cv::Range& r) {
      cv::Mat_<double> G(1, width), S(1, width), V(1, width);
      cv::Mat_<int> level(1, width);
      for (int y = r.start; y < r.end; ++y) {
        cv::RNG rng(o.seed * 0x9E3779B97F4A7C15ull + e * 0x100000001B3ull + uint64_t(y));
        rng.fill(G, cv::RNG::NORMAL, 0.0, 1.0);
        cv::Mat(1, width, CV_32F, const_cast<float*>(radiance.ptr<float>(y))).convertTo(S, CV_64F, t);
        // v = clamp(s + sqrt(read^2 + shot max(s, 0)) g, 0, 1), in 2^16 levels (double).
        cv::max(S, 0.0, V);
        V.convertTo(V, CV_64F, o.shot_noise, o.read_noise * o.read_noise);
        cv::sqrt(V, V);
        cv::multiply(V, G, V);
        V += S;
        if (o.offset != 0) V += o.offset;
        cv::max(V, 0.0, V);
        cv::min(V, 1.0, V);
        V.convertTo(level, CV_32S, kLevels - 1);
        const int* lv = level[0];
        if (o.bits == 8) {
          uint8_t* out8 = img.ptr<uint8_t>(y);
          for (int x = 0; x < width; x += 3)
            for (int c = 0; c < 3; ++c) out8[x + c] = lut[size_t(c * kLevels + lv[x + c])];
        } else {
          uint16_t* out16 = img.ptr<uint16_t>(y);
          for (int i = 0; i < width; ++i) out16[i] = uint16_t(lv[i]);
        }
      }
    });
    out.push_back(img);
  }
  return out;
}

cv::Mat SyntheticHdrScene(cv::Size size, double decades, uint64_t seed) {
  cv::Mat E(size, CV_32FC3);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(0, 1);
  for (int y = 0; y < E.rows; ++y)
    for (int x = 0; x < E.cols; ++x)
      for (int c = 0; c < 3; ++c) {
        const double l = -decades + decades * (x + 0.5) / E.cols - 0.15 * c * (y % 7) / 7.0;
        E.at<cv::Vec3f>(y, x)[c] = float(std::pow(10.0, std::clamp(l, -decades, 0.0)));
      }
  for (int k = 0; k < 40; ++k) {
    const cv::Rect r(int(U(rng) * (E.cols - 20)), int(U(rng) * (E.rows - 20)), 12, 12);
    const cv::Vec3f v(float(std::pow(10.0, -decades + decades * U(rng))), float(std::pow(10.0, -decades + decades * U(rng))),
                      float(std::pow(10.0, -decades + decades * U(rng))));
    E(r).setTo(cv::Scalar(v[0], v[1], v[2]));
  }
  return E;
}

}  // namespace translume::calib
