// SPDX-License-Identifier: MIT
// One relaxation step of the polygrid diffusion (render/diffusion.h, HierarchyRelaxer), RGB:
//   dst[n] = sum_k a[n][k] src[nb[n][k]] + (n >= num_interior ? s[n - num_interior] : 0),
// k < 6, the fluence and sources RGB vec4s (w unused). A row entry is one ivec4: the weight's
// three channels as float bits in xyz, the neighbour in w (one load per entry), entry-major so
// that neighbouring invocations read neighbouring words: k < 3 at row0[k * stride + n], the
// others at row1[(k - 3) * stride + n], stride = the level's size (two buffers, so that each
// stays within GL_MAX_SHADER_STORAGE_BLOCK_SIZE on larger levels; eight blocks, GL 4.3's
// minimum); with rows > 0 (rows == size) the row's extra entries (JacobiSystem's) follow in
// row1, row1[rows * 3 + e] for extra_start[n] <= e < extra_start[n + 1]; for n = active[i]
// (adaptive) or n = i, i < count; with use_prev, Chebyshev's semi-iteration
// (render/diffusion.h): dst[n] = prev[n] + omega (that - prev[n]), per channel.
#version 430
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer ExtraStart { int extra_start[]; };
layout(std430, binding = 1) readonly buffer Rows0 { ivec4 row0[]; };
layout(std430, binding = 2) readonly buffer S { vec4 s[]; };
layout(std430, binding = 3) readonly buffer Active { int active_nodes[]; };
layout(std430, binding = 4) readonly buffer Src { vec4 src[]; };
layout(std430, binding = 5) writeonly buffer Dst { vec4 dst[]; };
layout(std430, binding = 6) readonly buffer Prev { vec4 prev[]; };
layout(std430, binding = 7) readonly buffer Rows1 { ivec4 row1[]; };
layout(location = 0) uniform int count;
layout(location = 1) uniform int num_interior;
layout(location = 2) uniform int use_list;
layout(location = 3) uniform int use_prev;
layout(location = 4) uniform vec3 omega;
layout(location = 5) uniform int rows;
layout(location = 6) uniform int stride;

// One entry's term: its weight (float bits) times its neighbour's fluence, per channel.
vec3 Term(ivec4 r) { return intBitsToFloat(r.xyz) * src[r.w].rgb; }

void main() {
  int i = int(gl_WorkGroupID.y * gl_NumWorkGroups.x * 256u + gl_GlobalInvocationID.x);
  if (i >= count) return;
  int n = use_list != 0 ? active_nodes[i] : i;
  vec3 acc = n < num_interior ? vec3(0.0) : s[n - num_interior].rgb;
  for (int k = 0; k < 6; ++k) acc += Term(k < 3 ? row0[k * stride + n] : row1[(k - 3) * stride + n]);
  if (rows > 0) {
    int e1 = extra_start[n + 1];
    for (int e = extra_start[n]; e < e1; ++e) acc += Term(row1[rows * 3 + e]);
  }
  if (use_prev != 0) {
    vec3 p = prev[n].rgb;
    acc = p + omega * (acc - p);
  }
  dst[n] = vec4(acc, 0.0);
}
