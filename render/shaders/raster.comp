// SPDX-License-Identifier: MIT
// Z-buffer rasterisation of a triangle mesh, one invocation per triangle (after common.glsl).
// A pixel (x, y) is covered when its centre (x + 0.5, y + 0.5) has barycentrics >= 0; its
// depth is interpolated linearly in screen space (not perspective-correct; why that is kept:
// the comment on Raster in render/renderer.cc). mode 0: depth[base + pixel] = min over the
// covering triangles (atomicMin on the float bits); mode 1 (after mode 0): ids[pixel] = the
// lowest index among the triangles at that depth (the cpu raster keeps the first one drawn).
// Both are order-independent, so a triangle may be drawn in parts and a pass may be repeated.
//
// Large triangles (GlInfo::loop_budget, llvmpipe): with tile > 0, a triangle whose pixel bounds
// hold more than tile x tile pixels is not drawn by its invocation; in mode 0 it lists its
// tiles (tile x tile squares of its bounds, row by row from the bounds' corner) in tiles[],
// and a second dispatch (pass 1) draws one tile per invocation, in either mode. So one
// invocation loops over at most tile^2 pixels, or over the tiles of one triangle (at most
// ceil(W / tile) ceil(H / tile)); the host checks both against the budget.
layout(local_size_x = 256) in;
layout(std430, binding = 2) readonly buffer Verts { Vertex verts[]; };
layout(std430, binding = 3) readonly buffer Tris { int tris[]; };
layout(std430, binding = 4) buffer Ids { int ids[]; };
// num_tiles: tiles listed (also those beyond capacity, which are not stored); per tile
// (triangle, tile index, view_index, base).
layout(std430, binding = 5) buffer Tiles { uint num_tiles; ivec4 tiles[]; };
layout(location = 0) uniform int count;       // pass 0: triangles; pass 1: tiles
layout(location = 1) uniform int view_index;  // into samples[] (pass 0)
layout(location = 2) uniform int mode;
layout(location = 3) uniform int base;        // first texel of this raster in depth[] (pass 0)
layout(location = 4) uniform int tile;        // pixels per tile side; 0: no tiles
layout(location = 5) uniform int pass;        // 0: one invocation per triangle; 1: per tile
layout(location = 6) uniform int capacity;    // length of tiles[]

// Triangle t in view vw: its screen vertices (x, y pixels, depth), twice its signed area and its
// pixel bounds (x0, y0, x1, y1, inclusive, clipped to the raster); false where it is not drawn
// (a vertex behind the eye plane, or no area).
bool setup(int t, View vw, out vec3 a, out vec3 b, out vec3 c, out float area, out ivec4 box) {
  a = project(vw, verts[tris[3 * t]].p.xyz);
  b = project(vw, verts[tris[3 * t + 1]].p.xyz);
  c = project(vw, verts[tris[3 * t + 2]].p.xyz);
  area = (b.x - a.x) * (c.y - a.y) - (c.x - a.x) * (b.y - a.y);
  box = ivec4(0);
  if (a.z <= 0.0 || b.z <= 0.0 || c.z <= 0.0 || abs(area) < 1e-12) return false;
  int W = int(vw.p.z), H = int(vw.p.w);
  box = ivec4(max(0, int(floor(min(a.x, min(b.x, c.x))))), max(0, int(floor(min(a.y, min(b.y, c.y))))),
              min(W - 1, int(ceil(max(a.x, max(b.x, c.x))))), min(H - 1, int(ceil(max(a.y, max(b.y, c.y))))));
  return true;
}

// Draws triangle t over the pixels of r (inclusive bounds) of a raster W pixels wide at texel
// base: one loop of (r.z - r.x + 1)(r.w - r.y + 1) iterations (a single loop, so that an 8-lane
// chunk counts its largest rectangle, not a product of its lanes' widths and heights).
void draw(int t, vec3 a, vec3 b, vec3 c, float area, ivec4 r, int W, int rbase) {
  int x = r.x, y = r.y;
  for (int n = max(0, r.z - r.x + 1) * max(0, r.w - r.y + 1); n > 0; --n) {
    float px = float(x) + 0.5, py = float(y) + 0.5;
    float w1 = ((px - a.x) * (c.y - a.y) - (c.x - a.x) * (py - a.y)) / area;
    float w2 = ((b.x - a.x) * (py - a.y) - (px - a.x) * (b.y - a.y)) / area;
    float w0 = 1.0 - w1 - w2;
    if (w0 >= 0.0 && w1 >= 0.0 && w2 >= 0.0) {
      uint z = floatBitsToUint(w0 * a.z + w1 * b.z + w2 * c.z);
      int i = y * W + x;
      if (mode == 0)
        atomicMin(depth[rbase + i], z);
      else if (depth[rbase + i] == z)
        atomicMin(ids[i], t);
    }
    if (++x > r.z) {
      x = r.x;
      ++y;
    }
  }
}

void main() {
  int i = invocation();
  if (i >= count) return;
  ivec4 item = pass == 0 ? ivec4(i, 0, view_index, base) : tiles[i];
  View vw = samples[item.z].view;
  vec3 a, b, c;
  float area;
  ivec4 box;
  if (!setup(item.x, vw, a, b, c, area, box)) return;
  int W = int(vw.p.z);
  ivec2 size = max(box.zw - box.xy + 1, 0);  // 0 where it lies off the raster
  if (pass == 1) {
    int cols = (size.x + tile - 1) / tile;
    ivec2 o = box.xy + tile * ivec2(item.y % cols, item.y / cols);
    draw(item.x, a, b, c, area, ivec4(o, min(box.zw, o + tile - 1)), W, item.w);
  } else if (tile > 0 && float(size.x) * float(size.y) > float(tile * tile)) {
    if (mode != 0) return;  // listed by mode 0
    int n = ((size.x + tile - 1) / tile) * ((size.y + tile - 1) / tile);
    uint first = atomicAdd(num_tiles, uint(n));
    for (int k = 0; k < n; ++k)
      if (first + uint(k) < uint(capacity)) tiles[first + uint(k)] = ivec4(item.x, k, view_index, base);
  } else {
    draw(item.x, a, b, c, area, box, W, base);
  }
}
