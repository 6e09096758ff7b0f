// SPDX-License-Identifier: MIT
#include "calib/camera_calib.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <opencv2/calib3d.hpp>

#include "calib/error.h"
#include "calib/hdr.h"
#include "calib/parallel.h"

namespace translume::calib {
namespace {

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
}

}  // namespace

std::string CameraCalibOptions::Validate() const {
  if (min_views < 3) return "min_views (--min-views) must be at least 3";
  if (!(outlier_factor > 1)) return "outlier_factor (--outlier-factor) must be > 1";
  if (!(outlier_min_px >= 0)) return "outlier_min_px must be >= 0";
  return "";
}

std::string CameraCalibration::BriefReport() const {
  return fmt::format("{} views used, {} dropped; fx {:.2f} fy {:.2f} cx {:.2f} cy {:.2f} px "
                     "(1-sigma {:.2f} {:.2f} {:.2f} {:.2f}); RMS {:.3f} px",
                     used_views.size(), dropped.size(), K(0, 0), K(1, 1), K(0, 2), K(1, 2),
                     std_intrinsics.empty() ? 0.0 : std_intrinsics.at<double>(0),
                     std_intrinsics.empty() ? 0.0 : std_intrinsics.at<double>(1),
                     std_intrinsics.empty() ? 0.0 : std_intrinsics.at<double>(2),
                     std_intrinsics.empty() ? 0.0 : std_intrinsics.at<double>(3), rms);
}

CameraCalibration CalibrateCamera(const BoardSpec& board, const std::vector<NamedImage>& views,
                                  const CameraCalibOptions& o) {
  if (std::string why = o.Validate(); !why.empty()) throw CalibError("camera calibration: " + why);
  if (views.empty()) throw CalibError("camera calibration: no photos");
  CameraCalibration c;
  c.image_size = views[0].image.size();
  std::vector<std::vector<cv::Point3f>> obj;
  std::vector<std::vector<cv::Point2f>> img;
  std::vector<std::string> names;
  {  // before any (slow) detection
    std::vector<std::string> names;
    std::vector<cv::Size> sizes;
    for (const NamedImage& v : views) {
      names.push_back(v.name);
      sizes.push_back(v.image.size());
    }
    RequireOneSize(names, sizes, "the calibration's");
  }
  std::vector<BoardDetection> found(views.size());  // detected in parallel, used in order
  ParallelFor(int(views.size()), [&](int i) { found[size_t(i)] = DetectBoard(board, views[size_t(i)].image); });
  for (size_t i = 0; i < views.size(); ++i) {
    const NamedImage& v = views[i];
    const BoardDetection& d = found[i];
    if (!d.found) {
      c.dropped.push_back(v.name + ": board not found");
      continue;
    }
    obj.push_back(d.object_points);
    img.push_back(d.image_points);
    names.push_back(v.name);
  }
  int flags = o.fix_k3 ? cv::CALIB_FIX_K3 : 0;
  const cv::TermCriteria crit(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 100, 1e-12);
  cv::Mat K, dist, std_in, std_ex, errs;
  std::vector<cv::Mat> rv, tv;
  for (int round = 0;; ++round) {
    if (int(obj.size()) < o.min_views)
      throw CalibError(fmt::format(
          "camera calibration: only {} usable views of {} (need {}){}{}", obj.size(), views.size(), o.min_views,
          c.dropped.empty() ? ""
                            : fmt::format("; dropped {} ({}{})", c.dropped.size(), c.dropped.front(),
                                          c.dropped.size() > 1 ? fmt::format(", and {} more", c.dropped.size() - 1) : ""),
          round == 0 && obj.empty() ? "; the board was found in no photo: check the board spec (its type and inner "
                                      "corners per side)"
                                    : ""));
    c.rms = cv::calibrateCamera(obj, img, c.image_size, K, dist, rv, tv, std_in, std_ex, errs,
                                flags, crit);
    std::vector<double> e(errs.begin<double>(), errs.end<double>());
    const double limit = std::max(o.outlier_factor * Median(e), o.outlier_min_px);
    bool removed = false;
    for (int i = int(e.size()) - 1; i >= 0; --i)
      if (e[size_t(i)] > limit) {
        c.dropped.push_back(fmt::format("{}: reprojection RMS {:.3f} px is an outlier (limit "
                                        "{:.3f})", names[size_t(i)], e[size_t(i)], limit));
        obj.erase(obj.begin() + i);
        img.erase(img.begin() + i);
        names.erase(names.begin() + i);
        removed = true;
      }
    if (!removed || round >= 3) {
      c.per_view_errors = e;
      break;
    }
  }
  c.K = cv::Matx33d(K);
  dist.reshape(1, 1).convertTo(c.dist, CV_64F);
  c.std_intrinsics = std_in.reshape(1, 1).clone();
  c.used_views = names;
  for (size_t i = 0; i < rv.size(); ++i) {
    c.rvecs.push_back(cv::Vec3d(rv[i]));
    c.tvecs.push_back(cv::Vec3d(tv[i]));
  }
  return c;
}

void WriteCameraCalibration(const std::string& path, const CameraCalibration& c,
                            const std::string& board) {
  cv::FileStorage fs(path, cv::FileStorage::WRITE);
  if (!fs.isOpened()) throw CalibError(path + ": cannot open for writing");
  fs << "image_width" << c.image_size.width << "image_height" << c.image_size.height;
  fs << "camera_matrix" << cv::Mat(c.K) << "distortion_coefficients" << c.dist;
  fs << "rms" << c.rms << "per_view_errors" << c.per_view_errors;
  fs << "std_intrinsics" << c.std_intrinsics << "board" << board;
  fs << "views" << c.used_views << "dropped_views" << c.dropped;
}

CameraCalibration ReadCameraCalibration(const std::string& path) {
  cv::FileStorage fs;
  try {
    if (!fs.open(path, cv::FileStorage::READ)) throw CalibError(path + ": cannot read");
  } catch (const cv::Exception&) {
    throw CalibError(path + ": not an OpenCV YAML/XML file");
  }
  CameraCalibration c;
  cv::Mat K;
  fs["camera_matrix"] >> K;
  fs["distortion_coefficients"] >> c.dist;
  fs["image_width"] >> c.image_size.width;
  fs["image_height"] >> c.image_size.height;
  fs["rms"] >> c.rms;
  fs["per_view_errors"] >> c.per_view_errors;
  fs["std_intrinsics"] >> c.std_intrinsics;
  fs["views"] >> c.used_views;
  fs["dropped_views"] >> c.dropped;
  if (K.size() != cv::Size(3, 3) || c.dist.empty() || c.image_size.area() <= 0)
    throw CalibError(path + ": lacks camera_matrix, distortion_coefficients or image size");
  c.K = cv::Matx33d(K);
  c.dist.convertTo(c.dist, CV_64F);
  c.dist = c.dist.reshape(1, 1);
  if (std::string why = IntrinsicsProblem(c.K, c.dist, "camera_matrix", "distortion_coefficients"); !why.empty())
    throw CalibError(path + ": " + why);
  return c;
}

std::string IntrinsicsProblem(const cv::Matx33d& K, const cv::Mat& dist, const std::string& matrix,
                              const std::string& distortion) {
  for (int k = 0; k < 9; ++k)
    if (!std::isfinite(K.val[k])) return fmt::format("{}: element {} is {}, must be finite", matrix, k, K.val[k]);
  if (!(K(0, 0) > 0) || !(K(1, 1) > 0))
    return fmt::format("{}: fx {:g} and fy {:g} must be positive", matrix, K(0, 0), K(1, 1));
  cv::Mat d;
  dist.convertTo(d, CV_64F);
  for (int k = 0; k < int(d.total()); ++k)
    if (!std::isfinite(d.at<double>(k)))
      return fmt::format("{}: coefficient {} is {}, must be finite", distortion, k, d.at<double>(k));
  return "";
}

}  // namespace translume::calib
