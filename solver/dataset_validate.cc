// SPDX-License-Identifier: MIT
// The in-memory half of dataset.h (no file IO), so that code which builds datasets in memory
// (bench recovery in translume-gpubench) links without OpenImageIO.
#include <algorithm>
#include <cctype>
#include <cmath>
#include <fmt/format.h>
#include <set>

#include "solver/dataset.h"
#include "solver/grid.h"

namespace translume {

bool IsSafeConditionName(const std::string& s) {
  if (s.empty() || s.size() > 100) return false;
  for (char c : s)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '_' && c != '-' && c != '.') return false;
  return s != "." && s != "..";
}

std::string Dataset::Validate() const {
  if (shape.nx < 2 || shape.ny < 2 || shape.nz < 2)
    return fmt::format("grid {} needs at least 2 nodes per axis", shape.ToString());
  if (const std::string p = SpacingProblem(spacing_mm); !p.empty()) return "spacing_mm " + p;
  if (!(C >= 1 && C <= kMaxC)) return fmt::format("C must be within 1..{:g}, got {:g}", kMaxC, C);
  if (conditions.empty()) return "there are no conditions";
  std::set<std::string> names;
  for (const auto& c : conditions) {
    if (!IsSafeConditionName(c.name))
      return fmt::format("condition name '{}' must be 1-100 characters of [A-Za-z0-9_.-]", c.name);
    if (!names.insert(c.name).second) return fmt::format("condition '{}' appears twice", c.name);
    const size_t n = size_t(shape.face_size());
    for (int ch = 0; ch < 3; ++ch) {
      if (c.q[ch].size() != n || c.L[ch].size() != n)
        return fmt::format("condition '{}': q and L need {} values per channel", c.name, n);
      for (size_t p = 0; p < n; ++p) {
        if (!std::isfinite(c.q[ch][p]) || c.q[ch][p] < 0)
          return fmt::format("condition '{}': q must be finite and >= 0", c.name);
        if (!std::isfinite(c.L[ch][p]))
          return fmt::format("condition '{}': L must be finite", c.name);
      }
    }
    if (c.mask.size() != n) return fmt::format("condition '{}': mask needs {} values", c.name, n);
    for (float m : c.mask)
      if (!(m >= 0 && m <= 1)) return fmt::format("condition '{}': mask outside [0, 1]", c.name);
  }
  bool lit = false;
  for (const auto& c : conditions)
    for (int ch = 0; ch < 3; ++ch)
      for (float v : c.q[ch]) lit |= v > 0;
  if (!lit) return "q is 0 at every node of every condition: no condition has light";
  // The fit compares L with the model where the mask is > 0: each channel needs light there.
  for (int ch = 0; ch < 3; ++ch) {
    double sum = 0;
    for (const auto& c : conditions)
      for (size_t p = 0; p < c.mask.size(); ++p) sum += double(c.mask[p]) * std::abs(c.L[ch][p]);
    if (!(sum > 0))
      return fmt::format("channel {} has no light in any measured pixel (L is 0 wherever the mask is > 0)",
                         "RGB"[ch]);
  }
  return "";
}

bool NearlyEqual(double a, double b) { return std::abs(a - b) <= 1e-6 * std::max(std::abs(a), std::abs(b)); }

std::string DifferentProblem(const Dataset& other, const Dataset& training, bool same_setup) {
  if (other.shape == training.shape && NearlyEqual(other.spacing_mm, training.spacing_mm) &&
      NearlyEqual(other.C, training.C) &&
      (!same_setup || other.setup == training.setup))
    return "";
  if (!same_setup)
    return fmt::format("its grid {}, spacing {:g} mm and C {:g} differ from the training dataset's {}, {:g} mm "
                       "and {:g}", other.shape.ToString(), other.spacing_mm, other.C, training.shape.ToString(),
                       training.spacing_mm, training.C);
  return fmt::format("its grid {}, spacing {:g} mm, C {:g} and {}-lit setup differ from the training dataset's "
                     "{}, {:g} mm, {:g} and {}-lit", other.shape.ToString(), other.spacing_mm, other.C,
                     SetupName(other.setup), training.shape.ToString(), training.spacing_mm, training.C,
                     SetupName(training.setup));
}

}  // namespace translume
