// SPDX-License-Identifier: MIT
// Subcommands over the calib library: calibrate (camera, projector, response, white) and hdr.
#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "calib/camera_calib.h"
#include "calib/error.h"
#include "calib/hdr.h"
#include "calib/photo_io.h"
#include "calib/projector_calib.h"
#include "calib/white.h"
#include "solver/atomic_file.h"
#include "solver/threads.h"
#include "tools/commands.h"

namespace translume {
namespace {

namespace fs = std::filesystem;

// --exposure-times (calib/shutter.h; docs/capture.md, "Exposure times").
void AddExposureTimesOption(CLI::App& app, std::string& times, const std::string& what_auto) {
  app.add_option("--exposure-times", times,
                 "How EXIF/exposures.json times are read: labelled (as given), apex (camera labels such "
                 "as 1/30 as their APEX times, 1/32 s) or auto (" + what_auto + ")")
      ->check(CLI::IsMember({"auto", "labelled", "apex"}))
      ->capture_default_str();
}

// --sensor-black (calib::MergeOptions::sensor_black; docs/capture.md, "A sensor black level").
void AddSensorBlackOption(CLI::App& app, std::string& text) {
  app.add_option("--sensor-black", text,
                 "Linear photos: the camera's black level left in them, a fraction of full scale, B or R,G,B "
                 "(2048 in 16-bit codes: 0.03125); subtracted from every photo");
}

cv::Vec3d ParseSensorBlack(const std::string& text) {
  if (text.empty()) return {0, 0, 0};
  const std::vector<double> v = ParseNumbers(text, "--sensor-black", 1, 3);
  const cv::Vec3d black = v.size() == 1 ? cv::Vec3d::all(v[0]) : cv::Vec3d(v[0], v[1], v[2]);
  if (std::string why = calib::SensorBlackProblem(black); !why.empty())
    throw calib::CalibError(fmt::format("--sensor-black {}: {}", text, why));
  return black;
}

// OpenCV exceptions carry multi-line messages: keep the first meaningful line.
template <typename F>
int OneLineErrors(F&& f) {
  try {
    return f();
  } catch (const cv::Exception& e) {
    std::string msg = e.err.empty() ? e.what() : e.err;
    std::replace(msg.begin(), msg.end(), '\n', ' ');
    throw std::runtime_error("OpenCV: " + msg);
  }
}

int RunCalibrateCamera(int argc, char** argv) {
  CLI::App app{"Camera intrinsics (Zhang) from photos of a printed board in a folder.\n"
               "Boards: chessboard:COLSxROWS:SQUARE_MM (inner corners) or\n"
               "charuco:SXxSY:SQUARE_MM:MARKER_MM[:DICT] (squares; DICT 4X4_50, 4X4_100,\n"
               "5X5_100 (default), 6X6_250). Writes OpenCV FileStorage YAML.",
               "translume calibrate camera"};
  std::string dir, board_text, out;
  calib::CameraCalibOptions o;
  app.add_option("IMAGES_DIR", dir, "Folder of board photos")->required();
  app.add_option("--board", board_text, "Board specification")->required();
  app.add_option("--min-views", o.min_views, "Fewest usable views")->capture_default_str();
  app.add_option("--outlier-factor", o.outlier_factor,
                 "Drop views with RMS above this multiple of the median")->capture_default_str();
  app.add_option("-o,--output", out, "Output calibration (.yml)")->required();
  AddCommonOptions(app);
  if (ParseOrHelp(app, argc, argv)) return 0;
  RequireExtension(out, {".yml", ".yaml", ".xml"}, "-o");
  RequireNotInput("-o", out, {dir});
  const calib::BoardSpec board = calib::BoardSpec::Parse(board_text);
  const calib::CameraCalibration c = calib::CalibrateCamera(board, calib::ReadPhotoFolder(dir), o);
  WriteAtomically(out, [&](const std::string& tmp) {
    calib::WriteCameraCalibration(tmp, c, board.ToString());
  });
  std::printf("wrote %s: %s\n", out.c_str(), c.BriefReport().c_str());
  for (const std::string& d : c.dropped) std::printf("  dropped %s\n", d.c_str());
  return 0;
}

int RunCalibrateProjector(int argc, char** argv) {
  CLI::App app{"Projector intrinsics and camera-projector pose from planes (docs/capture.md):\n"
               "PLANES_DIR holds NAME_board.EXT (printed board on the plane) and\n"
               "NAME_pattern.EXT (projected chessboard on the same plane) per plane pose.\n"
               "--write-pattern writes the chessboard image to show on the projector.",
               "translume calibrate projector"};
  std::string dir, camera_path, board_text, pattern_text = "11x7:64", size = "1024x768", out,
      write_pattern;
  calib::ProjectorCalibOptions o;
  app.add_option("PLANES_DIR", dir, "Folder of plane photos");
  app.add_option("--camera", camera_path, "Camera calibration (.yml, translume calibrate camera)");
  app.add_option("--board", board_text, "Printed board specification");
  app.add_option("--pattern", pattern_text, "Projected chessboard COLSxROWS:SQUARE_PX (inner "
                 "corners), centred")->capture_default_str();
  app.add_option("--projector-size", size, "Projector resolution WxH")->capture_default_str();
  app.add_option("--min-planes", o.min_planes, "Fewest usable planes")->capture_default_str();
  app.add_flag("--rear", o.rear_projection, "Rear projection (back-lit rig): the projector lights "
               "the plane, a diffusing screen, from behind, so the camera sees the pattern mirrored");
  app.add_option("--max-rms", o.max_rms_px, "Refuse a calibration whose reprojection RMS (projector fit or "
                 "stereo) is above this, px")->capture_default_str();
  app.add_option("--write-pattern", write_pattern, "Write the pattern image (.png) and exit");
  app.add_option("-o,--output", out, "Output calibration (.yml)");
  AddCommonOptions(app);
  if (ParseOrHelp(app, argc, argv)) return 0;
  const calib::ProjectorChessboard pattern = calib::ParseProjectorChessboard(pattern_text, size);
  if (!write_pattern.empty()) {
    RequireExtension(write_pattern, {".png"}, "--write-pattern");
    RequireNotInput("--write-pattern", write_pattern, {dir, camera_path});
    WriteAtomically(write_pattern, [&](const std::string& tmp) {
      calib::WriteImage8(tmp, pattern.MakeImage());
    });
    std::printf("wrote %s: %dx%d projector chessboard, %dx%d inner corners of %d px\n",
                write_pattern.c_str(), pattern.projector_size.width,
                pattern.projector_size.height, pattern.cols, pattern.rows, pattern.square_px);
    return 0;
  }
  std::vector<std::string> missing;
  for (const auto& [value, name] : {std::pair{&dir, "PLANES_DIR"}, {&camera_path, "--camera"},
                                    {&board_text, "--board"}, {&out, "-o"}})
    if (value->empty()) missing.push_back(name);
  if (!missing.empty()) {
    std::string names = missing[0];
    for (size_t k = 1; k < missing.size(); ++k) names += (k + 1 < missing.size() ? ", " : " and ") + missing[k];
    throw CLI::RequiredError(names + (missing.size() > 1 ? " are required" : " is required"),
                             CLI::ExitCodes::RequiredError);
  }
  RequireExtension(out, {".yml", ".yaml", ".xml"}, "-o");
  RequireNotInput("-o", out, {dir, camera_path});
  const calib::BoardSpec board = calib::BoardSpec::Parse(board_text);
  const calib::CameraCalibration camera = calib::ReadCameraCalibration(camera_path);
  const calib::ProjectorCalibration p =
      calib::CalibrateProjector(camera, board, pattern, calib::ReadPlaneFolder(dir), o);
  WriteAtomically(out, [&](const std::string& tmp) {
    calib::WriteProjectorCalibration(tmp, p, camera, pattern_text + " on " + size);
  });
  std::printf("wrote %s: %s\n", out.c_str(), p.BriefReport().c_str());
  for (const std::string& d : p.dropped) std::printf("  dropped %s\n", d.c_str());
  return 0;
}

int RunCalibrateResponse(int argc, char** argv) {
  CLI::App app{"Camera response curve (Debevec & Malik 1997) from 8-bit exposure stacks, one\n"
               "folder each (exposure times from EXIF or exposures.json).",
               "translume calibrate response"};
  std::vector<std::string> dirs;
  std::string out;
  calib::ResponseOptions o;
  app.add_option("STACKS", dirs, "Exposure stack folders")->required();
  app.add_option("--samples", o.samples_per_stack, "Pixels sampled per stack")->capture_default_str();
  app.add_option("--smoothness", o.smoothness, "Smoothness weight lambda")->capture_default_str();
  std::string times = "auto";
  AddExposureTimesOption(app, times,
                         "fits both readings where the times include camera labels and keeps the better");
  app.add_option("-o,--output", out, "Output response curve (.yml)")->required();
  AddCommonOptions(app);
  if (ParseOrHelp(app, argc, argv)) return 0;
  o.shutter = calib::ParseShutterTimes(times, "--exposure-times");
  RequireExtension(out, {".yml", ".yaml", ".xml"}, "-o");
  RequireNotInput("-o", out, dirs);
  std::vector<calib::ExposureStack> stacks;
  for (const std::string& d : dirs) stacks.push_back(calib::ReadExposureStack(d));
  const calib::ResponseCurve curve = calib::CalibrateResponse(stacks, o);
  WriteAtomically(out, [&](const std::string& tmp) { calib::WriteResponse(tmp, curve); });
  std::printf("wrote %s: response from %zu stacks; linear value of code 32 / 224 "
              "(code 128 = 1): R %.4f %.4f, G %.4f %.4f, B %.4f %.4f\n",
              out.c_str(), stacks.size(), curve.lut.at<cv::Vec3f>(32)[0], curve.lut.at<cv::Vec3f>(224)[0],
              curve.lut.at<cv::Vec3f>(32)[1], curve.lut.at<cv::Vec3f>(224)[1],
              curve.lut.at<cv::Vec3f>(32)[2], curve.lut.at<cv::Vec3f>(224)[2]);
  std::printf("%s\n", curve.ShutterReport().c_str());
  return 0;
}

// A linear HDR image: an .exr file, or an exposure stack folder merged here.

int RunCalibrateWhite(int argc, char** argv) {
  CLI::App app{"White balance gains (camera HDR -> radiance in the projector's units of incoming\n"
               "light) from the HDR of a reference target under projector full white, minus the\n"
               "HDR under projector black. WHITE and --black are .exr files or exposure stack\n"
               "folders. Target: --chart colorchecker, or --patch X1,Y1,..,X4,Y4 --albedo A[,A,A].",
               "translume calibrate white"};
  std::string white_path, black_path, response_path, chart, patch, albedo_text, out;
  app.add_option("WHITE", white_path, "HDR (.exr) or stack folder under projector white")->required();
  app.add_option("--black", black_path, "HDR (.exr) or stack folder under projector black");
  app.add_option("--response", response_path, "Response curve for 8-bit stacks");
  app.add_option("--chart", chart, "Reference chart: colorchecker");
  app.add_option("--patch", patch, "Image corners of a white patch X1,Y1,X2,Y2,X3,Y3,X4,Y4");
  app.add_option("--albedo", albedo_text, "Albedo of the patch: A or R,G,B");
  std::string times = "auto";
  AddExposureTimesOption(app, times, "8-bit photos as the response was fitted, linear ones as each stack's "
                                     "brightness steps say; give the reading the lighting stacks take");
  std::string sensor_black, camera_flat_path;
  AddSensorBlackOption(app, sensor_black);
  app.add_option("--camera-flat", camera_flat_path,
                 "HDR (.exr) or stack folder of an evenly lit field through the lens (its vignetting): WHITE and "
                 "--black are divided by it, as acquire divides a capture's images (capture.json camera_flat)");
  app.add_option("-o,--output", out, "Output white balance (.yml)")->required();
  AddCommonOptions(app);
  if (ParseOrHelp(app, argc, argv)) return 0;
  calib::MergeOptions merge;
  merge.shutter = calib::ParseShutterTimes(times, "--exposure-times");
  merge.sensor_black = ParseSensorBlack(sensor_black);
  RequireExtension(out, {".yml", ".yaml", ".xml"}, "-o");
  const std::vector<std::string> inputs{white_path, black_path, response_path, camera_flat_path};
  RequireNotInput("-o", out, inputs);
  if (chart.empty() == patch.empty())
    throw calib::CalibError("give either --chart colorchecker or --patch (with --albedo)");
  if (!chart.empty() && chart != "colorchecker")
    throw calib::CalibError(fmt::format("--chart {}: only 'colorchecker' is known", chart));
  std::vector<cv::Point2f> corners;
  cv::Vec3d albedo;
  if (!patch.empty()) {
    if (albedo_text.empty()) throw calib::CalibError("--patch needs --albedo");
    const std::vector<double> p = ParseNumbers(patch, "--patch", 8, 8);
    for (int k = 0; k < 4; ++k) corners.emplace_back(float(p[2 * k]), float(p[2 * k + 1]));
    if (std::abs(cv::contourArea(corners)) < 1)
      throw calib::CalibError(fmt::format("--patch {}: the four corners enclose no area", patch));
    const std::vector<double> a = ParseNumbers(albedo_text, "--albedo", 1, 3);
    albedo = a.size() == 1 ? cv::Vec3d::all(a[0]) : cv::Vec3d(a[0], a[1], a[2]);
  }
  calib::ResponseCurve curve;
  if (!response_path.empty()) curve = calib::ReadResponse(response_path);
  const calib::ResponseCurve* response = response_path.empty() ? nullptr : &curve;
  // A stack merged here, its time warning shown (one per stack).
  auto read = [&](const std::string& path, calib::HdrReadInfo* info = nullptr) {
    calib::HdrReadInfo own;
    if (!info) info = &own;
    cv::Mat img = calib::ReadHdrOrStack(path, response, merge, info);
    if (!info->time_warning.empty()) std::printf("calibrate white: warning: %s\n", info->time_warning.c_str());
    return img;
  };
  calib::HdrReadInfo white_read;
  cv::Mat white = read(white_path, &white_read);
  const calib::ShutterTimes white_times = white_read.shutter;
  cv::Mat black = black_path.empty() ? cv::Mat() : read(black_path);
  if (!camera_flat_path.empty()) {
    const cv::Mat flat = calib::NormalizedCameraFlat(read(camera_flat_path), camera_flat_path);
    for (auto [img, path] : {std::pair<cv::Mat*, const std::string*>{&white, &white_path},
                             std::pair<cv::Mat*, const std::string*>{&black, &black_path}}) {
      if (img->empty()) continue;
      if (img->size() != flat.size())
        throw calib::CalibError(fmt::format("{}: images are {}x{} but --camera-flat {} is {}x{}", *path, img->cols,
                                            img->rows, camera_flat_path, flat.cols, flat.rows));
      cv::divide(*img, flat, *img);
    }
  }
  calib::WhiteBalance w;
  try {
    w = patch.empty() ? calib::WhiteFromColorChecker(white, black)
                      : calib::WhiteFromPatch(white, black, corners, albedo);
  } catch (const calib::CalibError& e) {
    throw calib::CalibError(fmt::format("{}{}: {}", white_path, black_path.empty() ? "" : " and --black " + black_path,
                                        e.what()));
  }
  if (white_times != calib::ShutterTimes::kAuto) w.exposure_times = calib::ToString(white_times);
  w.sensor_black = merge.sensor_black;
  w.camera_flat = !camera_flat_path.empty();
  cv::Vec3d black_mean(0, 0, 0);
  if (!black.empty()) {
    const cv::Scalar m = cv::mean(black);
    black_mean = cv::Vec3d(m[0], m[1], m[2]);
  }
  const std::string black_image =
      !black_path.empty() && !fs::is_directory(black_path) ? fs::absolute(black_path).string() : "";
  WriteAtomically(out, [&](const std::string& tmp) {
    calib::WriteWhiteBalance(tmp, w, black_mean, black_image);
  });
  std::printf("wrote %s: %s%s\n", out.c_str(), w.BriefReport().c_str(),
              white_times == calib::ShutterTimes::kAuto
                  ? ""
                  : ("; exposure times " + std::string(calib::Describe(white_times))).c_str());
  return 0;
}

struct CalibrateSubcommand {
  const char* name;
  const char* help;
  int (*run)(int, char**);
};

const CalibrateSubcommand kCalibrateSubcommands[] = {
    {"camera", "Camera intrinsics from photos of a printed board", RunCalibrateCamera},
    {"projector", "Projector intrinsics and camera-projector pose from board planes", RunCalibrateProjector},
    {"response", "Camera response curve from 8-bit exposure stacks", RunCalibrateResponse},
    {"white", "White balance gains and black level under projector white", RunCalibrateWhite},
};

}  // namespace

std::vector<std::string> CalibrateSubcommands() {
  std::vector<std::string> names;
  for (const CalibrateSubcommand& c : kCalibrateSubcommands) names.emplace_back(c.name);
  return names;
}

int RunCalibrate(int argc, char** argv) {
  std::string usage =
      "usage: translume calibrate SUBCOMMAND [options]   (translume calibrate SUBCOMMAND --help)\n\n"
      "subcommands:\n";
  for (const CalibrateSubcommand& c : kCalibrateSubcommands) usage += fmt::format("  {:<11} {}\n", c.name, c.help);
  usage += "Photo protocol: docs/capture.md.\n";
  // "calibrate --threads N camera ..." is "calibrate camera ... --threads N" (every command
  // takes --threads; the subcommand parses it).
  std::vector<char*> args(argv, argv + argc);
  size_t first = 1;
  while (first < args.size() && std::string(args[first]).rfind("--threads", 0) == 0)
    first += std::strchr(args[first], '=') ? 1 : 2;
  if (first > 1 && first < args.size()) {
    std::rotate(args.begin() + 1, args.begin() + long(first), args.end());
    argc = int(args.size());
    argv = args.data();
  }
  if (argc < 2 || !std::strcmp(argv[1], "--help") || !std::strcmp(argv[1], "-h")) {
    std::fputs(usage.c_str(), argc < 2 ? stderr : stdout);
    return argc < 2 ? 2 : 0;
  }
  const std::string sub = argv[1];
  return OneLineErrors([&] {
    for (const CalibrateSubcommand& c : kCalibrateSubcommands)
      if (sub == c.name) return c.run(argc - 1, argv + 1);
    throw calib::CalibError(
        fmt::format("unknown subcommand '{}' ({})", sub, fmt::join(CalibrateSubcommands(), ", ")));
  });
}

int RunHdr(int argc, char** argv) {
  CLI::App app{"Merge an exposure stack (a folder of photos; times from EXIF or exposures.json)\n"
               "into a linear HDR radiance image (OpenEXR, per second). 8-bit photos need\n"
               "--response; 16-bit, float and camera RAW photos are linear. Channels saturated\n"
               "in every exposure are written as +inf and counted.",
               "translume hdr"};
  std::string dir, response_path, black_dir, out;
  calib::MergeOptions o;
  app.add_option("STACK_DIR", dir, "Exposure stack folder")->required();
  app.add_option("--response", response_path, "Response curve (.yml) for 8-bit photos");
  app.add_option("--black", black_dir, "Black frame stack (same exposure times) to subtract");
  app.add_option("--low", o.low_code, "8-bit: highest under-exposed code")->capture_default_str();
  app.add_option("--high", o.high_code, "8-bit: lowest saturated code")->capture_default_str();
  std::string times = "auto";
  AddExposureTimesOption(app, times, "8-bit photos as the response was fitted, linear ones as "
                                     "this stack's brightness steps say");
  std::string sensor_black;
  AddSensorBlackOption(app, sensor_black);
  app.add_option("-o,--output", out, "Output HDR image (.exr)")->required();
  AddCommonOptions(app);
  if (ParseOrHelp(app, argc, argv)) return 0;
  return OneLineErrors([&] {
    o.shutter = calib::ParseShutterTimes(times, "--exposure-times");
    o.sensor_black = ParseSensorBlack(sensor_black);
    RequireExtension(out, {".exr"}, "-o");
    const std::vector<std::string> inputs{dir, black_dir, response_path};
    RequireNotInput("-o", out, inputs);
    calib::ResponseCurve curve;
    if (!response_path.empty()) curve = calib::ReadResponse(response_path);
    const calib::ExposureStack stack = calib::ReadExposureStack(dir);
    if (response_path.empty() && stack.IsEightBit())
      throw calib::CalibError(dir + ": 8-bit photos need --response (a curve from translume calibrate response)");
    if (!response_path.empty() && !stack.IsEightBit())
      std::printf("hdr: note: %s holds 16-bit, float or RAW photos, which are linear: --response %s is not used\n",
                  dir.c_str(), response_path.c_str());
    calib::ExposureStack black;
    if (!black_dir.empty()) black = calib::ReadExposureStack(black_dir);
    if (o.shutter == calib::ShutterTimes::kAuto && !stack.IsEightBit() && calib::HasApexLabels(stack)) {
      const calib::ShutterChoice choice = calib::ChooseShutterTimes(stack, black_dir.empty() ? nullptr : &black, o);
      std::printf("hdr: %s\n", choice.BriefReport().c_str());
      o.shutter = choice.times;
    }
    const calib::HdrImage h = calib::MergeHdr(stack, response_path.empty() ? nullptr : &curve,
                                              black_dir.empty() ? nullptr : &black, o);
    WriteAtomically(out, [&](const std::string& tmp) { calib::WriteExr(tmp, h.radiance); });
    if (stack.IsEightBit() && calib::HasApexLabels(stack))
      std::printf("hdr: exposure times %s, %s\n",
                  calib::Describe(h.shutter),
                  times != "auto" ? "as --exposure-times says" : "as the response was fitted");
    if (!h.time_warning.empty()) std::printf("hdr: warning: %s\n", h.time_warning.c_str());
    std::printf("wrote %s: %zu exposures, %s\n", out.c_str(), stack.exposures.size(),
                h.BriefReport().c_str());
    return 0;
  });
}

}  // namespace translume
