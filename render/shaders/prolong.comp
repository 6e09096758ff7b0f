// SPDX-License-Identifier: MIT
// Coarse-to-fine prolongation of the fluence (render/polygrid.h, Prolongation; RGB vec4s as
// jacobi.comp keeps them), into all three of the level's fluence buffers at once:
//   fine0[f] = fine1[f] = fine2[f] = sum_{k in [start[f], start[f + 1])} weight[k] coarse[index[k]]
// or, with zero != 0 (the coarsest level's start), 0 (bindings 0-3 then unread). One dispatch
// instead of glCopyBufferSubData / glClearBufferData: on the H200 (2026-12-04) the copies and
// clears left ~1.2 ms of a frame's diffusion outside any dispatch.
#version 430
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Start { int start[]; };
layout(std430, binding = 1) readonly buffer Index { int index[]; };
layout(std430, binding = 2) readonly buffer Weight { float weight[]; };
layout(std430, binding = 3) readonly buffer Coarse { vec4 coarse[]; };
layout(std430, binding = 4) writeonly buffer Fine0 { vec4 fine0[]; };
layout(std430, binding = 5) writeonly buffer Fine1 { vec4 fine1[]; };
layout(std430, binding = 6) writeonly buffer Fine2 { vec4 fine2[]; };
layout(location = 0) uniform int count;
layout(location = 1) uniform int zero;

void main() {
  int f = int(gl_WorkGroupID.y * gl_NumWorkGroups.x * 256u + gl_GlobalInvocationID.x);
  if (f >= count) return;
  vec3 acc = vec3(0.0);
  if (zero == 0)
    for (int k = start[f]; k < start[f + 1]; ++k) acc += weight[k] * coarse[index[k]].rgb;
  const vec4 v = vec4(acc, 0.0);
  fine0[f] = v;
  fine1[f] = v;
  fine2[f] = v;
}
