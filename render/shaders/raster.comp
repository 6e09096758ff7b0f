// SPDX-License-Identifier: MIT
// Z-buffer rasterisation of a triangle mesh, one invocation per triangle (after common.glsl).
// A pixel (x, y) is covered when its centre (x + 0.5, y + 0.5) has barycentrics >= 0; its
// depth is interpolated linearly in screen space (not perspective-correct; why that is kept:
// the comment on Raster in render/renderer.cc). mode 0: depth[base + pixel] = min over the
// covering triangles (atomicMin on the float bits); mode 1 (after mode 0): ids[pixel] = the
// lowest index among the triangles at that depth (the cpu raster keeps the first one drawn).
layout(local_size_x = 256) in;
layout(std430, binding = 2) readonly buffer Verts { Vertex verts[]; };
layout(std430, binding = 3) readonly buffer Tris { int tris[]; };
layout(std430, binding = 4) buffer Ids { int ids[]; };
layout(location = 0) uniform int num_tris;
layout(location = 1) uniform int view_index;  // into samples[]
layout(location = 2) uniform int mode;
layout(location = 3) uniform int base;        // first texel of this raster in depth[]

void main() {
  int t = invocation();
  if (t >= num_tris) return;
  View vw = samples[view_index].view;
  vec3 a = project(vw, verts[tris[3 * t]].p.xyz);
  vec3 b = project(vw, verts[tris[3 * t + 1]].p.xyz);
  vec3 c = project(vw, verts[tris[3 * t + 2]].p.xyz);
  if (a.z <= 0.0 || b.z <= 0.0 || c.z <= 0.0) return;
  float area = (b.x - a.x) * (c.y - a.y) - (c.x - a.x) * (b.y - a.y);
  if (abs(area) < 1e-12) return;
  int W = int(vw.p.z), H = int(vw.p.w);
  int x0 = max(0, int(floor(min(a.x, min(b.x, c.x)))));
  int x1 = min(W - 1, int(ceil(max(a.x, max(b.x, c.x)))));
  int y0 = max(0, int(floor(min(a.y, min(b.y, c.y)))));
  int y1 = min(H - 1, int(ceil(max(a.y, max(b.y, c.y)))));
  for (int y = y0; y <= y1; ++y)
    for (int x = x0; x <= x1; ++x) {
      float px = float(x) + 0.5, py = float(y) + 0.5;
      float w1 = ((px - a.x) * (c.y - a.y) - (c.x - a.x) * (py - a.y)) / area;
      float w2 = ((b.x - a.x) * (py - a.y) - (px - a.x) * (b.y - a.y)) / area;
      float w0 = 1.0 - w1 - w2;
      if (w0 < 0.0 || w1 < 0.0 || w2 < 0.0) continue;
      uint z = floatBitsToUint(w0 * a.z + w1 * b.z + w2 * c.z);
      int i = y * W + x;
      if (mode == 0)
        atomicMin(depth[base + i], z);
      else if (depth[base + i] == z)
        atomicMin(ids[i], t);
    }
}
