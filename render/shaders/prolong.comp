// SPDX-License-Identifier: MIT
// Coarse-to-fine prolongation of the fluence (render/polygrid.h, Prolongation; RGB vec4s as
// jacobi.comp keeps them):
//   fine[f] = sum_{k in [start[f], start[f + 1])} weight[k] coarse[index[k]]
#version 430
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Start { int start[]; };
layout(std430, binding = 1) readonly buffer Index { int index[]; };
layout(std430, binding = 2) readonly buffer Weight { float weight[]; };
layout(std430, binding = 3) readonly buffer Coarse { vec4 coarse[]; };
layout(std430, binding = 4) writeonly buffer Fine { vec4 fine[]; };
layout(location = 0) uniform int count;

void main() {
  int f = int(gl_WorkGroupID.y * gl_NumWorkGroups.x * 256u + gl_GlobalInvocationID.x);
  if (f >= count) return;
  vec3 acc = vec3(0.0);
  for (int k = start[f]; k < start[f + 1]; ++k) acc += weight[k] * coarse[index[k]].rgb;
  fine[f] = vec4(acc, 0.0);
}
