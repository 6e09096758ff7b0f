// SPDX-License-Identifier: MIT
// One relaxation step of the polygrid diffusion (render/diffusion.h, JacobiSystem):
//   dst[n] = (s[n] + sum_k w[n][k] src[nb[n][k]]) * inv_diag[n]   for n = active[a], RGB.
#version 430
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Nb { int nb[]; };
layout(std430, binding = 1) readonly buffer W { float w[]; };
layout(std430, binding = 2) readonly buffer S { float s[]; };
layout(std430, binding = 3) readonly buffer D { float inv_diag[]; };
layout(std430, binding = 4) readonly buffer Active { int active_nodes[]; };
layout(std430, binding = 5) readonly buffer Src { float src[]; };
layout(std430, binding = 6) writeonly buffer Dst { float dst[]; };
layout(location = 0) uniform int count;

void main() {
  int a = int(gl_WorkGroupID.y * gl_NumWorkGroups.x * 256u + gl_GlobalInvocationID.x);
  if (a >= count) return;
  int n = active_nodes[a];
  int nbr[6];
  for (int k = 0; k < 6; ++k) nbr[k] = nb[n * 6 + k];
  for (int c = 0; c < 3; ++c) {
    int row = (n * 3 + c) * 6;
    float acc = s[n * 3 + c];
    for (int k = 0; k < 6; ++k) acc += w[row + k] * src[nbr[k] * 3 + c];
    dst[n * 3 + c] = acc * inv_diag[n * 3 + c];
  }
}
