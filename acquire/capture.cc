// SPDX-License-Identifier: MIT
#include "acquire/capture.h"

#include <algorithm>
#include <fmt/format.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>

#include "acquire/face_mapping.h"
#include "calib/board.h"
#include "calib/error.h"
#include "calib/hdr.h"
#include "calib/photo_io.h"
#include "solver/dataset.h"
#include "solver/json_file.h"
#include "solver/material.h"
#include "solver/status.h"

namespace translume::acquire {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

constexpr const char* kFormat = "translume-capture/1";

// Field access that names the file and the field in every error.
class Reader {
 public:
  Reader(std::string file, std::string dir) : file_(std::move(file)), dir_(std::move(dir)) {}

  [[noreturn]] void Fail(const std::string& field, const std::string& why) const {
    throw InputError(fmt::format("{}: {}: {}", file_, field, why));
  }
  void CheckKeys(const json& obj, const std::string& where, const std::set<std::string>& known) const {
    for (const auto& [k, v] : obj.items())
      if (!known.count(k)) Fail(where.empty() ? k : where + "." + k, "unknown field");
  }
  const json& Get(const json& obj, const std::string& key, const std::string& where) const {
    if (!obj.contains(key)) Fail(where + key, "missing");
    return obj.at(key);
  }
  std::string String(const json& v, const std::string& field) const {
    if (!v.is_string()) Fail(field, "expected a string");
    return v.get<std::string>();
  }
  double Positive(const json& v, const std::string& field) const {
    if (!v.is_number()) Fail(field, "expected a number");
    const double x = v.get<double>();
    if (!(x > 0) || !std::isfinite(x)) Fail(field, fmt::format("must be positive, got {}", x));
    return x;
  }
  template <size_t N>
  std::array<double, N> Numbers(const json& v, const std::string& field) const {
    if (!v.is_array() || v.size() != N) Fail(field, fmt::format("expected {} numbers", N));
    std::array<double, N> out{};
    for (size_t i = 0; i < N; ++i) {
      if (!v[i].is_number()) Fail(field, fmt::format("expected {} numbers", N));
      out[i] = v[i].get<double>();
      if (!std::isfinite(out[i])) Fail(field, "not finite");
    }
    return out;
  }
  std::vector<std::array<double, 2>> Corners(const json& v, const std::string& field) const {
    if (!v.is_array() || v.size() != 4) Fail(field, "expected 4 [x, y] pixel pairs");
    std::vector<std::array<double, 2>> out;
    for (const json& p : v) out.push_back(Numbers<2>(p, field));
    std::vector<cv::Point2d> points;
    for (const auto& p : out) points.emplace_back(p[0], p[1]);
    if (std::string why = QuadrilateralProblem(points); !why.empty()) Fail(field, why);
    return out;
  }
  // A path relative to the folder that must exist (a folder when `folder`).
  std::string Path(const json& v, const std::string& field, bool folder) const {
    const std::string rel = String(v, field);
    const fs::path p = fs::path(dir_) / rel;
    if (folder ? !fs::is_directory(p) : !fs::is_regular_file(p))
      Fail(field, !fs::exists(p) ? fmt::format("{} {} not found", folder ? "folder" : "file", p.string())
                  : folder       ? fmt::format("{} is a file, expected a folder", p.string())
                                 : fmt::format("{} is a folder, expected a file", p.string()));
    return p.string();
  }
  // Runs a calib parser over a field's text; its CalibError becomes this file's InputError,
  // under `field` (empty: the message names the field itself).
  template <typename F>
  void Parse(const std::string& field, F&& parse) const {
    try {
      parse();
    } catch (const calib::CalibError& e) {
      if (!field.empty()) Fail(field, e.what());
      throw InputError(fmt::format("{}: {}", file_, e.what()));
    }
  }

 private:
  std::string file_, dir_;
};

}  // namespace

LightSpec CaptureSpec::Condition::Light(const std::string& dir) const {
  LightSpec l = LightSpec::Parse(light);
  if (l.kind == LightSpec::Kind::kImage && fs::path(l.image_path).is_relative())
    l.image_path = (fs::path(dir) / l.image_path).string();
  return l;
}

CaptureSpec ReadCapture(const std::string& path) {
  CaptureSpec s;
  const bool is_dir = fs::is_directory(path);
  const fs::path dir = is_dir ? fs::path(path) : fs::path(path).parent_path();
  s.dir = (dir.empty() ? fs::path(".") : dir).string();
  s.file = is_dir ? (fs::path(path) / "capture.json").string() : path;
  const json j = ReadJsonFile(s.file, " (a capture folder holds capture.json)");
  const Reader r(s.file, s.dir);
  if (!j.is_object()) r.Fail("(top level)", "expected an object");
  r.CheckKeys(j, "", {"format", "setup", "sample_mm", "spacing_mm", "grid", "eta", "C",
                      "face_corners_px", "camera_blur_px", "camera", "projector", "response", "white", "black",
                      "conditions", "exposure_times", "sensor_black", "camera_flat", "comment"});
  if (r.String(r.Get(j, "format", ""), "format") != kFormat)
    r.Fail("format", fmt::format("expected \"{}\"", kFormat));
  const std::string setup = r.String(r.Get(j, "setup", ""), "setup");
  if (setup != "back" && setup != "front") r.Fail("setup", "expected \"back\" or \"front\"");
  s.setup = setup == "back" ? Setup::kBack : Setup::kFront;
  s.size_mm = r.Numbers<3>(r.Get(j, "sample_mm", ""), "sample_mm");
  for (double v : s.size_mm)
    if (!(v > 0)) r.Fail("sample_mm", "every extent must be positive");
  if (j.contains("spacing_mm") == j.contains("grid"))
    r.Fail("spacing_mm", "give exactly one of spacing_mm and grid");
  int64_t n[3];
  if (j.contains("spacing_mm")) {
    s.spacing_mm = r.Positive(j["spacing_mm"], "spacing_mm");
    if (std::string why = SpacingProblem(s.spacing_mm); !why.empty()) r.Fail("spacing_mm", why);
    for (int a = 0; a < 3; ++a) {
      const double cells = s.size_mm[size_t(a)] / s.spacing_mm;
      if (!(cells < double(kMaxGridAxis)))
        r.Fail("spacing_mm", fmt::format("sample_mm[{}] = {:g} mm is {:.3g} spacings of {:g} mm, more than "
                                         "the {:g} nodes a grid axis may have", a, s.size_mm[size_t(a)],
                                         cells, s.spacing_mm, double(kMaxGridAxis)));
      if (std::abs(cells - std::round(cells)) > 1e-3 * std::max(1.0, cells))
        r.Fail("spacing_mm",
               fmt::format("sample_mm[{}] = {} is not a whole number of spacings {}: give {:g} or {:g} (the "
                           "grid's extent; acquire warns where the photos show the block's width is off)",
                           a, s.size_mm[size_t(a)], s.spacing_mm, std::floor(cells) * s.spacing_mm,
                           std::ceil(cells) * s.spacing_mm));
      n[a] = int64_t(std::llround(cells)) + 1;
    }
  } else {
    const auto g = r.Numbers<3>(j["grid"], "grid");
    for (int a = 0; a < 3; ++a) {
      const double v = g[size_t(a)];
      if (v != std::floor(v)) r.Fail("grid", fmt::format("expected 3 whole numbers of nodes, got {:g}", v));
      if (!(v >= 2 && v <= double(kMaxGridAxis)))
        r.Fail("grid", fmt::format("every axis must have 2..{:g} nodes, got {:g}", double(kMaxGridAxis), v));
      n[a] = int64_t(v);
    }
    s.spacing_mm = s.size_mm[0] / double(n[0] - 1);
    if (std::string why = SpacingProblem(s.spacing_mm); !why.empty())
      r.Fail("grid", "the spacing sample_mm[0] / (grid[0] - 1) " + why);
    for (int a = 0; a < 3; ++a)
      if (n[a] < 2 || std::abs(s.size_mm[size_t(a)] / double(n[a] - 1) - s.spacing_mm) > 1e-3 * s.spacing_mm)
        r.Fail("grid", "must have >= 2 nodes per axis and equal spacing on every axis "
                       "(sample_mm[a] / (grid[a] - 1))");
  }
  s.grid = {n[0], n[1], n[2]};
  if (j.contains("eta") && j.contains("C")) r.Fail("C", "give eta or C, not both");
  if (j.contains("eta")) {
    s.eta = r.Positive(j["eta"], "eta");
    if (!(s.eta > 1 && s.eta <= 3.5)) r.Fail("eta", "must be a refractive index in (1, 3.5]");
  }
  s.C = j.contains("C") ? r.Positive(j["C"], "C") : ReflectionParameterC(s.eta);
  if (s.C < 1) r.Fail("C", "must be >= 1");
  if (j.contains("face_corners_px") && !(j["face_corners_px"].is_string() && j["face_corners_px"] == "auto")) {
    const json& c = j["face_corners_px"];
    if (c.is_object()) {
      for (const auto& [k, v] : c.items())
        if (k != "near") r.Fail("face_corners_px." + k, "unknown field (\"near\" is the one)");
      if (!c.contains("near")) r.Fail("face_corners_px", "expected \"auto\", four [x, y] corners or {\"near\": four corners}");
      s.face_corners_px = r.Corners(c["near"], "face_corners_px.near");
      s.face_corners_near = true;
    } else {
      s.face_corners_px = r.Corners(c, "face_corners_px");
    }
  }
  if (j.contains("camera_blur_px") && !(j["camera_blur_px"].is_string() && j["camera_blur_px"] == "auto")) {
    const json& b = j["camera_blur_px"];
    if (!b.is_number() || !(b.get<double>() >= 0 && b.get<double>() <= 5))
      r.Fail("camera_blur_px", "expected \"auto\" or a Gaussian sigma in pixels, 0 to 5");
    s.camera_blur_px = b.get<double>();
  }

  const json& cam = r.Get(j, "camera", "");
  if (cam.is_string()) {
    s.camera.file = r.Path(cam, "camera", false);
  } else if (cam.is_object()) {
    r.CheckKeys(cam, "camera", {"photos", "board"});
    s.camera.photos = r.Path(r.Get(cam, "photos", "camera."), "camera.photos", true);
    s.camera.board = r.String(r.Get(cam, "board", "camera."), "camera.board");
    r.Parse("camera.board", [&] { calib::BoardSpec::Parse(s.camera.board); });
  } else {
    r.Fail("camera", "expected a calibration file or {\"photos\", \"board\"}");
  }
  if (j.contains("projector") && !j["projector"].is_null()) {
    const json& p = j["projector"];
    s.projector.rear = s.setup == Setup::kBack;
    if (p.is_string()) {
      s.projector.file = r.Path(p, "projector", false);
    } else if (p.is_object()) {
      r.CheckKeys(p, "projector", {"planes", "board", "pattern", "projector_size", "rear"});
      s.projector.planes = r.Path(r.Get(p, "planes", "projector."), "projector.planes", true);
      s.projector.board = r.String(r.Get(p, "board", "projector."), "projector.board");
      r.Parse("projector.board", [&] { calib::BoardSpec::Parse(s.projector.board); });
      if (p.contains("pattern")) s.projector.pattern = r.String(p["pattern"], "projector.pattern");
      if (p.contains("projector_size"))
        s.projector.projector_size = r.String(p["projector_size"], "projector.projector_size");
      r.Parse("", [&] {
        calib::ParseProjectorChessboard(s.projector.pattern, s.projector.projector_size, "projector.pattern",
                                        "projector.projector_size");
      });
      if (p.contains("rear")) {
        if (!p["rear"].is_boolean()) r.Fail("projector.rear", "expected true or false");
        s.projector.rear = p["rear"].get<bool>();
      }
    } else {
      r.Fail("projector", "expected a calibration file or {\"planes\", \"board\", ...}");
    }
  }
  const json& resp = r.Get(j, "response", "");
  if (resp.is_string() && resp == "linear") {
    s.response.linear = true;
  } else if (resp.is_string()) {
    s.response.file = r.Path(resp, "response", false);
  } else if (resp.is_object()) {
    r.CheckKeys(resp, "response", {"stacks"});
    const json& st = r.Get(resp, "stacks", "response.");
    if (!st.is_array() || st.empty()) r.Fail("response.stacks", "expected a list of folders");
    for (const json& d : st) s.response.stacks.push_back(r.Path(d, "response.stacks", true));
  } else {
    r.Fail("response", "expected \"linear\", a calibration file or {\"stacks\": [...]}");
  }
  const json& w = r.Get(j, "white", "");
  if (w.is_string()) {
    s.white.file = r.Path(w, "white", false);
  } else if (w.is_object()) {
    r.CheckKeys(w, "white", {"white", "black", "patch", "albedo", "flat_field"});
    auto stack_or_exr = [&](const json& v, const std::string& field) {
      const std::string p = (fs::path(s.dir) / r.String(v, field)).string();
      if (!fs::exists(p)) r.Fail(field, fmt::format("{} not found", p));
      return p;
    };
    s.white.white = stack_or_exr(r.Get(w, "white", "white."), "white.white");
    if (w.contains("black")) s.white.black = stack_or_exr(w["black"], "white.black");
    s.white.patch = r.Corners(r.Get(w, "patch", "white."), "white.patch");
    if (w.contains("flat_field")) {
      if (!w["flat_field"].is_boolean()) r.Fail("white.flat_field", "expected true or false");
      s.white.flat_field = w["flat_field"].get<bool>();
    }
    const json& a = r.Get(w, "albedo", "white.");
    if (a.is_number()) {
      const double v = r.Positive(a, "white.albedo");
      s.white.albedo = {v, v, v};
    } else {
      s.white.albedo = r.Numbers<3>(a, "white.albedo");
    }
    for (double v : s.white.albedo)
      if (!(v > 0 && v <= 1)) r.Fail("white.albedo", "must be in (0, 1]");
  } else {
    r.Fail("white", "expected a calibration file or {\"white\", \"patch\", \"albedo\", ...}");
  }
  if (j.contains("black")) s.black = r.Path(j["black"], "black", true);
  if (j.contains("camera_flat")) {
    s.camera_flat = (fs::path(s.dir) / r.String(j["camera_flat"], "camera_flat")).string();
    if (!fs::exists(s.camera_flat)) r.Fail("camera_flat", fmt::format("{} not found", s.camera_flat));
  }
  if (j.contains("exposure_times")) {
    const std::string times = r.String(j["exposure_times"], "exposure_times");
    if (times != "auto" && times != "labelled" && times != "apex")
      r.Fail("exposure_times", "expected \"auto\", \"labelled\" or \"apex\"");
    s.exposure_times = calib::ParseShutterTimes(times, s.file);
  }
  if (j.contains("sensor_black")) {
    const json& b = j["sensor_black"];
    if (b.is_number()) s.sensor_black.fill(b.get<double>());
    else if (b.is_array()) s.sensor_black = r.Numbers<3>(b, "sensor_black");
    else r.Fail("sensor_black", "expected a number or 3 numbers (fractions of full scale)");
    if (std::string why = calib::SensorBlackProblem({s.sensor_black[0], s.sensor_black[1], s.sensor_black[2]});
        !why.empty())
      r.Fail("sensor_black", why);
    if (!s.response.linear && s.sensor_black != std::array<double, 3>{})
      r.Fail("sensor_black", "applies to linear photos (\"response\": \"linear\"); an 8-bit camera's response "
                             "curve holds its black level");
  }

  const json& cs = r.Get(j, "conditions", "");
  if (!cs.is_array() || cs.empty()) r.Fail("conditions", "expected a non-empty list");
  std::set<std::string> names;
  for (size_t m = 0; m < cs.size(); ++m) {
    const std::string where = fmt::format("conditions[{}]", m);
    const json& c = cs[m];
    if (!c.is_object()) r.Fail(where, "expected an object");
    r.CheckKeys(c, where, {"name", "stack", "pattern", "light", "validation"});
    CaptureSpec::Condition cond;
    cond.name = r.String(r.Get(c, "name", where + "."), where + ".name");
    // The name becomes file names in the work folder and the node-space dataset: the
    // dataset's rule, checked here before minutes of calibration and HDR.
    if (!IsSafeConditionName(cond.name))
      r.Fail(where + ".name", fmt::format("'{}' must be 1-100 characters of [A-Za-z0-9_.-]", cond.name));
    if (!names.insert(cond.name).second) r.Fail(where + ".name", "duplicate name " + cond.name);
    cond.stack = r.Path(r.Get(c, "stack", where + "."), where + ".stack", true);
    if (c.contains("pattern") == c.contains("light"))
      r.Fail(where, "give exactly one of pattern (projector image) and light (spec on the lit face)");
    if (c.contains("pattern")) {
      cond.pattern = r.Path(c["pattern"], where + ".pattern", false);
      if (!s.projector.present())
        r.Fail(where + ".pattern", "projector patterns need a projector calibration (field projector)");
    } else {
      cond.light = r.String(c["light"], where + ".light");
      LightSpec light;
      std::string bad;
      try {
        light = cond.Light(s.dir);
      } catch (const InputError& e) {
        bad = e.what();
      }
      if (!bad.empty()) r.Fail(where + ".light", bad);
      if (light.kind == LightSpec::Kind::kImage && !fs::is_regular_file(light.image_path))
        r.Fail(where + ".light", "file " + light.image_path + " not found");
    }
    if (c.contains("validation")) {
      if (!c["validation"].is_boolean()) r.Fail(where + ".validation", "expected true or false");
      cond.validation = c["validation"].get<bool>();
    }
    s.conditions.push_back(cond);
  }
  if (std::none_of(s.conditions.begin(), s.conditions.end(), [](const auto& c) { return !c.validation; }))
    r.Fail("conditions", "every condition is a validation condition; the fit needs at least one other");
  return s;
}

std::string CaptureJson(const CaptureSpec& s) {
  auto rel = [&](const std::string& p) { return fs::path(p).lexically_relative(s.dir).generic_string(); };
  json j;
  j["format"] = kFormat;
  j["setup"] = SetupName(s.setup);
  j["sample_mm"] = s.size_mm;
  j["spacing_mm"] = s.spacing_mm;
  if (std::abs(s.C - ReflectionParameterC(s.eta)) < 1e-12) j["eta"] = s.eta;
  else j["C"] = s.C;
  if (s.face_corners_px.empty()) j["face_corners_px"] = "auto";
  else if (s.face_corners_near) j["face_corners_px"] = {{"near", s.face_corners_px}};
  else j["face_corners_px"] = s.face_corners_px;
  if (s.camera_blur_px) j["camera_blur_px"] = *s.camera_blur_px;
  else j["camera_blur_px"] = "auto";
  if (!s.camera.file.empty()) j["camera"] = rel(s.camera.file);
  else j["camera"] = {{"photos", rel(s.camera.photos)}, {"board", s.camera.board}};
  if (!s.projector.file.empty()) {
    j["projector"] = rel(s.projector.file);
  } else if (!s.projector.planes.empty()) {
    j["projector"] = {{"planes", rel(s.projector.planes)}, {"board", s.projector.board},
                      {"pattern", s.projector.pattern},
                      {"projector_size", s.projector.projector_size}, {"rear", s.projector.rear}};
  }
  if (s.response.linear) {
    j["response"] = "linear";
  } else if (!s.response.file.empty()) {
    j["response"] = rel(s.response.file);
  } else {
    json st = json::array();
    for (const auto& d : s.response.stacks) st.push_back(rel(d));
    j["response"] = {{"stacks", st}};
  }
  if (!s.white.file.empty()) {
    j["white"] = rel(s.white.file);
  } else {
    j["white"] = {{"white", rel(s.white.white)}, {"patch", s.white.patch}, {"albedo", s.white.albedo}};
    if (!s.white.black.empty()) j["white"]["black"] = rel(s.white.black);
    if (s.white.flat_field) j["white"]["flat_field"] = true;
  }
  if (!s.black.empty()) j["black"] = rel(s.black);
  if (!s.camera_flat.empty()) j["camera_flat"] = rel(s.camera_flat);
  if (s.exposure_times != calib::ShutterTimes::kAuto) j["exposure_times"] = calib::ToString(s.exposure_times);
  if (s.sensor_black != std::array<double, 3>{}) {
    if (s.sensor_black[0] == s.sensor_black[1] && s.sensor_black[1] == s.sensor_black[2]) j["sensor_black"] = s.sensor_black[0];
    else j["sensor_black"] = s.sensor_black;
  }
  json cs = json::array();
  for (const auto& c : s.conditions) {
    json e = {{"name", c.name}, {"stack", rel(c.stack)}};
    if (!c.pattern.empty()) e["pattern"] = rel(c.pattern);
    else e["light"] = c.light;
    if (c.validation) e["validation"] = true;
    cs.push_back(e);
  }
  j["conditions"] = cs;
  return j.dump(2) + "\n";
}

}  // namespace translume::acquire
