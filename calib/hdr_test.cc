// SPDX-License-Identifier: MIT
#include "calib/hdr.h"

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <OpenImageIO/imageio.h>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/photo.hpp>
#include <random>

#include "calib/error.h"
#include "calib/synthetic_rig.h"
#include "calib/test_util.h"

namespace translume::calib {
namespace {

namespace fs = std::filesystem;

// A radiance image spanning 4 decades (1e-4 .. 1 per second) and a 20x20 block far too bright
// for every exposure (top-left).
cv::Mat TestScene(uint64_t seed) {
  cv::Mat E = SyntheticHdrScene({240, 160}, 4, seed);
  E(cv::Rect(0, 0, 20, 20)).setTo(cv::Scalar(50, 50, 50));
  return E;
}

// n exposure times from `first` seconds, each `ratio` times the one before.
std::vector<double> GeometricTimes(double first, double ratio, int n) {
  std::vector<double> t;
  for (int j = 0; j < n; ++j) t.push_back(first * std::pow(ratio, j));
  return t;
}

std::vector<double> NineTimes() { return GeometricTimes(0.9, 2.5, 9); }  // 1.3 stops apart

ExposureStack MakeStack(const std::vector<cv::Mat>& images, const std::vector<double>& t) {
  ExposureStack s;
  s.dir = "synthetic";
  for (size_t j = 0; j < images.size(); ++j)
    s.exposures.push_back({fmt::format("e{}.png", j), images[j], t[j]});
  return s;
}

struct ErrorStats {
  double median = 0, p95 = 0;
  cv::Vec3d scale;
};

// Relative errors after one scale per channel (the median ratio) over finite, unflagged pixels
// outside the saturated block (truth above `brightest`).
ErrorStats Errors(const cv::Mat& truth, const HdrImage& h, bool one_scale_for_all, float brightest = 1.0f) {
  std::vector<double> ratio[3];
  for (int y = 0; y < truth.rows; ++y)
    for (int x = 0; x < truth.cols; ++x)
      for (int c = 0; c < 3; ++c) {
        const float t = truth.at<cv::Vec3f>(y, x)[c];
        if (t > brightest) continue;
        ratio[c].push_back(h.radiance.at<cv::Vec3f>(y, x)[c] / t);
      }
  ErrorStats s;
  std::vector<double> all;
  for (int c = 0; c < 3; ++c) {
    std::vector<double> r = ratio[c];
    std::nth_element(r.begin(), r.begin() + long(r.size() / 2), r.end());
    s.scale[c] = r[r.size() / 2];
    all.insert(all.end(), ratio[c].begin(), ratio[c].end());
  }
  if (one_scale_for_all) {
    std::vector<double> r = all;
    std::nth_element(r.begin(), r.begin() + long(r.size() / 2), r.end());
    s.scale = cv::Vec3d::all(r[r.size() / 2]);
  }
  std::vector<double> err;
  for (int c = 0; c < 3; ++c)
    for (double r : ratio[c]) err.push_back(std::abs(r / s.scale[c] - 1));
  std::sort(err.begin(), err.end());
  s.median = err[err.size() / 2];
  s.p95 = err[size_t(0.95 * (err.size() - 1))];
  return s;
}

// The recovered curve against the true inverse response of channel c (up to scale: both
// normalised at code 128), worst relative error over codes 8..245.
double WorstResponseError(const ResponseCurve& curve, const SyntheticResponse& f, int c) {
  auto inv = [&](double code) {  // true linear value of an 8-bit code, by bisection
    double lo = 0, hi = 1;
    for (int i = 0; i < 60; ++i) ((255 * f.Apply((lo + hi) / 2, c) < code) ? lo : hi) = (lo + hi) / 2;
    return (lo + hi) / 2;
  };
  const double ref = curve.lut.at<cv::Vec3f>(128)[c];
  double worst = 0;
  for (int z = 8; z <= 245; ++z)
    worst = std::max(worst, std::abs(curve.lut.at<cv::Vec3f>(z)[c] / ref * inv(128) / inv(z) - 1));
  return worst;
}

void ExpectSaturatedBlockFlagged(const HdrImage& h) {
  for (int y = 0; y < 20; ++y)
    for (int x = 0; x < 20; ++x)
      for (int c = 0; c < 3; ++c) {
        EXPECT_EQ(h.flags.at<cv::Vec3b>(y, x)[c], kHdrSaturated);
        EXPECT_TRUE(std::isinf(h.radiance.at<cv::Vec3f>(y, x)[c]));
      }
  EXPECT_EQ(h.saturated, 20u * 20u * 3u);
}

TEST(Hdr, EightBitResponseAndMergeMeetTargets) {
  const SyntheticResponse f;
  const auto t = NineTimes();
  StackOptions so;
  so.seed = 3;
  const ExposureStack calib = MakeStack(SyntheticRig::RenderExposureStack(TestScene(11), t, f, so), t);
  const ResponseCurve curve = CalibrateResponse({calib});
  ASSERT_EQ(curve.Validate(), "");
  for (int c = 0; c < 3; ++c) {
    const double worst = WorstResponseError(curve, f, c);
    std::printf("channel %d: worst response error over codes 8..245: %.3f%%\n", c, 100 * worst);
    EXPECT_LT(worst, 0.04);
  }
  so.seed = 4;
  const cv::Mat truth = TestScene(12);
  const ExposureStack stack = MakeStack(SyntheticRig::RenderExposureStack(truth, t, f, so), t);
  const HdrImage h = MergeHdr(stack, &curve);
  std::printf("%s\n", h.BriefReport().c_str());
  const ErrorStats e = Errors(truth, h, false);
  std::printf("8-bit: median error %.3f%%, 95th percentile %.3f%% over 4 decades\n",
              100 * e.median, 100 * e.p95);
  EXPECT_LE(e.median, 0.015);
  EXPECT_LE(e.p95, 0.04);
  ExpectSaturatedBlockFlagged(h);
  EXPECT_EQ(h.time_warning, "");
  // One time labelled 6 % short, as a camera labels 0.133 s "1/8": merged with a warning that
  // names the pair (a capture labelled so mapped 9.6 % RMS off, silently).
  ExposureStack labelled = stack;
  labelled.exposures[3].seconds *= 0.94;
  const std::string warning = MergeHdr(labelled, &curve).time_warning;
  EXPECT_NE(warning.find("synthetic: e3.png is"), std::string::npos) << warning;
  EXPECT_NE(warning.find("as bright as e2.png, but its exposure time is"), std::string::npos) << warning;
  EXPECT_NE(warning.find("is 2.350x as long (+6."), std::string::npos) << warning;  // 2.5 / 2.35
  MergeOptions sensor_black;
  sensor_black.sensor_black = cv::Vec3d(0.01, 0, 0);
  EXPECT_EQ(CalibErrorOf([&] { MergeHdr(stack, &curve, nullptr, sensor_black); }),
            "synthetic: a sensor black level applies to linear photos (16-bit, float); an 8-bit camera's response "
            "curve holds its black level");
  // OpenCV's stock MergeDebevec with the same curve, for comparison (SPEC section 8): its
  // weights do not exclude clipped samples.
  std::vector<cv::Mat> images;
  for (const Exposure& x : stack.exposures) images.push_back(x.pixels);
  cv::Mat ocv;
  cv::createMergeDebevec()->process(images, ocv, std::vector<float>(t.begin(), t.end()), curve.lut);
  HdrImage o;
  o.radiance = ocv;
  const ErrorStats eo = Errors(truth, o, false);
  std::printf("OpenCV MergeDebevec: median error %.3f%%, 95th percentile %.3f%%\n", 100 * eo.median,
              100 * eo.p95);
  EXPECT_GT(eo.p95, 2 * e.p95);
}

TEST(Hdr, ResponseFromTwoStacksWithDifferentTimes) {
  const SyntheticResponse f;
  const auto t = NineTimes();
  const std::vector<double> t2{0.5, 2.0, 8.0, 32.0, 128.0};
  StackOptions so;
  so.seed = 8;
  const ExposureStack a = MakeStack(SyntheticRig::RenderExposureStack(TestScene(21), t, f, so), t);
  so.seed = 9;
  const ExposureStack b = MakeStack(SyntheticRig::RenderExposureStack(TestScene(22), t2, f, so), t2);
  const ResponseCurve two = CalibrateResponse({a, b});
  for (int c = 0; c < 3; ++c) EXPECT_LT(WorstResponseError(two, f, c), 0.04) << "channel " << c;
  EXPECT_THROW(CalibrateResponse({a, ExposureStack{"one", {a.exposures[0]}}}), CalibError);
  // 16-bit photos need no response: the message says so, and how capture.json says it (it
  // said "expected 8-bit RGB of the stack's size with a positive time").
  ExposureStack deep = a;
  for (Exposure& e : deep.exposures) e.pixels.convertTo(e.pixels, CV_16UC3, 257);
  EXPECT_NE(CalibErrorOf([&] { CalibrateResponse({deep}); }).find("16-bit and RAW photos are linear and need none "
                                                                  "(in capture.json: \"response\": \"linear\")"),
            std::string::npos);
}

// A camera set to 1/15 s exposes 1/16 s and writes "1/15" into EXIF; the labels below are a
// one-stop bracket whose ends (1/15 and 15) are 6.7 % short of the APEX times.
std::vector<double> LabelledBracket() { return {1 / 15., 1 / 8., 1 / 4., 1 / 2., 1, 2, 4, 8, 15}; }

// TestScene brightened 10x (1e-3 .. 10 per second, the block 500) for the bracket's span.
cv::Mat BrightScene(uint64_t seed) { return TestScene(seed) * 10; }

std::vector<double> ApexTimes(const std::vector<double>& labels) {
  std::vector<double> t;
  for (double l : labels) t.push_back(ApexSeconds(l));
  return t;
}

TEST(Shutter, ApexSecondsOfCameraLabels) {
  EXPECT_DOUBLE_EQ(ApexSeconds(1 / 30.), 1 / 32.);
  EXPECT_DOUBLE_EQ(ApexSeconds(0.0333), 1 / 32.);  // written with 3 digits
  EXPECT_DOUBLE_EQ(ApexSeconds(1 / 125.), 1 / 128.);
  EXPECT_DOUBLE_EQ(ApexSeconds(15), 16);
  EXPECT_DOUBLE_EQ(ApexSeconds(30), 32);
  EXPECT_DOUBLE_EQ(ApexSeconds(1 / 8.), 1 / 8.);
  EXPECT_NEAR(ApexSeconds(1 / 10.), std::exp2(-10 / 3.), 1e-15);
  EXPECT_NEAR(ApexSeconds(0.3), std::exp2(-5 / 3.), 1e-15);
  EXPECT_NEAR(ApexSeconds(1 / 45.), std::exp2(-5.5), 1e-15);  // half stops
  EXPECT_NEAR(ApexSeconds(1 / 6000.), std::exp2(-12.5), 1e-15);
  for (double t : {1 / 32., 0.0417, 0.9, 2.25, 7.0, 1e-5, 100.0}) EXPECT_EQ(ApexSeconds(t), t);
  EXPECT_EQ(ShutterLabel(1 / 32.), 1 / 30.);
  EXPECT_EQ(ShutterLabel(16), 15);
  EXPECT_EQ(ShutterLabel(std::exp2(-10 / 3.)), 1 / 10.);
  EXPECT_EQ(ShutterLabel(0.0417), 0.0417);
  EXPECT_EQ(ParseShutterTimes("apex", "x"), ShutterTimes::kApex);
  EXPECT_EQ(CalibErrorOf([] { ParseShutterTimes("APEX?", "capture.json"); }),
            "capture.json: exposure times must be \"auto\", \"labelled\" or \"apex\", not \"APEX?\"");
  ExposureStack s{"s", {{"a", cv::Mat(), 1 / 8.}, {"b", cv::Mat(), 1 / 4.}}};
  EXPECT_FALSE(HasApexLabels(s));
  s.exposures[1].seconds = 1 / 15.;
  EXPECT_TRUE(HasApexLabels(s));
  EXPECT_EQ(WithShutterTimes(s, ShutterTimes::kApex).exposures[1].seconds, 1 / 16.);
  EXPECT_EQ(WithShutterTimes(s, ShutterTimes::kLabelled).exposures[1].seconds, 1 / 15.);
}

// 8-bit: the response fit reads the labels as APEX times where that fits the photos better, and
// the merge follows the curve. A camera that exposes exactly what it labels keeps its labels.
TEST(Hdr, EightBitShutterLabelsReadAsApexTimes) {
  const SyntheticResponse f;
  const std::vector<double> labels = LabelledBracket(), apex = ApexTimes(labels);
  StackOptions so;
  so.seed = 41;
  const ExposureStack calib = MakeStack(SyntheticRig::RenderExposureStack(BrightScene(41), apex, f, so), labels);
  const ResponseCurve curve = CalibrateResponse({calib});
  std::printf("%s\n", curve.ShutterReport().c_str());
  EXPECT_EQ(curve.shutter, ShutterTimes::kApex);
  EXPECT_GT(curve.other_fit_rms, 1.05 * curve.fit_rms);  // 2.81 % against 2.55 %
  ResponseOptions as_labelled;
  as_labelled.shutter = ShutterTimes::kLabelled;
  const ResponseCurve labelled_curve = CalibrateResponse({calib}, as_labelled);
  EXPECT_EQ(labelled_curve.shutter, ShutterTimes::kLabelled);
  so.seed = 42;
  const cv::Mat truth = BrightScene(43);
  const ExposureStack stack = MakeStack(SyntheticRig::RenderExposureStack(truth, apex, f, so), labels);
  const HdrImage h = MergeHdr(stack, &curve);
  EXPECT_EQ(h.shutter, ShutterTimes::kApex);
  EXPECT_EQ(h.time_warning, "");
  const ErrorStats e = Errors(truth, h, false, 10), el = Errors(truth, MergeHdr(stack, &labelled_curve), false, 10);
  std::printf("8-bit, labels read as APEX: median %.3f%%, p95 %.3f%%; as labelled: median %.3f%%, p95 %.3f%%\n",
              100 * e.median, 100 * e.p95, 100 * el.median, 100 * el.p95);
  // The dark end (1e-3 per second, codes near 10 in the longest exposure) sets the 95th
  // percentile; as labelled, the error is twice as large.
  EXPECT_LE(e.median, 0.015);
  EXPECT_LE(e.p95, 0.06);
  EXPECT_GT(el.median, 2 * e.median);
  EXPECT_GT(el.p95, 1.5 * e.p95);
  // A camera exposing exactly 1/15 s etc.
  const ExposureStack exact = MakeStack(SyntheticRig::RenderExposureStack(BrightScene(41), labels, f, so), labels);
  const ResponseCurve exact_curve = CalibrateResponse({exact});
  std::printf("exact labels: %s\n", exact_curve.ShutterReport().c_str());
  EXPECT_EQ(exact_curve.shutter, ShutterTimes::kLabelled);
}

// Linear stacks: each stack's brightness steps decide.
TEST(Hdr, LinearShutterLabelsReadAsApexTimes) {
  const std::vector<double> labels = LabelledBracket(), apex = ApexTimes(labels);
  StackOptions so;
  so.bits = 16;
  so.seed = 44;
  const cv::Mat truth = BrightScene(44);
  const ExposureStack stack = MakeStack(SyntheticRig::RenderExposureStack(truth, apex, {}, so), labels);
  const ShutterChoice choice = ChooseShutterTimes(stack);
  std::printf("%s\n", choice.BriefReport().c_str());
  EXPECT_EQ(choice.times, ShutterTimes::kApex);
  EXPECT_LT(choice.apex_rms, 0.005);
  EXPECT_GT(choice.labelled_rms, 0.02);
  const HdrImage h = MergeHdr(stack, nullptr);
  EXPECT_EQ(h.shutter, ShutterTimes::kApex);
  EXPECT_EQ(h.time_warning, "");
  MergeOptions as_labelled;
  as_labelled.shutter = ShutterTimes::kLabelled;
  const HdrImage hl = MergeHdr(stack, nullptr, nullptr, as_labelled);
  EXPECT_NE(hl.time_warning, "");
  const ErrorStats e = Errors(truth, h, true, 10), el = Errors(truth, hl, true, 10);
  std::printf("16-bit, labels read as APEX: scale %.4f, median %.3f%%, p95 %.3f%%; as labelled: scale %.4f, "
              "median %.3f%%, p95 %.3f%%\n", e.scale[0], 100 * e.median, 100 * e.p95, el.scale[0], 100 * el.median,
              100 * el.p95);
  EXPECT_NEAR(e.scale[0], 1.0, 0.005);
  EXPECT_LE(e.median, 0.015);
  EXPECT_LE(e.p95, 0.06);  // read noise at the dark end
  EXPECT_GT(el.median, 2 * e.median);
  EXPECT_GT(el.p95, 1.5 * e.p95);
  // A grey card lies well inside the valid range in a few exposures only: the pairs that tell
  // the readings apart (1/15 -> 1/8, 8 -> 15) are judged in another stack of the capture.
  const cv::Mat card(40, 60, CV_32FC3, cv::Scalar::all(0.2));
  const ExposureStack grey = MakeStack(SyntheticRig::RenderExposureStack(card, apex, {}, so), labels);
  ShutterJudge judge;
  judge.Add(grey);
  EXPECT_FALSE(judge.Decisive());
  EXPECT_EQ(judge.Choice().times, ShutterTimes::kLabelled);  // not judged: as given
  EXPECT_FALSE(judge.Choice().decisive);
  EXPECT_NE(judge.Choice().BriefReport().find("no well-exposed pair of photos tells the labels from APEX times"),
            std::string::npos) << judge.Choice().BriefReport();
  judge.Add(stack);
  EXPECT_TRUE(judge.Decisive());
  EXPECT_EQ(judge.Choice().times, ShutterTimes::kApex);
  // A black level left in the photos (2 % of full scale, no black stack) lowers every step alike
  // (by about 5 %); the steps' mean is removed before the readings are compared.
  so.offset = 0.02;
  const ExposureStack pedestal = MakeStack(SyntheticRig::RenderExposureStack(truth, apex, {}, so), labels);
  const ShutterChoice pc = ChooseShutterTimes(pedestal);
  std::printf("black level 2 %%: %s\n", pc.BriefReport().c_str());
  EXPECT_EQ(pc.times, ShutterTimes::kApex);
  EXPECT_LT(pc.step_bias, -0.01);
  EXPECT_NE(pc.BriefReport().find("a black level left in the photos? Give it (sensor black) or a black stack"),
            std::string::npos);
  EXPECT_NE(MergeHdr(pedestal, nullptr).time_warning.find("; or a black level left in the photos (give it as the "
                                                          "sensor black, or a black stack)"), std::string::npos)
      << MergeHdr(pedestal, nullptr).time_warning;
  // Given as the sensor black level, it is removed before anything is judged or merged: the
  // steps are even again, no warning, and the radiance is as accurate as with no black level.
  MergeOptions with_black;
  with_black.sensor_black = cv::Vec3d::all(0.02);
  const ShutterChoice wc = ChooseShutterTimes(pedestal, nullptr, with_black);
  EXPECT_EQ(wc.times, ShutterTimes::kApex);
  EXPECT_LT(std::abs(wc.step_bias), 0.003) << wc.BriefReport();
  EXPECT_EQ(wc.BriefReport().find("black level"), std::string::npos) << wc.BriefReport();
  const HdrImage hb = MergeHdr(pedestal, nullptr, nullptr, with_black), hp = MergeHdr(pedestal, nullptr);
  EXPECT_EQ(hb.time_warning, "");
  const ErrorStats eb = Errors(truth, hb, true, 10), ep = Errors(truth, hp, true, 10);
  std::printf("black level 2 %% given as sensor_black: scale %.4f, median %.3f%%, p95 %.3f%%; not given: scale %.4f, "
              "median %.3f%%, p95 %.3f%%\n", eb.scale[0], 100 * eb.median, 100 * eb.p95, ep.scale[0],
              100 * ep.median, 100 * ep.p95);
  EXPECT_NEAR(eb.scale[0], 1.0, 0.005);
  EXPECT_LE(eb.median, 0.015);
  EXPECT_LE(eb.p95, 0.06);
  EXPECT_GT(ep.p95, 2 * eb.p95);
  // With a black stack that carries the same black level, the two cancel (no double subtraction).
  const ExposureStack black_frames = MakeStack(
      SyntheticRig::RenderExposureStack(cv::Mat::zeros(truth.size(), CV_32FC3), apex, {}, so), labels);
  const HdrImage hs = MergeHdr(pedestal, nullptr, &black_frames, with_black);
  const ErrorStats es = Errors(truth, hs, true, 10);
  EXPECT_NEAR(es.scale[0], 1.0, 0.005);
  EXPECT_LE(es.median, 0.015);
  // An HDR image is merged already: its black level cannot be taken off again.
  const std::string exr = (fs::temp_directory_path() / "translume_hdr_test_sensor_black.exr").string();
  WriteExr(exr, hb.radiance);
  EXPECT_NE(CalibErrorOf([&] { ReadHdrOrStack(exr, nullptr, with_black); }).find(": an HDR image is merged already"),
            std::string::npos);
  fs::remove(exr);
  with_black.sensor_black[1] = 0.5;
  EXPECT_NE(CalibErrorOf([&] { MergeHdr(pedestal, nullptr, nullptr, with_black); })
                .find("sensor_black 0.02,0.5,0.02: expected fractions of full scale in [0, 0.5)"), std::string::npos);
  so.offset = 0;
  so.seed = 45;
  const ExposureStack exact = MakeStack(SyntheticRig::RenderExposureStack(truth, labels, {}, so), labels);
  EXPECT_EQ(ChooseShutterTimes(exact).times, ShutterTimes::kLabelled);
  EXPECT_EQ(MergeHdr(exact, nullptr).shutter, ShutterTimes::kLabelled);
  // A black stack without the shortest time: the message quotes the time as labelled (it quoted
  // 0.0625, the APEX time read for 1/15, which appears in no file).
  const ExposureStack black = MakeStack(
      std::vector<cv::Mat>(labels.size() - 1, cv::Mat::zeros(truth.size(), CV_16UC3)),
      std::vector<double>(labels.begin() + 1, labels.end()));
  EXPECT_NE(CalibErrorOf([&] { MergeHdr(stack, nullptr, &black); }).find("has no photo at 0.0666667 s"),
            std::string::npos) << CalibErrorOf([&] { MergeHdr(stack, nullptr, &black); });
  // Forced the wrong way, the warning says which way the times were read.
  MergeOptions as_apex;
  as_apex.shutter = ShutterTimes::kApex;
  EXPECT_NE(MergeHdr(exact, nullptr, nullptr, as_apex).time_warning.find("read as APEX shutter speeds: are they true "
                                                                         "times? Then read them as labelled"),
            std::string::npos);
  EXPECT_NE(hl.time_warning.find("times as a camera labels them (1/30 for 1/32 s)?"), std::string::npos) << hl.time_warning;
  EXPECT_NE(CalibErrorOf([&] { ChooseShutterTimes(MakeStack(SyntheticRig::RenderExposureStack(truth, apex,
                                                                  SyntheticResponse(), {}), labels)); })
                .find("judged by the response fit"), std::string::npos);
}

// Six copies of one photo with different exposure times fitted a curve that falls within the
// codes the photos cover, and it was written as a calibration.
TEST(Hdr, ResponseFromPhotosThatDoNotBrightenIsRefused) {
  const SyntheticResponse f;
  const auto t = NineTimes();
  const auto images = SyntheticRig::RenderExposureStack(TestScene(31), t, f);
  const ExposureStack copies = MakeStack(std::vector<cv::Mat>(6, images[4]), {t.begin(), t.begin() + 6});
  EXPECT_NE(CalibErrorOf([&] { CalibrateResponse({copies}); })
                .find("the photos of synthetic do not brighten with their exposure times"), std::string::npos);
}

// Two exposure times swapped (in exposures.json, say) gave radiance 3.5x off without a word:
// exposures next in time must brighten by their times' ratio within 2x.
TEST(Hdr, MergeRefusesTimesThatContradictThePhotos) {
  auto t = NineTimes();
  StackOptions so;
  so.bits = 16;
  so.seed = 15;
  const auto images = SyntheticRig::RenderExposureStack(TestScene(14), t, {}, so);
  EXPECT_NO_THROW(MergeHdr(MakeStack(images, t), nullptr));
  std::swap(t[3], t[4]);
  const std::string e = CalibErrorOf([&] { MergeHdr(MakeStack(images, t), nullptr); });
  EXPECT_EQ(e.find("synthetic: e4.png ("), 0u) << e;
  EXPECT_NE(e.find("x as bright as e2.png ("), std::string::npos) << e;  // ~6.25x
  EXPECT_NE(e.find("but its exposure time is 2.50x as long"), std::string::npos) << e;
  // 8-bit photos through a response curve, as acquire merges them.
  const SyntheticResponse f;
  t = NineTimes();
  const auto eight = SyntheticRig::RenderExposureStack(TestScene(16), t, f, {});
  const ResponseCurve curve = CalibrateResponse({MakeStack(eight, t)});
  EXPECT_NO_THROW(MergeHdr(MakeStack(eight, t), &curve));
  std::swap(t[5], t[6]);
  EXPECT_NE(CalibErrorOf([&] { MergeHdr(MakeStack(eight, t), &curve); }).find("as bright as e4.png"), std::string::npos);
}

// The merge's time warning for `photos` labelled with `t`, one of whose times is off by `factor`.
std::string WarningWithOneTimeScaled(const std::vector<cv::Mat>& photos, std::vector<double> t,
                                     const ResponseCurve* curve, size_t index, double factor) {
  t[index] *= factor;
  return MergeHdr(MakeStack(photos, t), curve).time_warning;
}

// A dim 8-bit stack (the projector's black level on a sample): in the shorter photo of each pair
// most values lie just above the window's floor, where they are partly because their noise is
// positive. Chosen by those values, the ratio came out 3-4 % short of the times' and the merge
// warned "times as a camera labels them?" on exact times (a simulated capture's lighting/black).
TEST(Hdr, DimStacksOnExactTimesDoNotWarn) {
  const SyntheticResponse f;
  const std::vector<double> t{1, 2, 4, 8, 16, 32};
  const ResponseCurve curve = CalibrateResponse({MakeStack(SyntheticRig::RenderExposureStack(TestScene(16), NineTimes(), f, {}), NineTimes())});
  cv::Mat dim(160, 240, CV_32FC3);
  for (int y = 0; y < dim.rows; ++y)
    for (int x = 0; x < dim.cols; ++x) dim.at<cv::Vec3f>(y, x) = cv::Vec3f::all(float(0.028 + 0.002 * (3 * x / dim.cols)));
  StackOptions so;
  so.read_noise = 0.004;
  so.seed = 9;
  const auto photos = SyntheticRig::RenderExposureStack(dim, t, f, so);
  EXPECT_EQ(MergeHdr(MakeStack(photos, t), &curve).time_warning, "");
  // The pairs are judged: a time 5 % off is still found.
  const std::string w = WarningWithOneTimeScaled(photos, t, &curve, 1, 1.05);
  EXPECT_EQ(w.find("synthetic: e1.png is "), 0u) << w;
}

// 16-bit photos 1.6 stops apart (3.05x): a third exposure is well inside with both of a pair
// only in a narrow band, and judged by third exposures alone the last pair kept 149 samples, too
// few for the 3 % warning (a time 5 % off merged without a word). Pixels that no third exposure
// sees well inside are chosen by the pair's own values.
TEST(Hdr, StacksOneAndAHalfStopsApartAreJudgedAtThreePercent) {
  const std::vector<double> t = GeometricTimes(0.9, 3.05, 6);
  StackOptions so;
  so.bits = 16;
  so.seed = 29;
  const auto photos = SyntheticRig::RenderExposureStack(TestScene(24), t, {}, so);
  EXPECT_EQ(MergeHdr(MakeStack(photos, t), nullptr).time_warning, "");
  const std::string w = WarningWithOneTimeScaled(photos, t, nullptr, 5, 1 / 1.05);
  EXPECT_EQ(w.find("synthetic: e5.png is "), 0u) << w;
}

// 16-bit photos four stops apart share no sample in the 8-bit-sized window "well inside" the
// valid range (0.1 of it in from both ends: [0.097, 0.873], 3.2 stops), so a wrong time used to
// merge without a word. Linear pairs are judged on a wider window where the narrow one has too few
// samples (a warning: a black level left in the photos contradicts there too); exposures that
// still share none, though each sees the scene, are named as unchecked.
TEST(Hdr, FourStopLinearBracketsAreChecked) {
  const std::vector<double> t = GeometricTimes(0.01, 16.0, 5);
  StackOptions so;
  so.bits = 16;
  so.seed = 21;
  const auto images = SyntheticRig::RenderExposureStack(TestScene(22), t, {}, so);
  const HdrImage h = MergeHdr(MakeStack(images, t), nullptr);
  EXPECT_EQ(h.time_warning, "");
  std::vector<double> wrong = t;
  wrong[2] *= 3;  // a slip in exposures.json
  const std::string w = MergeHdr(MakeStack(images, wrong), nullptr).time_warning;
  EXPECT_EQ(w.find("synthetic: e2.png (7.68 s) is 15.92x as bright as e1.png (0.16 s) over pixels dim in e1.png, but "
                   "its exposure time is 48.00x as long: check the times"), 0u) << w;
  EXPECT_NE(w.find(", or give the black level left in the photos"), std::string::npos) << w;
  // Photos twelve stops apart: each sees part of the scene, no pixel is valid in both.
  const std::vector<double> far{0.01, 40.96};
  const auto far_images = SyntheticRig::RenderExposureStack(TestScene(22), far, {}, so);
  const HdrImage hf = MergeHdr(MakeStack(far_images, far), nullptr);
  EXPECT_NE(hf.time_warning.find("synthetic: e1.png and e0.png share"), std::string::npos) << hf.time_warning;
  EXPECT_NE(hf.time_warning.find("their times are not checked"), std::string::npos) << hf.time_warning;
  // A later pair's times 5 % off: that warning, not the first pair's note.
  const std::vector<double> three{0.01, 40.96, 81.92};
  const auto three_images = SyntheticRig::RenderExposureStack(TestScene(22), three, {}, so);
  const std::vector<double> three_labelled{0.01, 40.96, 81.92 * 1.05};
  const std::string tw = MergeHdr(MakeStack(three_images, three_labelled), nullptr).time_warning;
  EXPECT_EQ(tw.find("synthetic: e2.png is "), 0u) << tw;
  // A dim stack two stops apart with a black level of 1 % left in: few samples well inside, but
  // the times do not say the photos are far apart, and the wider window's dark end is mostly
  // black level. Not judged there: no false "check the times".
  const std::vector<double> dim{0.01, 0.04, 0.16};
  StackOptions offset = so;
  offset.offset = 0.01;
  const auto dim_images = SyntheticRig::RenderExposureStack(SyntheticHdrScene({240, 160}, 4, 23), dim, {}, offset);
  const std::string dw = MergeHdr(MakeStack(dim_images, dim), nullptr).time_warning;
  EXPECT_EQ(dw.find("check the times"), std::string::npos) << dw;
}

// Each half of the rule that widens the window, on its own (a 16-bit, noise-free two-level scene:
// the narrow window is [0.097, 0.873] of full scale, 8.96x; the wide one [0.010, 0.960]).
TEST(Hdr, EachReasonToWidenTheWindowIsChecked) {
  // A 16-bit photo of `rows` rows at `level` (fraction of full scale, clipped at 1) over the rest at
  // `rest`, both times `gain`.
  auto photo = [](double level, int rows, double rest, double gain) {
    cv::Mat m(120, 160, CV_16UC3, cv::Scalar::all(std::min(1.0, rest * gain) * 65535));
    m.rowRange(0, rows).setTo(cv::Scalar::all(std::min(1.0, level * gain) * 65535));
    return m;
  };
  // The times are close (8x, inside the narrow window's span) and each photo sees the scene, but
  // no pixel is well inside in both: the bright half saturates in the long photo and the dark half
  // is below the window in the short one. Labelled 2.5x apart, not 8x: found in the wide window.
  const std::vector<cv::Mat> close{photo(0.5, 60, 0.03, 1), photo(0.5, 60, 0.03, 8)};
  EXPECT_EQ(MergeHdr(MakeStack(close, {1, 8}), nullptr).time_warning, "");
  const std::string cw = MergeHdr(MakeStack(close, {1, 2.5}), nullptr).time_warning;
  EXPECT_EQ(cw.find("synthetic: e1.png (2.5 s) is 8.00x as bright as e0.png (1 s) over pixels dim in e0.png, but its "
                    "exposure time is 2.50x as long: check the times"), 0u) << cw;
  // The times say 16x (past the narrow window's span) and the short photo sees nothing well inside.
  // Labelled 48x apart, not 16x: found in the wide window.
  const std::vector<cv::Mat> far{photo(0.5, 0, 0.03, 1), photo(0.5, 0, 0.03, 16)};
  EXPECT_EQ(MergeHdr(MakeStack(far, {1, 16}), nullptr).time_warning, "");
  const std::string fw = MergeHdr(MakeStack(far, {1, 48}), nullptr).time_warning;
  EXPECT_EQ(fw.find("synthetic: e1.png (48 s) is 16.00x as bright as e0.png (1 s) over pixels dim in e0.png, but its "
                    "exposure time is 48.00x as long: check the times"), 0u) << fw;
}

TEST(Hdr, SixteenBitLinearMergeWithBlackFrames) {
  const auto t = NineTimes();
  StackOptions so;
  so.bits = 16;
  so.seed = 5;
  const cv::Mat truth = TestScene(13);
  auto images = SyntheticRig::RenderExposureStack(truth, t, {}, so);
  // A sensor offset of 1% of full scale, recorded by black frames at the same times.
  so.seed = 6;
  auto darks = SyntheticRig::RenderExposureStack(cv::Mat::zeros(truth.size(), CV_32FC3), t, {}, so);
  for (auto* v : {&images, &darks})
    for (cv::Mat& m : *v) m += cv::Scalar::all(655);
  const ExposureStack stack = MakeStack(images, t), black = MakeStack(darks, t);
  const HdrImage h = MergeHdr(stack, nullptr, &black);
  const ErrorStats e = Errors(truth, h, true);
  std::printf("16-bit + black: scale %.4f, median error %.3f%%, 95th percentile %.3f%%\n",
              e.scale[0], 100 * e.median, 100 * e.p95);
  EXPECT_NEAR(e.scale[0], 1.0, 0.01);  // linear data: absolute units (per second)
  EXPECT_LE(e.median, 0.015);
  EXPECT_LE(e.p95, 0.04);
  ExpectSaturatedBlockFlagged(h);
  // Without the black frames the dark end is biased.
  const ErrorStats biased = Errors(truth, MergeHdr(stack, nullptr), true);
  EXPECT_GT(biased.p95, e.p95 + 0.01);
}

// A float (linear, full scale 1) stack built by hand, 1x2 pixels, times 0.5, 2 and 8 s, default
// MergeOptions (valid: 0.0005 < x < 0.97). Where some exposure is valid and the samples agree
// (x = E t), the merge is E to float rounding (1e-6 relative) whatever the weights. Where no
// exposure is valid, MergeHdr documents: saturated in the shortest one, +inf; else the longest
// exposure's x / t (>= 0). The under-exposed samples here disagree (as read noise makes them),
// so taking another exposure gives another number.
TEST(Hdr, FloatStackExactWhereValidAndFlaggedElsewhere) {
  const std::vector<double> t{0.5, 2.0, 8.0};
  // Pixel 0: E = 0.001 (valid at 2 and 8 s only), 0.05 (valid in all), 1.5 (valid at 0.5 s
  //          only; 3 and 12 clip to 1).
  // Pixel 1: R under-exposed everywhere (0.0001, 0.0004, 0.0002: the longest gives 0.000025),
  //          G clipped everywhere, B E = 0.2 valid at 0.5 and 2 s.
  const cv::Vec3f px0[3] = {{0.0005f, 0.025f, 0.75f}, {0.002f, 0.1f, 1.f}, {0.008f, 0.4f, 1.f}};
  const cv::Vec3f px1[3] = {{0.0001f, 1.f, 0.1f}, {0.0004f, 1.f, 0.4f}, {0.0002f, 1.f, 1.f}};
  std::vector<cv::Mat> images;
  for (int j = 0; j < 3; ++j) {
    cv::Mat m(1, 2, CV_32FC3);
    m.at<cv::Vec3f>(0, 0) = px0[j];
    m.at<cv::Vec3f>(0, 1) = px1[j];
    images.push_back(m);
  }
  const HdrImage h = MergeHdr(MakeStack(images, t), nullptr);
  const cv::Vec3f e0 = h.radiance.at<cv::Vec3f>(0, 0), e1 = h.radiance.at<cv::Vec3f>(0, 1);
  std::printf("float stack: (%g %g %g) (%g %g %g)\n", e0[0], e0[1], e0[2], e1[0], e1[1], e1[2]);
  EXPECT_NEAR(e0[0] / 0.001, 1.0, 1e-6);
  EXPECT_NEAR(e0[1] / 0.05, 1.0, 1e-6);
  EXPECT_NEAR(e0[2] / 1.5, 1.0, 1e-6);
  EXPECT_NEAR(e1[0] / 0.000025, 1.0, 1e-6);
  EXPECT_TRUE(std::isinf(e1[1]) && e1[1] > 0);
  EXPECT_NEAR(e1[2] / 0.2, 1.0, 1e-6);
  EXPECT_EQ(h.flags.at<cv::Vec3b>(0, 0), cv::Vec3b(kHdrOk, kHdrOk, kHdrOk));
  EXPECT_EQ(h.flags.at<cv::Vec3b>(0, 1), cv::Vec3b(kHdrUnderexposed, kHdrSaturated, kHdrOk));
  EXPECT_EQ(h.saturated, 1u);
  EXPECT_EQ(h.underexposed, 1u);
}

class HdrFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("translume_hdr_" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  // Writes a 3-photo 8-bit stack as PNG with exposures.json.
  void WriteStack(bool with_json = true) {
    const std::vector<double> t{0.01, 0.04, 0.16};
    auto images = SyntheticRig::RenderExposureStack(TestScene(1)(cv::Rect(0, 0, 64, 48)), t, {}, {});
    nlohmann_json_ = "{";
    for (size_t j = 0; j < images.size(); ++j) {
      cv::Mat bgr;
      cv::cvtColor(images[j], bgr, cv::COLOR_RGB2BGR);
      cv::imwrite((dir_ / fmt::format("img{}.png", j)).string(), bgr);
      nlohmann_json_ += fmt::format("{}\"img{}.png\": {}", j ? ", " : "", j, t[j]);
    }
    nlohmann_json_ += "}";
    if (with_json) std::ofstream(dir_ / "exposures.json") << nlohmann_json_;
  }
  std::string P(const std::string& n) const { return (dir_ / n).string(); }
  // 8x8 JPEGs PREFIX0.jpg, PREFIX1.jpg, ... with these EXIF exposure times.
  void WriteJpegs(const std::string& prefix, const std::vector<float>& seconds) {
    const cv::Mat img8(8, 8, CV_8UC3, cv::Scalar(10, 20, 30));
    for (size_t j = 0; j < seconds.size(); ++j) {
      const std::string path = P(fmt::format("{}{}.jpg", prefix, j));
      auto out = OIIO::ImageOutput::create(path);
      OIIO::ImageSpec spec(8, 8, 3, OIIO::TypeDesc::UINT8);
      spec.attribute("ExposureTime", seconds[j]);
      ASSERT_TRUE(out->open(path, spec));
      ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, img8.data));
      out->close();
    }
  }
  fs::path dir_;
  std::string nlohmann_json_;
};

TEST_F(HdrFiles, ReadsStackWithJsonTimes) {
  WriteStack();
  const ExposureStack s = ReadExposureStack(dir_.string());
  ASSERT_EQ(s.exposures.size(), 3u);
  EXPECT_DOUBLE_EQ(s.exposures[1].seconds, 0.04);
  EXPECT_EQ(s.exposures[0].pixels.type(), CV_8UC3);
  EXPECT_TRUE(s.IsEightBit());
}

TEST_F(HdrFiles, ReadsExifExposureTime) {
  cv::Mat img(8, 8, CV_16UC3, cv::Scalar(1000, 2000, 3000));
  for (int j = 0; j < 2; ++j) {
    auto out = OIIO::ImageOutput::create(P(fmt::format("x{}.tif", j)));
    OIIO::ImageSpec spec(8, 8, 3, OIIO::TypeDesc::UINT16);
    spec.attribute("ExposureTime", j ? 0.5f : 0.125f);
    ASSERT_TRUE(out->open(P(fmt::format("x{}.tif", j)), spec));
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT16, img.data));
    out->close();
  }
  const ExposureStack s = ReadExposureStack(dir_.string());
  ASSERT_EQ(s.exposures.size(), 2u);
  EXPECT_DOUBLE_EQ(s.exposures[0].seconds, 0.125);
  EXPECT_DOUBLE_EQ(s.exposures[1].seconds, 0.5);
  EXPECT_EQ(s.exposures[0].pixels.type(), CV_16UC3);
  EXPECT_EQ(s.exposures[0].pixels.at<cv::Vec3w>(0, 0)[2], 3000);
  // JPEG carries EXIF too; 8-bit stays 8-bit.
  fs::remove_all(dir_);
  fs::create_directories(dir_);
  WriteJpegs("j", {0.01f, 0.02f});
  const ExposureStack j = ReadExposureStack(dir_.string());
  EXPECT_NEAR(j.exposures[1].seconds, 0.02, 1e-5);  // EXIF rational
  EXPECT_TRUE(j.IsEightBit());
  // An entry in exposures.json overrides EXIF (a camera writing wrong times).
  std::ofstream(dir_ / "exposures.json") << "{\"j1.jpg\": 0.04}";
  const ExposureStack k = ReadExposureStack(dir_.string());
  EXPECT_NEAR(k.exposures[0].seconds, 0.01, 1e-5);
  EXPECT_DOUBLE_EQ(k.exposures[1].seconds, 0.04);
  // Times as cameras show them ("1/30") or as strings, names in another case.
  std::ofstream(dir_ / "exposures.json") << "{\"J0.JPG\": \"1/30\", \"j1.jpg\": \"0.25\"}";
  const ExposureStack shown = ReadExposureStack(dir_.string());
  EXPECT_DOUBLE_EQ(shown.exposures[0].seconds, 1.0 / 30);
  EXPECT_DOUBLE_EQ(shown.exposures[1].seconds, 0.25);
  for (const char* bad_time : {"\"1/0\"", "\"1/\"", "\"fast\"", "\"2 s\"", "-1", "\"0x10\"", "\"inf\""}) {
    std::ofstream(dir_ / "exposures.json") << "{\"j0.jpg\": " << bad_time << "}";
    EXPECT_NE(CalibErrorOf([&] { ReadExposureStack(dir_.string()); }).find("is not a positive number of seconds"),
              std::string::npos) << bad_time;
  }
  // An entry that names no photo (misspelt: j1.jpg then took its EXIF time without a word).
  std::ofstream(dir_ / "exposures.json") << "{\"j_1.jpg\": 0.04}";
  EXPECT_EQ(CalibErrorOf([&] { ReadExposureStack(dir_.string()); }),
            (dir_ / "exposures.json").string() + ": the entry \"j_1.jpg\" names no photo of the stack (the folder "
            "holds j0.jpg to j1.jpg)");
  std::ofstream(dir_ / "notes.txt") << "tripod";
  std::ofstream(dir_ / "exposures.json") << "{\"notes.txt\": 0.04}";
  EXPECT_NE(CalibErrorOf([&] { ReadExposureStack(dir_.string()); }).find("that file is not read as a photo"),
            std::string::npos);
  // A broken exposures.json says why (it said only "not valid JSON").
  std::ofstream(dir_ / "exposures.json") << "{\"j1.jpg\": 1e999}";
  const std::string bad = CalibErrorOf([&] { ReadExposureStack(dir_.string()); });
  EXPECT_EQ(bad, (dir_ / "exposures.json").string() + ": not valid JSON: number overflow parsing '1e999'");
}

// An EXIF time that is no time falls back to exposures.json, and without an entry there the
// message says what was wrong. (OpenImageIO 2.4 writes a JPEG's ExposureTime of 1/8 or 1/2
// so that it reads back as inf; such files exist.)
TEST_F(HdrFiles, UnusableExifTimeFallsBackToJson) {
  WriteJpegs("x", {0.125f, 0.5f});
  double exif = 0;
  ReadRgbImage(P("x0.jpg"), &exif);
  if (std::isfinite(exif)) GTEST_SKIP() << "this OpenImageIO writes 1/8 s readably: " << exif;
  EXPECT_EQ(CalibErrorOf([&] { ReadExposureStack(dir_.string()); })
                .find(P("x0.jpg") + ": no exposure time (its EXIF ExposureTime inf is unusable"), 0u);
  std::ofstream(dir_ / "exposures.json") << "{\"x0.jpg\": 0.125, \"x1.jpg\": 0.5}";
  const ExposureStack s = ReadExposureStack(dir_.string());
  EXPECT_DOUBLE_EQ(s.exposures[0].seconds, 0.125);
  EXPECT_DOUBLE_EQ(s.exposures[1].seconds, 0.5);
}

TEST_F(HdrFiles, BadStacksNameTheFile) {
  WriteStack(false);
  EXPECT_EQ(CalibErrorOf([&] { ReadExposureStack(dir_.string()); }).find(P("img0.png") + ": no exposure time"), 0u);
  std::ofstream(dir_ / "exposures.json") << nlohmann_json_;
  cv::imwrite(P("img3.png"), cv::Mat(10, 10, CV_8UC3));
  std::ofstream(dir_ / "exposures.json") << nlohmann_json_.substr(0, nlohmann_json_.size() - 1) + ", \"img3.png\": 1}";
  EXPECT_EQ(CalibErrorOf([&] { ReadExposureStack(dir_.string()); }).find(P("img3.png") + ": image is 10x10 but 3 of the stack's 4 photos are 64x48"), 0u);
  // The odd photo is named also when it sorts first.
  fs::rename(P("img3.png"), P("a.png"));
  std::ofstream(dir_ / "exposures.json") << nlohmann_json_.substr(0, nlohmann_json_.size() - 1) + ", \"a.png\": 1}";
  EXPECT_EQ(CalibErrorOf([&] { ReadExposureStack(dir_.string()); }).find(P("a.png") + ": image is 10x10"), 0u);
  fs::remove(P("a.png"));
  std::ofstream(dir_ / "exposures.json") << nlohmann_json_.substr(0, nlohmann_json_.size() - 1) + ", \"img3.png\": 1}";
  // A greyscale photo among colour ones (read as grey RGB, it would skew the colours).
  cv::imwrite(P("img3.png"), cv::Mat(48, 64, CV_8UC1, cv::Scalar(100)));
  EXPECT_EQ(CalibErrorOf([&] { ReadExposureStack(dir_.string()); }).find(P("img3.png") + ": a greyscale photo"), 0u);
  std::ofstream(P("img3.png")) << "not a png at all";
  EXPECT_EQ(CalibErrorOf([&] { ReadExposureStack(dir_.string()); }).find(P("img3.png") + ": cannot read image"), 0u);
  std::ofstream(P("img3.png")).flush();  // a zero-byte photo (a copy that failed)
  EXPECT_EQ(CalibErrorOf([&] { ReadExposureStack(dir_.string()); }).find(P("img3.png") + ": empty file (0 bytes)"), 0u);
  for (int j : {1, 2, 3}) fs::remove(P(fmt::format("img{}.png", j)));
  EXPECT_NE(CalibErrorOf([&] { ReadExposureStack(dir_.string()); }).find("at least 2 images, found 1"), std::string::npos);
  // An 8-bit stack needs a response curve; a response file must be valid.
  WriteStack();
  const ExposureStack s = ReadExposureStack(dir_.string());
  EXPECT_NE(CalibErrorOf([&] { MergeHdr(s, nullptr); }).find("need a response curve"), std::string::npos);
  std::ofstream(P("bad.yml")) << "%YAML:1.0\nresponse: 3\n";
  EXPECT_NE(CalibErrorOf([&] { ReadResponse(P("bad.yml")); }).find(P("bad.yml") + ": "), std::string::npos);
}

// A JPEG cut short (a copy interrupted, a failing card) decodes "successfully" in OpenImageIO,
// grey where data is missing; it must be refused, naming the file.
TEST_F(HdrFiles, CutShortJpegIsRefused) {
  cv::Mat img(96, 128, CV_8UC3);
  cv::randu(img, cv::Scalar::all(0), cv::Scalar::all(255));
  const std::string whole = P("whole.jpg"), cut = P("cut.jpg");
  ASSERT_TRUE(cv::imwrite(whole, img));
  EXPECT_EQ(ReadRgbImage(whole).size(), img.size());
  std::ifstream in(whole, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::ofstream(cut, std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  EXPECT_EQ(CalibErrorOf([&] { ReadRgbImage(cut); }).find(cut + ": damaged image"), 0u);
}

TEST_F(HdrFiles, ResponseAndExrRoundTrip) {
  ResponseCurve c;
  c.lut.create(256, 1, CV_32FC3);
  for (int z = 0; z < 256; ++z) c.lut.at<cv::Vec3f>(z) = cv::Vec3f::all(float(std::pow((z + 1) / 129.0, 2.2)));
  WriteResponse(P("r.yml"), c);
  EXPECT_EQ(cv::norm(ReadResponse(P("r.yml")).lut, c.lut, cv::NORM_INF), 0.0);
  EXPECT_EQ(ReadResponse(P("r.yml")).shutter, ShutterTimes::kLabelled);
  c.shutter = ShutterTimes::kApex;
  WriteResponse(P("r.yml"), c);
  EXPECT_EQ(ReadResponse(P("r.yml")).shutter, ShutterTimes::kApex);
  // A file of an older translume has no exposure_times: labelled.
  {
    cv::FileStorage f(P("old.yml"), cv::FileStorage::WRITE);
    f << "channels" << "RGB" << "response" << c.lut;
  }
  EXPECT_EQ(ReadResponse(P("old.yml")).shutter, ShutterTimes::kLabelled);
  {
    cv::FileStorage f(P("bad.yml"), cv::FileStorage::WRITE);
    f << "response" << c.lut << "exposure_times" << "auto";
  }
  EXPECT_NE(CalibErrorOf([&] { ReadResponse(P("bad.yml")); }).find("bad.yml: exposure_times must be \"labelled\" or "
                                                                   "\"apex\", not \"auto\""), std::string::npos);
  {
    cv::FileStorage f(P("bad.yml"), cv::FileStorage::WRITE);
    f << "response" << c.lut << "exposure_times" << "APEX";
  }
  EXPECT_NE(CalibErrorOf([&] { ReadResponse(P("bad.yml")); }).find("bad.yml: exposure_times must be \"labelled\" or "
                                                                   "\"apex\", not \"APEX\""), std::string::npos);
  cv::Mat img(5, 7, CV_32FC3, cv::Scalar(0.5, 2.0, 1e-4));
  img.at<cv::Vec3f>(1, 1)[0] = std::numeric_limits<float>::infinity();
  WriteExr(P("a.exr"), img);
  const cv::Mat back = ReadLinearRgb(P("a.exr"));
  EXPECT_FLOAT_EQ(back.at<cv::Vec3f>(4, 6)[1], 2.0f);
  EXPECT_TRUE(std::isinf(back.at<cv::Vec3f>(1, 1)[0]));
}

}  // namespace
}  // namespace translume::calib
