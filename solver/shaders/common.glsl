// SPDX-License-Identifier: MIT
// Prepended to every compute shader, after "#version 430" (gl_solver.cc). Dispatches are 1-D
// over `count` threads, tiled into 2-D work-group grids where a dimension would exceed 65535
// groups.
layout(local_size_x = 256) in;

uint ThreadIndex() {
  return gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * 256u;
}
