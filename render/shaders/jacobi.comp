// SPDX-License-Identifier: MIT
// One relaxation step of the polygrid diffusion (render/diffusion.h, HierarchyRelaxer), RGB:
//   dst[n] = sum_k a[n][k] src[nb[n][k]] + (n >= num_interior ? s[n - num_interior] : 0),
// k < 6, the rows at nb[n * nb_node + k * entry], a[n * a_node + (c * 6 + k) * entry]: node-major
// as HierarchyRelaxer's Level holds them (nb_node 6, a_node 18, entry 1; llvmpipe) or
// entry-major, so that neighbouring invocations read neighbouring words (1, 1, size; GPUs:
// gl_diffusion.cc's RowLayout); plus with rows > 0 (rows == size) the row's extra entries
// (JacobiSystem's), which follow in the same buffers: nb[rows * 6 + n] is extra_start[n], nb[rows * 7 + 1 + e]
// extra_nb[e], and a[rows * 18 + e * 3 + c] extra_a[e * 3 + c]
// for n = active[i] (adaptive) or n = i, i < count; with use_prev, Chebyshev's semi-iteration
// (render/diffusion.h): dst[n] = prev[n] + omega (that - prev[n]), per channel.
#version 430
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Nb { int nb[]; };
layout(std430, binding = 1) readonly buffer A { float a[]; };
layout(std430, binding = 2) readonly buffer S { float s[]; };
layout(std430, binding = 3) readonly buffer Active { int active_nodes[]; };
layout(std430, binding = 4) readonly buffer Src { float src[]; };
layout(std430, binding = 5) writeonly buffer Dst { float dst[]; };
layout(std430, binding = 6) readonly buffer Prev { float prev[]; };
layout(location = 0) uniform int count;
layout(location = 1) uniform int num_interior;
layout(location = 2) uniform int use_list;
layout(location = 3) uniform int use_prev;
layout(location = 4) uniform vec3 omega;
layout(location = 5) uniform int rows;
layout(location = 6) uniform int nb_node;
layout(location = 7) uniform int a_node;
layout(location = 8) uniform int entry;

void main() {
  int i = int(gl_WorkGroupID.y * gl_NumWorkGroups.x * 256u + gl_GlobalInvocationID.x);
  if (i >= count) return;
  int n = use_list != 0 ? active_nodes[i] : i;
  int nbr[6];
  for (int k = 0; k < 6; ++k) nbr[k] = nb[n * nb_node + k * entry];
  int e0 = 0, e1 = 0;
  if (rows > 0) {
    e0 = nb[rows * 6 + n];
    e1 = nb[rows * 6 + n + 1];
  }
  for (int c = 0; c < 3; ++c) {
    float acc = n < num_interior ? 0.0 : s[(n - num_interior) * 3 + c];
    for (int k = 0; k < 6; ++k) acc += a[n * a_node + (c * 6 + k) * entry] * src[nbr[k] * 3 + c];
    for (int e = e0; e < e1; ++e) acc += a[rows * 18 + e * 3 + c] * src[nb[rows * 7 + 1 + e] * 3 + c];
    dst[n * 3 + c] = use_prev != 0 ? prev[n * 3 + c] + omega[c] * (acc - prev[n * 3 + c]) : acc;
  }
}
