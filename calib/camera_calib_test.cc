// SPDX-License-Identifier: MIT
#include "calib/camera_calib.h"

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <opencv2/imgproc.hpp>

#include "calib/error.h"
#include "calib/synthetic_rig.h"
#include "calib/test_util.h"

namespace translume::calib {
namespace {

std::vector<NamedImage> RenderViews(const SyntheticRig& rig, const BoardSpec& board, int n,
                                    uint64_t seed) {
  std::vector<NamedImage> views;
  int k = 0;
  for (const Pose& p : rig.BoardPoses(board, n, 450, seed)) {
    PhotoOptions o;
    o.seed = seed * 100 + uint64_t(k);
    views.push_back({fmt::format("view{:02d}.png", k++), rig.RenderBoard(board, p, o)});
  }
  return views;
}

// Twelve chessboard views, rendered once for the whole suite.
const std::vector<NamedImage>& ChessViews() {
  static const std::vector<NamedImage> views = RenderViews(
      SyntheticRig::Default(), BoardSpec::Parse("chessboard:9x6:25"), 12, 7);
  return views;
}

void ExpectIntrinsics(const SyntheticRig& rig, const CameraCalibration& c) {
  const double fx = rig.camera.K(0, 0), fy = rig.camera.K(1, 1);
  std::printf("fx %.3f (%.4f%%) fy %.3f (%.4f%%) cx %.3f (%+.3f) cy %.3f (%+.3f) RMS %.4f px\n",
              c.K(0, 0), 100 * (c.K(0, 0) / fx - 1), c.K(1, 1), 100 * (c.K(1, 1) / fy - 1),
              c.K(0, 2), c.K(0, 2) - rig.camera.K(0, 2), c.K(1, 2), c.K(1, 2) - rig.camera.K(1, 2),
              c.rms);
  EXPECT_NEAR(c.K(0, 0) / fx, 1.0, 0.002);
  EXPECT_NEAR(c.K(1, 1) / fy, 1.0, 0.002);
  EXPECT_NEAR(c.K(0, 2), rig.camera.K(0, 2), 1.0);
  EXPECT_NEAR(c.K(1, 2), rig.camera.K(1, 2), 1.0);
  EXPECT_LE(c.rms, 0.1);
  EXPECT_NEAR(c.dist.at<double>(0), rig.camera.dist[0], 0.01);
}

TEST(CameraCalib, ChessboardMeetsTargets) {
  const SyntheticRig rig = SyntheticRig::Default();
  const BoardSpec board = BoardSpec::Parse("chessboard:9x6:25");
  const auto& views = ChessViews();
  ASSERT_EQ(views.size(), 12u);
  const CameraCalibration c = CalibrateCamera(board, views);
  std::printf("%s\n", c.BriefReport().c_str());
  EXPECT_EQ(c.used_views.size(), 12u);
  EXPECT_TRUE(c.dropped.empty());
  ExpectIntrinsics(rig, c);
}

TEST(CameraCalib, CharucoMeetsTargets) {
  const SyntheticRig rig = SyntheticRig::Default();
  const BoardSpec board = BoardSpec::Parse("charuco:10x7:25:18");
  const auto views = RenderViews(rig, board, 9, 11);
  const CameraCalibration c = CalibrateCamera(board, views);
  std::printf("%s\n", c.BriefReport().c_str());
  EXPECT_EQ(c.used_views.size(), 9u);
  ExpectIntrinsics(rig, c);
}

// A 12 MP photo is searched at a quarter of its size and refined at full size: its corners are
// as close to the truth as at 1024 x 768 (0.04 px). A full-size search took longer and put some
// corners pixels off (2.6 px RMS).
TEST(CameraCalib, LargePhotosKeepTheirCornerAccuracy) {
  const SyntheticRig rig = LargeCameraRig();
  const BoardSpec board = BoardSpec::Parse("chessboard:9x6:25");
  const Pose pose = rig.BoardPoses(board, 3, 450, 5)[2];
  PhotoOptions o;
  o.blur_sigma_px = 2;  // the optics blur the same fraction of the view as 0.5 px at 1024 x 768
  const cv::Mat photo = rig.RenderBoard(board, pose, o);
  std::vector<cv::Point3d> corners;
  for (const cv::Point3f& p : board.CornerPositions()) {
    const cv::Vec3d c = pose.Apply(cv::Vec3d(p.x, p.y, p.z));
    corners.push_back({c[0], c[1], c[2]});
  }
  ExpectReducedSearchAccurate(photo, board.cols, board.rows, rig.camera.Project(corners), 0.05);
}

// ChArUco boards are searched at full size: quick and accurate also in a 12 MP photo (0.07-0.2 s,
// 0.05 px on the 2-core VM), so they need no reduced search.
TEST(CameraCalib, LargeCharucoPhotosAtFullSize) {
  const SyntheticRig rig = LargeCameraRig();
  const BoardSpec board = BoardSpec::Parse("charuco:10x7:25:18");
  const Pose pose = rig.BoardPoses(board, 3, 450, 5)[2];
  PhotoOptions o;
  o.blur_sigma_px = 2;
  const cv::Mat photo = rig.RenderBoard(board, pose, o);
  const std::vector<cv::Point3f> all = board.CornerPositions();
  const auto t0 = std::chrono::steady_clock::now();
  const BoardDetection d = DetectBoard(board, photo);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_TRUE(d.found);
  std::vector<cv::Point3d> corners;
  for (const int id : d.ids) {
    const cv::Vec3d c = pose.Apply(cv::Vec3d(all[size_t(id)].x, all[size_t(id)].y, all[size_t(id)].z));
    corners.push_back({c[0], c[1], c[2]});
  }
  const double rms = CornerRmsToTruth(d.image_points, rig.camera.Project(corners));
  std::printf("ChArUco 4096 x 3072: %zu corners in %.2f s, RMS %.3f px against the truth\n", d.ids.size(),
              seconds, rms);
  EXPECT_GE(d.ids.size(), 40u);
  EXPECT_LT(rms, 0.1);
}

TEST(CameraCalib, DropsBlankAndOutlierViewsAndListsThem) {
  const SyntheticRig rig = SyntheticRig::Default();
  const BoardSpec board = BoardSpec::Parse("chessboard:9x6:25");
  std::vector<NamedImage> views(ChessViews().begin(), ChessViews().begin() + 8);
  views.push_back({"blank.png", cv::Mat(rig.camera.size, CV_8UC1, cv::Scalar(90))});
  // A photo with a wavy, non-rigid distortion of 1.5 px: its corners fit no camera.
  cv::Mat mx(rig.camera.size, CV_32F), my(rig.camera.size, CV_32F);
  for (int y = 0; y < mx.rows; ++y)
    for (int x = 0; x < mx.cols; ++x) {
      mx.at<float>(y, x) = float(x + 1.5 * std::sin(y / 25.0));
      my.at<float>(y, x) = float(y + 1.5 * std::cos(x / 31.0));
    }
  cv::Mat warped;
  cv::remap(ChessViews()[9].image, warped, mx, my, cv::INTER_LINEAR);
  views.push_back({"wavy.png", warped});
  const CameraCalibration c = CalibrateCamera(board, views);
  std::printf("%s\n", c.BriefReport().c_str());
  ASSERT_EQ(c.dropped.size(), 2u);
  EXPECT_NE(c.dropped[0].find("blank.png: board not found"), std::string::npos);
  EXPECT_NE(c.dropped[1].find("wavy.png: reprojection RMS"), std::string::npos) << c.dropped[1];
  EXPECT_EQ(c.used_views.size(), 8u);
  EXPECT_NEAR(c.K(0, 0) / rig.camera.K(0, 0), 1.0, 0.003);
}

TEST(CameraCalib, BadInputsThrowNamingTheFile) {
  const SyntheticRig rig = SyntheticRig::Default();
  const BoardSpec board = BoardSpec::Parse("chessboard:9x6:25");
  auto views = RenderViews(rig, board, 3, 7);  // the first 3 of ChessViews()
  try {
    CalibrateCamera(board, views);
    FAIL() << "3 views accepted";
  } catch (const CalibError& e) {
    EXPECT_NE(std::string(e.what()).find("only 3 usable views"), std::string::npos) << e.what();
  }
  views.push_back({"small.png", cv::Mat(100, 120, CV_8UC1, cv::Scalar(0))});
  try {
    CalibrateCamera(board, views);
    FAIL() << "different sizes accepted";
  } catch (const CalibError& e) {
    EXPECT_NE(std::string(e.what()).find("small.png: image is 120x100"), std::string::npos)
        << e.what();
  }
  EXPECT_THROW(BoardSpec::Parse("chessboard:9x9:25"), CalibError);
  EXPECT_THROW(BoardSpec::Parse("chessboard:9x6"), CalibError);
  EXPECT_THROW(BoardSpec::Parse("charuco:9x7:20:25"), CalibError);
  EXPECT_THROW(BoardSpec::Parse("charuco:9x7:20:15:7X7_1"), CalibError);
  // Sizes no printed board has: 100000x99999 allocated 5 GB, a charuco board of 1000x999 hung,
  // 1e308 mm reached an OpenCV assertion.
  const auto message = [](const std::string& text) {
    try {
      BoardSpec::Parse(text);
    } catch (const CalibError& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_EQ(message("chessboard:100000x99999:1"), "board 'chessboard:100000x99999:1': at most 100 inner corners per side");
  EXPECT_EQ(message("charuco:20x21:25:18:5X5_100"), "board 'charuco:20x21:25:18:5X5_100': needs 210 markers, dictionary 5X5_100 has 100");
  EXPECT_EQ(message("charuco:20x21:25:18:6X6_250"), "accepted");
  EXPECT_EQ(message("chessboard:9x6:1e308"), "board 'chessboard:9x6:1e308': square size must be within (0, 10000] mm");
}

// The file keeps every stored number exactly: OpenCV 4 writes doubles as "%.16e" (17
// significant digits), enough to read back the same IEEE double. So the comparisons are exact,
// with values chosen to have no short binary form (a float or "%.6g" writer would fail them).
TEST(CameraCalib, YamlRoundTripLoadsInOpenCV) {
  CameraCalibration c;
  c.image_size = {1024, 768};
  c.K = {1200.123456789012, 0, 515.2718281828459, 0, 1201.7531415926535, 380.5772156649015, 0, 0, 1};
  c.dist = (cv::Mat_<double>(1, 5) << -0.1234567890123, 0.0987654321987, 0.00041421356237,
            -0.00031415926535, 0.0000271828182846);
  c.std_intrinsics = (cv::Mat_<double>(1, 4) << 0.9012345678901, 0.8765432109876,
                      1.0601234567891, 0.7101234567890);
  c.rms = 0.0612345678901234;
  c.per_view_errors = {0.0512345678901234, 0.0712345678901234};
  c.used_views = {"a.png", "b.png"};
  c.dropped = {"c.png: board not found"};
  const BoardSpec board = BoardSpec::Parse("charuco:10x7:25:18");
  const std::string path = TempPath("translume_camera_roundtrip.yml");
  WriteCameraCalibration(path, c, board.ToString());
  {
    // Other tools read the file with plain OpenCV: the names and the board are as documented.
    cv::FileStorage fs(path, cv::FileStorage::READ);
    cv::Mat K;
    std::string b;
    fs["camera_matrix"] >> K;
    fs["board"] >> b;
    EXPECT_EQ(cv::norm(K, cv::Mat(c.K), cv::NORM_INF), 0.0) << K;
    EXPECT_EQ(b, board.ToString());
  }
  const CameraCalibration r = ReadCameraCalibration(path);
  EXPECT_EQ(r.image_size, c.image_size);
  ExpectSameMat(cv::Mat(r.K), cv::Mat(c.K), "K");
  ExpectSameMat(r.dist, c.dist, "dist");  // all 5 coefficients, 1x5 CV_64F
  ExpectSameMat(r.std_intrinsics, c.std_intrinsics, "std_intrinsics");
  EXPECT_EQ(r.rms, c.rms);
  EXPECT_EQ(r.per_view_errors, c.per_view_errors);
  EXPECT_EQ(r.used_views, c.used_views);
  EXPECT_EQ(r.dropped, c.dropped);
  // The per-view extrinsics (rvecs, tvecs) are not part of the file format.
  EXPECT_TRUE(r.rvecs.empty());
  std::filesystem::remove(path);
  EXPECT_THROW(ReadCameraCalibration(path), CalibError);
}

// Intrinsics no camera has (fx 0, a NaN) are refused at read, naming the file and the field;
// they went on into the pose and the mapping.
TEST(CameraCalib, UnusableIntrinsicsAreRefusedAtRead) {
  const std::string path = TempPath("translume_camera_bad.yml");
  auto expect = [&](const CameraCalibration& c, const std::string& what) {
    WriteCameraCalibration(path, c, "chessboard:9x6:25");
    try {
      ReadCameraCalibration(path);
      ADD_FAILURE() << "accepted; expected " << what;
    } catch (const CalibError& e) {
      EXPECT_EQ(std::string(e.what()).find(path + ": " + what), 0u) << e.what();
    }
  };
  CameraCalibration c;
  c.image_size = {640, 480};
  c.K = {0, 0, 320, 0, 1000, 240, 0, 0, 1};
  c.dist = cv::Mat::zeros(1, 5, CV_64F);
  expect(c, "camera_matrix: fx 0 and fy 1000 must be positive");
  c.K(0, 0) = std::nan("");
  expect(c, "camera_matrix: element 0 is ");  // "nan" or "-nan", "must be finite"
  c.K(0, 0) = 1000;
  c.dist.at<double>(1) = std::numeric_limits<double>::infinity();
  expect(c, "distortion_coefficients: coefficient 1 is inf, must be finite");
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace translume::calib
