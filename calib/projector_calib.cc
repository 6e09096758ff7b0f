// SPDX-License-Identifier: MIT
#include "calib/projector_calib.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <opencv2/calib3d.hpp>

#include "calib/error.h"
#include "calib/parallel.h"

namespace translume::calib {

std::string ProjectorCalibOptions::Validate() const {
  if (min_planes < 3) return "min_planes (--min-planes) must be at least 3";
  if (!(outlier_factor > 1)) return "outlier_factor (--outlier-factor) must be > 1";
  if (!(max_rms_px > 0)) return "max_rms_px (--max-rms) must be positive";
  return "";
}

std::string ProjectorCalibration::BriefReport() const {
  return fmt::format("{} planes used, {} dropped; projector fx {:.2f} fy {:.2f} cx {:.2f} cy "
                     "{:.2f} px, RMS {:.3f} px; pose T ({:.2f}, {:.2f}, {:.2f}) mm, stereo RMS "
                     "camera {:.3f} px, projector {:.3f} px",
                     used_planes.size(), dropped.size(), K(0, 0), K(1, 1), K(0, 2), K(1, 2),
                     projector_rms, T[0], T[1], T[2], stereo_camera_rms, stereo_projector_rms);
}

std::vector<cv::Point3f> CornersOnPlane(const CameraCalibration& camera,
                                        const std::vector<cv::Point2f>& corners,
                                        const cv::Matx33d& R, const cv::Vec3d& t) {
  std::vector<cv::Point2d> in(corners.begin(), corners.end()), n;
  cv::undistortPoints(in, n, camera.K, camera.dist, cv::noArray(), cv::noArray(),
                      cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 100, 1e-12));
  const cv::Vec3d normal(R(0, 2), R(1, 2), R(2, 2));
  std::vector<cv::Point3f> out;
  for (const cv::Point2d& q : n) {
    const cv::Vec3d d(q.x, q.y, 1.0);
    const double s = normal.dot(t) / normal.dot(d);
    const cv::Vec3d p = R.t() * (s * d - t);
    out.emplace_back(float(p[0]), float(p[1]), 0.f);
  }
  return out;
}

ProjectorCalibration CalibrateProjector(const CameraCalibration& camera, const BoardSpec& board,
                                        const ProjectorChessboard& pattern,
                                        const std::vector<PlaneView>& planes,
                                        const ProjectorCalibOptions& o) {
  if (std::string why = o.Validate(); !why.empty()) throw CalibError("projector calibration: " + why);
  if (std::string why = pattern.Validate(); !why.empty())
    throw CalibError("projector pattern: " + why);
  ProjectorCalibration pc;
  pc.projector_size = pattern.projector_size;
  std::vector<std::vector<cv::Point3f>> obj;
  std::vector<std::vector<cv::Point2f>> cam, proj;
  std::vector<std::string> names;
  const std::vector<cv::Point2f> proj_corners = pattern.Corners();
  for (const PlaneView& v : planes)  // before any (slow) detection
    for (const cv::Mat* m : {&v.board_photo, &v.pattern_photo})
      if (!m->empty() && m->size() != camera.image_size)
        throw CalibError(fmt::format("{}: photo is {}x{} but the camera calibration is {}x{}",
                                     v.name, m->cols, m->rows, camera.image_size.width,
                                     camera.image_size.height));
  // Both detections of every plane in parallel, used in order.
  std::vector<BoardDetection> boards(planes.size());
  std::vector<std::vector<cv::Point2f>> grids(planes.size());
  ParallelFor(int(planes.size()), [&](int i) {
    if (planes[size_t(i)].board_photo.empty() || planes[size_t(i)].pattern_photo.empty()) return;
    boards[size_t(i)] = DetectBoard(board, planes[size_t(i)].board_photo);
    if (boards[size_t(i)].found)
      grids[size_t(i)] = FindChessboardGrid(planes[size_t(i)].pattern_photo, pattern.cols, pattern.rows);
  });
  for (size_t i = 0; i < planes.size(); ++i) {
    const PlaneView& v = planes[i];
    const BoardDetection& d = boards[i];
    if (v.board_photo.empty() || v.pattern_photo.empty()) {
      pc.dropped.push_back(fmt::format("{}: no {} photo", v.name, v.board_photo.empty() ? "_board" : "_pattern"));
      continue;
    }
    if (!d.found) {
      pc.dropped.push_back(v.name + ": printed board not found");
      continue;
    }
    std::vector<cv::Point2f> c = std::move(grids[i]);
    if (o.rear_projection)
      for (size_t r = 0; r < c.size(); r += size_t(pattern.cols))
        std::reverse(c.begin() + long(r), c.begin() + long(r) + pattern.cols);
    if (c.empty()) {
      pc.dropped.push_back(v.name + ": projected pattern not found");
      continue;
    }
    cv::Vec3d rvec, tvec;
    cv::solvePnP(d.object_points, d.image_points, camera.K, camera.dist, rvec, tvec, false,
                 cv::SOLVEPNP_ITERATIVE);
    cv::Matx33d R;
    cv::Rodrigues(rvec, R);
    obj.push_back(CornersOnPlane(camera, c, R, tvec));
    cam.push_back(c);
    proj.push_back(proj_corners);
    names.push_back(v.name);
  }
  int flags = cv::CALIB_USE_INTRINSIC_GUESS;
  if (o.fix_k3) flags |= cv::CALIB_FIX_K3;
  if (o.zero_tangent) flags |= cv::CALIB_ZERO_TANGENT_DIST;
  const cv::TermCriteria crit(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 100, 1e-12);
  cv::Mat K, dist, std_in, std_ex, errs;
  std::vector<cv::Mat> rv, tv;
  for (int round = 0;; ++round) {
    if (int(obj.size()) < o.min_planes)
      throw CalibError(fmt::format("projector calibration: only {} usable planes of {} (need {}){}",
                                   obj.size(), planes.size(), o.min_planes,
                                   pc.dropped.empty() ? "" : "; dropped: " + pc.dropped.front() +
                                   (pc.dropped.size() > 1 ? ", ..." : "")));
    // Initial guess: a centred principal point; OpenCV's planar initialisation assumes it.
    K = (cv::Mat_<double>(3, 3) << pc.projector_size.width, 0, pc.projector_size.width / 2.0, 0,
         pc.projector_size.width, pc.projector_size.height / 2.0, 0, 0, 1);
    dist = cv::Mat::zeros(1, 5, CV_64F);
    pc.projector_rms = cv::calibrateCamera(obj, proj, pc.projector_size, K, dist, rv, tv, std_in,
                                           std_ex, errs, flags, crit);
    std::vector<double> e(errs.begin<double>(), errs.end<double>());
    std::vector<double> sorted = e;
    std::sort(sorted.begin(), sorted.end());
    const double limit = std::max(o.outlier_factor * sorted[sorted.size() / 2], o.outlier_min_px);
    bool removed = false;
    for (int i = int(e.size()) - 1; i >= 0; --i)
      if (e[size_t(i)] > limit) {
        pc.dropped.push_back(fmt::format("{}: projector RMS {:.3f} px is an outlier (limit {:.3f})",
                                         names[size_t(i)], e[size_t(i)], limit));
        obj.erase(obj.begin() + i);
        cam.erase(cam.begin() + i);
        proj.erase(proj.begin() + i);
        names.erase(names.begin() + i);
        removed = true;
      }
    if (!removed || round >= 3) break;
  }
  pc.K = cv::Matx33d(K);
  dist.reshape(1, 1).convertTo(pc.dist, CV_64F);
  pc.std_intrinsics = std_in.reshape(1, 1).clone();
  cv::Mat Kc(camera.K), R, T, E, F, per_view;
  cv::stereoCalibrate(obj, cam, proj, Kc, camera.dist.clone(), K, dist, camera.image_size, R, T,
                      E, F, per_view, cv::CALIB_FIX_INTRINSIC, crit);
  pc.R = cv::Matx33d(R);
  pc.T = cv::Vec3d(T);
  double sc = 0, sp = 0;
  for (int i = 0; i < per_view.rows; ++i) {
    const cv::Vec2d e(per_view.at<double>(i, 0), per_view.at<double>(i, 1));
    pc.per_plane_errors.push_back(e);
    sc += e[0] * e[0];  // every plane has the same number of corners
    sp += e[1] * e[1];
  }
  pc.stereo_camera_rms = std::sqrt(sc / std::max(per_view.rows, 1));
  pc.stereo_projector_rms = std::sqrt(sp / std::max(per_view.rows, 1));
  pc.used_planes = names;
  const double worst = std::max({pc.projector_rms, pc.stereo_camera_rms, pc.stereo_projector_rms});
  if (!(worst <= o.max_rms_px))
    throw CalibError(fmt::format(
        "projector calibration: reprojection RMS {:.2f} px (projector fit {:.2f}, stereo camera {:.2f}, "
        "stereo projector {:.2f}) is above {:g} px: the projected corners do not match the pattern's; {}",
        worst, pc.projector_rms, pc.stereo_camera_rms, pc.stereo_projector_rms, o.max_rms_px,
        o.rear_projection ? "the planes were taken as rear projection (--rear, capture.json projector.rear): "
                            "if the projector lit them from the camera's side, leave it off"
                          : "if the projector lit the planes from behind (a back-lit rig), calibrate with "
                            "rear projection (--rear, capture.json projector.rear)"));
  return pc;
}

void WriteProjectorCalibration(const std::string& path, const ProjectorCalibration& p,
                               const CameraCalibration& camera, const std::string& pattern) {
  cv::FileStorage fs(path, cv::FileStorage::WRITE);
  if (!fs.isOpened()) throw CalibError(path + ": cannot open for writing");
  fs << "projector_width" << p.projector_size.width << "projector_height" << p.projector_size.height;
  fs << "projector_matrix" << cv::Mat(p.K) << "projector_distortion" << p.dist;
  fs << "projector_std_intrinsics" << p.std_intrinsics;
  fs << "R" << cv::Mat(p.R) << "T" << cv::Mat(p.T);
  fs << "pose_convention" << "x_projector = R x_camera + T (mm)";
  fs << "projector_rms" << p.projector_rms << "stereo_camera_rms" << p.stereo_camera_rms
     << "stereo_projector_rms" << p.stereo_projector_rms;
  cv::Mat e(int(p.per_plane_errors.size()), 2, CV_64F);
  for (int i = 0; i < e.rows; ++i) {
    e.at<double>(i, 0) = p.per_plane_errors[size_t(i)][0];
    e.at<double>(i, 1) = p.per_plane_errors[size_t(i)][1];
  }
  fs << "per_plane_errors" << e << "planes" << p.used_planes << "dropped_planes" << p.dropped;
  fs << "pattern" << pattern;
  fs << "image_width" << camera.image_size.width << "image_height" << camera.image_size.height;
  fs << "camera_matrix" << cv::Mat(camera.K) << "distortion_coefficients" << camera.dist;
}

ProjectorCalibration ReadProjectorCalibration(const std::string& path) {
  cv::FileStorage fs;
  try {
    if (!fs.open(path, cv::FileStorage::READ)) throw CalibError(path + ": cannot read");
  } catch (const cv::Exception&) {
    throw CalibError(path + ": not an OpenCV YAML/XML file");
  }
  ProjectorCalibration p;
  cv::Mat K, R, T;
  fs["projector_matrix"] >> K;
  fs["projector_distortion"] >> p.dist;
  fs["projector_width"] >> p.projector_size.width;
  fs["projector_height"] >> p.projector_size.height;
  fs["R"] >> R;
  fs["T"] >> T;
  if (K.size() != cv::Size(3, 3) || R.size() != cv::Size(3, 3) || T.total() != 3 || p.dist.empty())
    throw CalibError(path + ": lacks projector_matrix, projector_distortion, R or T");
  p.K = cv::Matx33d(K);
  p.R = cv::Matx33d(R);
  p.T = cv::Vec3d(T.reshape(1, 3));
  if (std::string why = IntrinsicsProblem(p.K, p.dist, "projector_matrix", "projector_distortion"); !why.empty())
    throw CalibError(path + ": " + why);
  if (p.projector_size.width <= 0 || p.projector_size.height <= 0)
    throw CalibError(fmt::format("{}: projector_width {} and projector_height {} must be positive", path,
                                 p.projector_size.width, p.projector_size.height));
  // A rotation: finite and orthonormal (to the precision of a written file).
  if (!cv::checkRange(R) || !cv::checkRange(T) || cv::norm(p.R * p.R.t() - cv::Matx33d::eye()) > 1e-6)
    throw CalibError(path + ": R must be a rotation and T finite");
  fs["projector_rms"] >> p.projector_rms;
  fs["stereo_camera_rms"] >> p.stereo_camera_rms;
  fs["stereo_projector_rms"] >> p.stereo_projector_rms;
  fs["projector_std_intrinsics"] >> p.std_intrinsics;
  cv::Mat e;
  fs["per_plane_errors"] >> e;
  for (int i = 0; i < e.rows && e.cols == 2; ++i)
    p.per_plane_errors.emplace_back(e.at<double>(i, 0), e.at<double>(i, 1));
  fs["planes"] >> p.used_planes;
  fs["dropped_planes"] >> p.dropped;
  return p;
}

std::string CameraMismatch(const CameraCalibration& camera, const std::string& projector_path) {
  CameraCalibration kept;
  try {
    kept = ReadCameraCalibration(projector_path);
  } catch (const CalibError&) {
    return "";
  }
  const double w = camera.image_size.width;
  const bool differs = kept.image_size != camera.image_size ||
                       std::abs(kept.K(0, 0) / camera.K(0, 0) - 1) > 0.02 ||
                       std::abs(kept.K(1, 1) / camera.K(1, 1) - 1) > 0.02 ||
                       std::abs(kept.K(0, 2) - camera.K(0, 2)) > 0.02 * w ||
                       std::abs(kept.K(1, 2) - camera.K(1, 2)) > 0.02 * w;
  if (!differs) return "";
  return fmt::format("{} was calibrated through another camera calibration ({}x{}, fx {:.1f}, cx {:.1f}, cy {:.1f} "
                     "against {}x{}, fx {:.1f}, cx {:.1f}, cy {:.1f} px): its camera-projector pose holds for that one",
                     projector_path, kept.image_size.width, kept.image_size.height, kept.K(0, 0), kept.K(0, 2),
                     kept.K(1, 2), camera.image_size.width, camera.image_size.height, camera.K(0, 0), camera.K(0, 2),
                     camera.K(1, 2));
}

}  // namespace translume::calib
