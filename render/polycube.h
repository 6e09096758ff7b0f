// SPDX-License-Identifier: MIT
#pragma once

#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

namespace translume {

// A polycube (Tarini et al. 2004; Wang et al. 2008, Section 5.1): unit cubes on an integer
// lattice, cube (x, y, z) covering [x, x+1] x [y, y+1] x [z, z+1] in polycube units. Text file
// format (docs/render.md): one cube per line as three integers "x y z"; '#' starts a comment;
// blank lines are ignored; optionally one line "axes" and nine numbers, the rows of `axes`.
// At least one cube, no duplicates, coordinates in [0, 1023], and the cubes must form one
// face-connected piece.
struct Polycube {
  std::vector<std::array<int, 3>> cubes;
  // The lattice's x, y and z axes in the shape's coordinates (rows; a rotation): the polycube
  // is laid over the shape in the frame whose coordinates are axes * p (mm), stretched onto the
  // shape's bounding box in that frame. Identity: the shape's own axes.
  Eigen::Matrix3d axes = Eigen::Matrix3d::Identity();

  // Largest cube coordinate + 1 per axis (the lattice extent in cube units).
  std::array<int, 3> Extent() const;
  bool Has(int x, int y, int z) const;
  // Empty if valid, else the broken constraint.
  std::string Validate() const;
  // The genus of the solid's surface (its holes: 0 for a cube, 1 for a ring), from
  // V - E + F = 2 - 2 genus over the exposed unit faces; -1 where the surface is not a
  // 2-manifold (cubes that meet along an edge or at a corner only).
  int Genus() const;
  // The face-connected pieces, the one holding cubes[0] first; each keeps the cubes' order.
  std::vector<Polycube> Pieces() const;
};

// Parses the text format; throws InputError naming `what` (a file name) and the line.
Polycube ParsePolycube(const std::string& text, const std::string& what);
Polycube ReadPolycube(const std::string& path);
std::string FormatPolycube(const Polycube& polycube);

// The polycubes of the built-in shapes: slab 3x3x1 cubes, sphere and blob one cube, torus a
// ring of 8 cubes (3x3x1 without the centre), bunny 253 cubes (a blocky bunny grown from
// ellipsoids for body, head, ears and tail; polycube.cc). Throws InputError on an unknown name.
Polycube BuiltinPolycube(const std::string& shape);

}  // namespace translume
