// SPDX-License-Identifier: MIT
// Runs `translume calibrate ...` and `translume hdr` on synthetic photos, and on bad inputs.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "calib/camera_calib.h"
#include "calib/hdr.h"
#include "calib/projector_calib.h"
#include "calib/synthetic_rig.h"
#include "calib/white.h"
#include "tests/cli_harness.h"

namespace translume {
namespace {

namespace fs = std::filesystem;
using namespace translume::calib;

using testing_cli::CommandRun;
using testing_cli::Translume;

std::string ReadAll(const std::string& path) {
  std::ifstream f(path);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

class CalibCli : public testing_cli::CliTest {
 protected:
  // A failed command: exit 1 or 2, exactly one line of output naming `what`; the sentinel
  // output file is unchanged and no temporary file is left.
  void ExpectOneLineError(const CommandRun& r, const std::string& what) {
    CliTest::ExpectOneLineError(r, what);
    EXPECT_EQ(ReadAll(P("out.yml")), "sentinel");
    EXPECT_EQ(ReadAll(P("out.exr")), "sentinel");
    for (const auto& e : fs::recursive_directory_iterator(dir_))
      EXPECT_EQ(e.path().string().find(".tmp"), std::string::npos) << e.path();
  }
  void WriteSentinels() {
    std::ofstream(P("out.yml")) << "sentinel";
    std::ofstream(P("out.exr")) << "sentinel";
  }
  // An exposure stack folder: photos e0.png.. (RGB written as PNG) and exposures.json.
  void WriteStack(const std::string& name, const std::vector<cv::Mat>& images,
                  const std::vector<double>& t, bool json = true) {
    fs::create_directories(P(name));
    std::string j = "{";
    for (size_t k = 0; k < images.size(); ++k) {
      cv::Mat bgr;
      cv::cvtColor(images[k], bgr, cv::COLOR_RGB2BGR);
      cv::imwrite(P(fmt::format("{}/e{}.png", name, k)), bgr);
      j += fmt::format("{}\"e{}.png\": {}", k ? ", " : "", k, t[k]);
    }
    if (json) std::ofstream(P(name + "/exposures.json")) << j << "}";
  }
};

cv::Mat Ramp(int w, int h) {
  cv::Mat E(h, w, CV_32FC3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      E.at<cv::Vec3f>(y, x) = cv::Vec3f::all(float(std::pow(10.0, -3 + 3.0 * (x + y) / (w + h))));
  return E;
}

TEST_F(CalibCli, CalibrateCameraFromPhotos) {
  const SyntheticRig rig = SyntheticRig::Default();
  const BoardSpec board = BoardSpec::Parse("chessboard:9x6:25");
  fs::create_directories(P("photos"));
  int k = 0;
  for (const Pose& p : rig.BoardPoses(board, 6, 450, 21))
    cv::imwrite(P(fmt::format("photos/v{}.png", k++)), rig.RenderBoard(board, p));
  cv::imwrite(P("photos/zz_blank.png"), cv::Mat(rig.camera.size, CV_8UC1, cv::Scalar(80)));
  const CommandRun r = Translume("calibrate camera " + P("photos") +
                                 " --board chessboard:9x6:25 -o " + P("cam/camera.yml"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("zz_blank.png: board not found"), std::string::npos) << r.output;
  const CameraCalibration c = ReadCameraCalibration(P("cam/camera.yml"));
  EXPECT_NEAR(c.K(0, 0) / rig.camera.K(0, 0), 1.0, 0.003);
  EXPECT_EQ(c.image_size, rig.camera.size);
}

TEST_F(CalibCli, CameraBadInputs) {
  WriteSentinels();
  fs::create_directories(P("blank"));
  for (int k = 0; k < 3; ++k)
    cv::imwrite(P(fmt::format("blank/b{}.png", k)), cv::Mat(60, 80, CV_8UC1, cv::Scalar(50)));
  // Every photo that was dropped is counted, and a board found in none points at its spec.
  ExpectOneLineError(Translume("calibrate camera " + P("blank") + " --board chessboard:9x6:25 -o " + P("out.yml")),
                     "only 0 usable views of 3 (need 5); dropped 3 (" + P("blank/b0.png") +
                         ": board not found, and 2 more); the board was found in no photo: check the board spec");
  cv::imwrite(P("blank/c.png"), cv::Mat(61, 80, CV_8UC1, cv::Scalar(50)));
  ExpectOneLineError(Translume("calibrate camera " + P("blank") + " --board chessboard:9x6:25 -o " +
                               P("out.yml")), P("blank/c.png") + ": image is 80x61");
  std::ofstream(P("blank/c.png")) << "garbage";
  ExpectOneLineError(Translume("calibrate camera " + P("blank") + " --board chessboard:9x6:25 -o " +
                               P("out.yml")), P("blank/c.png") + ": cannot read image");
  ExpectOneLineError(Translume("calibrate camera " + P("blank") + " --board chess:9x6 -o " +
                               P("out.yml")), "board 'chess:9x6'");
  ExpectOneLineError(Translume("calibrate camera " + P("nothere") + " --board chessboard:9x6:25 -o " +
                               P("out.yml")), P("nothere") + ": not a folder");
  ExpectOneLineError(Translume("calibrate camera " + P("blank") + " --board chessboard:9x6:25 -o " +
                               P("blank/cam.yml")), "would write into the input folder");
  ExpectOneLineError(Translume("calibrate wobble"), "translume calibrate: error: unknown subcommand 'wobble'");
  ExpectOneLineError(Translume("calibrate wobble white"), "translume calibrate: error: unknown subcommand 'wobble'");
  ExpectOneLineError(Translume("calibrate -v white"), "translume calibrate: error: unknown subcommand '-v'");
  // --threads before the subcommand, as every command takes it; the line names the subcommand.
  for (const char* threads : {"--threads 1", "--threads=1"})
    ExpectOneLineError(Translume(std::string("calibrate ") + threads + " camera " + P("blank") +
                                 " --board chessboard:9x6:25 -o " + P("out.yml")),
                       "translume calibrate camera: error: " + P("blank/c.png") + ": cannot read image");
}

TEST_F(CalibCli, CalibrateProjectorFromPlanes) {
  const SyntheticRig rig = SyntheticRig::Default();
  const BoardSpec board = BoardSpec::Parse("chessboard:9x6:25");
  CameraCalibration cam;
  cam.image_size = rig.camera.size;
  cam.K = rig.camera.K;
  cam.dist = cv::Mat(rig.camera.dist).reshape(1, 1).clone();
  WriteCameraCalibration(P("camera.yml"), cam, board.ToString());
  ASSERT_EQ(Translume("calibrate projector --write-pattern " + P("pattern.png") +
                      " --pattern 11x7:64 --projector-size 1024x768").status, 0);
  const cv::Mat shown = ReadRgbImage(P("pattern.png"));
  const ProjectorChessboard pattern = ProjectorChessboard::Centered({1024, 768}, 11, 7, 64);
  EXPECT_EQ(shown.size(), cv::Size(1024, 768));
  EXPECT_EQ(shown.at<cv::Vec3b>(pattern.origin.y, pattern.origin.x)[0], 0);
  EXPECT_EQ(shown.at<cv::Vec3b>(pattern.origin.y, pattern.origin.x + 64)[0], 255);
  fs::create_directories(P("planes"));
  int k = 0;
  for (const Pose& p : rig.PlanePoses(pattern, 5, 520, 3, &board)) {
    cv::imwrite(P(fmt::format("planes/p{}_board.png", k)), rig.RenderBoard(board, p));
    cv::imwrite(P(fmt::format("planes/p{}_pattern.png", k++)), rig.RenderProjectedChessboard(p, pattern));
  }
  const std::string args = "calibrate projector " + P("planes") + " --camera " + P("camera.yml") +
                           " --board chessboard:9x6:25 --pattern 11x7:64 -o ";
  CommandRun r = Translume(args + P("projector.yml"));
  ASSERT_EQ(r.status, 0) << r.output;
  const ProjectorCalibration pc = ReadProjectorCalibration(P("projector.yml"));
  EXPECT_NEAR(pc.K(0, 0) / rig.projector.K(0, 0), 1.0, 0.005);
  EXPECT_LT(cv::norm(pc.T - rig.projector_from_camera.t), 1.0);
  // Bad inputs: a photo without its partner, a pattern that does not fit, a bad camera file.
  WriteSentinels();
  ExpectOneLineError(Translume(args.substr(0, args.find("11x7:64")) + "11x7:200 -o " + P("out.yml")),
                     "--pattern 11x7:200");
  ExpectOneLineError(Translume("calibrate projector " + P("planes") + " --camera " + P("out.yml") +
                               " --board chessboard:9x6:25 -o " + P("out.yml")),
                     "would overwrite the input");
  ExpectOneLineError(Translume("calibrate projector " + P("planes") + " --camera " + P("pattern.png") +
                               " --board chessboard:9x6:25 -o " + P("out.yml")), P("pattern.png"));
  // The missing option is named, not the list of all four.
  ExpectOneLineError(Translume("calibrate projector " + P("planes") + " --board chessboard:9x6:25 -o " + P("out.yml")),
                     "--camera is required");
  ExpectOneLineError(Translume("calibrate projector " + P("planes") + " --board chessboard:9x6:25"),
                     "--camera and -o are required");
  // Planes shot from the camera's side, calibrated as rear projection: refused, with the hint.
  ExpectOneLineError(Translume(args + P("out.yml") + " --rear"), "if the projector lit them from the camera's side");
  // A plane missing one photo is dropped, as one whose board is not found; the suffixes may be
  // in any case.
  fs::remove(P("planes/p2_pattern.png"));
  fs::rename(P("planes/p1_board.png"), P("planes/p1_BOARD.png"));
  r = Translume(args + P("projector.yml"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("dropped " + P("planes/p2") + ": no _pattern photo"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("dropped " + P("planes/p1")), std::string::npos) << r.output;
}

TEST_F(CalibCli, CalibrateWhite) {
  const SyntheticRig rig = SyntheticRig::Default();
  const SyntheticChart chart = SyntheticChart::ColorChecker();
  Pose pose;
  const cv::Size2d size = chart.SizeMm();
  pose.t = cv::Vec3d(-size.width / 2, -size.height / 2, 600);
  const cv::Vec3d gain(0.9, 1.1, 0.7);
  WriteExr(P("white.exr"), rig.RenderChartRadiance(chart, pose, {1, 1, 1}, gain));
  WriteExr(P("black.exr"), rig.RenderChartRadiance(chart, pose, {0.01, 0.01, 0.01}, gain));
  CommandRun r = Translume("calibrate white " + P("white.exr") + " --black " + P("black.exr") +
                           " --chart colorchecker -o " + P("white.yml"));
  ASSERT_EQ(r.status, 0) << r.output;
  WhiteBalance w = ReadWhiteBalance(P("white.yml"));
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(w.gains[c] * gain[c] * 0.99, 1.0, 0.01);
  EXPECT_FALSE(w.camera_flat);
  // Through a camera flat: an even one (twice as bright as needed) changes nothing but the record.
  const cv::Size image = ReadLinearRgb(P("white.exr")).size();
  WriteExr(P("flat.exr"), cv::Mat(image, CV_32FC3, cv::Scalar::all(2)));
  r = Translume("calibrate white " + P("white.exr") + " --black " + P("black.exr") + " --camera-flat " + P("flat.exr") +
                " --chart colorchecker -o " + P("white_flat.yml"));
  ASSERT_EQ(r.status, 0) << r.output;
  const WhiteBalance wf = ReadWhiteBalance(P("white_flat.yml"));
  EXPECT_TRUE(wf.camera_flat);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(wf.gains[c] / w.gains[c], 1.0, 1e-4);
  // A white stack whose times disagree with its photos by 8 %: calibrated, with the merge's warning.
  StackOptions so;
  so.bits = 16;
  std::vector<double> t{0.1, 0.2, 0.4, 0.8};
  const std::vector<cv::Mat> photos = SyntheticRig::RenderExposureStack(ReadLinearRgb(P("white.exr")), t, {}, so);
  t[2] *= 1.08;
  WriteStack("white_stack", photos, t);
  r = Translume("calibrate white " + P("white_stack") + " --chart colorchecker -o " + P("white_stack.yml"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("calibrate white: warning: " + P("white_stack") + ": e3.png is 1.999x as bright as e2.png"), std::string::npos)
      << r.output;
  WriteExr(P("small_flat.exr"), cv::Mat(image / 2, CV_32FC3, cv::Scalar::all(1)));
  WriteSentinels();
  ExpectOneLineError(Translume("calibrate white " + P("white.exr") + " --camera-flat " + P("small_flat.exr") +
                               " --chart colorchecker -o " + P("out.yml")),
                     P("white.exr") + ": images are " + std::to_string(image.width) + "x" +
                         std::to_string(image.height) + " but --camera-flat " + P("small_flat.exr") + " is");
  // The white patch (index 18) by its corners, from the chart geometry.
  const cv::Point2d ctr = chart.PatchCenter(18);
  std::vector<cv::Point3d> X;
  for (const auto& d : {cv::Point2d(-8, -8), cv::Point2d(8, -8), cv::Point2d(8, 8), cv::Point2d(-8, 8)}) {
    const cv::Vec3d x = pose.Apply({ctr.x + d.x, ctr.y + d.y, 0});
    X.emplace_back(x[0], x[1], x[2]);
  }
  std::string corners;
  for (const auto& p : rig.camera.Project(X)) corners += fmt::format("{}{:.2f},{:.2f}", corners.empty() ? "" : ",", p.x, p.y);
  const cv::Vec3d a = chart.albedo[18];
  r = Translume(fmt::format("calibrate white {} --black {} --patch {} --albedo {},{},{} -o {}",
                            P("white.exr"), P("black.exr"), corners, a[0], a[1], a[2], P("patch.yml")));
  ASSERT_EQ(r.status, 0) << r.output;
  w = ReadWhiteBalance(P("patch.yml"));
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(w.gains[c] * gain[c] * 0.99, 1.0, 0.01);
  WriteSentinels();
  const std::string base = "calibrate white " + P("white.exr") + " ";
  ExpectOneLineError(Translume(base + "-o " + P("out.yml")), "either --chart");
  ExpectOneLineError(Translume(base + "--patch 1,2,3 --albedo 0.9 -o " + P("out.yml")),
                     "--patch 1,2,3: expected 8");
  ExpectOneLineError(Translume(base + "--patch " + corners + " -o " + P("out.yml")), "--patch needs --albedo");
  ExpectOneLineError(Translume(base + "--chart macbeth -o " + P("out.yml")), "--chart macbeth");
  ExpectOneLineError(Translume(base + "--sensor-black 0.01 --chart colorchecker -o " + P("out.yml")),
                     P("white.exr") + ": an HDR image is merged already; give the sensor black level where it is "
                                      "merged (translume hdr --sensor-black), or give the stack folder");
  ExpectOneLineError(Translume("calibrate white " + P("missing.exr") + " --chart colorchecker -o " +
                               P("out.yml")), P("missing.exr") + ": no such file");
  ExpectOneLineError(Translume(base + "--black " + P("out.exr") + " --chart colorchecker -o " + P("out.yml")),
                     P("out.exr") + ": cannot read image");
  // White and black swapped gave negative gains, written as a calibration; a patch reaching out
  // of the image gave gains 28% off.
  ExpectOneLineError(Translume(fmt::format("calibrate white {} --black {} --patch {} --albedo 0.9 -o {}", P("black.exr"),
                                           P("white.exr"), corners, P("out.yml"))),
                     P("black.exr") + " and --black " + P("white.exr") +
                         ": white balance: the white reference is not brighter than the black reference");
  ExpectOneLineError(Translume(base + "--patch 100,100,5000,100,5000,400,100,400 --albedo 0.9 -o " + P("out.yml")),
                     "patch corner 1 (5000.0, 100.0) is outside the");
}

TEST_F(CalibCli, ResponseThenHdr) {
  std::vector<double> t;
  for (int j = 0; j < 8; ++j) t.push_back(0.01 * std::pow(3.0, j));
  const SyntheticResponse f;
  WriteStack("cal", SyntheticRig::RenderExposureStack(Ramp(160, 120), t, f), t);
  CommandRun r = Translume("calibrate response " + P("cal") + " -o " + P("response.yml"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_EQ(ReadResponse(P("response.yml")).Validate(), "");
  r = Translume("hdr " + P("cal") + " --response " + P("response.yml") + " -o " + P("hdr/ramp.exr"));
  ASSERT_EQ(r.status, 0) << r.output;
  const cv::Mat E = ReadLinearRgb(P("hdr/ramp.exr"));
  ASSERT_EQ(E.size(), cv::Size(160, 120));
  // A 1000:1 ramp: the merged image spans it (up to one scale). Block means at both ends.
  const cv::Mat truth = Ramp(160, 120);
  const cv::Rect dark(0, 0, 10, 10), bright(150, 110, 10, 10);
  const double ratio = cv::mean(E(bright))[1] / cv::mean(E(dark))[1];
  const double expected = cv::mean(truth(bright))[1] / cv::mean(truth(dark))[1];
  EXPECT_NEAR(ratio / expected, 1.0, 0.03);
  // 16-bit photos are linear and need no response.
  StackOptions so;
  so.bits = 16;
  WriteStack("lin", SyntheticRig::RenderExposureStack(Ramp(40, 30), t, f, so), t);
  r = Translume("hdr " + P("lin") + " -o " + P("lin.exr"));
  ASSERT_EQ(r.status, 0) << r.output;
  const cv::Rect block(0, 0, 8, 8);
  EXPECT_NEAR(cv::mean(ReadLinearRgb(P("lin.exr"))(block))[0] / cv::mean(Ramp(40, 30)(block))[0], 1.0, 0.02);
  // With a sensor black level of 3 % of full scale left in them: --sensor-black removes it.
  so.offset = 0.03;
  WriteStack("lin_black", SyntheticRig::RenderExposureStack(Ramp(40, 30), t, f, so), t);
  r = Translume("hdr " + P("lin_black") + " --sensor-black 0.03 -o " + P("lin_black.exr"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NEAR(cv::mean(ReadLinearRgb(P("lin_black.exr"))(block))[0] / cv::mean(Ramp(40, 30)(block))[0], 1.0, 0.02);
  r = Translume("hdr " + P("lin_black") + " -o " + P("lin_left.exr"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_GT(cv::mean(ReadLinearRgb(P("lin_left.exr"))(block))[0] / cv::mean(Ramp(40, 30)(block))[0], 1.1);
}

TEST_F(CalibCli, HdrBadInputs) {
  WriteSentinels();
  const std::vector<double> t{0.1, 0.4, 1.6};
  const auto images = SyntheticRig::RenderExposureStack(Ramp(40, 30), t, {});
  WriteStack("s", images, t, false);
  ExpectOneLineError(Translume("hdr " + P("s") + " -o " + P("out.exr")),
                     P("s/e0.png") + ": no exposure time");
  WriteStack("s", images, t);
  ExpectOneLineError(Translume("hdr " + P("s") + " -o " + P("out.exr")), "8-bit photos need --response");
  ExpectOneLineError(Translume("hdr " + P("s") + " --sensor-black 0.5 -o " + P("out.exr")),
                     "--sensor-black 0.5: expected fractions of full scale in [0, 0.5)");
  ExpectOneLineError(Translume("hdr " + P("s") + " --sensor-black 0.01,0.02 -o " + P("out.exr")),
                     "--sensor-black 0.01,0.02: expected 1 or 3 comma-separated numbers");
  ExpectOneLineError(Translume("hdr " + P("s") + " --response " + P("none.yml") + " -o " + P("out.exr")),
                     P("none.yml") + ": no such file");
  // A PNG cut short: our line only, not libpng's own "libpng error:" line too.
  const std::string whole = ReadAll(P("s/e1.png"));
  std::ofstream(P("s/e1.png"), std::ios::binary) << whole.substr(0, whole.size() / 2);
  ExpectOneLineError(Translume("hdr " + P("s") + " -o " + P("out.exr")),
                     P("s/e1.png") + ": damaged image (a PNG cut short");
  std::ofstream(P("s/e1.png")) << "truncated";
  ExpectOneLineError(Translume("hdr " + P("s") + " -o " + P("out.exr")), P("s/e1.png") + ": cannot read image");
  fs::remove(P("s/e1.png"));
  fs::remove(P("s/e2.png"));
  ExpectOneLineError(Translume("hdr " + P("s") + " -o " + P("out.exr")), "at least 2 images, found 1");
  ExpectOneLineError(Translume("hdr " + P("s") + " -o " + P("s/x.exr")), "would write into the input folder");
  ExpectOneLineError(Translume("hdr " + P("s") + " -o " + P("x.png")), "must end in .exr");
  ExpectOneLineError(Translume("calibrate response " + P("s") + " -o " + P("out.yml")),
                     "at least 2 images, found 1");
}

}  // namespace
}  // namespace translume
