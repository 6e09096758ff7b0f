// SPDX-License-Identifier: MIT
#include "solver/grid.h"

#include <cmath>
#include <fmt/format.h>
#include <vector>

#include "solver/parse.h"
#include "solver/status.h"

namespace translume {

GridShape ParseGridShape(const std::string& text, const std::string& what) {
  const auto parsed = WholeNumbers(text, "xx");
  if (!parsed) throw InputError(what + ": '" + text + "' is not a grid size NXxNYxNZ");
  const std::vector<int64_t>& values = *parsed;
  for (int64_t v : values) {
    if (v < 2) throw InputError(what + ": every grid dimension must be at least 2 nodes, got '" + text + "'");
    if (v > kMaxGridAxis)
      throw InputError(what + ": every grid dimension must be at most " + std::to_string(kMaxGridAxis) +
                       " nodes, got '" + text + "'");
  }
  return {values[0], values[1], values[2]};
}

std::string SpacingProblem(double spacing_mm) {
  if (std::isfinite(spacing_mm) && spacing_mm >= kMinSpacingMm && spacing_mm <= kMaxSpacingMm) return "";
  return fmt::format("must be within {:g}..{:g} mm, got {:g}", kMinSpacingMm, kMaxSpacingMm, spacing_mm);
}

Setup ParseSetup(const std::string& text, const char* flag) {
  if (text == "back") return Setup::kBack;
  if (text == "front") return Setup::kFront;
  throw InputError(std::string(flag) + ": '" + text + "' is not 'back' or 'front'");
}

const char* SetupName(Setup setup) { return setup == Setup::kBack ? "back" : "front"; }

}  // namespace translume
