// SPDX-License-Identifier: MIT
// Dataset files (ReadDataset, WriteDataset): OpenImageIO. The in-memory checks are in
// dataset_validate.cc, which the GPU benchmark links without the file libraries.
#include "solver/dataset.h"

#include <cmath>
#include <filesystem>
#include <fmt/format.h>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>

#include "solver/atomic_file.h"
#include "solver/image_io.h"
#include "solver/json_file.h"
#include "solver/status.h"

namespace translume {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;
constexpr const char* kFormat = "translume-dataset/1";

// Reads an image and checks its size and channel count against the dataset grid.
Image ReadFaceImage(const fs::path& file, const std::string& field, const GridShape& s,
                    int channels) {
  const Image img = ReadImage(file.string());
  if (img.width != s.nx || img.height != s.ny)
    throw InputError(fmt::format("{}: {} is {}x{} pixels but the grid face is {}x{} nodes",
                                 file.string(), field, img.width, img.height, s.nx, s.ny));
  if (img.channels != channels)
    throw InputError(fmt::format("{}: {} has {} channels, expected {}", file.string(), field,
                                 img.channels, channels));
  for (float v : img.data)
    if (!std::isfinite(v))
      throw InputError(fmt::format("{}: {} has a non-finite pixel", file.string(), field));
  return img;
}

FacePattern Planes(const Image& img) {
  FacePattern out;
  const size_t n = size_t(img.width) * img.height;
  for (int c = 0; c < 3; ++c) {
    out[c].resize(n);
    for (size_t p = 0; p < n; ++p) out[c][p] = img.data[p * 3 + c];
  }
  return out;
}

template <typename T>
T Field(const json& j, const char* key, const std::string& file) {
  if (!j.contains(key)) throw InputError(fmt::format("{}: missing field \"{}\"", file, key));
  try {
    return j.at(key).get<T>();
  } catch (const json::exception&) {
    throw InputError(fmt::format("{}: field \"{}\" has the wrong type", file, key));
  }
}

}  // namespace

std::string DatasetFolder(const std::string& path) {
  if (fs::is_directory(path)) return path;
  const fs::path parent = fs::path(path).parent_path();
  return parent.empty() ? "." : parent.string();
}

Dataset ReadDataset(const std::string& path) {
  fs::path file = path;
  if (fs::is_directory(file)) file /= "dataset.json";
  const std::string f = file.string();
  if (!fs::exists(file)) throw InputError(fmt::format("{}: no such file", f));
  const json j = ReadJsonFile(f);
  if (!j.is_object()) throw InputError(fmt::format("{}: expected a JSON object", f));
  const std::string format = Field<std::string>(j, "format", f);
  if (format != kFormat)
    throw InputError(fmt::format("{}: field \"format\" is '{}', expected '{}'", f, format, kFormat));
  Dataset d;
  const auto grid = Field<std::vector<int64_t>>(j, "grid", f);
  bool whole = j["grid"].is_array();
  for (const json& v : j["grid"]) whole &= v.is_number_integer();
  bool in_range = grid.size() == 3;
  for (int64_t n : grid) in_range &= n >= 2 && n <= kMaxGridAxis;
  if (!whole || !in_range)
    throw InputError(fmt::format("{}: field \"grid\" must be [nx, ny, nz], whole numbers within 2..{}", f,
                                 kMaxGridAxis));
  d.shape = {grid[0], grid[1], grid[2]};
  d.spacing_mm = Field<double>(j, "spacing_mm", f);
  if (const std::string p = SpacingProblem(d.spacing_mm); !p.empty())
    throw InputError(fmt::format("{}: field \"spacing_mm\" {}", f, p));
  d.C = Field<double>(j, "C", f);
  if (!(d.C >= 1 && d.C <= Dataset::kMaxC))
    throw InputError(fmt::format("{}: field \"C\" must be within 1..{:g}, got {:g}", f,
                                 Dataset::kMaxC, d.C));
  const std::string setup = Field<std::string>(j, "setup", f);
  if (setup != "back" && setup != "front")
    throw InputError(fmt::format("{}: field \"setup\" is '{}', expected 'back' or 'front'", f, setup));
  d.setup = setup == "back" ? Setup::kBack : Setup::kFront;
  if (!j.contains("conditions") || !j["conditions"].is_array() || j["conditions"].empty())
    throw InputError(fmt::format("{}: field \"conditions\" must be a non-empty array", f));
  const fs::path dir = file.parent_path();
  std::set<std::string> names;
  for (size_t i = 0; i < j["conditions"].size(); ++i) {
    const json& c = j["conditions"][i];
    const std::string where = fmt::format("{}: conditions[{}]", f, i);
    if (!c.is_object()) throw InputError(where + " must be an object");
    DatasetCondition cond;
    cond.name = Field<std::string>(c, "name", where);
    if (!IsSafeConditionName(cond.name))
      throw InputError(fmt::format("{}: name '{}' must be 1-100 characters of [A-Za-z0-9_.-]",
                                   where, cond.name));
    if (!names.insert(cond.name).second)
      throw InputError(fmt::format("{}: name '{}' appears twice", where, cond.name));
    const Image q = ReadFaceImage(dir / Field<std::string>(c, "q", where), "q", d.shape, 3);
    for (float v : q.data)
      if (v < 0) throw InputError(fmt::format("{}: q has a negative pixel", (dir / c["q"].get<std::string>()).string()));
    cond.q = Planes(q);
    const fs::path lf = dir / Field<std::string>(c, "L", where);
    const Image L = ReadFaceImage(lf, "L", d.shape, 3);
    // Radiance spans decades below white: 8 or 16 integer bits would round it away silently.
    if (L.integer_bits != 0)
      throw InputError(fmt::format("{}: L is stored as {}-bit integers; radiance must be a float or half "
                                   "image (EXR)", lf.string(), L.integer_bits));
    cond.L = Planes(L);
    if (c.contains("mask")) {
      const fs::path mf = dir / Field<std::string>(c, "mask", where);
      const Image m = ReadFaceImage(mf, "mask", d.shape, 1);
      for (float v : m.data)
        if (!(v >= 0 && v <= 1))
          throw InputError(fmt::format("{}: mask has a pixel outside [0, 1]", mf.string()));
      cond.mask = m.data;
    } else {
      cond.mask.assign(d.shape.face_size(), 1.0f);
    }
    d.conditions.push_back(std::move(cond));
  }
  if (const std::string err = d.Validate(); !err.empty()) throw InputError(fmt::format("{}: {}", f, err));
  return d;
}

void WriteDataset(const std::string& dir, const Dataset& d) {
  if (std::string err = d.Validate(); !err.empty())
    throw InputError(fmt::format("{}: cannot write dataset: {}", dir, err));
  json j;
  j["format"] = kFormat;
  j["grid"] = {d.shape.nx, d.shape.ny, d.shape.nz};
  j["spacing_mm"] = d.spacing_mm;
  j["C"] = d.C;
  j["setup"] = SetupName(d.setup);
  j["conditions"] = json::array();
  const int w = int(d.shape.nx), h = int(d.shape.ny);
  for (const auto& c : d.conditions) {
    json jc;
    jc["name"] = c.name;
    jc["q"] = "q_" + c.name + ".exr";
    jc["L"] = "L_" + c.name + ".exr";
    WriteImage((fs::path(dir) / jc["q"].get<std::string>()).string(),
               ImageFromPlanes(w, h, {c.q[0].data(), c.q[1].data(), c.q[2].data()}));
    WriteImage((fs::path(dir) / jc["L"].get<std::string>()).string(),
               ImageFromPlanes(w, h, {c.L[0].data(), c.L[1].data(), c.L[2].data()}));
    bool all_one = true;
    for (float m : c.mask) all_one &= m == 1.0f;
    if (!all_one) {
      jc["mask"] = "mask_" + c.name + ".exr";
      WriteImage((fs::path(dir) / jc["mask"].get<std::string>()).string(),
                 ImageFromPlanes(w, h, {c.mask.data()}));
    }
    j["conditions"].push_back(jc);
  }
  WriteAtomically((fs::path(dir) / "dataset.json").string(), [&](const std::string& tmp) {
    std::ofstream out(tmp);
    out << j.dump(2) << "\n";
    if (!out) throw InputError(fmt::format("{}: cannot write dataset.json", dir));
  });
}

}  // namespace translume
