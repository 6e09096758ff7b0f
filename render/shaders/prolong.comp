// SPDX-License-Identifier: MIT
// Coarse-to-fine prolongation of the fluence (render/polygrid.h, Prolongation; RGB):
//   fine[f * 3 + c] = sum_{k in [start[f], start[f + 1])} weight[k] coarse[index[k] * 3 + c]
#version 430
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Start { int start[]; };
layout(std430, binding = 1) readonly buffer Index { int index[]; };
layout(std430, binding = 2) readonly buffer Weight { float weight[]; };
layout(std430, binding = 3) readonly buffer Coarse { float coarse[]; };
layout(std430, binding = 4) writeonly buffer Fine { float fine[]; };
layout(location = 0) uniform int count;

void main() {
  int f = int(gl_WorkGroupID.y * gl_NumWorkGroups.x * 256u + gl_GlobalInvocationID.x);
  if (f >= count) return;
  vec3 acc = vec3(0.0);
  for (int k = start[f]; k < start[f + 1]; ++k) {
    int c = index[k] * 3;
    acc += weight[k] * vec3(coarse[c], coarse[c + 1], coarse[c + 2]);
  }
  fine[f * 3] = acc.x;
  fine[f * 3 + 1] = acc.y;
  fine[f * 3 + 2] = acc.z;
}
