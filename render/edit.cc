// SPDX-License-Identifier: MIT
#include "render/edit.h"

#include <algorithm>
#include <charconv>
#include <cctype>
#include <cmath>
#include <cstring>
#include <fmt/format.h>

#include "solver/status.h"

namespace translume {

std::string EditOptions::Validate() const {
  for (double v : {scale_kappa, scale_mu})
    if (!std::isfinite(v)) return "--scale: the multipliers must be finite";
  for (double v : {add_kappa, add_mu})
    if (!std::isfinite(v)) return "--add: the added values must be finite";
  if (scale_kappa < 0 || scale_mu < 0)
    return fmt::format("--scale: the multipliers must be >= 0 (kappa x{:g}, mu x{:g})", scale_kappa, scale_mu);
  if (depth_begin < 0 || (depth_end >= 0 && depth_end < depth_begin))
    return "--depth A:B: needs 0 <= A <= B";
  return "";
}

void EditOptions::ParseTerm(const std::string& text, bool add) {
  const std::string flag = add ? "--add" : "--scale";
  const auto eq = text.find('=');
  if (eq == std::string::npos) throw InputError(flag + " " + text + ": expected kappa=VALUE or mu=VALUE");
  const std::string name = text.substr(0, eq);
  double value = 0;
  try {
    size_t used = 0;
    value = std::stod(text.substr(eq + 1), &used);
    if (used != text.size() - eq - 1) throw std::invalid_argument("trailing");
  } catch (const std::exception&) {
    throw InputError(flag + " " + text + ": '" + text.substr(eq + 1) + "' is not a number");
  }
  if (name != "kappa" && name != "mu")
    throw InputError(flag + " " + text + ": unknown parameter '" + name + "' (expected kappa or mu)");
  if (add)
    (name == "kappa" ? add_kappa : add_mu) += value;
  else
    (name == "kappa" ? scale_kappa : scale_mu) *= value;
}

void EditOptions::ParseDepth(const std::string& text) {
  int a = 0, b = 0;
  const size_t colon = text.find(':');
  auto whole = [&](size_t from, size_t to, int* v) {  // the whole text, in int's range (no wrap-around)
    const auto [end, ec] = std::from_chars(text.data() + from, text.data() + to, *v);
    return ec == std::errc() && end == text.data() + to && to > from;
  };
  if (colon == std::string::npos || !whole(0, colon, &a) || !whole(colon + 1, text.size(), &b))
    throw InputError("--depth " + text + ": expected A:B (node layers, whole numbers)");
  if (a < 0 || b < a) throw InputError("--depth " + text + ": the depth range A:B needs 0 <= A <= B");
  depth_begin = a;
  depth_end = b;
}

void EditOptions::ParseChannels(const std::string& text) {
  if (text.empty()) throw InputError("--channels: name at least one of r, g, b");
  static constexpr char kLetters[] = "rgb";
  std::array<bool, 3> chosen{false, false, false};
  for (char ch : text) {
    const char* at = ch == '\0' ? nullptr : std::strchr(kLetters, std::tolower(static_cast<unsigned char>(ch)));
    if (!at) throw InputError("--channels " + text + ": expected letters of r, g, b (e.g. r or gb)");
    bool& c = chosen[at - kLetters];
    if (c) throw InputError(fmt::format("--channels {}: '{}' is named twice", text, ch));
    c = true;
  }
  channels = chosen;
}

Material EditMaterial(const Material& material, const EditOptions& o, const Image* mask) {
  if (std::string err = o.Validate(); !err.empty()) throw InputError(err);
  Material m = material;
  const GridShape& s = m.shape;
  if (o.depth_begin >= s.nz || o.depth_end >= s.nz)
    throw InputError(fmt::format("--depth {}:{}: the material has node layers 0..{}", o.depth_begin,
                                 o.depth_end < 0 ? std::string("") : std::to_string(o.depth_end), s.nz - 1));
  const int64_t k_end = o.depth_end < 0 ? s.nz - 1 : std::min<int64_t>(o.depth_end, s.nz - 1);
  for (int64_t k = o.depth_begin; k <= k_end; ++k)
    for (int64_t j = 0; j < s.ny; ++j)
      for (int64_t i = 0; i < s.nx; ++i) {
        double w = 1;
        if (mask) {
          const int px = std::min<int>(mask->width - 1, int((i + 0.5) * mask->width / s.nx));
          const int py = std::min<int>(mask->height - 1, int((j + 0.5) * mask->height / s.ny));
          if (mask->channels >= 3)
            w = 0.2126 * mask->at(px, py, 0) + 0.7152 * mask->at(px, py, 1) + 0.0722 * mask->at(px, py, 2);
          else
            w = mask->at(px, py, 0);
          w = std::clamp(w, 0.0, 1.0);
        }
        const int64_t n = s.index(i, j, k);
        for (int c = 0; c < 3; ++c) {
          if (!o.channels[c]) continue;
          float& kv = m.kappa[c][n];
          float& mv = m.mu[c][n];
          kv = float(kv + w * (o.scale_kappa * kv + o.add_kappa - kv));
          mv = float(mv + w * (o.scale_mu * mv + o.add_mu - mv));
          if (!(kv > 0) || !(mv > 0) || !std::isfinite(kv) || !std::isfinite(mv))
            throw InputError(fmt::format("edit: node ({}, {}, {}) channel {} would get kappa {} mm, "
                                         "mu {} /mm; both must stay > 0", i, j, k, "RGB"[c], kv, mv));
        }
      }
  return m;
}

}  // namespace translume
