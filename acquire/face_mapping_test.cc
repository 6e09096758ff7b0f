// SPDX-License-Identifier: MIT
#include "acquire/face_mapping.h"

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <random>

#include "acquire/simulate_capture.h"
#include "solver/evaluate.h"
#include "solver/light.h"
#include "solver/status.h"

namespace translume::acquire {
namespace {

const GridShape kGrid{24, 18, 6};
constexpr double kH = 0.5;

// The front face's corners in the camera image; `stretch_x` scales the face along x (a sample
// that is not the size capture.json says).
std::vector<cv::Point2d> TrueCorners(const CaptureRig& rig, double stretch_x = 1) {
  std::vector<cv::Point3d> cam;
  for (const auto& p : FrontFaceCorners(kGrid, kH)) {
    const cv::Vec3d x = rig.camera_from_sample.Apply({p.x * stretch_x, p.y, p.z});
    cam.emplace_back(x[0], x[1], x[2]);
  }
  return rig.camera.Project(cam);
}

// A photo of a lit card or sample whose dark background is clipped at 0 (an 8-bit photo in a
// dark room): only noise is left there, which the log scale lifted to mid grey in scattered
// pixels; the threshold then outlined the whole image and the corners were not found.
TEST(FaceMapping, CornersFoundOnABackgroundClippedAtZero) {
  const CaptureRig rig = DefaultCaptureRig(kGrid, kH, Setup::kBack);
  const std::vector<cv::Point2d> truth = TrueCorners(rig);
  // The card's coverage of each pixel (4x4 samples; pixel centres at integer coordinates).
  cv::Mat coverage(rig.camera.size, CV_32F, cv::Scalar(0));
  for (int y = 0; y < coverage.rows; ++y)
    for (int x = 0; x < coverage.cols; ++x)
      for (int k = 0; k < 16; ++k) {
        const cv::Point2d p(x - 0.375 + 0.25 * (k % 4), y - 0.375 + 0.25 * (k / 4));
        bool in = true;
        for (size_t e = 0; e < 4; ++e) in = in && (truth[(e + 1) % 4] - truth[e]).cross(p - truth[e]) >= 0;
        coverage.at<float>(y, x) += in ? 1.0f / 16 : 0.0f;
      }
  ASSERT_GT(cv::sum(coverage)[0], 1000);  // the corners run clockwise in the image
  for (double level : {0.05, 0.25, 0.8}) {
    cv::Mat grey = coverage * level;
    cv::GaussianBlur(grey, grey, cv::Size(0, 0), 0.7);
    cv::Mat noise(grey.size(), CV_32F);
    cv::RNG(7).fill(noise, cv::RNG::NORMAL, 0.0, 0.01);
    grey = cv::max(grey + noise, 0.0);
    cv::Mat rgb;
    cv::merge(std::vector<cv::Mat>{grey, grey, grey}, rgb);
    const std::vector<cv::Point2d> found = DetectFaceCorners(rgb);
    ASSERT_EQ(found.size(), 4u) << "card at " << level;
    double worst = 0;  // found in image order (top-left first), compared as a set
    for (const auto& t : truth) {
      double nearest = 1e9;
      for (const auto& f : found) nearest = std::min(nearest, cv::norm(f - t));
      worst = std::max(worst, nearest);
    }
    std::printf("card at %.2f of full scale, noise 0.01, background clipped at 0: corners within %.2f px\n", level,
                worst);
    EXPECT_LT(worst, 0.5) << "card at " << level;
  }
}

// Corners refined through a blurring lens: a face whose radiance falls towards its edges, by
// 60 % over ~8 px (light leaves through them) or linearly by 60 % over 20 px, photographed
// through Gaussian lenses of 0.5, 1.2 and 2.5 px with 0.5 % noise over a dim surround, one photo
// saturated over its middle (+inf, as a front-lit condition where it lights the face). Starting
// from the corners found on the sum (DetectFaceCorners: 0.12-1.5 px off) and from a blur 20 %
// low (EstimateOutlineBlur along an outline that is off reads it low), RefineFaceCorners finds
// the lens (0.40, 1.20, 2.50 px) and the corners within 0.1 px (measured: 0.03, 0.03, 0.09 px
// for the fall, 0.05, 0.02, 0.04 px for the linear one; on the sum 0.06-1.8 px).
TEST(FaceMapping, CornersRefinedThroughTheLensBlur) {
  const CaptureRig rig = DefaultCaptureRig(kGrid, kH, Setup::kBack);
  const std::vector<cv::Point2d> truth = TrueCorners(rig);
  const cv::Mat fine = FaceCoverage(rig.camera, rig.camera_from_sample, kGrid, kH, 0, 16);
  for (const bool linear : {false, true}) {
    cv::Mat radiance(fine.size(), CV_32FC1);
    for (int y = 0; y < radiance.rows; ++y)
      for (int x = 0; x < radiance.cols; ++x) {
        double inside = 1e9;  // distance from the nearest side, px
        for (size_t e = 0; e < 4; ++e) {
          const cv::Point2d a = truth[e], d = truth[(e + 1) % 4] - a;
          inside = std::min(inside, d.cross(cv::Point2d(x, y) - a) / cv::norm(d));
        }
        inside = std::max(inside, 0.0);
        radiance.at<float>(y, x) = float(linear ? 0.4 + 0.6 * std::min(inside, 20.0) / 20 : 1 - 0.6 * std::exp(-inside / 8));
      }
    std::mt19937 rng(11);
    std::normal_distribution<float> noise(0, 0.005f);
    for (double sigma : {0.5, 1.2, 2.5}) {
      SCOPED_TRACE(fmt::format("{} fall, lens {} px", linear ? "linear" : "exponential", sigma));
      std::vector<cv::Mat> photos;
      cv::Mat sum = cv::Mat::zeros(fine.size(), CV_32FC3);
      for (int m = 0; m < 4; ++m) {
        cv::Mat photo = fine.mul(radiance) * (0.5 + 0.25 * m);
        cv::GaussianBlur(photo, photo, cv::Size(0, 0), sigma, sigma, cv::BORDER_CONSTANT);
        photo += 0.02;
        for (auto it = photo.begin<float>(); it != photo.end<float>(); ++it) *it += noise(rng);
        if (m == 3)
          for (auto it = photo.begin<float>(); it != photo.end<float>(); ++it)
            if (*it > 1.2f) *it = std::numeric_limits<float>::infinity();
        cv::Mat rgb;
        cv::merge(std::vector<cv::Mat>{photo, 1.5 * photo, 0.5 * photo}, rgb);
        photos.push_back(rgb);
        sum += rgb;
      }
      const std::vector<cv::Point2d> detected = DetectFaceCorners(sum, &rig.camera);
      ASSERT_EQ(detected.size(), 4u);
      int points = 0;
      double blur = 0;
      const std::vector<cv::Point2d> refined =
          RefineFaceCorners(photos, rig.camera, detected, 0.8 * sigma, cv::Mat(), &points, &blur);
      ASSERT_EQ(refined.size(), 4u);
      double worst = 0, worst_detected = 0;
      for (size_t k = 0; k < 4; ++k) {
        worst = std::max(worst, cv::norm(refined[k] - truth[k]));
        worst_detected = std::max(worst_detected, cv::norm(detected[k] - truth[k]));
      }
      std::printf("%s fall, lens sigma %.1f px: found %.2f px; corners refined within %.3f px on %d edge points, "
                  "found on the sum within %.3f px\n",
                  linear ? "linear" : "exponential", sigma, blur, worst, points, worst_detected);
      EXPECT_GT(points, 4 * 4 * 50);
      EXPECT_NEAR(blur, sigma, 0.15);
      EXPECT_LT(worst, 0.1);
      if (worst_detected > 0.1) {
        EXPECT_LT(worst, 0.6 * worst_detected);
      }
    }
  }
  // Photos without an edge leave nothing to refine.
  const cv::Mat dark(rig.camera.size, CV_32FC3, cv::Scalar::all(0.01));
  EXPECT_TRUE(RefineFaceCorners({dark}, rig.camera, truth, 0.5).empty());
}

TEST(FaceMapping, PoseFromExactCorners) {
  for (translume::Setup setup : {Setup::kBack, Setup::kFront}) {
    const CaptureRig rig = DefaultCaptureRig(kGrid, kH, setup);
    double rms = -1;
    const calib::Pose p = EstimateSamplePose(rig.camera, TrueCorners(rig), kGrid, kH, "test", &rms);
    EXPECT_LT(rms, 1e-6);
    EXPECT_LT(cv::norm(p.t - rig.camera_from_sample.t), 1e-4 * cv::norm(rig.camera_from_sample.t));
    EXPECT_LT(cv::norm(cv::Mat(p.R - rig.camera_from_sample.R)), 1e-5);
  }
}

// A sample_mm that is off (a whole number of spacings, where the real block is not) fits the
// corners worse than the face's own width; FaceWidthFittingCorners finds that width, and
// SampleSizeHint names it only where the size is off by enough to miss the corners by 1 px.
TEST(FaceMapping, FaceWidthFromTheCornersNamesAWrongSampleSize) {
  for (translume::Setup setup : {Setup::kBack, Setup::kFront}) {
    const CaptureRig rig = DefaultCaptureRig(kGrid, kH, setup);
    const std::array<double, 3> size = SampleSize(kGrid, kH);
    for (double scale : {0.97, 1.0, 1.03}) {
      const std::array<double, 3> declared = {size[0] * scale, size[1], size[2]};
      const FaceWidthFit fit = FaceWidthFittingCorners(rig.camera, TrueCorners(rig), declared);
      EXPECT_NEAR(fit.width_mm, size[0], 1e-3 * size[0]) << SetupName(setup) << " x " << scale;
      EXPECT_LT(fit.rms_px, 0.01);
      double rms = 0;
      EstimateSamplePose(rig.camera, TrueCorners(rig), declared, "test", &rms, false);
      const std::string hint = SampleSizeHint(rig.camera, TrueCorners(rig), declared, rms);
      if (scale == 1.0) {
        EXPECT_EQ(hint, "");
      } else {
        EXPECT_GT(rms, 1) << SetupName(setup) << " x " << scale;
        EXPECT_NE(hint.find(fmt::format("a face of {:.2f} x {:g} mm", size[0], size[1])), std::string::npos) << hint;
      }
    }
  }
}

TEST(FaceMapping, CornersInTheWrongOrderOrOutsideAreRejected) {
  const CaptureRig rig = DefaultCaptureRig(kGrid, kH, Setup::kBack);
  auto c = TrueCorners(rig);
  std::swap(c[1], c[3]);  // counter-clockwise: the face seen from behind
  EXPECT_THROW(EstimateSamplePose(rig.camera, c, kGrid, kH, "test"), InputError);
  c = TrueCorners(rig);
  c[0].x = -20;
  EXPECT_THROW(EstimateSamplePose(rig.camera, c, kGrid, kH, "test"), InputError);
  // Clockwise but starting at the top-right corner: the 11.5 x 8.5 mm face transposed.
  c = TrueCorners(rig);
  std::rotate(c.begin(), c.begin() + 1, c.end());
  try {
    EstimateSamplePose(rig.camera, c, kGrid, kH, "test");
    ADD_FAILURE() << "rotated corners accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("test: the corners do not fit the 11.5 x 8.5 mm front face"),
              std::string::npos) << e.what();
  }
}

// Corners clicked by hand (1.5 px errors) on a sample 1 % wider than measured give a pose.
TEST(FaceMapping, HandClickedCornersAreAccepted) {
  const CaptureRig rig = DefaultCaptureRig(kGrid, kH, Setup::kBack);
  std::mt19937_64 rng(7);
  std::normal_distribution<double> noise(0, 1.5);
  auto c = TrueCorners(rig, 1.01);
  for (auto& p : c) p += cv::Point2d(noise(rng), noise(rng));
  double rms = -1;
  EXPECT_NO_THROW(EstimateSamplePose(rig.camera, c, kGrid, kH, "test", &rms));
  EXPECT_GT(rms, 0.1);
  std::printf("hand-clicked corners: pose RMS %.2f px\n", rms);
}

// A projector image lighting region (I, J) of a 2x2 split, mapped back onto the lit face,
// matches the ideal region light of solver/light.h (up to the projector's pixels at the edges).
TEST(FaceMapping, RegionPatternRoundTrip) {
  for (translume::Setup setup : {Setup::kBack, Setup::kFront}) {
    const CaptureRig rig = DefaultCaptureRig(kGrid, kH, setup);
    const double X = double(kGrid.nx - 1) * kH, Y = double(kGrid.ny - 1) * kH;
    std::vector<FacePattern> got, want;
    for (int m = 0; m < 4; ++m) {
      const int I = m % 2, J = m / 2;
      const cv::Mat p8 = PatternForFaceRect(rig.projector, rig.projector_from_camera, rig.camera_from_sample,
                                            kGrid, kH, setup, {I * X / 2, (I + 1) * X / 2, J * Y / 2, (J + 1) * Y / 2});
      cv::Mat p;
      p8.convertTo(p, CV_32F, 1.0 / 255);
      got.push_back(GreyPattern(ProjectPatternOnFace(p, rig.projector, rig.projector_from_camera,
                                                     rig.camera_from_sample, kGrid, kH, setup, 8)));
      want.push_back(GreyPattern(RasterizeLight(LightSpec::Parse(fmt::format("region:{},{}/2", I, J)), kGrid, kH)));
    }
    const double rms = std::sqrt(RelightingError(got, want));
    std::printf("%s-lit: region pattern q vs ideal region light: relative RMS %.3f %%\n", SetupName(setup), 100 * rms);
    EXPECT_LT(rms, 0.02);
    // RegionPatterns makes all four at once, the same images.
    const std::vector<cv::Mat> all = RegionPatterns(rig.projector, rig.projector_from_camera, rig.camera_from_sample,
                                                    SampleSize(kGrid, kH), setup, 2);
    ASSERT_EQ(all.size(), 4u);
    for (int m = 0; m < 4; ++m) {
      const int I = m % 2, J = m / 2;
      const cv::Mat one = PatternForFaceRect(rig.projector, rig.projector_from_camera, rig.camera_from_sample, kGrid,
                                             kH, setup, {I * X / 2, (I + 1) * X / 2, J * Y / 2, (J + 1) * Y / 2});
      EXPECT_EQ(cv::countNonZero(one != all[size_t(m)]), 0) << "region " << m;
      EXPECT_GT(cv::countNonZero(one), 1000) << "region " << m;
    }
  }
}

// An anchor independent of face_mapping.cc's own lit-face geometry (which the round trip above
// shares on both sides): a point of the lit face (z = Z back-lit, z = 0 front-lit: SPEC's
// sample frame), taken through camera_from_sample, projector_from_camera and the projector's
// model by hand, lands on a lit pixel of the pattern for a rectangle when it lies just inside
// the rectangle (half a node) and on a dark one just outside, at each of the four edges. A
// mirrored face parametrisation, swapped axes or the wrong face's depth would move it.
TEST(FaceMapping, PatternLightsTheRectangleWhereTheRigModelSays) {
  for (translume::Setup setup : {Setup::kBack, Setup::kFront}) {
    SCOPED_TRACE(SetupName(setup));
    const CaptureRig rig = DefaultCaptureRig(kGrid, kH, setup);
    const double X = double(kGrid.nx - 1) * kH, Y = double(kGrid.ny - 1) * kH;
    const double z = setup == Setup::kBack ? double(kGrid.nz - 1) * kH : 0.0;
    const std::array<double, 4> rect{0.25 * X, 0.6 * X, 0.3 * Y, 0.7 * Y};  // x0, x1, y0, y1
    const cv::Mat pattern = PatternForFaceRect(rig.projector, rig.projector_from_camera, rig.camera_from_sample,
                                               kGrid, kH, setup, rect);
    auto pixel = [&](double x, double y) {
      const cv::Vec3d p = rig.projector_from_camera.Apply(rig.camera_from_sample.Apply({x, y, z}));
      const cv::Point2d uv = rig.projector.Project({cv::Point3d(p[0], p[1], p[2])})[0];
      return int(pattern.at<uint8_t>(int(std::lround(uv.y)), int(std::lround(uv.x))));
    };
    const double d = kH / 2, xm = (rect[0] + rect[1]) / 2, ym = (rect[2] + rect[3]) / 2;
    EXPECT_EQ(pixel(xm, ym), 255);
    EXPECT_EQ(pixel(rect[0] + d, ym), 255);
    EXPECT_EQ(pixel(rect[0] - d, ym), 0);
    EXPECT_EQ(pixel(rect[1] - d, ym), 255);
    EXPECT_EQ(pixel(rect[1] + d, ym), 0);
    EXPECT_EQ(pixel(xm, rect[2] + d), 255);
    EXPECT_EQ(pixel(xm, rect[2] - d), 0);
    EXPECT_EQ(pixel(xm, rect[3] - d), 255);
    EXPECT_EQ(pixel(xm, rect[3] + d), 0);
  }
}

TEST(FaceMapping, ResamplingAveragesAndFlagsSaturation) {
  const CaptureRig rig = DefaultCaptureRig(kGrid, kH, Setup::kBack);
  cv::Mat img(rig.camera.size, CV_32FC3, cv::Scalar(0.25, 0.5, 0.75));
  FaceSamples s = ResampleFrontFace(img, rig.camera, rig.camera_from_sample, kGrid, kH);
  for (int64_t f = 0; f < kGrid.face_size(); ++f) {
    EXPECT_FLOAT_EQ(s.value[0][size_t(f)], 0.25f);
    EXPECT_FLOAT_EQ(s.value[2][size_t(f)], 0.75f);
    EXPECT_EQ(s.saturated[size_t(f)], 0.0f);
  }
  // A saturated pixel under node (5, 4): that node (and at most its neighbours) is flagged.
  std::vector<cv::Point3d> node{{5 * kH, 4 * kH, 0}};
  const cv::Vec3d x = rig.camera_from_sample.Apply({node[0].x, node[0].y, 0});
  const cv::Point2d px = rig.camera.Project({cv::Point3d(x[0], x[1], x[2])})[0];
  img.at<cv::Vec3f>(int(std::lround(px.y)), int(std::lround(px.x)))[1] = std::numeric_limits<float>::infinity();
  s = ResampleFrontFace(img, rig.camera, rig.camera_from_sample, kGrid, kH);
  EXPECT_GT(s.saturated[size_t(5 + kGrid.nx * 4)], 0.0f);
  int flagged = 0;
  for (float v : s.saturated) flagged += v > 0;
  EXPECT_LE(flagged, 4);
}

// The face's coverage is 1 inside its outline and 0 outside, and sums to its area in pixels;
// a uniformly bright face photographed through it (the image the simulator renders) reads back
// its radiance at every node, border nodes included, where the plain mean loses the light of the
// pixels across the outline.
TEST(FaceMapping, OutlineCoverageGivesTheBorderNodesTheirLightBack) {
  const CaptureRig rig = DefaultCaptureRig(kGrid, kH, Setup::kBack);
  const cv::Mat cov = FaceCoverage(rig.camera, rig.camera_from_sample, kGrid, kH);
  ASSERT_EQ(cov.size(), rig.camera.size);
  std::vector<cv::Point3d> outline;
  const auto size = SampleSize(kGrid, kH);
  for (int k = 0; k < 400; ++k) {  // counter-clockwise around the face, finely (distortion)
    const double t = (k % 100) / 100.0;
    const int side = k / 100;
    outline.emplace_back(side == 0 ? t * size[0] : side == 1 ? size[0] : side == 2 ? (1 - t) * size[0] : 0,
                         side == 0 ? 0 : side == 1 ? t * size[1] : side == 2 ? size[1] : (1 - t) * size[1], 0);
  }
  std::vector<cv::Point3d> cam;
  for (const auto& p : outline) {
    const cv::Vec3d x = rig.camera_from_sample.Apply({p.x, p.y, p.z});
    cam.emplace_back(x[0], x[1], x[2]);
  }
  const auto px = rig.camera.Project(cam);
  const std::vector<cv::Point2f> poly(px.begin(), px.end());
  EXPECT_NEAR(cv::sum(cov)[0], cv::contourArea(poly), 1e-3 * cv::contourArea(poly));
  const cv::Point2d centre = (px[50] + px[250]) * 0.5;
  EXPECT_EQ(cov.at<float>(int(centre.y), int(centre.x)), 1.0f);
  EXPECT_EQ(cov.at<float>(0, 0), 0.0f);

  cv::Mat img;
  cv::merge(std::vector<cv::Mat>{0.25 * cov, 0.5 * cov, 0.75 * cov}, img);
  const FaceSamples with = ResampleFrontFace(img, rig.camera, rig.camera_from_sample, kGrid, kH, 6, &cov);
  const FaceSamples plain = ResampleFrontFace(img, rig.camera, rig.camera_from_sample, kGrid, kH);
  float least_border = 1;
  for (int64_t f = 0; f < kGrid.face_size(); ++f) {
    EXPECT_NEAR(with.value[1][size_t(f)], 0.5f, 1e-5f) << f;
    const int64_t i = f % kGrid.nx, j = f / kGrid.nx;
    const bool border = i == 0 || j == 0 || i == kGrid.nx - 1 || j == kGrid.ny - 1;
    if (border) least_border = std::min(least_border, plain.value[1][size_t(f)]);
    else EXPECT_NEAR(plain.value[1][size_t(f)], 0.5f, 1e-5f) << f;
  }
  EXPECT_LT(least_border, 0.49f);  // the plain mean of a border node loses light (measured 0.483: 3.4 %)
}

// The lens's blur in the coverage: blurring keeps the face's light (the image's sum), and a
// uniformly bright face seen through the blur reads back exactly, border nodes included.
TEST(FaceMapping, BlurredCoverageGivesABlurredFaceItsLightBack) {
  const CaptureRig rig = DefaultCaptureRig(kGrid, kH, Setup::kBack);
  const cv::Mat sharp = FaceCoverage(rig.camera, rig.camera_from_sample, kGrid, kH);
  const cv::Mat blurred = FaceCoverage(rig.camera, rig.camera_from_sample, kGrid, kH, 1.2);
  EXPECT_NEAR(cv::sum(blurred)[0], cv::sum(sharp)[0], 1e-4 * cv::sum(sharp)[0]);
  cv::Mat lens;  // the photo: the sharp face through a Gaussian lens
  cv::GaussianBlur(sharp, lens, cv::Size(0, 0), 1.2, 1.2, cv::BORDER_CONSTANT);
  cv::Mat img;
  cv::merge(std::vector<cv::Mat>{0.25 * lens, 0.5 * lens, 0.75 * lens}, img);
  const FaceSamples with = ResampleFrontFace(img, rig.camera, rig.camera_from_sample, kGrid, kH, 6, &blurred);
  const FaceSamples sharp_only = ResampleFrontFace(img, rig.camera, rig.camera_from_sample, kGrid, kH, 6, &sharp);
  float least = 1;
  for (int64_t f = 0; f < kGrid.face_size(); ++f) {
    EXPECT_NEAR(with.value[1][size_t(f)], 0.5f, 1e-5f) << f;
    least = std::min(least, sharp_only.value[1][size_t(f)]);
  }
  EXPECT_LT(least, 0.48f);  // the sharp coverage leaves the blur's loss at the border
}

// The lens's blur read off the face's outline: a face whose radiance varies (not linearly) and
// a dim surround, photographed through Gaussian lenses of known sigma with 0.5 % noise, the
// pixels integrated more finely than the coverage does (16 x 16 samples).
TEST(FaceMapping, OutlineBlurRecoversTheLensSigma) {
  const CaptureRig rig = DefaultCaptureRig(kGrid, kH, Setup::kBack);
  const cv::Mat fine = FaceCoverage(rig.camera, rig.camera_from_sample, kGrid, kH, 0, 16);
  cv::Mat radiance(fine.size(), CV_32FC1);
  for (int y = 0; y < radiance.rows; ++y)
    for (int x = 0; x < radiance.cols; ++x)
      radiance.at<float>(y, x) = float(1 + 0.4 * std::sin(x / 37.0) * std::cos(y / 53.0) + 0.3 * std::exp(-x / 90.0));
  std::mt19937 rng(7);
  std::normal_distribution<float> noise(0, 0.005f);
  for (double sigma : {0.0, 0.4, 0.8, 1.5, 2.2}) {
    cv::Mat photo = fine.mul(radiance);
    if (sigma > 0) cv::GaussianBlur(photo, photo, cv::Size(0, 0), sigma, sigma, cv::BORDER_CONSTANT);
    photo += 0.02;
    for (auto it = photo.begin<float>(); it != photo.end<float>(); ++it) *it += noise(rng);
    cv::Mat rgb;
    cv::merge(std::vector<cv::Mat>{photo, 1.5 * photo, 0.5 * photo}, rgb);
    const OutlineBlur b = EstimateOutlineBlur({rgb}, rig.camera, rig.camera_from_sample, kGrid, kH);
    std::printf("lens sigma %.2f px: found %.3f px from %d profiles, rms %.4f (sharp %.4f)\n", sigma, b.sigma_px,
                b.profiles, b.rms, b.rms_sharp);
    EXPECT_GT(b.profiles, 200);
    // A sharp lens reads as 0.28 px: a Gaussian narrower than ~0.3 px weights a pixel's
    // neighbours by less than 0.2 %, and the pixel grid cannot tell it from none.
    EXPECT_NEAR(b.sigma_px, sigma, sigma > 0 ? 0.05 : 0.3);
    if (sigma > 0.5) {
      EXPECT_LT(b.rms, 0.5 * b.rms_sharp);
    }
  }
  // Saturated (+inf) photos leave nothing to fit, and say so.
  const cv::Mat saturated(rig.camera.size, CV_32FC3, cv::Scalar::all(std::numeric_limits<float>::infinity()));
  const OutlineBlur none = EstimateOutlineBlur({saturated}, rig.camera, rig.camera_from_sample, kGrid, kH);
  EXPECT_EQ(none.profiles, 0);
  EXPECT_GT(none.positions, 200);
  // A face a few pixels wide leaves no room for a profile: no positions, which acquire tells
  // apart from a saturated outline.
  CaptureRig far = rig;
  far.camera_from_sample.t *= 40.0;
  const cv::Mat dot = FaceCoverage(far.camera, far.camera_from_sample, kGrid, kH);
  cv::Mat dot_rgb;
  cv::merge(std::vector<cv::Mat>{dot, dot, dot}, dot_rgb);
  const OutlineBlur small = EstimateOutlineBlur({dot_rgb}, far.camera, far.camera_from_sample, kGrid, kH);
  EXPECT_EQ(small.positions, 0);
  EXPECT_EQ(small.profiles, 0);
  EXPECT_EQ(small.sigma_px, 0);
}

}  // namespace
}  // namespace translume::acquire
