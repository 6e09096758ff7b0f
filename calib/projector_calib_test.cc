// SPDX-License-Identifier: MIT
#include "calib/projector_calib.h"

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "calib/error.h"
#include "calib/synthetic_rig.h"
#include "calib/test_util.h"

namespace translume::calib {
namespace {

constexpr double kPi = 3.14159265358979323846;

// The rig's true camera as a calibration.
CameraCalibration TrueCamera(const SyntheticRig& rig) {
  CameraCalibration c;
  c.image_size = rig.camera.size;
  c.K = rig.camera.K;
  c.dist = cv::Mat(rig.camera.dist).reshape(1, 1).clone();
  return c;
}

// n planes with board and pattern photos, and the camera: calibrated from the planes' board
// photos (as a user may do), or the rig's true one.
struct ProjectorScene {
  SyntheticRig rig = SyntheticRig::Default();
  BoardSpec board = BoardSpec::Parse("chessboard:9x6:25");
  ProjectorChessboard pattern = ProjectorChessboard::Centered({1024, 768}, 11, 7, 64);
  CameraCalibration camera;
  std::vector<PlaneView> planes;
  ProjectorScene(int n, bool calibrate_camera) {
    int k = 0;
    for (const Pose& p : rig.PlanePoses(pattern, n, 520, 17, &board)) {
      PhotoOptions o;
      o.seed = uint64_t(200 + k);
      PlaneView v;
      v.name = fmt::format("plane{}", k++);
      v.board_photo = rig.RenderBoard(board, p, o);
      o.seed += 1000;
      v.pattern_photo = rig.RenderProjectedChessboard(p, pattern, o);
      planes.push_back(v);
    }
    if (calibrate_camera) {
      std::vector<NamedImage> views;
      for (const PlaneView& v : planes) views.push_back({v.name, v.board_photo});
      camera = CalibrateCamera(board, views);
    } else {
      camera = TrueCamera(rig);
    }
  }
};

TEST(ProjectorCalib, MeetsTargets) {
  const ProjectorScene s(8, true);
  ASSERT_EQ(s.planes.size(), 8u);
  std::printf("camera: %s\n", s.camera.BriefReport().c_str());
  const ProjectorCalibration p = CalibrateProjector(s.camera, s.board, s.pattern, s.planes);
  std::printf("%s\n", p.BriefReport().c_str());
  for (const auto& d : p.dropped) std::printf("dropped %s\n", d.c_str());
  const cv::Matx33d& Kt = s.rig.projector.K;
  cv::Vec3d dr;
  cv::Rodrigues(p.R * s.rig.projector_from_camera.R.t(), dr);
  const double rot_deg = cv::norm(dr) * 180 / kPi;
  const double dt = cv::norm(p.T - s.rig.projector_from_camera.t);
  std::printf("projector fx %.4f%% fy %.4f%% cx %+.2f cy %+.2f px; rotation error %.4f deg, "
              "translation error %.3f mm (|T| %.1f mm)\n",
              100 * (p.K(0, 0) / Kt(0, 0) - 1), 100 * (p.K(1, 1) / Kt(1, 1) - 1),
              p.K(0, 2) - Kt(0, 2), p.K(1, 2) - Kt(1, 2), rot_deg, dt,
              cv::norm(s.rig.projector_from_camera.t));
  const cv::Vec<double, 5>& dist_true = s.rig.projector.dist;
  ASSERT_EQ(p.std_intrinsics.total(), 18u);  // OpenCV's order: fx, fy, cx, cy, k1, k2, ...
  std::printf("projector k1 %.5f (truth %.5f) k2 %.5f (truth %.5f); 1-sigma fx %.3f fy %.3f "
              "cx %.3f cy %.3f k1 %.5f k2 %.5f\n", p.dist.at<double>(0), dist_true[0],
              p.dist.at<double>(1), dist_true[1], p.std_intrinsics.at<double>(0),
              p.std_intrinsics.at<double>(1), p.std_intrinsics.at<double>(2),
              p.std_intrinsics.at<double>(3), p.std_intrinsics.at<double>(4),
              p.std_intrinsics.at<double>(5));
  EXPECT_EQ(p.used_planes.size(), 8u);
  EXPECT_NEAR(p.K(0, 0) / Kt(0, 0), 1.0, 0.005);
  EXPECT_NEAR(p.K(1, 1) / Kt(1, 1), 1.0, 0.005);
  // Principal point: the truth (520, 600) is 8 px right of and 216 px below the centred guess
  // (512, 384) the solver starts from. With 1-code noise the corners fit to ~0.09 px RMS and
  // OpenCV's 1-sigma of cx, cy is ~0.3 and ~0.5 px (printed above; the camera calibrated from
  // the same photos adds its own error), so 2 px is 4-7 sigma and 100x smaller than the 216 px
  // of a principal point left at the guess.
  EXPECT_NEAR(p.K(0, 2), Kt(0, 2), 2.0);
  EXPECT_NEAR(p.K(1, 2), Kt(1, 2), 2.0);
  EXPECT_EQ(p.K(0, 1), 0.0);  // no skew is estimated
  // Radial k1 (truth 0.03): 1-sigma ~0.002, so 0.006 (3 sigma, a fifth of k1) tells it from 0.
  // k2 (truth -0.01) is not asserted: its 1-sigma (~0.013) exceeds its size on this data.
  // The default options fix p1, p2 and k3 at exactly 0.
  EXPECT_NEAR(p.dist.at<double>(0), dist_true[0], 0.006);
  EXPECT_EQ(p.dist.at<double>(2), 0.0);
  EXPECT_EQ(p.dist.at<double>(3), 0.0);
  EXPECT_EQ(p.dist.at<double>(4), 0.0);
  // Every used plane's stereo errors, as the summary RMS values below bound their root mean
  // square only.
  ASSERT_EQ(p.per_plane_errors.size(), 8u);
  for (const cv::Vec2d& e : p.per_plane_errors) {
    EXPECT_LE(e[0], 0.5);
    EXPECT_LE(e[1], 0.5);
  }
  EXPECT_LE(p.projector_rms, 0.5);
  EXPECT_LE(p.stereo_projector_rms, 0.5);
  EXPECT_LE(p.stereo_camera_rms, 0.5);
  EXPECT_LE(rot_deg, 0.1);
  EXPECT_LE(dt, 1.0);
}

// A projected pattern in a 12 MP photo through a lens zoomed 2x (a projector pixel 3-4 camera
// pixels wide, as in a close-up of the sample), searched at reduced size and refined coarse to
// fine: its corners are within 0.1 px of the truth (0.06-0.07 px). Before the refinement's
// run-off limit grew with the squares, one SB corner stayed 3.6 px off (0.42 px RMS).
TEST(ProjectorCalib, LargePhotosKeepTheirPatternCornerAccuracy) {
  const SyntheticRig rig = LargeCameraRig(2);
  const ProjectorChessboard pattern = ProjectorChessboard::Centered({1024, 768}, 11, 7, 32);
  for (const Pose& pose : rig.PlanePoses(pattern, 2, 520, 17)) {
    PhotoOptions o;
    o.blur_sigma_px = 0.5;
    const cv::Mat photo = rig.RenderProjectedChessboard(pose, pattern, o);
    std::vector<cv::Point3d> on_plane;
    for (const cv::Point2f& p : pattern.Corners()) {
      cv::Vec3d xyz;
      ASSERT_TRUE(rig.ProjectorPixelOnPlane(pose, p, &xyz));
      on_plane.push_back({xyz[0], xyz[1], xyz[2]});
    }
    ExpectReducedSearchAccurate(photo, pattern.cols, pattern.rows, rig.camera.Project(on_plane), 0.1, 0.005);
  }
}

// Projected boards in JPEG photos (quality 90, as cameras save "fine" JPEGs): OpenCV's SB
// detector missed most of them in a simulated capture (6 of 8 planes); the fallback to the
// quad detector finds every one, as accurately as the refinement allows.
TEST(ProjectorCalib, JpegPhotosOfProjectedPatternsAreFound) {
  const SyntheticRig rig = SyntheticRig::Default();
  const ProjectorChessboard pattern = ProjectorChessboard::Centered({1024, 768}, 11, 7, 32);
  int planes = 0, sb_alone = 0;
  for (const Pose& pose : rig.PlanePoses(pattern, 8, 520, 29)) {
    PhotoOptions o;
    o.blur_sigma_px = 0.5;
    std::vector<uchar> jpeg;
    cv::imencode(".jpg", rig.RenderProjectedChessboard(pose, pattern, o), jpeg, {cv::IMWRITE_JPEG_QUALITY, 90});
    const cv::Mat photo = cv::imdecode(jpeg, cv::IMREAD_UNCHANGED);
    std::vector<cv::Point3d> on_plane;
    for (const cv::Point2f& p : pattern.Corners()) {
      cv::Vec3d xyz;
      ASSERT_TRUE(rig.ProjectorPixelOnPlane(pose, p, &xyz));
      on_plane.push_back({xyz[0], xyz[1], xyz[2]});
    }
    std::vector<cv::Point2f> sb;
    sb_alone += cv::findChessboardCornersSB(photo, cv::Size(pattern.cols, pattern.rows), sb,
                                            cv::CALIB_CB_ACCURACY | cv::CALIB_CB_NORMALIZE_IMAGE);
    const std::vector<cv::Point2f> found = FindChessboardGrid(photo, pattern.cols, pattern.rows);
    ASSERT_EQ(found.size(), size_t(pattern.cols * pattern.rows)) << "plane " << planes;
    const double rms = CornerRmsToTruth(found, rig.camera.Project(on_plane));
    std::printf("plane %d: RMS %.3f px from the truth\n", planes, rms);
    EXPECT_LT(rms, 0.15) << "plane " << planes;
    ++planes;
  }
  std::printf("the SB detector alone found %d of %d\n", sb_alone, planes);
}

TEST(ProjectorCalib, DropsPlanesWithoutPatternAndRejectsTooFew) {
  const ProjectorScene s(4, false);
  std::vector<PlaneView> planes = s.planes;
  planes[2].pattern_photo = cv::Mat(s.rig.camera.size, CV_8UC1, cv::Scalar(30));
  planes.push_back({"blank", cv::Mat(s.rig.camera.size, CV_8UC1, cv::Scalar(30)), planes[0].pattern_photo});
  const ProjectorCalibration p = CalibrateProjector(s.camera, s.board, s.pattern, planes,
                                                    {.min_planes = 3});
  ASSERT_EQ(p.dropped.size(), 2u);
  EXPECT_EQ(p.dropped[0], "plane2: projected pattern not found");
  EXPECT_EQ(p.dropped[1], "blank: printed board not found");
  try {
    CalibrateProjector(s.camera, s.board, s.pattern, {planes[0], planes[1], planes[2]});
    FAIL();
  } catch (const CalibError& e) {
    EXPECT_NE(std::string(e.what()).find("only 2 usable planes of 3 (need 4)"), std::string::npos) << e.what();
  }
  planes[0].board_photo = cv::Mat(10, 10, CV_8UC1);
  EXPECT_THROW(CalibrateProjector(s.camera, s.board, s.pattern, planes), CalibError);
}

// Planes calibrated with the wrong projection side (rear-projected planes without --rear gave a
// stereo RMS of ~16 px, and the calibration was written) are refused, with the hint.
TEST(ProjectorCalib, ImplausibleRmsIsRefusedWithARearHint) {
  const ProjectorScene s(5, false);
  try {
    CalibrateProjector(s.camera, s.board, s.pattern, s.planes, {.min_planes = 3, .rear_projection = true});
    ADD_FAILURE() << "no error";
  } catch (const CalibError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(") is above 3 px: the projected corners do not match"), std::string::npos) << msg;
    EXPECT_NE(msg.find("if the projector lit them from the camera's side, leave it off"), std::string::npos) << msg;
  }
}

// CornersOnPlane inverts the camera: points of a tilted plane projected through the rig's own
// distortion code (not OpenCV's) come back onto the plane. The image points are floats (~3e-5
// px at 1000 px, ~1e-5 mm at 480 mm with f = 1200 px) and undistortion iterates to 1e-12, so
// 1e-3 mm (0.0025 px) is far above the arithmetic and far below what a wrong pose convention or
// ignored distortion gives (millimetres).
TEST(ProjectorCalib, CornersOnPlaneInvertsTheCamera) {
  const SyntheticRig rig = SyntheticRig::Default();
  const Pose plane = Pose::FromRodrigues({0.3, -0.4, 0.1}, {-120, -80, 480});
  std::vector<cv::Point3f> truth;
  std::vector<cv::Point3d> X;
  for (int j = 0; j < 7; ++j)
    for (int i = 0; i < 11; ++i) {
      truth.emplace_back(float(i * 24), float(j * 24), 0.f);
      const cv::Vec3d x = plane.Apply({i * 24.0, j * 24.0, 0});
      X.emplace_back(x[0], x[1], x[2]);
    }
  std::vector<cv::Point2f> px;
  for (const cv::Point2d& q : rig.camera.Project(X)) {
    ASSERT_TRUE(q.x > 0 && q.y > 0 && q.x < rig.camera.size.width && q.y < rig.camera.size.height) << q;
    px.emplace_back(float(q.x), float(q.y));
  }
  const std::vector<cv::Point3f> back = CornersOnPlane(TrueCamera(rig), px, plane.R, plane.t);
  ASSERT_EQ(back.size(), truth.size());
  double worst = 0;
  for (size_t k = 0; k < back.size(); ++k) {
    EXPECT_EQ(back[k].z, 0.f);
    worst = std::max(worst, double(cv::norm(back[k] - truth[k])));
  }
  std::printf("CornersOnPlane: worst error %.2e mm\n", worst);
  EXPECT_LT(worst, 1e-3);
}

// The projector file gives back every projector number exactly (doubles are written with 17
// significant digits; values chosen to have no short binary form), and plain OpenCV finds the
// camera's part and the pattern under their documented names.
TEST(ProjectorCalib, YamlRoundTrip) {
  ProjectorCalibration p;
  p.projector_size = {1280, 800};
  p.K = {1500.123456789012, 0, 520.2718281828459, 0, 1499.8765432109876, 600.5772156649015, 0, 0, 1};
  p.dist = (cv::Mat_<double>(1, 5) << 0.0281234567890123, -0.0115432109876543, 0.000123456789,
            -0.000234567891, 0.0000345678912);
  p.std_intrinsics = (cv::Mat_<double>(1, 4) << 0.6671234567891, 0.6591234567891,
                      0.2941234567891, 0.4831234567891);
  cv::Rodrigues(cv::Vec3d(0.0123456789012, 0.2987654321098, -0.00876543210987), p.R);
  p.T = {-143.6912345678901, -4.9212345678901, 42.6412345678901};
  p.projector_rms = 0.0881234567890123;
  p.stereo_camera_rms = 0.0111234567890123;
  p.stereo_projector_rms = 0.0891234567890123;
  p.used_planes = {"plane0", "plane1", "plane3"};
  p.per_plane_errors = {{0.0101234567891, 0.0801234567891}, {0.0121234567891, 0.0911234567891},
                        {0.0111234567891, 0.0951234567891}};
  p.dropped = {"plane2: projected pattern not found"};
  const CameraCalibration camera = TrueCamera(SyntheticRig::Default());
  const std::string path = TempPath("translume_projector_roundtrip.yml");
  WriteProjectorCalibration(path, p, camera, "11x7:64");
  const ProjectorCalibration r = ReadProjectorCalibration(path);
  EXPECT_EQ(r.projector_size, p.projector_size);
  ExpectSameMat(cv::Mat(r.K), cv::Mat(p.K), "projector K");
  ExpectSameMat(r.dist, p.dist, "projector dist");  // all 5 coefficients
  ExpectSameMat(r.std_intrinsics, p.std_intrinsics, "projector std_intrinsics");
  ExpectSameMat(cv::Mat(r.R), cv::Mat(p.R), "R");
  ExpectSameMat(cv::Mat(r.T), cv::Mat(p.T), "T");
  EXPECT_EQ(r.projector_rms, p.projector_rms);
  EXPECT_EQ(r.stereo_camera_rms, p.stereo_camera_rms);
  EXPECT_EQ(r.stereo_projector_rms, p.stereo_projector_rms);
  EXPECT_EQ(r.per_plane_errors, p.per_plane_errors);
  EXPECT_EQ(r.used_planes, p.used_planes);
  EXPECT_EQ(r.dropped, p.dropped);
  {
    cv::FileStorage fs(path, cv::FileStorage::READ);
    cv::Mat K, dist;
    int width = 0, height = 0;
    std::string pattern;
    fs["camera_matrix"] >> K;
    fs["distortion_coefficients"] >> dist;
    fs["image_width"] >> width;
    fs["image_height"] >> height;
    fs["pattern"] >> pattern;
    ExpectSameMat(K, cv::Mat(camera.K), "camera K");
    ExpectSameMat(dist, camera.dist, "camera dist");
    EXPECT_EQ(cv::Size(width, height), camera.image_size);
    EXPECT_EQ(pattern, "11x7:64");
  }
  std::filesystem::remove(path);
  EXPECT_THROW(ReadProjectorCalibration(path), CalibError);
  // Unusable values are refused naming the file and the field (a NaN went on into q).
  for (int k : {0, 1, 2}) {
    ProjectorCalibration bad = p;
    if (k == 0) bad.K(1, 2) = std::nan("");
    if (k == 1) bad.R(0, 0) = std::nan("");
    if (k == 2) bad.T[2] = std::numeric_limits<double>::infinity();
    WriteProjectorCalibration(path, bad, camera, "11x7:64");
    try {
      ReadProjectorCalibration(path);
      ADD_FAILURE() << "case " << k << " accepted";
    } catch (const CalibError& e) {
      EXPECT_EQ(std::string(e.what()).find(path + (k ? ": R must be a rotation and T finite"
                                                     : ": projector_matrix: element 5 is ")), 0u) << e.what();
    }
  }
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace translume::calib
