// SPDX-License-Identifier: MIT
#include "calib/projector_calib.h"

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/calib3d.hpp>

#include "calib/error.h"
#include "calib/synthetic_rig.h"

namespace translume::calib {
namespace {

constexpr double kPi = 3.14159265358979323846;

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
      camera.image_size = rig.camera.size;
      camera.K = rig.camera.K;
      camera.dist = cv::Mat(rig.camera.dist).reshape(1, 1).clone();
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
  EXPECT_EQ(p.used_planes.size(), 8u);
  EXPECT_NEAR(p.K(0, 0) / Kt(0, 0), 1.0, 0.005);
  EXPECT_NEAR(p.K(1, 1) / Kt(1, 1), 1.0, 0.005);
  EXPECT_LE(p.projector_rms, 0.5);
  EXPECT_LE(p.stereo_projector_rms, 0.5);
  EXPECT_LE(p.stereo_camera_rms, 0.5);
  EXPECT_LE(rot_deg, 0.1);
  EXPECT_LE(dt, 1.0);
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

}  // namespace
}  // namespace translume::calib
