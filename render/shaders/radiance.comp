// SPDX-License-Identifier: MIT
// The finest level's shaded radiance (render/diffusion.h, ShadedRadiance), from the relaxation's
// fluence (RGB vec4s, jacobi.comp) straight into the shading pass's buffer
// (HierarchyRelaxer::WriteShadedRadiance):
//   out[out_first + c * num_boundary + b] = max(0, phi'[num_interior + b][c] * scale[b * 3 + c])
// with scale = 1 / (2 pi kappa_b): L_b = phi_b / (2 pi), phi = phi' / kappa.
#version 430
layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Phi { vec4 phi[]; };
layout(std430, binding = 1) readonly buffer Scale { float scale[]; };
layout(std430, binding = 2) writeonly buffer Out { float radiance[]; };
layout(location = 0) uniform int num_boundary;
layout(location = 1) uniform int num_interior;
layout(location = 2) uniform int out_first;

void main() {
  int b = int(gl_WorkGroupID.y * gl_NumWorkGroups.x * 256u + gl_GlobalInvocationID.x);
  if (b >= num_boundary) return;
  vec4 p = phi[num_interior + b];
  for (int c = 0; c < 3; ++c) radiance[out_first + c * num_boundary + b] = max(0.0, p[c] * scale[b * 3 + c]);
}
