// SPDX-License-Identifier: MIT
#include "calib/white.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/mcc.hpp>

#include "calib/colorchecker.h"
#include "calib/error.h"

namespace translume::calib {
namespace {

constexpr double kPi = 3.14159265358979323846;

cv::Mat Subtract(const cv::Mat& white, const cv::Mat& black) {
  if (white.type() != CV_32FC3) throw CalibError("white balance: the white HDR must be float RGB");
  if (black.empty()) return white;
  if (black.size() != white.size() || black.type() != white.type())
    throw CalibError(fmt::format("white balance: the black HDR is {}x{} but the white HDR is {}x{}",
                                 black.cols, black.rows, white.cols, white.rows));
  return white - black;
}

// Least-squares gains mapping measured values m to rho / pi, and the relative misfit.
void FitGains(const std::vector<cv::Vec3d>& m, const std::vector<cv::Vec3d>& rho, WhiteBalance* w) {
  for (int c = 0; c < 3; ++c) {
    double num = 0, den = 0;
    for (size_t k = 0; k < m.size(); ++k) {
      num += rho[k][c] / kPi * m[k][c];
      den += m[k][c] * m[k][c];
    }
    if (!(den > 0)) throw CalibError("white balance: the reference patches are black");
    // Negative or zero gains would turn every measurement dark or negative.
    if (!(num > 0))
      throw CalibError(fmt::format("white balance: the white reference is not brighter than the black "
                                   "reference in the {} channel (maybe the white and black images are "
                                   "swapped)", "RGB"[c]));
    w->gains[c] = num / den;
    double r = 0;
    for (size_t k = 0; k < m.size(); ++k) {
      const double e = w->gains[c] * m[k][c] / (rho[k][c] / kPi) - 1;
      r += e * e;
    }
    w->residual[c] = std::sqrt(r / double(m.size()));
  }
  w->patches = int(m.size());
}

}  // namespace

std::string WhiteBalance::BriefReport() const {
  return fmt::format("{} from {} patch{}: gains R {:.6g} G {:.6g} B {:.6g}; misfit R {:.2f}% G "
                     "{:.2f}% B {:.2f}%", method, patches, patches == 1 ? "" : "es", gains[0], gains[1], gains[2],
                     100 * residual[0], 100 * residual[1], 100 * residual[2]);
}

cv::Vec3d MeanInPolygon(const cv::Mat& hdr, const std::vector<cv::Point2f>& polygon) {
  cv::Mat mask(hdr.size(), CV_8U, cv::Scalar(0));
  std::vector<cv::Point> poly;
  for (const auto& p : polygon) poly.emplace_back(int(std::lround(p.x * 16)), int(std::lround(p.y * 16)));
  cv::fillConvexPoly(mask, poly, cv::Scalar(255), cv::LINE_8, 4);
  cv::Vec3d sum(0, 0, 0);
  int n = 0;
  for (int y = 0; y < hdr.rows; ++y)
    for (int x = 0; x < hdr.cols; ++x)
      if (mask.at<uint8_t>(y, x)) {
        const cv::Vec3f v = hdr.at<cv::Vec3f>(y, x);
        if (!std::isfinite(v[0]) || !std::isfinite(v[1]) || !std::isfinite(v[2]))
          throw CalibError(fmt::format("white balance: the region around ({:.0f}, {:.0f}) is "
                                       "saturated in every exposure; take shorter exposures",
                                       polygon[0].x, polygon[0].y));
        sum += cv::Vec3d(v);
        ++n;
      }
  if (n == 0)
    throw CalibError(fmt::format("white balance: the region at ({:.0f}, {:.0f}) holds no pixels "
                                 "of the {}x{} image", polygon[0].x, polygon[0].y, hdr.cols, hdr.rows));
  return sum / double(n);
}

WhiteBalance WhiteFromPatch(const cv::Mat& white, const cv::Mat& black,
                            const std::vector<cv::Point2f>& corners, const cv::Vec3d& albedo) {
  if (corners.size() != 4) throw CalibError("white balance: a patch needs 4 corners");
  for (size_t k = 0; k < 4; ++k)
    if (corners[k].x < -0.5 || corners[k].y < -0.5 || corners[k].x > white.cols - 0.5 ||
        corners[k].y > white.rows - 0.5)
      throw CalibError(fmt::format("white balance: patch corner {} ({:.1f}, {:.1f}) is outside the {}x{} image",
                                   k, corners[k].x, corners[k].y, white.cols, white.rows));
  for (int c = 0; c < 3; ++c)
    if (!(albedo[c] > 0 && albedo[c] <= 1)) throw CalibError("white balance: albedo must be in (0, 1]");
  WhiteBalance w;
  w.method = "patch";
  FitGains({MeanInPolygon(Subtract(white, black), corners)}, {albedo}, &w);
  return w;
}

WhiteBalance WhiteFromColorChecker(const cv::Mat& white, const cv::Mat& black,
                                   std::vector<cv::Vec3d>* patch_values) {
  const cv::Mat hdr = Subtract(white, black);
  // Tone-map for detection: finite values scaled so that the 99th percentile maps to 0.9,
  // gamma 1/2.2, 8-bit BGR (mcc's input).
  std::vector<float> lum;
  for (int y = 0; y < hdr.rows; y += 2)
    for (int x = 0; x < hdr.cols; x += 2) {
      const cv::Vec3f v = hdr.at<cv::Vec3f>(y, x);
      const float l = std::max({v[0], v[1], v[2]});
      if (std::isfinite(l)) lum.push_back(l);
    }
  if (lum.empty()) throw CalibError("white balance: the white HDR has no finite pixels");
  std::nth_element(lum.begin(), lum.begin() + long(0.99 * (lum.size() - 1)), lum.end());
  const float top = std::max(lum[size_t(0.99 * (lum.size() - 1))], 1e-30f);
  cv::Mat t(hdr.size(), CV_8UC3);
  for (int y = 0; y < hdr.rows; ++y)
    for (int x = 0; x < hdr.cols; ++x) {
      const cv::Vec3f v = hdr.at<cv::Vec3f>(y, x);
      for (int c = 0; c < 3; ++c) {
        const float u = std::isfinite(v[c]) ? std::clamp(0.9f * v[c] / top, 0.f, 1.f) : 1.f;
        t.at<cv::Vec3b>(y, x)[2 - c] = uint8_t(std::lround(255 * std::pow(u, 1 / 2.2f)));
      }
    }
  cv::Ptr<cv::mcc::CCheckerDetector> detector = cv::mcc::CCheckerDetector::create();
  if (!detector->process(t, cv::mcc::MCC24, 1))
    throw CalibError("white balance: no ColorChecker found in the white HDR");
  const std::vector<cv::Point2f> box = detector->getBestColorChecker()->getBox();
  if (box.size() != 4) throw CalibError("white balance: the ColorChecker detection has no box");
  const std::vector<cv::Vec3d> rho = ColorCheckerLinearAlbedos();
  // Try the 8 ways the chart's corners can map onto the box; keep the best fit of all 24.
  const std::vector<cv::Point2f> unit{{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  double best = 1e30;
  std::vector<cv::Vec3d> best_values;
  for (int dir = 0; dir < 2; ++dir)
    for (int shift = 0; shift < 4; ++shift) {
      std::vector<cv::Point2f> dst(4);
      for (int k = 0; k < 4; ++k) dst[size_t(k)] = box[size_t((shift + (dir ? 4 - k : k)) % 4)];
      const cv::Matx33d H(cv::getPerspectiveTransform(unit, dst));
      std::vector<cv::Vec3d> values;
      try {
        for (int k = 0; k < 24; ++k) {
          const double u = ((k % 6) + 0.5) / 6, v = ((k / 6) + 0.5) / 4;
          std::vector<cv::Point2f> q;
          for (const auto& d : {cv::Point2d(-1, -1), cv::Point2d(1, -1), cv::Point2d(1, 1), cv::Point2d(-1, 1)}) {
            const cv::Vec3d p = H * cv::Vec3d(u + d.x * 0.25 / 6, v + d.y * 0.25 / 4, 1);
            q.emplace_back(float(p[0] / p[2]), float(p[1] / p[2]));
          }
          values.push_back(MeanInPolygon(hdr, q));
        }
      } catch (const CalibError&) {
        if (dir == 1 && shift == 3 && best_values.empty()) throw;
        continue;
      }
      WhiteBalance trial;
      FitGains(values, rho, &trial);
      const double misfit = cv::norm(trial.residual);
      if (misfit < best) {
        best = misfit;
        best_values = values;
      }
    }
  if (best_values.empty()) throw CalibError("white balance: ColorChecker patches are saturated");
  WhiteBalance w;
  w.method = "colorchecker";
  FitGains(std::vector<cv::Vec3d>(best_values.begin() + 18, best_values.end()),
           std::vector<cv::Vec3d>(rho.begin() + 18, rho.end()), &w);
  if (patch_values) *patch_values = best_values;
  return w;
}

void WriteWhiteBalance(const std::string& path, const WhiteBalance& w,
                       const cv::Vec3d& black_mean, const std::string& black_image) {
  cv::FileStorage fs(path, cv::FileStorage::WRITE);
  if (!fs.isOpened()) throw CalibError(path + ": cannot open for writing");
  fs << "white_gains" << cv::Mat(cv::Matx13d(w.gains[0], w.gains[1], w.gains[2]));
  fs << "convention" << "L = white_gains * (camera HDR - black HDR), RGB; projector white = q 1";
  fs << "residual" << cv::Mat(cv::Matx13d(w.residual[0], w.residual[1], w.residual[2]));
  fs << "patches" << w.patches << "method" << w.method;
  fs << "black_level_mean" << cv::Mat(cv::Matx13d(black_mean[0], black_mean[1], black_mean[2]));
  fs << "black_image" << black_image;
  if (!w.exposure_times.empty()) fs << "exposure_times" << w.exposure_times;
  if (w.sensor_black != cv::Vec3d(0, 0, 0))
    fs << "sensor_black" << cv::Mat(cv::Matx13d(w.sensor_black[0], w.sensor_black[1], w.sensor_black[2]));
  if (w.camera_flat) fs << "camera_flat" << 1;
}

WhiteBalance ReadWhiteBalance(const std::string& path) {
  cv::FileStorage fs;
  try {
    if (!fs.open(path, cv::FileStorage::READ)) throw CalibError(path + ": cannot read");
  } catch (const cv::Exception&) {
    throw CalibError(path + ": not an OpenCV YAML/XML file");
  }
  cv::Mat g;
  fs["white_gains"] >> g;
  if (g.total() != 3) throw CalibError(path + ": lacks white_gains");
  WhiteBalance w;
  g.convertTo(g, CV_64F);
  w.gains = cv::Vec3d(g.at<double>(0), g.at<double>(1), g.at<double>(2));
  for (int c = 0; c < 3; ++c)
    if (!(w.gains[c] > 0) || !std::isfinite(w.gains[c]))
      throw CalibError(fmt::format("{}: white_gains must be finite and positive, got {} {} {}", path,
                                   w.gains[0], w.gains[1], w.gains[2]));
  cv::Mat r;
  fs["residual"] >> r;
  if (r.total() == 3) {
    r.convertTo(r, CV_64F);
    w.residual = cv::Vec3d(r.at<double>(0), r.at<double>(1), r.at<double>(2));
  }
  fs["patches"] >> w.patches;
  fs["method"] >> w.method;
  if (!fs["exposure_times"].empty()) fs["exposure_times"] >> w.exposure_times;
  cv::Mat b;
  fs["sensor_black"] >> b;
  if (b.total() == 3) {
    b.convertTo(b, CV_64F);
    w.sensor_black = cv::Vec3d(b.at<double>(0), b.at<double>(1), b.at<double>(2));
  }
  if (!fs["camera_flat"].empty()) w.camera_flat = int(fs["camera_flat"]) != 0;
  return w;
}

}  // namespace translume::calib
