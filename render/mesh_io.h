// SPDX-License-Identifier: MIT
#pragma once

#include <string>
#include <vector>

#include "render/shape.h"

namespace translume {

// Reads a Wavefront OBJ ("v" and "f" records; "f a/b/c", negative indices, "#" comments at the
// end of a line and "\" continuations accepted) or a PLY (ascii, binary_little_endian or
// binary_big_endian; vertex x, y, z and a face vertex_indices list, or a tristrips list with -1
// between strips) by extension, repairs what exporters commonly write, and validates the
// result as a closed 2-manifold (TriangleMesh::Validate). The repairs, in order:
// - polygons are triangulated: convex ones as a fan from their first corner, others by ear
//   clipping in their plane (Newell's normal);
// - a face's repeated corners ("f 1 2 3 3", a triangle written as a quad) are dropped, and a
//   face left with fewer than three distinct corners is dropped;
// - vertices at the same position (within 1e-7 of the bounding box's diagonal) are welded
//   into one (exporters split them along UV and normal seams; STL conversions repeat every
//   vertex per triangle), and triangles that this makes degenerate are dropped; a welded
//   vertex where separate pieces touch (more than one fan of triangles around it) is split
//   again, one copy per fan;
// - a triangle written twice (same corners, same way round) is kept once;
// - vertices no triangle uses are dropped;
// - triangles whose orientation disagrees with their neighbours' are flipped (per connected
//   piece, the orientation of the majority of its triangles is kept);
// Each repair that changed something appends a sentence to *repairs (when given). Throws
// InputError naming the file and the problem, with the file's own vertex numbers (OBJ from 1,
// PLY indices from 0) and the face's OBJ line or PLY face number.
TriangleMesh ReadMesh(const std::string& path, std::vector<std::string>* repairs = nullptr);

void WriteObj(const std::string& path, const TriangleMesh& mesh);

}  // namespace translume
