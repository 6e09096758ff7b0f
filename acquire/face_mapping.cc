// SPDX-License-Identifier: MIT
#include "acquire/face_mapping.h"

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <numeric>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "solver/status.h"

namespace translume::acquire {
namespace {

// EstimateSamplePose refuses corners that the best pose misses by more than this many pixels
// RMS or this fraction of the face's mean side in the image, whichever is larger.
constexpr double kMaxCornerMissPx = 3.0;
constexpr double kMaxCornerMissFraction = 0.02;

// `samples` coordinates (mm) spread evenly over node n's dual interval along one axis.
std::vector<double> DualBoxSamples(int64_t n, int64_t count, double h, int samples) {
  const double lo = std::max(0.0, (double(n) - 0.5) * h);
  const double hi = std::min(double(count - 1) * h, (double(n) + 0.5) * h);
  std::vector<double> out(static_cast<size_t>(samples));
  for (int s = 0; s < samples; ++s) out[size_t(s)] = lo + (s + 0.5) * (hi - lo) / samples;
  return out;
}

// Sample-frame points of every face node's dual box at depth z: node-major, samples^2 each.
std::vector<cv::Point3d> FaceBoxPoints(const GridShape& g, double h, double z, int samples) {
  std::vector<cv::Point3d> pts;
  pts.reserve(size_t(g.face_size()) * size_t(samples * samples));
  for (int64_t j = 0; j < g.ny; ++j) {
    const auto ys = DualBoxSamples(j, g.ny, h, samples);
    for (int64_t i = 0; i < g.nx; ++i) {
      const auto xs = DualBoxSamples(i, g.nx, h, samples);
      for (double y : ys)
        for (double x : xs) pts.emplace_back(x, y, z);
    }
  }
  return pts;
}

std::vector<cv::Point3d> Transform(const calib::Pose& to_from, const std::vector<cv::Point3d>& in) {
  std::vector<cv::Point3d> out;
  out.reserve(in.size());
  for (const auto& p : in) {
    const cv::Vec3d x = to_from.Apply({p.x, p.y, p.z});
    out.emplace_back(x[0], x[1], x[2]);
  }
  return out;
}

// Where the ray through normalised (undistorted) image point r of a device meets the plane z of
// the sample frame, sample_from_device the device's pose; false when it does not (parallel, or
// behind the device).
bool RayOnPlane(const calib::Pose& sample_from_device, const cv::Point2d& r, double z, cv::Point2d* xy) {
  const cv::Vec3d o = sample_from_device.t, d = sample_from_device.R * cv::Vec3d(r.x, r.y, 1.0);
  if (std::abs(d[2]) < 1e-12) return false;
  const double s = (z - o[2]) / d[2];
  if (s <= 0) return false;
  *xy = {o[0] + s * d[0], o[1] + s * d[1]};
  return true;
}

// Bilinear sample of a CV_32FC3 image at continuous pixel position p; false outside.
bool Bilinear(const cv::Mat& img, const cv::Point2d& p, cv::Vec3f* v) {
  const double fx = std::floor(p.x), fy = std::floor(p.y);
  const int x0 = int(fx), y0 = int(fy);
  if (x0 < 0 || y0 < 0 || x0 + 1 >= img.cols || y0 + 1 >= img.rows) return false;
  const float ax = float(p.x - fx), ay = float(p.y - fy);
  const cv::Vec3f& a = img.at<cv::Vec3f>(y0, x0);
  const cv::Vec3f& b = img.at<cv::Vec3f>(y0, x0 + 1);
  const cv::Vec3f& c = img.at<cv::Vec3f>(y0 + 1, x0);
  const cv::Vec3f& d = img.at<cv::Vec3f>(y0 + 1, x0 + 1);
  *v = (1 - ay) * ((1 - ax) * a + ax * b) + ay * ((1 - ax) * c + ax * d);
  return true;
}

// The channels' mean of `img` less `black` (empty: none) at p, bilinear; false outside the
// image or where not finite (saturated).
bool MeanLessBlack(const cv::Mat& img, const cv::Mat& black, const cv::Point2d& p, double* y) {
  cv::Vec3f v, b(0, 0, 0);
  if (!Bilinear(img, p, &v) || (!black.empty() && !Bilinear(black, p, &b))) return false;
  v -= b;
  *y = (double(v[0]) + v[1] + v[2]) / 3;
  return std::isfinite(*y);
}

// Image points and the ideal pinhole image of the same camera (pixels, through K without the
// distortion): sides of the face are straight lines in the latter.
std::vector<cv::Point2f> IdealFromImage(const DeviceIntrinsics& camera, const std::vector<cv::Point2f>& px) {
  std::vector<cv::Point2f> ideal;
  cv::undistortPoints(px, ideal, camera.K, camera.dist, cv::noArray(), camera.K);
  return ideal;
}
std::vector<cv::Point2d> ImageFromIdeal(const DeviceIntrinsics& camera, const std::vector<cv::Point2d>& ideal) {
  std::vector<cv::Point3d> rays;
  for (const cv::Point2d& u : ideal)
    rays.emplace_back((u.x - camera.K(0, 2)) / camera.K(0, 0), (u.y - camera.K(1, 2)) / camera.K(1, 1), 1.0);
  return camera.Project(rays);
}

// The same for a CV_32FC1 image; p must be inside (Bilinear said so for the same size).
double BilinearGrey(const cv::Mat& img, const cv::Point2d& p) {
  const double fx = std::floor(p.x), fy = std::floor(p.y);
  const int x0 = int(fx), y0 = int(fy);
  const double ax = p.x - fx, ay = p.y - fy;
  return (1 - ay) * ((1 - ax) * img.at<float>(y0, x0) + ax * img.at<float>(y0, x0 + 1)) +
         ay * ((1 - ax) * img.at<float>(y0 + 1, x0) + ax * img.at<float>(y0 + 1, x0 + 1));
}

// The corners of a face of the block at depth z (sample frame, mm), in CaptureSpec's order:
// (0, 0, z), (X, 0, z), (X, Y, z), (0, Y, z).
std::vector<cv::Point3d> FaceCorners(const std::array<double, 3>& size_mm, double z) {
  return {{0, 0, z}, {size_mm[0], 0, z}, {size_mm[0], size_mm[1], z}, {0, size_mm[1], z}};
}

// The lit face's plane z (sample frame, mm): the back face back-lit, the front face front-lit.
double LitFaceZ(const std::array<double, 3>& size_mm, Setup setup) {
  return setup == Setup::kBack ? size_mm[2] : 0.0;
}

// Whether the lit face (plane z) is turned towards the projector: its outward normal is +z
// back-lit, -z front-lit.
bool LitFaceFacesProjector(const calib::Pose& projector_from_camera, const calib::Pose& camera_from_sample,
                           double z, Setup setup) {
  const cv::Vec3d projector_in_sample = camera_from_sample.Inverse().Apply(projector_from_camera.Inverse().t);
  return (projector_in_sample[2] - z) * (setup == Setup::kBack ? 1.0 : -1.0) > 0;
}

}  // namespace

double LitFaceZ(const GridShape& g, double h, Setup setup) { return LitFaceZ(SampleSize(g, h), setup); }

std::vector<cv::Point2d> DeviceIntrinsics::Project(const std::vector<cv::Point3d>& xyz) const {
  std::vector<cv::Point2d> px;
  if (xyz.empty()) return px;
  cv::projectPoints(xyz, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), K, dist, px);
  return px;
}

std::vector<cv::Point3d> FrontFaceCorners(const GridShape& g, double h) { return FaceCorners(SampleSize(g, h), 0); }

DeviceIntrinsics DeviceIntrinsics::From(const cv::Size& size, const cv::Matx33d& K, const cv::Mat& dist) {
  DeviceIntrinsics d;
  d.size = size;
  d.K = K;
  cv::Mat d64;
  dist.reshape(1, 1).convertTo(d64, CV_64F);
  for (int i = 0; i < std::min(5, d64.cols); ++i) d.dist[i] = d64.at<double>(0, i);
  return d;
}

std::array<double, 3> SampleSize(const GridShape& g, double h) {
  return {double(g.nx - 1) * h, double(g.ny - 1) * h, double(g.nz - 1) * h};
}

std::string QuadrilateralProblem(const std::vector<cv::Point2d>& c) {
  TL_CHECK(c.size() == 4);
  double area = 0;
  int left = 0, right = 0;
  for (size_t i = 0; i < 4; ++i) {
    const cv::Point2d &a = c[i], &b = c[(i + 1) % 4], &d = c[(i + 2) % 4];
    area += 0.5 * a.cross(b);
    const double turn = (b - a).cross(d - b);
    left += turn > 0;
    right += turn < 0;
  }
  if (std::abs(area) < 16 || (left != 4 && right != 4))
    return fmt::format("the 4 corners must enclose a convex quadrilateral of at least 16 px^2 (area {:.1f})",
                       std::abs(area));
  return "";
}

calib::Pose EstimateSamplePose(const DeviceIntrinsics& camera, const std::vector<cv::Point2d>& corners,
                               const GridShape& grid, double h, const std::string& what,
                               double* rms_px, bool fit_bound) {
  return EstimateSamplePose(camera, corners, SampleSize(grid, h), what, rms_px, fit_bound);
}

calib::Pose EstimateSamplePose(const DeviceIntrinsics& camera, const std::vector<cv::Point2d>& corners,
                               const std::array<double, 3>& size_mm, const std::string& what,
                               double* rms_px, bool fit_bound) {
  TL_CHECK(corners.size() == 4);
  for (size_t k = 0; k < 4; ++k)
    if (corners[k].x < -0.5 || corners[k].y < -0.5 || corners[k].x > camera.size.width - 0.5 ||
        corners[k].y > camera.size.height - 0.5)
      throw InputError(fmt::format("{}: corner {} ({:.1f}, {:.1f}) is outside the {}x{} image", what,
                                   k, corners[k].x, corners[k].y, camera.size.width,
                                   camera.size.height));
  if (std::string why = QuadrilateralProblem(corners); !why.empty()) throw InputError(what + ": " + why);
  const std::vector<cv::Point3d> obj = FaceCorners(size_mm, 0);
  cv::Vec3d rvec, tvec;
  if (!cv::solvePnP(obj, corners, camera.K, camera.dist, rvec, tvec, false, cv::SOLVEPNP_IPPE))
    throw InputError(fmt::format("{}: no sample pose fits the four corners", what));
  cv::solvePnPRefineLM(obj, corners, camera.K, camera.dist, rvec, tvec);
  const calib::Pose pose = calib::Pose::FromRodrigues(rvec, tvec);
  for (const auto& p : obj)
    if (pose.Apply({p.x, p.y, p.z})[2] <= 0)
      throw InputError(fmt::format("{}: the corners put the sample behind the camera", what));
  // The face must be seen from its front (its outward normal, -z, towards the camera).
  const cv::Vec3d n = pose.R * cv::Vec3d(0, 0, -1);
  if (n.dot(-pose.t) <= 0)
    throw InputError(fmt::format("{}: the corners are in the wrong order (expected the face's corners "
                                 "(0, 0), (X, 0), (X, Y), (0, Y): the sample seen upright, clockwise from its "
                                 "top-left corner)", what));
  const auto px = camera.Project(Transform(pose, obj));
  double sq = 0, side = 0;
  for (size_t k = 0; k < 4; ++k) {
    sq += std::pow(cv::norm(px[k] - corners[k]), 2);
    side += cv::norm(corners[(k + 1) % 4] - corners[k]) / 4;
  }
  const double rms = std::sqrt(sq / 4);
  if (rms_px) *rms_px = rms;
  // Corners listed from the wrong corner (rotated order) fit a face of the transposed shape:
  // the best pose misses them by a fair part of the face. Clicking errors and a slightly
  // mismeasured sample stay well under the bound.
  const double bound = std::max(kMaxCornerMissPx, kMaxCornerMissFraction * side);
  if (fit_bound && rms > bound)
    throw InputError(fmt::format(
        "{}: the corners do not fit the {:g} x {:g} mm front face (the best pose misses them by "
        "{:.1f} px RMS, more than {:.1f} px): check their order (the face's corner (0, 0) first, then clockwise "
        "as the camera sees the face) and the sample's size", what, obj[2].x, obj[2].y, rms, bound));
  return pose;
}

FaceWidthFit FaceWidthFittingCorners(const DeviceIntrinsics& camera, const std::vector<cv::Point2d>& corners,
                                     const std::array<double, 3>& size_mm) {
  const auto rms_at = [&](double width) {
    double rms = INFINITY;
    try {
      EstimateSamplePose(camera, corners, {width, size_mm[1], size_mm[2]}, "", &rms, false);
    } catch (const InputError&) {
    }
    return rms;
  };
  // Every 1 % of the range, then golden sections about the best.
  FaceWidthFit best;
  const double lo = std::log(0.67), hi = std::log(1.5);
  const int steps = 80;
  int at = 0;
  for (int k = 0; k <= steps; ++k) {
    const double w = size_mm[0] * std::exp(lo + (hi - lo) * k / steps), r = rms_at(w);
    if (r < best.rms_px) best = {w, r}, at = k;
  }
  if (!std::isfinite(best.rms_px)) return best;
  double a = lo + (hi - lo) * std::max(0, at - 1) / steps, b = lo + (hi - lo) * std::min(steps, at + 1) / steps;
  const double g = (std::sqrt(5.0) - 1) / 2;
  // Each step keeps one of its two inner points (and its RMS) for the next.
  double c = b - g * (b - a), d = a + g * (b - a);
  double rc = rms_at(size_mm[0] * std::exp(c)), rd = rms_at(size_mm[0] * std::exp(d));
  for (int k = 0; k < 40; ++k) {
    if (rc < rd) {
      b = d, d = c, rd = rc;
      c = b - g * (b - a), rc = rms_at(size_mm[0] * std::exp(c));
    } else {
      a = c, c = d, rc = rd;
      d = a + g * (b - a), rd = rms_at(size_mm[0] * std::exp(d));
    }
  }
  const double w = size_mm[0] * std::exp((a + b) / 2), r = rms_at(w);
  if (r < best.rms_px) best = {w, r};
  return best;
}

std::string SampleSizeHint(const DeviceIntrinsics& camera, const std::vector<cv::Point2d>& corners,
                           const std::array<double, 3>& size_mm, double rms_px, FaceWidthFit* width_fit) {
  if (!(rms_px > 1)) return "";
  const FaceWidthFit fit = FaceWidthFittingCorners(camera, corners, size_mm);
  if (!(fit.rms_px < 0.5 * rms_px) || std::abs(fit.width_mm - size_mm[0]) < 0.005 * size_mm[0]) return "";
  if (width_fit) *width_fit = fit;
  return fmt::format("the corners found fit a face of {:.2f} x {:g} mm (pose RMS {:.2f} px) better than {:g} x {:g} "
                     "mm ({:.2f} px)", fit.width_mm, size_mm[1], fit.rms_px, size_mm[0], size_mm[1], rms_px);
}

namespace {

// The corners where the lines through consecutive sides' edge points (image points of the four
// sides, in DetectFaceCorners' order: side s runs from corner s to corner s + 1) meet; empty
// where two lines are parallel. With `camera`, the lines are fitted after undistortion and the
// corners returned in the distorted image.
std::vector<cv::Point2d> CornersFromSideEdges(const std::vector<std::vector<cv::Point2f>>& sides,
                                              const DeviceIntrinsics* camera) {
  CV_Assert(sides.size() == 4);
  std::vector<cv::Vec3d> lines;  // a x + b y = c
  for (const std::vector<cv::Point2f>& side : sides) {
    // The face's sides are straight in the ideal pinhole image, not in a distorted one (barrel
    // distortion bows them outwards, and lines through their middles meet outside the corners).
    const std::vector<cv::Point2f> edge = camera ? IdealFromImage(*camera, side) : side;
    cv::Vec4f l;
    cv::fitLine(edge, l, cv::DIST_HUBER, 0, 0.01, 0.01);
    lines.emplace_back(l[1], -l[0], l[1] * l[2] - l[0] * l[3]);
  }
  std::vector<cv::Point2d> out;
  for (int s = 0; s < 4; ++s) {
    const cv::Vec3d& p = lines[size_t((s + 3) % 4)];
    const cv::Vec3d& q = lines[size_t(s)];
    const double det = p[0] * q[1] - p[1] * q[0];
    if (std::abs(det) < 1e-9) return {};
    out.emplace_back((p[2] * q[1] - p[1] * q[2]) / det, (p[0] * q[2] - p[2] * q[0]) / det);
  }
  return camera ? ImageFromIdeal(*camera, out) : out;
}

// The corners of `quad` (the outline of a bright blob in `lin`, luminance) to sub-pixel
// accuracy, in DetectFaceCorners' order; empty where an edge does not show along a side.
// A quadrilateral's corners in DetectFaceCorners' order: top-left (smallest x + y) first, then
// clockwise in the image.
std::vector<cv::Point2d> OrderedQuadrilateral(const std::vector<cv::Point>& quad) {
  std::vector<cv::Point2d> c(quad.begin(), quad.end());
  if ((c[1] - c[0]).cross(c[2] - c[1]) < 0) std::reverse(c.begin(), c.end());
  const auto tl = std::min_element(c.begin(), c.end(), [](const auto& a, const auto& b) {
    return a.x + a.y < b.x + b.y;
  });
  std::rotate(c.begin(), tl, c.end());
  return c;
}

std::vector<cv::Point2d> RefineQuadrilateral(const cv::Mat& lin, const std::vector<cv::Point>& quad,
                                             const DeviceIntrinsics* camera) {
  const std::vector<cv::Point2d> c = OrderedQuadrilateral(quad);
  // Each side: sub-pixel edge points where the image crosses half-way between the values just
  // inside and just outside, along the side's normal; a line through them; corners where
  // consecutive lines meet.
  std::vector<std::vector<cv::Point2f>> sides;
  for (int s = 0; s < 4; ++s) {
    const cv::Point2d a = c[size_t(s)], b = c[size_t((s + 1) % 4)];
    const cv::Point2d d = (b - a) / cv::norm(b - a);
    const cv::Point2d n(d.y, -d.x);  // outward for a clockwise outline (image y down)
    std::vector<cv::Point2f> edge;
    const int count = std::max(8, int(cv::norm(b - a) / 2));
    for (int k = 0; k < count; ++k) {
      const cv::Point2d p = a + (b - a) * (0.15 + 0.7 * (k + 0.5) / count);
      auto at = [&](double t) {
        const cv::Point2d q = p + t * n;
        const int x = int(std::floor(q.x)), y = int(std::floor(q.y));
        if (x < 0 || y < 0 || x + 1 >= lin.cols || y + 1 >= lin.rows) return std::numeric_limits<double>::quiet_NaN();
        const double fx = q.x - x, fy = q.y - y;
        return (1 - fy) * ((1 - fx) * lin.at<float>(y, x) + fx * lin.at<float>(y, x + 1)) +
               fy * ((1 - fx) * lin.at<float>(y + 1, x) + fx * lin.at<float>(y + 1, x + 1));
      };
      const double in = 0.5 * (at(-4) + at(-3)), out = 0.5 * (at(3) + at(4));
      if (!(in > 2 * out)) continue;
      // Where the profile first falls below `level` between -3 and 3 px; NaN where it does not.
      auto crossing = [&](double level) {
        double prev = at(-3);
        for (double t = -2.95; t <= 3; t += 0.05) {
          const double v = at(t);
          if (prev >= level && v < level) return t - 0.05 * (level - v) / (prev - v);
          prev = v;
        }
        return std::numeric_limits<double>::quiet_NaN();
      };
      double tt = crossing(0.5 * (in + out));
      // Half-way between the inside's level at the edge and the outside's: a translucent sample
      // dims towards its edges (light leaves through them), and half-way down from its level a
      // few pixels inside lies inside the edge (0.1-0.2 px here). The inside's profile from 4 to
      // 2 px within the first estimate, extrapolated to it, gives that level.
      if (std::isfinite(tt)) {
        const double near = at(tt - 2), far = at(tt - 4);
        const double at_edge = near + (near - far);
        if (at_edge > 2 * out) {
          const double again = crossing(0.5 * (at_edge + out));
          if (std::isfinite(again)) tt = again;
        }
      }
      if (std::isfinite(tt)) edge.emplace_back(p + tt * n);
    }
    if (edge.size() < 4 || edge.size() < size_t(count) / 2) return {};  // no edge along most of the side
    sides.push_back(std::move(edge));
  }
  return CornersFromSideEdges(sides, camera);
}

}  // namespace

std::vector<cv::Point2d> DetectFaceCorners(const cv::Mat& rgb, const DeviceIntrinsics* camera,
                                           std::vector<cv::Point2d>* outline) {
  CV_Assert(rgb.type() == CV_32FC3);
  if (outline) outline->clear();
  // Luminance (R + G + B), saturated pixels at the brightest finite value, negatives at 0.
  cv::Mat lin(rgb.size(), CV_32F);
  float top = 0;
  for (int y = 0; y < rgb.rows; ++y)
    for (int x = 0; x < rgb.cols; ++x) {
      const cv::Vec3f v = rgb.at<cv::Vec3f>(y, x);
      const float l = v[0] + v[1] + v[2];
      lin.at<float>(y, x) = l;
      if (std::isfinite(l)) top = std::max(top, l);
    }
  if (!(top > 0)) return {};
  for (float& l : cv::Mat_<float>(lin)) l = std::isfinite(l) ? std::max(l, 0.0f) : top;
  // The largest blob of a log-domain Otsu threshold, as a convex quadrilateral; the log scale
  // starts at top * floor_fraction. A photo whose dark background is clipped at 0 keeps only its
  // noise there, which a deep log scale lifts to mid grey in scattered pixels: a median removes
  // most, and shallower scales (1e-4, 1e-2 of the top) are tried where no quadrilateral shows.
  auto quadrilateral = [&](float floor_fraction) -> std::vector<cv::Point> {
    cv::Mat log8(lin.size(), CV_8U);
    const float floor = top * floor_fraction;
    for (int y = 0; y < lin.rows; ++y)
      for (int x = 0; x < lin.cols; ++x) {
        const float l = std::max(lin.at<float>(y, x), floor);
        log8.at<uint8_t>(y, x) = cv::saturate_cast<uint8_t>(255.0 * std::log(l / floor) / std::log(top / floor));
      }
    cv::medianBlur(log8, log8, 5);
    cv::Mat mask;
    cv::threshold(log8, mask, 0, 255, cv::THRESH_BINARY | cv::THRESH_OTSU);
    std::vector<std::vector<cv::Point>> contours;
    cv::findContours(mask, contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_NONE);
    if (contours.empty()) return {};
    const auto& blob = *std::max_element(contours.begin(), contours.end(), [](const auto& a, const auto& b) {
      return cv::contourArea(a) < cv::contourArea(b);
    });
    std::vector<cv::Point> hull, quad;
    cv::convexHull(blob, hull);
    const double perimeter = cv::arcLength(hull, true);
    for (double eps = 0.005; eps < 0.2 && quad.size() != 4; eps *= 1.3)
      cv::approxPolyDP(hull, quad, eps * perimeter, true);
    if (quad.size() != 4 || !cv::isContourConvex(quad)) return {};
    // A sample is solid: nearly all of its outline's inside lies above the threshold (an outline
    // of scattered noise pixels is full of holes).
    cv::Mat inside(mask.size(), CV_8U, cv::Scalar(0));
    cv::fillConvexPoly(inside, quad, cv::Scalar(255));
    const double area = cv::countNonZero(inside);
    if (!(cv::countNonZero(inside & mask) >= 0.97 * area)) return {};
    return quad;
  };
  // Each scale's quadrilateral in turn, until one refines (a scale that lets the background's
  // noise through outlines the whole image, and no edge shows along its sides).
  for (float floor_fraction : {1e-6f, 1e-4f, 1e-2f, 1e-1f}) {
    const std::vector<cv::Point> quad = quadrilateral(floor_fraction);
    if (quad.empty()) continue;
    if (outline && outline->empty()) *outline = OrderedQuadrilateral(quad);
    std::vector<cv::Point2d> corners = RefineQuadrilateral(lin, quad, camera);
    if (!corners.empty()) return corners;
  }
  return {};
}

namespace {

// px^2: the spread a profile sampled across an edge has on top of the lens's blur, the pixel's
// area and the bilinear sampling (1/12 + 1/6).
constexpr double kSamplingVariance = 0.25;

// The least of a cost smooth in sigma = 0.05 st over the steps st: every fifth step from 0 to
// coarse_last (and coarse_last), then every step within 4 of the best of those, up to
// fine_last. `evaluate(trials, &cost)` fills cost[st] for each trial step; cost (NaN where not
// tried, sized fine_last + 1) and the best step come back.
size_t CoarseThenFine(int coarse_last, int fine_last,
                      const std::function<void(const std::vector<int>&, std::vector<double>*)>& evaluate,
                      std::vector<double>* cost) {
  cost->assign(size_t(fine_last + 1), std::numeric_limits<double>::quiet_NaN());
  const auto least = [&] {
    size_t best = 0;
    for (size_t k = 1; k < cost->size(); ++k)
      if ((*cost)[k] < (*cost)[best]) best = k;  // NaN compares false: untried steps never win
    return best;
  };
  std::vector<int> trials;
  for (int st = 0; st <= coarse_last; st += 5) trials.push_back(st);
  if (trials.back() != coarse_last) trials.push_back(coarse_last);
  evaluate(trials, cost);
  const int coarse = int(least());
  trials.clear();
  for (int st = std::max(0, coarse - 4); st <= std::min(fine_last, coarse + 4); ++st)
    if (std::isnan((*cost)[size_t(st)])) trials.push_back(st);
  evaluate(trials, cost);
  return least();
}

// RefineFaceCorners' model of a profile across the face's outline for one lens, on a lattice of
// 0.05 px: samples t = t_lo..t_hi (lattice units, every t_step; > 0 outside), edge offsets
// t0 = -reach..reach, and the model's columns at s = t - t0, tabled once for all profiles:
//     E(s),  s E(s) - sigma_e^2 G(s),  (s^2 + sigma_e^2) E(s) - sigma_e^2 s G(s),  1:
// the blurred images (Gaussian of sigma_e) of a step, and of a ramp and a parabola that the step
// cuts off at s = 0, and a constant surround. The columns' Gram matrix depends on the offset
// only, not on the profile: its inverse is kept per offset, so that a fit costs one correlation.
constexpr double kLattice = 0.05;
struct EdgeModel {
  int t_lo = 0, t_hi = 0, t_step = 5, reach = 0;
  std::vector<int> ts;
  std::vector<cv::Vec4d> table;           // lattice points t_lo - reach .. t_hi + reach
  std::vector<cv::Matx44d> gram_inverse;  // offsets -reach .. reach

  EdgeModel(double sigma_e, double inside_px, double outside_px, double reach_px) {
    t_lo = -t_step * int(std::ceil(inside_px / (t_step * kLattice) - 1e-9));
    t_hi = t_step * int(std::ceil(outside_px / (t_step * kLattice) - 1e-9));
    reach = int(std::ceil(reach_px / kLattice - 1e-9));
    for (int t = t_lo; t <= t_hi; t += t_step) ts.push_back(t);
    for (int k = t_lo - reach; k <= t_hi + reach; ++k) {
      const double sk = k * kLattice, u = sk / sigma_e;
      const double e = 0.5 * std::erfc(u / std::sqrt(2.0)), s2g = sigma_e * std::exp(-0.5 * u * u) / std::sqrt(2 * M_PI);
      table.emplace_back(e, sk * e - s2g, (sk * sk + sigma_e * sigma_e) * e - sk * s2g, 1.0);
    }
    for (int o = -reach; o <= reach; ++o) {
      cv::Matx44d gram = cv::Matx44d::zeros();
      for (int t : ts) gram += Row(t, o) * Row(t, o).t();
      cv::Matx44d inverse;
      if (!cv::invert(gram, inverse, cv::DECOMP_CHOLESKY)) inverse = cv::Matx44d::zeros();
      gram_inverse.push_back(inverse);
    }
  }
  const cv::Vec4d& Row(int t, int o) const { return table[size_t(t - o - (t_lo - reach))]; }
  // The residual sum of squares y'y - c'A'y of the least-squares fit at each offset; the best
  // offset (px, parabola-refined) and its cost. *t0 is NaN where the best is at the reach's end.
  double Fit(const std::vector<double>& y, double* t0) const {
    double yy = 0;
    for (double v : y) yy += v * v;
    double best = INFINITY, l = 0, r = 0;
    int at = 0;
    double previous = INFINITY;
    for (int o = -reach; o <= reach; ++o) {
      cv::Vec4d aty(0, 0, 0, 0);
      for (size_t k = 0; k < ts.size(); ++k) aty += y[k] * Row(ts[k], o);
      const double cost = yy - aty.dot(gram_inverse[size_t(o + reach)] * aty);
      if (cost < best) best = cost, at = o, l = previous, r = INFINITY;
      else if (o == at + 1) r = cost;
      previous = cost;
    }
    *t0 = NAN;
    if (at == -reach || at == reach) return best;
    *t0 = at * kLattice;
    const double curvature = l - 2 * best + r;
    if (curvature > 0) *t0 += kLattice * 0.5 * (l - r) / curvature;
    return best;
  }
};

// RefineFaceCorners' edge points along the sides of a convex polygon (`corners` in order, side s
// from corner s to s + 1, any number of sides): per side, the points p + t0 n found (image px),
// few or none where the edge does not show. *blur_found (optional) receives the blur searched;
// search_blur false fits through blur_px as it is. blur_sides (optional, one flag per side):
// the sides whose profiles the blur is searched on (all where empty).
std::vector<std::vector<cv::Point2f>> OutlineEdgePoints(const std::vector<cv::Mat>& images,
                                                        const DeviceIntrinsics& camera,
                                                        const std::vector<cv::Point2d>& corners, double blur_px,
                                                        const cv::Mat& black, double* blur_found, double reach_px,
                                                        bool search_blur = true,
                                                        const std::vector<bool>& blur_sides = {},
                                                        std::vector<size_t>* profiles = nullptr) {
  CV_Assert(corners.size() >= 3 && blur_px >= 0 && reach_px >= 0);
  for (const cv::Mat& img : images) CV_Assert(img.type() == CV_32FC3 && img.size() == camera.size);
  CV_Assert(black.empty() || (black.type() == CV_32FC3 && black.size() == camera.size));
  const int N = int(corners.size());
  if (blur_found) *blur_found = NAN;
  // sigma_e^2 = blur^2 + kSamplingVariance. The window: t from -max(6, 4 sigma_w) to
  // max(5, 3 sigma_w + 1.5) px, offsets within r = max(1.5, sigma_w), sigma_w the sigma_e of
  // `window_blur`; with reach_px > r, the offsets within reach_px and the window that much wider
  // at both ends.
  const auto sigma_e = [](double blur) { return std::sqrt(blur * blur + kSamplingVariance); };
  const auto model = [&](double blur, double window_blur) {
    const double w = sigma_e(window_blur), reach = std::max(1.5, w), wider = std::max(0.0, reach_px - reach);
    return EdgeModel(sigma_e(blur), std::max(6.0, 4 * w) + wider, std::max(5.0, 3 * w + 1.5) + wider, reach + wider);
  };

  // The profiles: evenly along each side's middle 70 %, straight in the ideal image.
  const std::vector<cv::Point2f> ideal =
      IdealFromImage(camera, std::vector<cv::Point2f>(corners.begin(), corners.end()));
  cv::Point2d centre(0, 0);
  for (const cv::Point2d& c : corners) centre += c * (1.0 / N);
  struct Position {
    int side;
    cv::Point2d p, n;  // the foot on the current outline, the outward unit normal
  };
  std::vector<Position> positions;
  for (int side = 0; side < N; ++side) {
    const cv::Point2d a = ideal[size_t(side)], b = ideal[size_t((side + 1) % N)];
    const double length = cv::norm(b - a);
    const int count = std::max(8, int(length / 2));
    std::vector<cv::Point2d> along;
    for (int k = 0; k < count; ++k) {
      const double u = 0.15 + 0.7 * (k + 0.5) / count, du = 0.5 / std::max(length, 1.0);
      for (double v : {u - du, u, u + du}) along.push_back(a + v * (b - a));
    }
    const auto px = ImageFromIdeal(camera, along);
    for (size_t k = 0; k + 2 < px.size(); k += 3) {
      const cv::Point2d tangent = px[k + 2] - px[k];
      if (!(cv::norm(tangent) > 0)) continue;
      cv::Point2d n(tangent.y, -tangent.x);
      n *= 1.0 / cv::norm(n);
      if (n.dot(px[k + 1] - centre) < 0) n = -n;
      positions.push_back({side, px[k + 1], n});
    }
  }
  const size_t P = positions.size();
  if (profiles) {
    profiles->assign(size_t(N), 0);
    for (const Position& pos : positions) (*profiles)[size_t(pos.side)] += images.size();
  }

  // Profile j (image j / P at position j % P) sampled at m's ts, less the black, over its
  // inside's level; false without an edge to speak of (a non-finite sample, or the inside not
  // above 4x the surround).
  const auto profile = [&](const EdgeModel& m, size_t j, std::vector<double>* y) {
    const cv::Mat& img = images[j / P];
    const Position& pos = positions[j % P];
    y->resize(m.ts.size());
    double inside = 0, outside = 0;
    int n_in = 0, n_out = 0;
    for (size_t k = 0; k < m.ts.size(); ++k) {
      if (!MeanLessBlack(img, black, pos.p + m.ts[k] * kLattice * pos.n, &(*y)[k])) return false;
      if (m.ts[k] - m.t_lo <= 10) inside += (*y)[k], ++n_in;    // the first 0.5 px
      if (m.t_hi - m.ts[k] <= 20) outside += (*y)[k], ++n_out;  // the last 1 px
    }
    inside /= n_in;
    outside /= n_out;
    if (!(inside > 0 && inside > 4 * std::abs(outside))) return false;
    for (double& v : *y) v /= inside;
    return true;
  };

  // The lens's blur: t0 moves with a wrong blur (at 2 px, a blur 13 % low moves the outline
  // ~0.6 px out), and the blur read along an outline that is itself off (EstimateOutlineBlur)
  // is off. So the blur that fits the profiles best is searched for: the sum of the profiles'
  // best costs over ~2000 of them, every 0.25 px from 0 to 2 blur + 1 px, then every 0.05 px
  // within 0.2 px of the best; again with the window of the blur found, until it stays within
  // 0.1 px (three rounds at most).
  std::vector<size_t> usable;  // profiles on the sides the blur is searched on
  for (size_t j = 0; search_blur && j < images.size() * P; ++j)
    if (blur_sides.empty() || blur_sides[size_t(positions[j % P].side)]) usable.push_back(j);
  double blur = blur_px;
  for (int round = 0; round < (search_blur ? 3 : 0); ++round) {
    const double window_blur = blur;
    const EdgeModel window = model(window_blur, window_blur);
    const size_t stride = std::max<size_t>(1, usable.size() / 2000);
    std::vector<std::vector<double>> subset;
    std::vector<double> y;
    for (size_t u = 0; u < usable.size(); u += stride)
      if (profile(window, usable[u], &y)) subset.push_back(y);
    if (subset.empty()) break;
    const int last = 5 * int(std::floor((2 * window_blur + 1) / 0.25 + 1e-9));
    std::vector<double> cost;
    const auto evaluate = [&](const std::vector<int>& trials, std::vector<double>* sums) {
      std::vector<double> fits(subset.size());
      for (int st : trials) {
        const EdgeModel m(sigma_e(0.05 * st), -window.t_lo * kLattice, window.t_hi * kLattice, window.reach * kLattice);
        cv::parallel_for_(cv::Range(0, int(subset.size())), [&](const cv::Range& r) {
          double t0;
          for (int i = r.start; i < r.end; ++i) fits[size_t(i)] = m.Fit(subset[size_t(i)], &t0);
        });
        (*sums)[size_t(st)] = std::accumulate(fits.begin(), fits.end(), 0.0);
      }
    };
    blur = 0.05 * double(CoarseThenFine(last, last + 4, evaluate, &cost));
    if (blur_found) *blur_found = blur;
    if (std::abs(blur - window_blur) < 0.1) break;
  }

  // Each image's profile at each position, fitted for its edge offset.
  const EdgeModel m = model(blur, blur);
  std::vector<cv::Point2f> found(images.size() * P, cv::Point2f(NAN, NAN));
  cv::parallel_for_(cv::Range(0, int(images.size() * P)), [&](const cv::Range& range) {
    std::vector<double> y;
    for (int job = range.start; job < range.end; ++job) {
      double t0;
      if (!profile(m, size_t(job), &y)) continue;
      m.Fit(y, &t0);
      const Position& pos = positions[size_t(job) % P];
      if (std::isfinite(t0)) found[size_t(job)] = cv::Point2f(pos.p + t0 * pos.n);
    }
  });
  std::vector<std::vector<cv::Point2f>> sides(static_cast<size_t>(N));
  for (size_t j = 0; j < found.size(); ++j)
    if (std::isfinite(found[j].x)) sides[size_t(positions[j % P].side)].push_back(found[j]);
  return sides;
}

}  // namespace

std::vector<cv::Point2d> RefineFaceCorners(const std::vector<cv::Mat>& images, const DeviceIntrinsics& camera,
                                           const std::vector<cv::Point2d>& corners, double blur_px,
                                           const cv::Mat& black, int* edge_points, double* blur_found,
                                           double reach_px) {
  CV_Assert(corners.size() == 4);
  if (edge_points) *edge_points = 0;
  const std::vector<std::vector<cv::Point2f>> sides =
      OutlineEdgePoints(images, camera, corners, blur_px, black, blur_found, reach_px);
  for (const auto& side : sides)
    if (side.size() < 8) return {};
  if (edge_points)
    for (const auto& side : sides) *edge_points += int(side.size());
  return CornersFromSideEdges(sides, &camera);
}

std::vector<cv::Point2d> RefineFaceCornersWithin(const std::vector<cv::Mat>& images, const DeviceIntrinsics& camera,
                                                 const std::vector<cv::Point2d>& corners, double blur_px,
                                                 double reach_px, const cv::Mat& black, int* edge_points,
                                                 double* blur_found) {
  std::vector<cv::Point2d> refined = corners;
  double blur = blur_px;
  if (reach_px > 0) refined = RefineFaceCorners(images, camera, corners, blur_px, black, nullptr, &blur, reach_px);
  if (refined.empty()) return {};
  if (!std::isfinite(blur)) blur = blur_px;
  return RefineFaceCorners(images, camera, refined, blur, black, edge_points, blur_found);
}

namespace {

// The block's corner c (bits: x, y, z) in the sample frame.
cv::Vec3d BlockCorner(const std::array<double, 3>& size_mm, int c) {
  return {c & 1 ? size_mm[0] : 0.0, c & 2 ? size_mm[1] : 0.0, c & 4 ? size_mm[2] : 0.0};
}

// A point's ideal pinhole image (pixels through K, no distortion).
cv::Point2d IdealImage(const DeviceIntrinsics& camera, const calib::Pose& camera_from_sample, const cv::Vec3d& x) {
  const cv::Vec3d c = camera_from_sample.Apply(x);
  const cv::Vec3d u = camera.K * cv::Vec3d(c[0] / c[2], c[1] / c[2], 1.0);
  return {u[0], u[1]};
}

// One edge point's distance from the line through two box corners' ideal images, as a function
// of the pose (angle-axis, translation).
struct OutlineDistance {
  OutlineDistance(const cv::Matx33d& K, const cv::Vec3d& a, const cv::Vec3d& b, const cv::Point2d& p)
      : K(K), a(a), b(b), p(p) {}
  template <typename T>
  bool operator()(const T* const r, const T* const t, T* residual) const {
    const auto image = [&](const cv::Vec3d& x, T* u) {
      const T X[3] = {T(x[0]), T(x[1]), T(x[2])};
      T c[3];
      ceres::AngleAxisRotatePoint(r, X, c);
      for (int k = 0; k < 3; ++k) c[k] += t[k];
      const T xn = c[0] / c[2], yn = c[1] / c[2];
      u[0] = K(0, 0) * xn + K(0, 1) * yn + K(0, 2);
      u[1] = K(1, 1) * yn + K(1, 2);
    };
    T ua[2], ub[2];
    image(a, ua);
    image(b, ub);
    const T dx = ub[0] - ua[0], dy = ub[1] - ua[1];
    residual[0] = (dx * (T(p.y) - ua[1]) - dy * (T(p.x) - ua[0])) / ceres::sqrt(dx * dx + dy * dy);
    return true;
  }
  cv::Matx33d K;
  cv::Vec3d a, b;
  cv::Point2d p;
};

}  // namespace

std::array<double, 4> SideFaceSignedWidthsPx(const DeviceIntrinsics& camera, const calib::Pose& camera_from_sample,
                                             const std::array<double, 3>& size_mm) {
  // Per side face: its front edge's two corners (bits); outward is away from the front face's
  // centre.
  const int edges[4][2] = {{0, 2}, {1, 3}, {0, 1}, {2, 3}};
  const cv::Point2d centre =
      IdealImage(camera, camera_from_sample, cv::Vec3d(size_mm[0] / 2, size_mm[1] / 2, 0));
  std::array<double, 4> width{};
  for (int f = 0; f < 4; ++f) {
    const cv::Point2d a = IdealImage(camera, camera_from_sample, BlockCorner(size_mm, edges[f][0]));
    const cv::Point2d b = IdealImage(camera, camera_from_sample, BlockCorner(size_mm, edges[f][1]));
    const cv::Point2d d = (b - a) * (1.0 / std::max(cv::norm(b - a), 1e-12));
    const double outward = d.cross(centre - a) > 0 ? -1 : 1;
    width[size_t(f)] = -INFINITY;
    for (int e : edges[f]) {
      const cv::Point2d back = IdealImage(camera, camera_from_sample, BlockCorner(size_mm, e | 4));
      width[size_t(f)] = std::max(width[size_t(f)], outward * d.cross(back - a));
    }
  }
  return width;
}

std::array<double, 4> SideFaceWidthsPx(const DeviceIntrinsics& camera, const calib::Pose& camera_from_sample,
                                       const std::array<double, 3>& size_mm) {
  std::array<double, 4> width = SideFaceSignedWidthsPx(camera, camera_from_sample, size_mm);
  for (double& w : width) w = std::max(w, 0.0);
  return width;
}

namespace {

// FitBlockOutline from one starting pose.
BlockOutlineFit FitBlockOutlineFrom(const std::vector<cv::Mat>& images, const DeviceIntrinsics& camera,
                                    const std::array<double, 3>& size_mm, const calib::Pose& camera_from_sample,
                                    double blur_px, double reach_px, const cv::Mat& black) {
  BlockOutlineFit fit;
  fit.camera_from_sample = camera_from_sample;
  double blur = blur_px;
  std::vector<cv::Point2d> front;
  const auto front_corners = [&](const calib::Pose& pose) {
    std::vector<cv::Point3d> x;
    for (int c : {0, 1, 3, 2}) {
      const cv::Vec3d p = pose.Apply(BlockCorner(size_mm, c));
      x.emplace_back(p[0], p[1], p[2]);
    }
    return camera.Project(x);
  };
  front = front_corners(fit.camera_from_sample);
  bool settled = false;
  double last_moved = INFINITY;
  // Later rounds still let the edges lie up to 3 px off: a hull side the pose puts a few pixels
  // off the real edge (a side face predicted where none shows) finds no points in the usual
  // window, and nothing would move it.
  constexpr double kLaterReachPx = 3;
  // A side of the outline is explained where at least kSideSupport of its profiles (over all
  // images) find the edge within reach: the block's sides found 75-100 % on the simulated rigs
  // (front-lit regions leave some dark), a side the pose puts where no edge is (a wrong
  // sample_mm: the box cannot match all four of the face's edges) 4-8 %, from noise. Sides
  // shorter than kSupportedSidePx (a narrow side face's ends) are not counted.
  constexpr double kSideSupport = 0.25, kSupportedSidePx = 20;
  for (int round = 0; round < 16; ++round) {
    // The outline: the convex hull of the eight corners' ideal images, its corners in order.
    std::vector<cv::Point2f> ideal;
    for (int c = 0; c < 8; ++c) ideal.push_back(IdealImage(camera, fit.camera_from_sample, BlockCorner(size_mm, c)));
    std::vector<int> hull;
    cv::convexHull(ideal, hull, /*clockwise=*/false);
    std::vector<cv::Point2d> polygon;
    for (int c : hull) polygon.push_back(ImageFromIdeal(camera, {cv::Point2d(ideal[size_t(c)])})[0]);
    // The wide first round fits through the blur given: a blur search in a window that wide
    // reads more than the edge. The blur is searched in the second round, and again once the
    // pose has nearly settled (a blur that changes every round moves the edges by tenths of a
    // pixel, and the pose with them, back and forth).
    double found_blur = NAN;
    const bool search = round == 1 || (round > 1 && last_moved < 0.1);
    // The blur is searched on the hull's sides that are front-face edges: across a side face's
    // outer edge the profile's inside holds the crease, where the radiance's slope along the
    // image changes (the side face is foreshortened), which a narrow strip puts within the
    // window and the model does not follow (a strip of a few pixels read the blur as 1.5-2.4 px).
    std::vector<bool> front_edge;
    for (size_t k = 0; k < hull.size(); ++k) front_edge.push_back(hull[k] < 4 && hull[(k + 1) % hull.size()] < 4);
    std::vector<size_t> profiles;
    const std::vector<std::vector<cv::Point2f>> sides =
        OutlineEdgePoints(images, camera, polygon, blur, black, &found_blur,
                          round == 0 ? reach_px : kLaterReachPx, search, front_edge, &profiles);
    const bool blur_moved = std::isfinite(found_blur) && std::abs(found_blur - blur) >= 0.05;
    if (std::isfinite(found_blur)) blur = found_blur;
    ceres::Problem problem;
    cv::Vec3d r;
    cv::Rodrigues(fit.camera_from_sample.R, r);
    double rv[3] = {r[0], r[1], r[2]};
    double tv[3] = {fit.camera_from_sample.t[0], fit.camera_from_sample.t[1], fit.camera_from_sample.t[2]};
    fit.sides = fit.edge_points = 0;
    fit.least_side_support = 1;
    for (size_t s = 0; s < sides.size(); ++s) {
      const double length = cv::norm(ideal[size_t(hull[s])] - ideal[size_t(hull[(s + 1) % hull.size()])]);
      if (length >= kSupportedSidePx)
        fit.least_side_support =
            std::min(fit.least_side_support, double(sides[s].size()) / double(std::max<size_t>(1, profiles[s])));
      if (sides[s].size() < 8) continue;
      ++fit.sides;
      const cv::Vec3d a = BlockCorner(size_mm, hull[s]), b = BlockCorner(size_mm, hull[(s + 1) % hull.size()]);
      for (const cv::Point2f& p : IdealFromImage(camera, sides[s])) {
        problem.AddResidualBlock(new ceres::AutoDiffCostFunction<OutlineDistance, 1, 3, 3>(
                                     new OutlineDistance(camera.K, a, b, cv::Point2d(p))),
                                 new ceres::HuberLoss(1.0), rv, tv);
        ++fit.edge_points;
      }
    }
    if (fit.sides < 4) return fit;
    ceres::Solver::Options options;
    options.linear_solver_type = ceres::DENSE_QR;
    options.max_num_iterations = 50;
    ceres::Solver::Summary summary;
    ceres::Solve(options, &problem, &summary);
    fit.camera_from_sample = calib::Pose::FromRodrigues({rv[0], rv[1], rv[2]}, {tv[0], tv[1], tv[2]});
    fit.rms_px = std::sqrt(2 * summary.final_cost / std::max(1, fit.edge_points));
    fit.blur_px = blur;
    const std::vector<cv::Point2d> moved = front_corners(fit.camera_from_sample);
    double most = 0;
    for (size_t k = 0; k < 4; ++k) most = std::max(most, cv::norm(moved[k] - front[k]));
    front = moved;
    last_moved = most;
    if (round > 1 && most < 0.02 && !blur_moved) {
      settled = true;
      break;
    }
  }
  fit.ok = true;
  fit.corners = front;
  fit.converged = settled && fit.least_side_support >= kSideSupport;
  return fit;
}

}  // namespace

OutlineFitNeed NeedsBlockOutlineFit(const DeviceIntrinsics& camera, const calib::Pose& camera_from_sample,
                                    const std::array<double, 3>& size_mm, CornerSource source,
                                    double pose_rms_px, bool outline_unrefined) {
  const std::array<double, 4> side_px = SideFaceSignedWidthsPx(camera, camera_from_sample, size_mm);
  const double widest = *std::max_element(side_px.begin(), side_px.end());
  OutlineFitNeed need;
  need.required =
      widest > kSideFaceShowsPx || (source == CornerSource::kFound && (pose_rms_px > 1 || outline_unrefined));
  need.needed = need.required || (source != CornerSource::kExact && widest > -kSideFaceNearPx);
  need.reach_px = source == CornerSource::kExact ? 0 : std::min(kNearCornerReachPx + 2 * pose_rms_px, 15.0);
  need.source = source;
  need.pose_rms_px = pose_rms_px;
  return need;
}

BlockOutlineFit FitBlockOutline(const std::vector<cv::Mat>& images, const DeviceIntrinsics& camera,
                                const std::array<double, 3>& size_mm, const calib::Pose& camera_from_sample,
                                double blur_px, double reach_px, const cv::Mat& black) {
  // A block's outline fits two poses nearly as well where the view is close to parallel (the
  // side face seen may be taken for its neighbour, the block turned the other way): the fit
  // starts from the given pose and from it turned about the front face's x and y axes through
  // its centre, both ways, by the angle at which a side face starts to show plus 5 degrees.
  const cv::Vec3d centre(size_mm[0] / 2, size_mm[1] / 2, 0);
  const double distance = cv::norm(camera_from_sample.Apply(centre));
  const double angle = std::atan(0.5 * std::max(size_mm[0], size_mm[1]) / distance) + 5 * CV_PI / 180;
  std::vector<calib::Pose> starts = {camera_from_sample};
  for (int axis = 0; axis < 2; ++axis)
    for (double sign : {-1.0, 1.0}) {
      cv::Vec3d r(0, 0, 0);
      r[axis] = sign * angle;
      calib::Pose turn = calib::Pose::FromRodrigues(r, {0, 0, 0});
      turn.t = centre - turn.R * centre;  // about the face's centre
      starts.push_back(camera_from_sample * turn);
    }
  std::vector<BlockOutlineFit> fits(starts.size());
  for (size_t k = 0; k < starts.size(); ++k)
    fits[k] = FitBlockOutlineFrom(images, camera, size_mm, starts[k], blur_px, reach_px, black);
  // The fit that explains the most of the outline: among those that use at least 80 % of the
  // most edge points any fit used, a settled one before any other, then the least RMS.
  int most = 0;
  for (const BlockOutlineFit& f : fits)
    if (f.ok) most = std::max(most, f.edge_points);
  const BlockOutlineFit* best = nullptr;
  for (const BlockOutlineFit& f : fits)
    if (f.ok && f.edge_points >= 0.8 * most && (!best || f.converged > best->converged ||
                                                (f.converged == best->converged && f.rms_px < best->rms_px)))
      best = &f;
  return best ? *best : fits.front();
}

OutlineChoice ChooseBlockOutline(const std::vector<cv::Mat>& images, const DeviceIntrinsics& camera,
                                 const std::array<double, 3>& size_mm, const calib::Pose& camera_from_sample,
                                 const std::vector<cv::Point2d>& corners, double blur_px,
                                 const OutlineFitNeed& need, const cv::Mat& black) {
  OutlineChoice c;
  c.fit = FitBlockOutline(images, camera, size_mm, camera_from_sample, blur_px, need.reach_px, black);
  c.settled = c.fit.ok && c.fit.converged;
  c.side_px = SideFaceWidthsPx(camera, c.settled ? c.fit.camera_from_sample : camera_from_sample, size_mm);
  const bool shows = *std::max_element(c.side_px.begin(), c.side_px.end()) > kSideFaceShowsPx;
  // A fit that only looked for a side face near showing is kept where it found one.
  c.use_fit = need.required || (c.settled && shows);
  if (!need.required || need.source == CornerSource::kExact) return c;
  FaceWidthFit width;
  std::string hint = SampleSizeHint(camera, corners, size_mm, need.pose_rms_px, &width);
  if (hint.empty()) return c;
  const std::array<double, 3> other = {width.width_mm, size_mm[1], size_mm[2]};
  const BlockOutlineFit alt = FitBlockOutline(
      images, camera, other, EstimateSamplePose(camera, corners, other, "", nullptr, false), blur_px,
      need.reach_px, black);
  if (alt.ok && alt.converged && (!c.settled || c.fit.rms_px > 1.5 * alt.rms_px)) {
    c.size_hint = hint;
    c.use_fit = false;
  }
  return c;
}

FaceSamples ResampleFrontFace(const cv::Mat& img, const DeviceIntrinsics& camera,
                              const calib::Pose& camera_from_sample, const GridShape& g, double h,
                              int samples, const cv::Mat* coverage) {
  CV_Assert(img.type() == CV_32FC3);
  CV_Assert(!coverage || (coverage->type() == CV_32FC1 && coverage->size() == img.size()));
  // At least one sample per pixel of the node's footprint (measured around the face's centre
  // and corners), so that every pixel under a node is seen: a box filter over the footprint.
  {
    std::vector<cv::Point3d> probe;
    for (double fx : {0.0, 0.5, 1.0})
      for (double fy : {0.0, 0.5, 1.0}) {
        const double x = fx * double(g.nx - 2) * h, y = fy * double(g.ny - 2) * h;
        for (const cv::Vec3d& d : {cv::Vec3d(0, 0, 0), cv::Vec3d(h, 0, 0), cv::Vec3d(0, h, 0)}) {
          const cv::Vec3d c = camera_from_sample.Apply(cv::Vec3d(x, y, 0) + d);
          probe.emplace_back(c[0], c[1], c[2]);
        }
      }
    const auto pp = camera.Project(probe);
    double px_per_node = 0;
    for (size_t k = 0; k < pp.size(); k += 3)
      px_per_node = std::max({px_per_node, cv::norm(pp[k + 1] - pp[k]), cv::norm(pp[k + 2] - pp[k])});
    samples = std::max(samples, std::min(64, int(std::ceil(px_per_node)) + 1));
  }
  const auto px = camera.Project(Transform(camera_from_sample, FaceBoxPoints(g, h, 0, samples)));
  const int64_t F = g.face_size();
  const size_t S = size_t(samples * samples);
  FaceSamples out;
  for (auto& ch : out.value) ch.assign(size_t(F), std::numeric_limits<float>::quiet_NaN());
  out.saturated.assign(size_t(F), 0.0f);
  for (int64_t f = 0; f < F; ++f) {
    cv::Vec3d sum(0, 0, 0);
    double weight = 0;
    int n = 0, sat = 0;
    for (size_t s = 0; s < S; ++s) {
      const cv::Point2d& at = px[size_t(f) * S + s];
      cv::Vec3f v;
      if (!Bilinear(img, at, &v)) continue;
      if (!std::isfinite(v[0] + v[1] + v[2])) {
        ++sat;
        continue;
      }
      sum += cv::Vec3d(v);
      ++n;
      if (coverage) weight += BilinearGrey(*coverage, at);
    }
    if (!coverage) weight = n;
    out.saturated[size_t(f)] = float(sat) / float(S);
    if (n == int(S) && weight > 0)
      for (int c = 0; c < 3; ++c) out.value[size_t(c)][size_t(f)] = float(sum[c] / weight);
  }
  return out;
}

cv::Mat FaceCoverage(const DeviceIntrinsics& camera, const calib::Pose& camera_from_sample, const GridShape& g,
                     double h, double blur_px, int s) {
  TL_CHECK(blur_px >= 0 && s >= 1);
  cv::Mat cov(camera.size, CV_32FC1, cv::Scalar(0));
  // The face's bounding box in the image (its outline sampled, for the distortion), 3 px wider.
  const std::array<double, 3> size = SampleSize(g, h);
  std::vector<cv::Point3d> outline;
  for (int k = 0; k <= 64; ++k) {
    const double t = k / 64.0;
    for (const cv::Point3d& p : {cv::Point3d(t * size[0], 0, 0), cv::Point3d(t * size[0], size[1], 0),
                                 cv::Point3d(0, t * size[1], 0), cv::Point3d(size[0], t * size[1], 0)})
      outline.push_back(p);
  }
  const auto opx = camera.Project(Transform(camera_from_sample, outline));
  cv::Rect2d box = cv::boundingRect(std::vector<cv::Point2f>(opx.begin(), opx.end()));
  const cv::Rect roi = cv::Rect(int(std::floor(box.x)) - 3, int(std::floor(box.y)) - 3, int(std::ceil(box.width)) + 7,
                                int(std::ceil(box.height)) + 7) & cv::Rect(cv::Point(0, 0), camera.size);
  if (roi.empty()) return cov;
  // Each pixel corner's ray (undistorted, normalised) and where it meets the face's plane.
  std::vector<cv::Point2d> corners;
  for (int y = 0; y <= roi.height; ++y)
    for (int x = 0; x <= roi.width; ++x) corners.emplace_back(roi.x + x - 0.5, roi.y + y - 0.5);
  std::vector<cv::Point2d> rays;
  cv::undistortPoints(corners, rays, camera.K, camera.dist);
  const calib::Pose sample_from_camera = camera_from_sample.Inverse();
  auto sees_face = [&](const cv::Point2d& r) {
    cv::Point2d xy;
    return RayOnPlane(sample_from_camera, r, 0.0, &xy) && xy.x >= 0 && xy.y >= 0 && xy.x <= size[0] &&
           xy.y <= size[1];
  };
  const int W = roi.width + 1;
  cv::parallel_for_(cv::Range(0, roi.height), [&](const cv::Range& rr) {
    for (int y = rr.start; y < rr.end; ++y)
      for (int x = 0; x < roi.width; ++x) {
        const cv::Point2d r00 = rays[size_t(y * W + x)], r10 = rays[size_t(y * W + x + 1)];
        const cv::Point2d r01 = rays[size_t((y + 1) * W + x)], r11 = rays[size_t((y + 1) * W + x + 1)];
        int in = 0;
        for (const cv::Point2d& r : {r00, r10, r01, r11}) in += sees_face(r);
        float v = in == 4 ? 1.0f : 0.0f;
        if (in > 0 && in < 4) {
          int count = 0;
          for (int b = 0; b < s; ++b)
            for (int a = 0; a < s; ++a) {
              const double fa = (a + 0.5) / s, fb = (b + 0.5) / s;
              const cv::Point2d r = (1 - fb) * ((1 - fa) * r00 + fa * r10) + fb * ((1 - fa) * r01 + fa * r11);
              count += sees_face(r);
            }
          v = float(count) / float(s * s);
        }
        cov.at<float>(roi.y + y, roi.x + x) = v;
      }
  });
  if (blur_px > 0) {  // on the face's box widened by the kernel's reach (OpenCV's: 4 sigma)
    const int reach = int(std::ceil(4 * blur_px)) + 1;
    const cv::Rect wide = cv::Rect(roi.x - reach, roi.y - reach, roi.width + 2 * reach, roi.height + 2 * reach) &
                          cv::Rect(cv::Point(0, 0), camera.size);
    cv::Mat part = cov(wide).clone();
    cv::GaussianBlur(part, part, cv::Size(0, 0), blur_px, blur_px, cv::BORDER_CONSTANT);
    part.copyTo(cov(wide));
  }
  return cov;
}

OutlineBlur EstimateOutlineBlur(const std::vector<cv::Mat>& images, const DeviceIntrinsics& camera,
                                const calib::Pose& camera_from_sample, const GridShape& g, double h,
                                double max_sigma_px, const cv::Mat& black) {
  for (const cv::Mat& img : images) CV_Assert(img.type() == CV_32FC3 && img.size() == camera.size);
  CV_Assert(black.empty() || (black.type() == CV_32FC3 && black.size() == camera.size));
  TL_CHECK(max_sigma_px > 0);
  const double reach = 3 * max_sigma_px + 3;  // a profile's half length, px
  const int half = int(std::ceil(reach / 0.5));
  const int nt = 2 * half + 1;
  std::vector<double> ts(static_cast<size_t>(nt));
  for (int k = 0; k < nt; ++k) ts[size_t(k)] = 0.5 * (k - half);

  // The profiles: for each, nt image points from inside (t < 0) to outside.
  const std::vector<cv::Point3d> corners = FrontFaceCorners(g, h);
  const auto project = [&](const cv::Point3d& p) { return camera.Project(Transform(camera_from_sample, {p}))[0]; };
  const cv::Point2d centre = project(0.5 * (corners[0] + corners[2]));
  std::vector<cv::Point2d> points;
  for (int side = 0; side < 4; ++side) {
    const cv::Point3d A = corners[size_t(side)], B = corners[size_t((side + 1) % 4)];
    const cv::Point2d a = project(A), b = project(B);
    const double length = cv::norm(b - a);
    const int count = int(length / 1.5);
    if (count < 2) continue;
    std::vector<cv::Point3d> along;  // each profile's foot and two points half a pixel either side
    for (int k = 1; k < count; ++k) {
      const double u = double(k) / count, du = 0.5 / length;
      for (double v : {u - du, u, u + du}) along.push_back(A + v * (B - A));
    }
    const auto px = camera.Project(Transform(camera_from_sample, along));
    for (size_t k = 0; k + 2 < px.size(); k += 3) {
      const cv::Point2d p = px[k + 1], tangent = px[k + 2] - px[k];
      if (cv::norm(p - a) < reach + 2 || cv::norm(p - b) < reach + 2 || !(cv::norm(tangent) > 0)) continue;
      cv::Point2d n(tangent.y, -tangent.x);
      n *= 1.0 / cv::norm(n);
      if (n.dot(p - centre) < 0) n = -n;
      const cv::Point2d first = p + ts.front() * n, last = p + ts.back() * n;
      const auto inside = [&](const cv::Point2d& q) {
        return q.x >= 0 && q.y >= 0 && q.x <= camera.size.width - 2 && q.y <= camera.size.height - 2;
      };
      if (!inside(first) || !inside(last)) continue;
      for (double t : ts) points.push_back(p + t * n);
    }
  }
  const int P = int(points.size()) / nt;

  // Each image along them (the channels' mean), scaled to its brightest usable profile's
  // largest value, so that dim profiles weigh less; profiles with a non-finite sample dropped.
  struct Profile {
    int geometry;           // index into the P profiles
    std::vector<double> y;  // nt values
  };
  std::vector<Profile> profiles;
  for (const cv::Mat& img : images) {
    std::vector<Profile> own;
    double brightest = 0;
    for (int p = 0; p < P; ++p) {
      Profile pr{p, std::vector<double>(static_cast<size_t>(nt))};
      double top = 0;
      bool ok = true;
      for (int k = 0; k < nt && ok; ++k) {
        ok = MeanLessBlack(img, black, points[size_t(p * nt + k)], &pr.y[size_t(k)]);
        if (!ok) pr.y[size_t(k)] = 0;
        top = std::max(top, std::abs(pr.y[size_t(k)]));
      }
      if (!ok || !(top > 0)) continue;
      brightest = std::max(brightest, top);
      own.push_back(std::move(pr));
    }
    for (Profile& pr : own) {
      for (double& v : pr.y) v /= brightest;
      profiles.push_back(std::move(pr));
    }
  }
  OutlineBlur out;
  out.positions = P;
  out.profiles = int(profiles.size());
  if (profiles.empty()) return out;

  // The coverage on the profiles' box widened by the largest kernel's reach, blurred per sigma.
  const cv::Mat sharp = FaceCoverage(camera, camera_from_sample, g, h);
  const int margin = int(std::ceil(4 * max_sigma_px)) + 2;
  cv::Rect box = cv::boundingRect(std::vector<cv::Point2f>(points.begin(), points.end()));
  box = cv::Rect(box.x - margin, box.y - margin, box.width + 2 * margin, box.height + 2 * margin) &
        cv::Rect(cv::Point(0, 0), camera.size);
  const cv::Mat crop = sharp(box).clone();
  const cv::Point2d origin(box.x, box.y);
  const int steps = int(std::floor(max_sigma_px / 0.05 + 1e-9));
  // The summed squared residual per trial sigma = 0.05 st (NaN: not tried): every fifth first,
  // then every step within 0.2 px of the best of those (the cost is smooth in sigma).
  std::vector<double> cost;
  const auto evaluate = [&](const std::vector<int>& trials, std::vector<double>* sums) {
    // One sigma per task: each has its own design rows and normal matrices.
    cv::parallel_for_(cv::Range(0, int(trials.size())), [&](const cv::Range& range) {
      std::vector<cv::Vec3d> rows(static_cast<size_t>(P) * size_t(nt));
      std::vector<cv::Matx33d> inverse(static_cast<size_t>(P));
      for (int trial = range.start; trial < range.end; ++trial) {
        const int st = trials[size_t(trial)];
        const double sigma = 0.05 * st;
        double sum = 0;
        cv::Mat c;
        if (sigma > 0) cv::GaussianBlur(crop, c, cv::Size(0, 0), sigma, sigma, cv::BORDER_CONSTANT);
        else c = crop;
        // The design (c, t c + v c', 1) of each profile's points and its normal matrix, shared by
        // the images: the blurred images of a radiance constant and linear up to the outline (for a
        // kernel of variance v, K * (t f) = t (K * f) + v (K * f)'; v = sigma^2 + 1/4 px^2 with the
        // pixel's area and the bilinear sampling), and the surround.
        const double v = sigma * sigma + kSamplingVariance;
        for (int p = 0; p < P; ++p) {
          cv::Matx33d AtA = cv::Matx33d::zeros();
          for (int k = 0; k < nt; ++k) rows[size_t(p * nt + k)][0] = BilinearGrey(c, points[size_t(p * nt + k)] - origin);
          for (int k = 0; k < nt; ++k) {
            const size_t i = size_t(p * nt + k);
            const double cov = rows[i][0];
            const double slope = (rows[size_t(p * nt + std::min(k + 1, nt - 1))][0] - rows[size_t(p * nt + std::max(k - 1, 0))][0]) /
                                 (ts[size_t(std::min(k + 1, nt - 1))] - ts[size_t(std::max(k - 1, 0))]);
            rows[i] = cv::Vec3d(cov, ts[size_t(k)] * cov + v * slope, 1.0);
            AtA += rows[i] * rows[i].t();
          }
          inverse[size_t(p)] = AtA.inv(cv::DECOMP_SVD);
        }
        for (const Profile& pr : profiles) {
          cv::Vec3d Aty(0, 0, 0);
          for (int k = 0; k < nt; ++k) Aty += pr.y[size_t(k)] * rows[size_t(pr.geometry * nt + k)];
          const cv::Vec3d coef = inverse[size_t(pr.geometry)] * Aty;
          for (int k = 0; k < nt; ++k) {
            const double e = pr.y[size_t(k)] - rows[size_t(pr.geometry * nt + k)].dot(coef);
            sum += e * e;
          }
        }
        (*sums)[size_t(st)] = sum;
      }
    });
  };
  const size_t best = CoarseThenFine(steps, steps, evaluate, &cost);
  double sigma = 0.05 * double(best);
  if (best > 0 && best + 1 < cost.size()) {
    const double l = cost[best - 1], m = cost[best], r = cost[best + 1];
    const double curvature = l - 2 * m + r;
    if (curvature > 0) sigma += 0.05 * 0.5 * (l - r) / curvature;
  }
  const double samples = double(out.profiles) * nt;
  out.sigma_px = sigma;
  out.rms = std::sqrt(cost[best] / samples);
  out.rms_sharp = std::sqrt(cost[0] / samples);
  return out;
}

std::vector<float> ProjectPatternOnFace(const cv::Mat& pattern, const DeviceIntrinsics& projector,
                                        const calib::Pose& projector_from_camera,
                                        const calib::Pose& camera_from_sample, const GridShape& g,
                                        double h, Setup setup, int samples) {
  CV_Assert(pattern.type() == CV_32FC1);
  const double z = LitFaceZ(g, h, setup);
  const std::vector<cv::Point3d> cam = Transform(camera_from_sample, FaceBoxPoints(g, h, z, samples));
  const auto px = projector.Project(Transform(projector_from_camera, cam));
  const bool faces = LitFaceFacesProjector(projector_from_camera, camera_from_sample, z, setup);
  const int64_t F = g.face_size();
  const size_t S = size_t(samples * samples);
  std::vector<float> q(size_t(F), 0.0f);
  if (!faces) return q;
  for (int64_t f = 0; f < F; ++f) {
    double sum = 0;
    for (size_t s = 0; s < S; ++s) {
      const cv::Point2d& p = px[size_t(f) * S + s];
      const int x = int(std::lround(p.x)), y = int(std::lround(p.y));
      if (x >= 0 && y >= 0 && x < pattern.cols && y < pattern.rows) sum += pattern.at<float>(y, x);
    }
    q[size_t(f)] = float(sum / double(S));
  }
  return q;
}

namespace {

// Where each projector pixel's centre ray meets the plane z = `z` of the sample frame (mm):
// CV_64FC2, NaN where it does not (parallel, or behind the projector).
cv::Mat PlaneHits(const DeviceIntrinsics& projector, const calib::Pose& projector_from_camera,
                  const calib::Pose& camera_from_sample, double z) {
  std::vector<cv::Point2d> pix, norm;
  pix.reserve(size_t(projector.size.area()));
  for (int y = 0; y < projector.size.height; ++y)
    for (int x = 0; x < projector.size.width; ++x) pix.emplace_back(x, y);
  cv::undistortPoints(pix, norm, projector.K, projector.dist, cv::noArray(), cv::noArray(),
                      cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 50, 1e-12));
  const calib::Pose sample_from_projector = camera_from_sample.Inverse() * projector_from_camera.Inverse();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  cv::Mat hits(projector.size, CV_64FC2, cv::Scalar(nan, nan));
  for (size_t k = 0; k < norm.size(); ++k) {
    cv::Point2d xy;
    if (RayOnPlane(sample_from_projector, norm[k], z, &xy))
      hits.at<cv::Vec2d>(int(k) / projector.size.width, int(k) % projector.size.width) = cv::Vec2d(xy.x, xy.y);
  }
  return hits;
}

}  // namespace

cv::Mat PatternForFaceRect(const DeviceIntrinsics& projector, const calib::Pose& projector_from_camera,
                           const calib::Pose& camera_from_sample, const GridShape& g, double h,
                           Setup setup, const std::array<double, 4>& rect) {
  const cv::Mat hits = PlaneHits(projector, projector_from_camera, camera_from_sample, LitFaceZ(g, h, setup));
  cv::Mat out(projector.size, CV_8UC1, cv::Scalar(0));
  for (int y = 0; y < out.rows; ++y)
    for (int x = 0; x < out.cols; ++x) {
      const cv::Vec2d p = hits.at<cv::Vec2d>(y, x);
      if (p[0] >= rect[0] && p[0] <= rect[1] && p[1] >= rect[2] && p[1] <= rect[3]) out.at<uint8_t>(y, x) = 255;
    }
  return out;
}

bool LitFaceInsideProjector(const DeviceIntrinsics& projector, const calib::Pose& projector_from_camera,
                            const calib::Pose& camera_from_sample, const std::array<double, 3>& size_mm,
                            Setup setup) {
  const std::vector<cv::Point3d> in_projector =
      Transform(projector_from_camera, Transform(camera_from_sample, FaceCorners(size_mm, LitFaceZ(size_mm, setup))));
  for (const cv::Point3d& p : in_projector)
    if (p.z <= 0) return false;
  for (const cv::Point2d& uv : projector.Project(in_projector))
    if (!(uv.x >= -0.5 && uv.y >= -0.5 && uv.x <= projector.size.width - 0.5 && uv.y <= projector.size.height - 0.5))
      return false;
  return true;
}

namespace {

// The projector images (CV_8UC1, 255 inside) of `count` lit-face areas: visit(p, hit) calls
// hit(m) for each area m that the lit-face point p (mm, sample frame) lies in. `what(m)` names
// area m where no projector pixel lights it (InputError), and where the lit face is turned
// away from the projector.
std::vector<cv::Mat> FacePatterns(const DeviceIntrinsics& projector, const calib::Pose& projector_from_camera,
                                  const calib::Pose& camera_from_sample, const std::array<double, 3>& size_mm,
                                  Setup setup, int count,
                                  const std::function<void(const cv::Vec2d&, const std::function<void(int)>&)>& visit,
                                  const std::function<std::string(int)>& what) {
  const double z = LitFaceZ(size_mm, setup);
  const Setup other = setup == Setup::kBack ? Setup::kFront : Setup::kBack;
  if (!LitFaceFacesProjector(projector_from_camera, camera_from_sample, z, setup))
    throw InputError(fmt::format("the projector is on the {} side of the sample, so it cannot light its {} face: "
                                 "is the setup {}?", SetupName(other), SetupName(setup), SetupName(other)));
  const cv::Mat hits = PlaneHits(projector, projector_from_camera, camera_from_sample, z);
  auto for_areas = [&](const std::function<void(int, int, int)>& f) {
    for (int y = 0; y < hits.rows; ++y)
      for (int x = 0; x < hits.cols; ++x) {
        const cv::Vec2d p = hits.at<cv::Vec2d>(y, x);
        if (!(p[0] >= 0 && p[0] <= size_mm[0] && p[1] >= 0 && p[1] <= size_mm[1])) continue;
        visit(p, [&](int m) { f(m, x, y); });
      }
  };
  // Counted first, so that areas no pixel lights are named before the images are made.
  std::vector<int64_t> lit(size_t(count), 0);
  for_areas([&](int m, int, int) { ++lit[size_t(m)]; });
  for (int m = 0; m < count; ++m)
    if (lit[size_t(m)] == 0)
      throw InputError(fmt::format("no projector pixel lights {} of the {} face: the face lies partly outside the "
                                   "projector's image, or the {} smaller than its pixels", what(m),
                                   SetupName(setup), what(-1)));
  std::vector<cv::Mat> out;
  for (int m = 0; m < count; ++m) out.emplace_back(projector.size, CV_8UC1, cv::Scalar(0));
  for_areas([&](int m, int x, int y) { out[size_t(m)].at<uint8_t>(y, x) = 255; });
  return out;
}

}  // namespace

std::vector<cv::Mat> RegionPatterns(const DeviceIntrinsics& projector, const calib::Pose& projector_from_camera,
                                    const calib::Pose& camera_from_sample, const std::array<double, 3>& size_mm,
                                    Setup setup, int n) {
  TL_CHECK(n >= 1);
  // Region I covers [I X / n, (I + 1) X / n]; a pixel on a shared edge lights both.
  const auto visit = [&](const cv::Vec2d& p, const std::function<void(int)>& hit) {
    // The regions next to the one p's coordinates round into (an edge may round either way).
    const int i0 = int(p[0] * n / size_mm[0]), j0 = int(p[1] * n / size_mm[1]);
    for (int J = std::max(0, j0 - 1); J < std::min(n, j0 + 2); ++J)
      for (int I = std::max(0, i0 - 1); I < std::min(n, i0 + 2); ++I)
        if (p[0] >= I * size_mm[0] / n && p[0] <= (I + 1) * size_mm[0] / n && p[1] >= J * size_mm[1] / n &&
            p[1] <= (J + 1) * size_mm[1] / n)
          hit(I + n * J);
  };
  const auto what = [&](int m) {
    return m < 0 ? std::string("regions are") : fmt::format("region {} ({}, {})", m, m % n, m / n);
  };
  return FacePatterns(projector, projector_from_camera, camera_from_sample, size_mm, setup, n * n, visit, what);
}

std::vector<std::array<double, 3>> ValidationSpots(const std::array<double, 3>& size_mm, int count) {
  const double r = std::min(size_mm[0], size_mm[1]) / 8;
  // Halton's sequence in bases 2 and 3 from its second point (the first is the corner (0, 0)).
  const auto halton = [](int i, int base) {
    double f = 1, v = 0;
    for (; i > 0; i /= base) {
      f /= base;
      v += f * (i % base);
    }
    return v;
  };
  std::vector<std::array<double, 3>> spots;
  for (int i = 1; i <= count; ++i)
    spots.push_back({r + halton(i, 2) * (size_mm[0] - 2 * r), r + halton(i, 3) * (size_mm[1] - 2 * r), r});
  return spots;
}

std::vector<cv::Mat> SpotPatterns(const DeviceIntrinsics& projector, const calib::Pose& projector_from_camera,
                                  const calib::Pose& camera_from_sample, const std::array<double, 3>& size_mm,
                                  Setup setup, const std::vector<std::array<double, 3>>& spots) {
  const auto visit = [&](const cv::Vec2d& p, const std::function<void(int)>& hit) {
    for (size_t m = 0; m < spots.size(); ++m)
      if (std::hypot(p[0] - spots[m][0], p[1] - spots[m][1]) <= spots[m][2]) hit(int(m));
  };
  const auto what = [&](int m) {
    return m < 0 ? std::string("spots are")
                 : fmt::format("spot {} at ({:g}, {:g}) mm", m, spots[size_t(m)][0], spots[size_t(m)][1]);
  };
  return FacePatterns(projector, projector_from_camera, camera_from_sample, size_mm, setup, int(spots.size()),
                      visit, what);
}

}  // namespace translume::acquire
