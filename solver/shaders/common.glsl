// SPDX-License-Identifier: MIT
// Prepended to every compute shader, after "#version 430" (gl_solver.cc). Dispatches are 1-D
// over `count` threads per field, tiled into 2-D work-group grids where a dimension would
// exceed 65535 groups. Batched dispatches (several right-hand sides of one operator) add a
// third dimension: work-group z is the field index, and every per-field buffer holds its
// fields back to back (field f of a level with n nodes occupies [f n, (f + 1) n)).
layout(local_size_x = 256) in;

uint ThreadIndex() {
  return gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * 256u;
}

// The field (right-hand side) this invocation works on, 0 in unbatched dispatches.
uint Field() { return gl_WorkGroupID.z; }

// Per-field conjugate-gradient scalars (double), kCgStride per field, field f at f * kCgStride
// (gl_internal.h mirrors these slots): rz = r.z, pq = p.A p, rr = r.r, rz_new = the next r.z,
// bb = b.b, active = 1 while the field iterates (0: frozen, alpha = 0), iterations done, and
// tol2 = (tolerance ||b||)^2.
const int kCgRz = 0, kCgPq = 1, kCgRr = 2, kCgRzNew = 3, kCgBb = 4, kCgActive = 5, kCgIter = 6,
          kCgTol2 = 7, kCgStride = 8;
