// SPDX-License-Identifier: MIT
// The boundary rows' sources of the polygrid relaxation (render/diffusion.h, HierarchyRelaxer),
// one RGB vec4 per boundary node b < count as jacobi.comp reads them:
//   s[b][c] = q[q_first + b * 3 + c] * coef[b * 3 + c]
// q_first: where the level's q starts in the buffer (the incident pass's buffer holds every
// level's, one after the other).
#version 430
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Q { float q[]; };
layout(std430, binding = 1) readonly buffer Coef { float coef[]; };
layout(std430, binding = 2) writeonly buffer S { vec4 s[]; };
layout(location = 0) uniform int count;
layout(location = 1) uniform int q_first;

void main() {
  int b = int(gl_WorkGroupID.y * gl_NumWorkGroups.x * 256u + gl_GlobalInvocationID.x);
  if (b >= count) return;
  int i = q_first + b * 3;
  s[b] = vec4(q[i] * coef[b * 3], q[i + 1] * coef[b * 3 + 1], q[i + 2] * coef[b * 3 + 2], 0.0);
}
