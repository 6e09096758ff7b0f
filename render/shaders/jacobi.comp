// SPDX-License-Identifier: MIT
// One relaxation step of the polygrid diffusion (render/diffusion.h, HierarchyRelaxer), RGB:
//   dst[n] = sum_k a[n][k] src[nb[n][k]] + (n >= num_interior ? s[n - num_interior] : 0),
// k < 6, every value an RGB vec4 (w unused: one load per neighbour, weight and node). The rows
// at nb[n * node + k * entry], a[n * node + k * entry]: node-major as HierarchyRelaxer's Level
// holds them (node 6, entry 1; llvmpipe) or entry-major, so that neighbouring invocations read
// neighbouring words (node 1, entry size; GPUs: gl_diffusion.cc's RowsEntryMajor); plus with
// rows > 0 (rows == size) the row's extra entries (JacobiSystem's), which follow in the same
// buffers: nb[rows * 6 + n] is extra_start[n], nb[rows * 7 + 1 + e] extra_nb[e], and
// a[rows * 6 + e] extra_a[e * 3 + c]'s three channels;
// for n = active[i] (adaptive) or n = i, i < count; with use_prev, Chebyshev's semi-iteration
// (render/diffusion.h): dst[n] = prev[n] + omega (that - prev[n]), per channel.
#version 430
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Nb { int nb[]; };
layout(std430, binding = 1) readonly buffer A { vec4 a[]; };
layout(std430, binding = 2) readonly buffer S { vec4 s[]; };
layout(std430, binding = 3) readonly buffer Active { int active_nodes[]; };
layout(std430, binding = 4) readonly buffer Src { vec4 src[]; };
layout(std430, binding = 5) writeonly buffer Dst { vec4 dst[]; };
layout(std430, binding = 6) readonly buffer Prev { vec4 prev[]; };
layout(location = 0) uniform int count;
layout(location = 1) uniform int num_interior;
layout(location = 2) uniform int use_list;
layout(location = 3) uniform int use_prev;
layout(location = 4) uniform vec3 omega;
layout(location = 5) uniform int rows;
layout(location = 6) uniform int node;
layout(location = 7) uniform int entry;

void main() {
  int i = int(gl_WorkGroupID.y * gl_NumWorkGroups.x * 256u + gl_GlobalInvocationID.x);
  if (i >= count) return;
  int n = use_list != 0 ? active_nodes[i] : i;
  vec3 acc = n < num_interior ? vec3(0.0) : s[n - num_interior].rgb;
  for (int k = 0; k < 6; ++k) {
    int j = n * node + k * entry;
    acc += a[j].rgb * src[nb[j]].rgb;
  }
  if (rows > 0) {
    int e1 = nb[rows * 6 + n + 1];
    for (int e = nb[rows * 6 + n]; e < e1; ++e) acc += a[rows * 6 + e].rgb * src[nb[rows * 7 + 1 + e]].rgb;
  }
  if (use_prev != 0) {
    vec3 p = prev[n].rgb;
    acc = p + omega * (acc - p);
  }
  dst[n] = vec4(acc, 0.0);
}
