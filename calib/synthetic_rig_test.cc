// SPDX-License-Identifier: MIT
#include "calib/synthetic_rig.h"

#include <gtest/gtest.h>

#include <cmath>

#include "calib/board.h"

namespace translume::calib {
namespace {

double Rms(const std::vector<cv::Point2f>& a, const std::vector<cv::Point2d>& b) {
  double s = 0;
  for (size_t k = 0; k < a.size(); ++k) s += std::pow(cv::norm(cv::Point2d(a[k]) - b[k]), 2);
  return std::sqrt(s / double(a.size()));
}

// Corner id k's position by the documented board frame (board.h), independent of the code.
cv::Point3d DocumentedCorner(const BoardSpec& b, int k) {
  if (b.kind == BoardSpec::Kind::kChessboard)
    return {(k % b.cols) * b.square_mm, (k / b.cols) * b.square_mm, 0};
  return {(k % (b.cols - 1) + 1) * b.square_mm, (k / (b.cols - 1) + 1) * b.square_mm, 0};
}

// Both board kinds: every detected corner, placed by its id where board.h says that corner is,
// projects through the true camera within 0.1 px of where it was found (the renderer's
// antialiasing, 0.5 px blur and 1-code noise leave ~0.02-0.05 px; a wrong id or position is
// off by a square, ~60 px). The ChArUco view must show at least 40 of its 54 corners.
TEST(SyntheticRig, BoardCornersAreFoundWhereTheyProject) {
  const SyntheticRig rig = SyntheticRig::Default();
  for (const char* spec : {"chessboard:9x6:25", "charuco:10x7:25:18"}) {
    const BoardSpec board = BoardSpec::Parse(spec);
    const std::vector<Pose> poses = rig.BoardPoses(board, 2, 450, 3);
    ASSERT_EQ(poses.size(), 2u);
    const BoardDetection d = DetectBoard(board, rig.RenderBoard(board, poses[1]));
    ASSERT_TRUE(d.found) << spec;
    ASSERT_EQ(d.ids.size(), d.image_points.size());
    EXPECT_GE(d.ids.size(), board.kind == BoardSpec::Kind::kChessboard ? 54u : 40u) << spec;
    std::vector<cv::Point3d> X;
    for (size_t k = 0; k < d.ids.size(); ++k) {
      const cv::Point3d c = DocumentedCorner(board, d.ids[k]);
      EXPECT_EQ(cv::Point3d(d.object_points[k]), c) << spec << " corner id " << d.ids[k];
      const cv::Vec3d x = poses[1].Apply({c.x, c.y, c.z});
      X.emplace_back(x[0], x[1], x[2]);
    }
    const double rms = Rms(d.image_points, rig.camera.Project(X));
    std::printf("%s: %zu corners, RMS %.4f px from the truth\n", spec, d.ids.size(), rms);
    EXPECT_LT(rms, 0.1) << spec;
  }
}

TEST(SyntheticRig, ProjectedCornersAreFoundWhereTheProjectorRaysMeetThePlane) {
  const SyntheticRig rig = SyntheticRig::Default();
  const ProjectorChessboard pattern = ProjectorChessboard::Centered(rig.projector.size, 11, 7, 64);
  ASSERT_EQ(pattern.Validate(), "");
  const std::vector<Pose> planes = rig.PlanePoses(pattern, 1, 500, 4);
  ASSERT_EQ(planes.size(), 1u);
  const std::vector<cv::Point2f> found =
      FindChessboardGrid(rig.RenderProjectedChessboard(planes[0], pattern), 11, 7);
  ASSERT_EQ(found.size(), 77u);
  std::vector<cv::Point3d> X;
  for (const cv::Point2f& c : pattern.Corners()) {
    cv::Vec3d x;
    ASSERT_TRUE(rig.ProjectorPixelOnPlane(planes[0], c, &x));
    X.emplace_back(x[0], x[1], x[2]);
  }
  const double rms = Rms(found, rig.camera.Project(X));
  std::printf("projected corners: RMS %.4f px from the truth\n", rms);
  EXPECT_LT(rms, 0.1);
}

TEST(SyntheticRig, ExposureStackFollowsTheResponseAndClips) {
  cv::Mat E(1, 3, CV_32FC3);
  E.at<cv::Vec3f>(0, 0) = cv::Vec3f(0.1f, 0.2f, 0.3f);
  E.at<cv::Vec3f>(0, 1) = cv::Vec3f(0.001f, 0.001f, 0.001f);
  E.at<cv::Vec3f>(0, 2) = cv::Vec3f(5, 5, 5);
  const SyntheticResponse f;
  StackOptions o;
  o.read_noise = o.shot_noise = 0;
  const auto s8 = SyntheticRig::RenderExposureStack(E, {1.0, 2.0}, f, o);
  ASSERT_EQ(s8.size(), 2u);
  EXPECT_EQ(s8[0].type(), CV_8UC3);
  EXPECT_EQ(s8[1].at<cv::Vec3b>(0, 0)[1], std::lround(255 * f.Apply(0.4, 1)));
  EXPECT_EQ(s8[0].at<cv::Vec3b>(0, 2)[0], 255);
  o.bits = 16;
  const auto s16 = SyntheticRig::RenderExposureStack(E, {1.0}, f, o);
  EXPECT_EQ(s16[0].at<cv::Vec3w>(0, 0)[2], std::lround(65535 * 0.3f));
  EXPECT_EQ(s16[0].at<cv::Vec3w>(0, 2)[2], 65535);
  // The response is monotone, 0 at 0 and 1 at 1.
  EXPECT_DOUBLE_EQ(f.Apply(0, 0), 0.0);
  EXPECT_DOUBLE_EQ(f.Apply(1, 2), 1.0);
  EXPECT_LT(f.Apply(0.5, 1), f.Apply(0.51, 1));
}

TEST(SyntheticRig, ChartRadianceIsAlbedoTimesLightOverPi) {
  const SyntheticRig rig = SyntheticRig::Default();
  const SyntheticChart chart = SyntheticChart::ColorChecker();
  Pose pose;
  pose.t = cv::Vec3d(-chart.SizeMm().width / 2, -chart.SizeMm().height / 2, 600);
  const cv::Mat L = rig.RenderChartRadiance(chart, pose, {2, 2, 2}, {1, 0.5, 1});
  const cv::Point2d c = chart.PatchCenter(18);  // white
  const cv::Point2d px = rig.camera.Project({cv::Point3d(c.x + pose.t[0], c.y + pose.t[1], 600)})[0];
  const cv::Vec3f v = L.at<cv::Vec3f>(int(std::lround(px.y)), int(std::lround(px.x)));
  const double kPi = 3.14159265358979323846;
  EXPECT_NEAR(v[0], chart.albedo[18][0] * 2 / kPi, 1e-5);
  EXPECT_NEAR(v[1], chart.albedo[18][1] * 2 / kPi * 0.5, 1e-5);
  EXPECT_NEAR(chart.albedo[18][1], 0.9, 0.02);  // ColorChecker white 9.5
}

}  // namespace
}  // namespace translume::calib
