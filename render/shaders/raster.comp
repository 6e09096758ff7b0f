// SPDX-License-Identifier: MIT
// Z-buffer rasterisation of a triangle mesh, one invocation per triangle (after common.glsl).
// A pixel (x, y) is covered when the line of sight through its centre (x + 0.5, y + 0.5) meets
// the triangle deeper than the view's near plane (hit() and covered() in common.glsl, exact for
// perspective views and for triangles partly behind the eye; RasterTriangle in
// render/render_passes.h is the cpu's). mode 0: depth[base + pixel] = min over the
// covering triangles (atomicMin on the float bits); mode 1 (after mode 0): ids[pixel] = the
// lowest index among the triangles at that depth (the cpu raster keeps the first one drawn).
// Both are order-independent, so a triangle may be drawn in parts and a pass may be repeated.
// One dispatch draws count / triangles rasters (the shadow maps of all light samples):
// invocation i of pass 0 draws triangle i % triangles into raster r = i / triangles, whose view
// is samples[view_index + r] and whose first texel is base + r * stride.
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
// (triangle, tile index, view, first texel of its raster).
layout(std430, binding = 5) buffer Tiles { uint num_tiles; ivec4 tiles[]; };
layout(location = 0) uniform int count;       // pass 0: triangles x rasters; pass 1: tiles
layout(location = 1) uniform int view_index;  // into samples[]: the first raster's view (pass 0)
layout(location = 2) uniform int mode;
layout(location = 3) uniform int base;        // the first raster's first texel in depth[] (pass 0)
layout(location = 4) uniform int tile;        // pixels per tile side; 0: no tiles
layout(location = 5) uniform int pass;        // 0: one invocation per triangle; 1: per tile
layout(location = 6) uniform int capacity;    // length of tiles[]
layout(location = 7) uniform int triangles;   // triangles per raster (pass 0)
layout(location = 8) uniform int stride;      // texels per raster (pass 0)

// Triangle t in view vw: its homogeneous vertices (homogeneous() in common.glsl) and the pixel
// bounds (x0, y0, x1, y1, inclusive, clipped to the raster) of its part deeper than the near
// plane (RasterTriangle::Bounds); false where none of it is drawn.
bool setup(int t, View vw, out vec4 a, out vec4 b, out vec4 c, out ivec4 box) {
  a = homogeneous(vw, verts[tris[3 * t]].p.xyz);
  b = homogeneous(vw, verts[tris[3 * t + 1]].p.xyz);
  c = homogeneous(vw, verts[tris[3 * t + 2]].p.xyz);
  box = ivec4(0);
  float near = vw.eye.w;
  vec2 lo = vec2(3.0e38), hi = vec2(-3.0e38);
  vec4 h[3] = vec4[3](a, b, c);
  for (int i = 0; i < 3; ++i) {
    vec4 p = h[i], q = h[(i + 1) % 3];
    float dp = p.w - near, dq = q.w - near;
    if (dp >= 0.0) {
      lo = min(lo, p.xy / p.z);
      hi = max(hi, p.xy / p.z);
    }
    if ((dp < 0.0) != (dq < 0.0)) {  // the crossing of the near plane (w > 0)
      vec4 x = p + dp / (dp - dq) * (q - p);
      lo = min(lo, x.xy / x.z);
      hi = max(hi, x.xy / x.z);
    }
  }
  if (!(lo.x <= hi.x && lo.y <= hi.y)) return false;
  vec2 size = vw.p.zw;  // clamped before the conversion: a part next to the eye projects far off
  ivec2 l = max(ivec2(0), ivec2(floor(clamp(lo, vec2(-1.0), size))));
  ivec2 u = min(ivec2(size) - 1, ivec2(ceil(clamp(hi, vec2(-1.0), size))));
  box = ivec4(l, u);
  return l.x <= u.x && l.y <= u.y;
}

// Draws triangle t over the pixels of r (inclusive bounds) of a raster W pixels wide at texel
// base: one loop of (r.z - r.x + 1)(r.w - r.y + 1) iterations (a single loop, so that an 8-lane
// chunk counts its largest rectangle, not a product of its lanes' widths and heights).
void draw(int t, vec4 a, vec4 b, vec4 c, float near, ivec4 r, int W, int rbase) {
  int x = r.x, y = r.y;
  for (int n = max(0, r.z - r.x + 1) * max(0, r.w - r.y + 1); n > 0; --n) {
    vec4 h = hit(a, b, c, vec2(float(x) + 0.5, float(y) + 0.5));
    if (covered(h, near)) {
      uint z = floatBitsToUint(h.w);
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
  int r = i / triangles;
  ivec4 item = pass == 0 ? ivec4(i - r * triangles, 0, view_index + r, base + r * stride) : tiles[i];
  View vw = samples[item.z].view;
  vec4 a, b, c;
  ivec4 box;
  if (!setup(item.x, vw, a, b, c, box)) return;
  int W = int(vw.p.z);
  ivec2 size = max(box.zw - box.xy + 1, 0);  // 0 where it lies off the raster
  if (pass == 1) {
    int cols = (size.x + tile - 1) / tile;
    ivec2 o = box.xy + tile * ivec2(item.y % cols, item.y / cols);
    draw(item.x, a, b, c, vw.eye.w, ivec4(o, min(box.zw, o + tile - 1)), W, item.w);
  } else if (tile > 0 && float(size.x) * float(size.y) > float(tile * tile)) {
    if (mode != 0) return;  // listed by mode 0
    int n = ((size.x + tile - 1) / tile) * ((size.y + tile - 1) / tile);
    uint first = atomicAdd(num_tiles, uint(n));
    for (int k = 0; k < n; ++k)
      if (first + uint(k) < uint(capacity)) tiles[first + uint(k)] = ivec4(item.x, k, item.z, item.w);
  } else {
    draw(item.x, a, b, c, vw.eye.w, box, W, item.w);
  }
}
