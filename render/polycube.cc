// SPDX-License-Identifier: MIT
#include "render/polycube.h"

#include <algorithm>
#include <fstream>
#include <set>
#include <sstream>

#include "solver/status.h"

namespace translume {

std::array<int, 3> Polycube::Extent() const {
  std::array<int, 3> e = {0, 0, 0};
  for (const auto& c : cubes)
    for (int a = 0; a < 3; ++a) e[a] = std::max(e[a], c[a] + 1);
  return e;
}

bool Polycube::Has(int x, int y, int z) const {
  return std::find(cubes.begin(), cubes.end(), std::array<int, 3>{x, y, z}) != cubes.end();
}

std::string Polycube::Validate() const {
  if (cubes.empty()) return "a polycube needs at least one cube";
  std::set<std::array<int, 3>> seen;
  for (const auto& c : cubes) {
    for (int a = 0; a < 3; ++a)
      if (c[a] < 0 || c[a] > 1023)
        return "cube coordinates must be in [0, 1023], got " + std::to_string(c[a]);
    if (!seen.insert(c).second)
      return "duplicate cube " + std::to_string(c[0]) + " " + std::to_string(c[1]) + " " +
             std::to_string(c[2]);
  }
  // Face-connectivity by flood fill.
  std::set<std::array<int, 3>> reached = {cubes[0]};
  std::vector<std::array<int, 3>> stack = {cubes[0]};
  while (!stack.empty()) {
    const auto c = stack.back();
    stack.pop_back();
    for (int a = 0; a < 3; ++a)
      for (int s : {-1, 1}) {
        auto n = c;
        n[a] += s;
        if (seen.count(n) && reached.insert(n).second) stack.push_back(n);
      }
  }
  if (reached.size() != seen.size())
    return "the cubes are not face-connected (" + std::to_string(seen.size() - reached.size()) +
           " cube(s) not reachable from the first)";
  return "";
}

Polycube ParsePolycube(const std::string& text, const std::string& what) {
  Polycube p;
  std::istringstream in(text);
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    if (auto hash = line.find('#'); hash != std::string::npos) line.resize(hash);
    std::istringstream ls(line);
    std::array<int, 3> c;
    std::string rest;
    if (!(ls >> std::ws) || ls.eof()) continue;
    if (!(ls >> c[0] >> c[1] >> c[2]) || (ls >> rest))
      throw InputError(what + ":" + std::to_string(line_no) +
                       ": expected three integers \"x y z\" per cube, got '" + line + "'");
    p.cubes.push_back(c);
  }
  if (std::string err = p.Validate(); !err.empty()) throw InputError(what + ": " + err);
  return p;
}

Polycube ReadPolycube(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw InputError(path + ": cannot open the polycube file");
  std::stringstream ss;
  ss << in.rdbuf();
  return ParsePolycube(ss.str(), path);
}

std::string FormatPolycube(const Polycube& polycube) {
  std::string s = "# polycube: one unit cube per line, x y z\n";
  for (const auto& c : polycube.cubes)
    s += std::to_string(c[0]) + " " + std::to_string(c[1]) + " " + std::to_string(c[2]) + "\n";
  return s;
}

Polycube BuiltinPolycube(const std::string& shape) {
  Polycube p;
  if (shape == "sphere" || shape == "blob" || shape == "box") {
    p.cubes = {{0, 0, 0}};
  } else if (shape == "slab") {
    for (int y = 0; y < 3; ++y)
      for (int x = 0; x < 3; ++x) p.cubes.push_back({x, y, 0});
  } else if (shape == "torus") {
    for (int y = 0; y < 3; ++y)
      for (int x = 0; x < 3; ++x)
        if (x != 1 || y != 1) p.cubes.push_back({x, y, 0});
  } else {
    throw InputError("--shape: unknown shape '" + shape +
                     "' (expected slab, sphere, torus, blob, or a mesh file .obj/.ply)");
  }
  return p;
}

}  // namespace translume
