// SPDX-License-Identifier: MIT
#pragma once

#include <nlohmann/json.hpp>
#include <string>

namespace translume {

// Parses the JSON file at `path`. Bad input throws InputError naming the file: "PATH: cannot open"
// followed by `open_hint` (e.g. " the rig file"), a folder, or "PATH: not valid JSON: REASON" with
// the parser's reason and place (e.g. "number overflow parsing '1e999'", which a double cannot
// hold).
nlohmann::json ReadJsonFile(const std::string& path, const std::string& open_hint = "");

}  // namespace translume
