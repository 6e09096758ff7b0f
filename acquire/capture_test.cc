// SPDX-License-Identifier: MIT
#include "acquire/capture.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "solver/status.h"

namespace translume::acquire {
namespace {

namespace fs = std::filesystem;

class CaptureTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           (std::string("translume_capture_") + ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    for (const char* d : {"calib/camera", "calib/planes", "lighting/00", "lighting/01", "calib/white"})
      fs::create_directories(dir_ / d);
    std::ofstream(dir_ / "calib/response.yml") << "%YAML:1.0\n";
    base_ = nlohmann::json::parse(R"({
      "format": "translume-capture/1", "setup": "back", "sample_mm": [11.5, 8.5, 2.5],
      "spacing_mm": 0.5, "eta": 1.3,
      "face_corners_px": [[10, 10], [200, 12], [198, 150], [8, 148]],
      "camera": {"photos": "calib/camera", "board": "chessboard:9x6:2"},
      "response": "calib/response.yml",
      "white": {"white": "calib/white", "patch": [[20, 20], [180, 20], [180, 130], [20, 130]], "albedo": 0.9},
      "conditions": [{"name": "a", "stack": "lighting/00", "light": "region:0,0/2"},
                     {"name": "b", "stack": "lighting/01", "light": "region:1,0/2"}]})");
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Write(const nlohmann::json& j) {
    std::ofstream(dir_ / "capture.json") << j.dump(2);
    return dir_.string();
  }
  void ExpectError(const std::function<void(nlohmann::json&)>& edit, const std::string& what) {
    nlohmann::json j = base_;
    edit(j);
    try {
      ReadCapture(Write(j));
      ADD_FAILURE() << "no error; expected " << what;
    } catch (const InputError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find("capture.json: " + what), std::string::npos) << msg;
    }
  }
  fs::path dir_;
  nlohmann::json base_;
};

TEST_F(CaptureTest, ReadsAndRoundTrips) {
  const CaptureSpec s = ReadCapture(Write(base_));
  EXPECT_EQ(s.setup, Setup::kBack);
  EXPECT_EQ(s.grid.nx, 24);
  EXPECT_EQ(s.grid.ny, 18);
  EXPECT_EQ(s.grid.nz, 6);
  EXPECT_NEAR(s.C, 2.6021, 1e-4);
  EXPECT_EQ(s.face_corners_px.size(), 4u);
  EXPECT_TRUE(s.projector.file.empty() && s.projector.planes.empty());
  ASSERT_EQ(s.conditions.size(), 2u);
  EXPECT_EQ(s.conditions[1].light, "region:1,0/2");
  EXPECT_EQ(s.white.albedo[2], 0.9);
  // CaptureJson writes what ReadCapture reads back.
  std::ofstream(dir_ / "capture.json") << CaptureJson(s);
  const CaptureSpec t = ReadCapture(dir_.string());
  EXPECT_EQ(t.grid.nz, s.grid.nz);
  EXPECT_EQ(t.conditions[0].stack, s.conditions[0].stack);
  EXPECT_EQ(t.white.patch, s.white.patch);
  EXPECT_EQ(t.camera.board, s.camera.board);
  EXPECT_EQ(t.exposure_times, calib::ShutterTimes::kAuto);
  nlohmann::json j = base_;
  j["exposure_times"] = "apex";
  const CaptureSpec a = ReadCapture(Write(j));
  EXPECT_EQ(a.exposure_times, calib::ShutterTimes::kApex);
  std::ofstream(dir_ / "capture.json") << CaptureJson(a);
  EXPECT_EQ(ReadCapture(dir_.string()).exposure_times, calib::ShutterTimes::kApex);
  // The lens's blur: "auto" (the default) or a sigma, read and written back.
  EXPECT_FALSE(s.camera_blur_px.has_value());
  EXPECT_FALSE(t.camera_blur_px.has_value());
  j["camera_blur_px"] = 0.8;
  const CaptureSpec b = ReadCapture(Write(j));
  ASSERT_TRUE(b.camera_blur_px.has_value());
  EXPECT_EQ(*b.camera_blur_px, 0.8);
  std::ofstream(dir_ / "capture.json") << CaptureJson(b);
  EXPECT_EQ(ReadCapture(dir_.string()).camera_blur_px, 0.8);
  j["camera_blur_px"] = "auto";
  EXPECT_FALSE(ReadCapture(Write(j)).camera_blur_px.has_value());
  // Corners given near the face (clicked by hand), read and written back.
  EXPECT_FALSE(s.face_corners_near);
  j["face_corners_px"] = {{"near", base_["face_corners_px"]}};
  const CaptureSpec n = ReadCapture(Write(j));
  EXPECT_TRUE(n.face_corners_near);
  EXPECT_EQ(n.face_corners_px, s.face_corners_px);
  std::ofstream(dir_ / "capture.json") << CaptureJson(n);
  EXPECT_TRUE(ReadCapture(dir_.string()).face_corners_near);
  j["face_corners_px"] = base_["face_corners_px"];
  // Validation conditions, read and written back.
  EXPECT_FALSE(s.conditions[1].validation);
  j["conditions"][1]["validation"] = true;
  const CaptureSpec v = ReadCapture(Write(j));
  EXPECT_FALSE(v.conditions[0].validation);
  EXPECT_TRUE(v.conditions[1].validation);
  std::ofstream(dir_ / "capture.json") << CaptureJson(v);
  EXPECT_TRUE(ReadCapture(dir_.string()).conditions[1].validation);
}

TEST_F(CaptureTest, GridInsteadOfSpacing) {
  nlohmann::json j = base_;
  j.erase("spacing_mm");
  j["grid"] = {24, 18, 6};
  const CaptureSpec s = ReadCapture(Write(j));
  EXPECT_DOUBLE_EQ(s.spacing_mm, 0.5);
}

TEST_F(CaptureTest, EveryBrokenFieldIsNamed) {
  ExpectError([](auto& j) { j["format"] = "translume-capture/9"; }, "format: expected");
  ExpectError([](auto& j) { j["setup"] = "side"; }, "setup: expected");
  ExpectError([](auto& j) { j["sample_mm"] = {1, 2}; }, "sample_mm: expected 3 numbers");
  ExpectError([](auto& j) { j["spacing_mm"] = 0.3; }, "spacing_mm: sample_mm[0]");
  // A measured size that is no whole number of spacings: the two nearest that are.
  ExpectError([](auto& j) { j["sample_mm"] = {11.62, 8.5, 2.5}; },
              "spacing_mm: sample_mm[0] = 11.62 is not a whole number of spacings 0.5: give 11.5 or 12");
  ExpectError([](auto& j) { j["grid"] = {24, 18, 6}; }, "spacing_mm: give exactly one");
  ExpectError([](auto& j) { j["C"] = 2.0; }, "C: give eta or C");
  ExpectError([](auto& j) { j["face_corners_px"] = {{1, 2}}; }, "face_corners_px: expected 4");
  ExpectError([](auto& j) { j["face_corners_px"] = {{"near", {{1, 2}}}}; }, "face_corners_px.near: expected 4");
  ExpectError([](auto& j) { j["face_corners_px"] = {{"close", j["face_corners_px"]}}; },
              "face_corners_px.close: unknown field");
  ExpectError([](auto& j) { j["camera"]["photos"] = "nowhere"; }, "camera.photos: folder");
  ExpectError([](auto& j) { j["response"] = 3; }, "response: expected");
  for (const nlohmann::json& bad : {nlohmann::json(-0.5), nlohmann::json(7), nlohmann::json("sharp")})
    ExpectError([&](auto& j) { j["camera_blur_px"] = bad; }, "camera_blur_px: expected \"auto\" or a Gaussian sigma");
  ExpectError([](auto& j) { j["white"]["albedo"] = 1.5; }, "white.albedo: must be in (0, 1]");
  ExpectError([](auto& j) { j["colour"] = 1; }, "colour: unknown field");
  ExpectError([](auto& j) { j["exposure_times"] = "nominal"; },
              "exposure_times: expected \"auto\", \"labelled\" or \"apex\"");
  ExpectError([](auto& j) { j["conditions"][1]["name"] = "a"; }, "conditions[1].name: duplicate");
  ExpectError([](auto& j) { j["conditions"][1]["validation"] = "yes"; }, "conditions[1].validation: expected true or false");
  ExpectError([](auto& j) { j["conditions"][0]["validation"] = j["conditions"][1]["validation"] = true; },
              "conditions: every condition is a validation condition");
  // Names the node-space dataset would refuse after the HDR stage (it aborted there).
  for (const char* bad : {"lit(0,1)", "r\u00e9gion", "a:b", "..", "x y"})
    ExpectError([&](auto& j) { j["conditions"][1]["name"] = bad; }, "conditions[1].name: '");
  ExpectError([](auto& j) { j["conditions"][0]["stack"] = "lighting/07"; }, "conditions[0].stack: folder");
  ExpectError([](auto& j) { j["conditions"][0].erase("light"); }, "conditions[0]: give exactly one");
  ExpectError([](auto& j) { j["conditions"][0]["pattern"] = "calib/response.yml"; j["conditions"][0].erase("light"); },
              "conditions[0].pattern: projector patterns need a projector calibration");
  ExpectError([](auto& j) { j["conditions"] = nlohmann::json::array(); }, "conditions: expected a non-empty list");
  ExpectError([](auto& j) { j["face_corners_px"] = {{1, 1}, {2, 2}, {3, 3}, {4, 4}}; },
              "face_corners_px: the 4 corners must enclose a convex quadrilateral");
  ExpectError([](auto& j) { j["face_corners_px"] = {{0, 0}, {100, 100}, {100, 0}, {0, 100}}; },
              "face_corners_px: the 4 corners must enclose a convex quadrilateral");
  ExpectError([](auto& j) { j["conditions"][0]["light"] = "region:9,9/2"; }, "conditions[0].light: light 'region:9,9/2'");
  ExpectError([](auto& j) { j["conditions"][1]["light"] = "spot:1,1"; }, "conditions[1].light: light 'spot:1,1'");
  ExpectError([](auto& j) { j["conditions"][0]["light"] = "image:nope.png"; }, "conditions[0].light: file");
}

// Spacings outside SpacingProblem's range, grids too fine for any memory and fractional node
// counts are refused at read (a tiny spacing overflowed the node count: a crash, a raw
// "vector::reserve" or negative sizes in later messages; 16.5 nodes were truncated).
TEST_F(CaptureTest, GridOutOfRangeIsRefusedAtRead) {
  for (double h : {1e-320, 1e-200, 1e-20, 1e-8, 2e3})
    ExpectError([&](auto& j) { j["spacing_mm"] = h; }, "spacing_mm: must be within 0.001..1000 mm");
  ExpectError([](auto& j) { j["sample_mm"] = {1e300, 8.5, 2.5}; }, "spacing_mm: sample_mm[0] = 1e+300 mm is");
  auto grid = [](nlohmann::json g) {
    return [g](nlohmann::json& j) {
      j.erase("spacing_mm");
      j["grid"] = g;
    };
  };
  ExpectError(grid({16.5, 18, 6}), "grid: expected 3 whole numbers of nodes, got 16.5");
  ExpectError(grid({24, 1e12, 6}), "grid: every axis must have 2..65536 nodes, got 1e+12");
  ExpectError(grid({24, 18, 1}), "grid: every axis must have 2..65536 nodes, got 1");
  ExpectError([&](auto& j) { grid({24, 18, 6})(j); j["sample_mm"] = {1e-6, 8.5, 2.5}; },
              "grid: the spacing sample_mm[0] / (grid[0] - 1) must be within 0.001..1000 mm");
}

// An image: light's file, like every path in capture.json, is relative to the capture folder
// (it was read relative to the current folder).
TEST_F(CaptureTest, ImageLightsAreRelativeToTheFolder) {
  std::ofstream(dir_ / "stripes.png") << "not read here";
  nlohmann::json j = base_;
  j["conditions"][0]["light"] = "image:stripes.png";
  const CaptureSpec s = ReadCapture(Write(j));
  EXPECT_EQ(fs::path(s.conditions[0].Light(s.dir).image_path), dir_ / "stripes.png");
  EXPECT_EQ(s.conditions[0].light, "image:stripes.png");  // as given, for CaptureJson
}

// Every message names capture.json and the field (or the file): paths of the wrong kind said
// "not found", boards and the projector pattern were checked only after the camera calibration
// (naming --projector-size, a flag the user never gave), and a JSON number out of range or a
// folder named capture.json gave the JSON library's own text.
TEST_F(CaptureTest, MessagesNameTheFileAndField) {
  ExpectError([](auto& j) { j["camera"] = "calib/camera"; }, "camera: " + (dir_ / "calib/camera").string() +
                                                                 " is a folder, expected a file");
  ExpectError([](auto& j) { j["camera"]["photos"] = "calib/response.yml"; },
              "camera.photos: " + (dir_ / "calib/response.yml").string() + " is a file, expected a folder");
  ExpectError([](auto& j) { j["conditions"][1]["stack"] = "calib/response.yml"; },
              "conditions[1].stack: " + (dir_ / "calib/response.yml").string() + " is a file, expected a folder");
  ExpectError([](auto& j) { j["camera"]["board"] = "chess:9x6"; }, "camera.board: board 'chess:9x6': expected");
  auto projector = [](const char* key, const char* value) {
    return [=](nlohmann::json& j) {
      j["projector"] = {{"planes", "calib/planes"}, {"board", "chessboard:9x6:2"}};
      j["projector"][key] = value;
    };
  };
  ExpectError(projector("board", "chessboard:6x6:2"), "projector.board: board 'chessboard:6x6:2'");
  ExpectError(projector("projector_size", "1024"), "projector.projector_size 1024: expected WIDTHxHEIGHT");
  ExpectError(projector("projector_size", "32x32"), "projector.projector_size 32x32: each side must be");
  ExpectError(projector("pattern", "11x7:200"), "projector.pattern 11x7:200: ");
  ExpectError(projector("pattern", "11x7"), "projector.pattern 11x7: expected COLSxROWS:SQUARE_PX");
  nlohmann::json j = base_;
  projector("pattern", "11x7:64")(j);
  EXPECT_EQ(ReadCapture(Write(j)).projector.pattern, "11x7:64");

  std::ofstream(dir_ / "capture.json") << R"({"format": "translume-capture/1", "eta": 1e999})";
  try {
    ReadCapture(dir_.string());
    ADD_FAILURE() << "1e999 accepted";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), (dir_ / "capture.json").string() +
                                         ": not valid JSON: number overflow parsing '1e999'");
  }
  fs::remove(dir_ / "capture.json");
  fs::create_directories(dir_ / "capture.json");
  try {
    ReadCapture(dir_.string());
    ADD_FAILURE() << "a folder capture.json accepted";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), (dir_ / "capture.json").string() + ": is a folder, not a file");
  }
}

TEST_F(CaptureTest, NotJsonIsNamed) {
  std::ofstream(dir_ / "capture.json") << "{ not json";
  EXPECT_THROW(ReadCapture(dir_.string()), InputError);
  EXPECT_THROW(ReadCapture((dir_ / "missing").string()), InputError);
}

}  // namespace
}  // namespace translume::acquire
