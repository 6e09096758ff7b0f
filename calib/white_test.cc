// SPDX-License-Identifier: MIT
#include "calib/white.h"

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <limits>
#include <opencv2/calib3d.hpp>

#include "calib/colorchecker.h"
#include "calib/error.h"
#include "calib/hdr.h"
#include "calib/synthetic_rig.h"
#include "calib/test_util.h"

namespace translume::calib {
namespace {

constexpr double kPi = 3.14159265358979323846;

struct ChartScene {
  SyntheticRig rig = SyntheticRig::Default();
  SyntheticChart chart = SyntheticChart::ColorChecker();
  Pose pose;
  cv::Vec3d projector_white{0.8, 1.0, 1.2}, projector_black{0.008, 0.01, 0.012};
  cv::Vec3d camera_gain{0.9, 1.1, 0.7};
  cv::Mat white, black;  // linear radiance seen by the camera
  explicit ChartScene(const cv::Vec3d& rvec) {
    pose.R = cv::Matx33d::eye();
    cv::Rodrigues(rvec, pose.R);
    const cv::Size2d s = chart.SizeMm();
    pose.t = cv::Vec3d(0, 0, 600) - pose.R * cv::Vec3d(s.width / 2, s.height / 2, 0);
    white = rig.RenderChartRadiance(chart, pose, projector_white, camera_gain);
    black = rig.RenderChartRadiance(chart, pose, projector_black, camera_gain);
  }
  cv::Vec3d TrueGains() const {
    cv::Vec3d g;
    for (int c = 0; c < 3; ++c) g[c] = 1 / (camera_gain[c] * (projector_white[c] - projector_black[c]));
    return g;
  }
  // Image corners of the central half of patch k.
  std::vector<cv::Point2f> PatchCorners(int k) const {
    const cv::Point2d c = chart.PatchCenter(k);
    const double h = chart.patch_mm / 4;
    std::vector<cv::Point3d> X;
    for (const auto& d : {cv::Point2d(-1, -1), cv::Point2d(1, -1), cv::Point2d(1, 1), cv::Point2d(-1, 1)}) {
      const cv::Vec3d x = pose.Apply({c.x + d.x * h, c.y + d.y * h, 0});
      X.emplace_back(x[0], x[1], x[2]);
    }
    std::vector<cv::Point2f> out;
    for (const auto& p : rig.camera.Project(X)) out.emplace_back(float(p.x), float(p.y));
    return out;
  }
};

// HDR of a radiance image through a noisy 16-bit exposure stack.
cv::Mat Through16BitStack(const cv::Mat& radiance, uint64_t seed) {
  const std::vector<double> t{0.25, 1.0, 4.0, 16.0};
  StackOptions o;
  o.bits = 16;
  o.seed = seed;
  ExposureStack s;
  s.dir = "synthetic";
  const auto images = SyntheticRig::RenderExposureStack(radiance, t, {}, o);
  for (size_t j = 0; j < t.size(); ++j) s.exposures.push_back({"e", images[j], t[j]});
  return MergeHdr(s, nullptr).radiance;
}

void ExpectGains(const WhiteBalance& w, const cv::Vec3d& truth, double tol) {
  std::printf("%s; truth %.5g %.5g %.5g; errors %.3f%% %.3f%% %.3f%%\n", w.BriefReport().c_str(),
              truth[0], truth[1], truth[2], 100 * (w.gains[0] / truth[0] - 1),
              100 * (w.gains[1] / truth[1] - 1), 100 * (w.gains[2] / truth[2] - 1));
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(w.gains[c] / truth[c], 1.0, tol) << "channel " << c;
}

TEST(White, ColorCheckerThroughHdrStacksWithin1Percent) {
  const ChartScene s({0.15, -0.25, 0.05});
  const cv::Mat white = Through16BitStack(s.white, 1), black = Through16BitStack(s.black, 2);
  std::vector<cv::Vec3d> values;
  const WhiteBalance w = WhiteFromColorChecker(white, black, &values);
  ExpectGains(w, s.TrueGains(), 0.01);
  EXPECT_EQ(w.patches, 6);
  // The patches were read in the right order: the gains map every patch to rho / pi (where the
  // albedo is not so dark that the stack's noise dominates).
  const auto rho = ColorCheckerLinearAlbedos();
  for (int k = 0; k < 24; ++k)
    for (int c = 0; c < 3; ++c)
      if (rho[size_t(k)][c] > 0.05) {
        EXPECT_NEAR(w.gains[c] * values[size_t(k)][c] * kPi / rho[size_t(k)][c], 1.0, 0.03)
            << "patch " << k << " channel " << c;
      }
}

TEST(White, ColorCheckerUpsideDown) {
  const ChartScene s({0.1, 0.2, 3.0});  // rotated by ~172 degrees in the image
  const WhiteBalance w = WhiteFromColorChecker(s.white, s.black);
  ExpectGains(w, s.TrueGains(), 0.01);
}

TEST(White, PatchOfKnownAlbedo) {
  const ChartScene s({-0.2, 0.1, 0.0});
  const cv::Mat white = Through16BitStack(s.white, 3), black = Through16BitStack(s.black, 4);
  const WhiteBalance w = WhiteFromPatch(white, black, s.PatchCorners(18), s.chart.albedo[18]);
  ExpectGains(w, s.TrueGains(), 0.01);
}

TEST(White, BadInputs) {
  const ChartScene s({0, 0, 0});
  cv::Mat sat = s.white.clone();
  sat.setTo(cv::Scalar::all(std::numeric_limits<float>::infinity()));
  EXPECT_THROW(WhiteFromPatch(sat, cv::Mat(), s.PatchCorners(18), {0.9, 0.9, 0.9}), CalibError);
  EXPECT_THROW(WhiteFromPatch(s.white, s.black(cv::Rect(0, 0, 10, 10)).clone(), s.PatchCorners(18),
                              {0.9, 0.9, 0.9}), CalibError);
  EXPECT_THROW(WhiteFromPatch(s.white, cv::Mat(), {{5000, 5000}, {5010, 5000}, {5010, 5010}, {5000, 5010}},
                              {0.9, 0.9, 0.9}), CalibError);
  EXPECT_THROW(WhiteFromColorChecker(cv::Mat(s.white.size(), CV_32FC3, cv::Scalar::all(0.1)), cv::Mat()),
               CalibError);
}

// The white and black references swapped gave negative gains (every measurement dark), and a
// patch reaching outside the image averaged only its inside part (gains 28% off): both refused.
TEST(White, SwappedReferencesAndPatchOutsideTheImageAreRefused) {
  const ChartScene s({-0.2, 0.1, 0.0});
  EXPECT_NE(CalibErrorOf([&] { WhiteFromPatch(s.black, s.white, s.PatchCorners(18), s.chart.albedo[18]); })
                .find("the white reference is not brighter than the black reference in the R channel "
                      "(maybe the white and black images are swapped)"), std::string::npos);
  std::vector<cv::Point2f> corners = s.PatchCorners(18);
  corners[1].x = float(s.white.cols) + 20;
  EXPECT_NE(CalibErrorOf([&] { WhiteFromPatch(s.white, s.black, corners, s.chart.albedo[18]); })
                .find(fmt::format("patch corner 1 ({:.1f}, {:.1f}) is outside the {}x{} image", corners[1].x,
                                  corners[1].y, s.white.cols, s.white.rows)), std::string::npos);
  corners[1].x = float(s.white.cols) - 0.5f;  // the last pixel's far edge is inside
  EXPECT_NO_THROW(WhiteFromPatch(s.white, s.black, corners, s.chart.albedo[18]));
}

// MeanInPolygon of an image whose channels are x, y and x * y over the pixels with centres in the
// axis-aligned square (10..20, 5..15): a product set, so the means are exactly 15, 10 and 150
// (whether or not the boundary pixels count, as long as both sides are treated alike); one pixel
// too many or too few on one side moves them by >= 0.04.
TEST(White, MeanInPolygonOfKnownImage) {
  cv::Mat img(30, 40, CV_32FC3);
  for (int y = 0; y < img.rows; ++y)
    for (int x = 0; x < img.cols; ++x) img.at<cv::Vec3f>(y, x) = cv::Vec3f(float(x), float(y), float(x * y));
  const cv::Vec3d m = MeanInPolygon(img, {{10, 5}, {20, 5}, {20, 15}, {10, 15}});
  EXPECT_NEAR(m[0], 15.0, 1e-9);
  EXPECT_NEAR(m[1], 10.0, 1e-9);
  EXPECT_NEAR(m[2], 150.0, 1e-9);
}

// The white balance file gives back the gains, misfit, patch count and method exactly (17
// significant digits), and the black level under its documented names.
TEST(White, YamlRoundTrip) {
  WhiteBalance w;
  w.gains = {1.4029812345678901, 0.9181423456789012, 1.2031234567890123};
  w.residual = {0.0036123456789012, 0.0013123456789012, 0.0016123456789012};
  w.patches = 6;
  w.method = "colorchecker";
  const std::string path = TempPath("translume_white_roundtrip.yml");
  const cv::Vec3d black(0.0081234567890123, 0.0101234567890123, 0.0121234567890123);
  WriteWhiteBalance(path, w, black, "black.exr");
  const WhiteBalance r = ReadWhiteBalance(path);
  EXPECT_EQ(r.gains, w.gains);
  EXPECT_EQ(r.residual, w.residual);
  EXPECT_EQ(r.patches, 6);
  EXPECT_EQ(r.method, "colorchecker");
  EXPECT_EQ(r.exposure_times, "");  // an HDR image given as is
  w.exposure_times = "apex";
  WriteWhiteBalance(path, w, black, "black.exr");
  EXPECT_EQ(ReadWhiteBalance(path).exposure_times, "apex");
  {
    cv::FileStorage fs(path, cv::FileStorage::READ);
    cv::Mat b;
    std::string image;
    fs["black_level_mean"] >> b;
    fs["black_image"] >> image;
    ExpectSameMat(b, cv::Mat(cv::Matx13d(black[0], black[1], black[2])), "black_level_mean");
    EXPECT_EQ(image, "black.exr");
  }
  std::filesystem::remove(path);
  EXPECT_THROW(ReadWhiteBalance(path), CalibError);
}

// Gains that are not finite and positive are refused naming the file (NaN gains aborted acquire
// on an internal check; negative or zero ones zeroed a channel's measurements).
TEST(White, NonPositiveOrNonFiniteGainsAreRefusedAtRead) {
  const std::string path = TempPath("translume_white_bad_gains.yml");
  for (double g : {std::nan(""), std::numeric_limits<double>::infinity(), -1.0, 0.0}) {
    WhiteBalance w;
    w.gains = {g, 1.0, 1.0};
    WriteWhiteBalance(path, w, {0, 0, 0}, "");
    try {
      ReadWhiteBalance(path);
      ADD_FAILURE() << "gain " << g << " accepted";
    } catch (const CalibError& e) {
      EXPECT_EQ(std::string(e.what()).find(path + ": white_gains must be finite and positive"), 0u) << e.what();
    }
  }
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace translume::calib
