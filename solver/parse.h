// SPDX-License-Identifier: MIT
#pragma once

#include <algorithm>
#include <charconv>
#include <cstdint>
#include <optional>
#include <string_view>
#include <vector>

namespace translume {

// The whole numbers of `text` separated by the characters of `separators` in order:
// WholeNumbers("3,1/4", ",/") = {3, 1, 4}, WholeNumbers("640x480", "x") = {640, 480}. Nothing
// when a part is empty, not a decimal integer (signs allowed), beyond int64, or anything else
// is in the text. (sscanf's %d wraps out-of-range values silently: 4294967297 read as 1.)
inline std::optional<std::vector<int64_t>> WholeNumbers(std::string_view text, std::string_view separators) {
  std::vector<int64_t> values;
  for (size_t part = 0; part <= separators.size(); ++part) {
    const size_t end = part < separators.size() ? text.find(separators[part]) : text.size();
    if (end == std::string_view::npos) return std::nullopt;
    int64_t v = 0;
    const char* first = text.data();
    if (!text.empty() && text[0] == '+') ++first;  // from_chars takes '-' only
    const auto [ptr, ec] = std::from_chars(first, text.data() + end, v);
    if (ec != std::errc() || ptr != text.data() + end || end == 0) return std::nullopt;
    values.push_back(v);
    text.remove_prefix(std::min(text.size(), end + 1));
  }
  return values;
}

}  // namespace translume
