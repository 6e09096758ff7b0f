// SPDX-License-Identifier: MIT
#include "solver/json_file.h"

#include <filesystem>
#include <fmt/format.h>
#include <fstream>

#include "solver/status.h"

namespace translume {

nlohmann::json ReadJsonFile(const std::string& path, const std::string& open_hint) {
  if (std::filesystem::is_directory(path)) throw InputError(path + ": is a folder, not a file");
  std::ifstream in(path);
  if (!in) throw InputError(path + ": cannot open" + open_hint);
  try {
    return nlohmann::json::parse(in);
  } catch (const nlohmann::json::exception& e) {
    std::string why = e.what();  // without the "[json.exception.KIND.ID] " prefix
    if (const size_t at = why.find("] "); why.rfind("[json.exception.", 0) == 0 && at != std::string::npos)
      why.erase(0, at + 2);
    throw InputError(fmt::format("{}: not valid JSON: {}", path, why));
  }
}

}  // namespace translume
