// SPDX-License-Identifier: MIT
// The boundary rows' sources of the polygrid relaxation (render/diffusion.h, HierarchyRelaxer):
//   s[i] = q[q_first + i] * coef[i],  i = b * 3 + c < count  (per boundary node and channel)
// q_first: where the level's q starts in the buffer (the incident pass's buffer holds every
// level's, one after the other).
#version 430
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Q { float q[]; };
layout(std430, binding = 1) readonly buffer Coef { float coef[]; };
layout(std430, binding = 2) writeonly buffer S { float s[]; };
layout(location = 0) uniform int count;
layout(location = 1) uniform int q_first;

void main() {
  int i = int(gl_WorkGroupID.y * gl_NumWorkGroups.x * 256u + gl_GlobalInvocationID.x);
  if (i >= count) return;
  s[i] = q[q_first + i] * coef[i];
}
