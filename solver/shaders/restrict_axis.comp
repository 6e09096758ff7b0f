// SPDX-License-Identifier: MIT
// Restriction (transpose of linear interpolation) along one axis: `outer` blocks of n_in nodes
// of `inner` contiguous values become blocks of n_out nodes (multigrid.glsl's RestrictValue).
// Batched: one field (outer n_in inner values in, outer n_out inner out) per work-group z.
FLOATS(0, In, mg_src, readonly);
FLOATS(1, Out, dst, writeonly);
INTS(2, GStart, mg_gstart, readonly);
INTS(3, GIdx, mg_gidx, readonly);
FLOATS(4, GW, mg_gw, readonly);
layout(location = 0) uniform int n_in;
layout(location = 1) uniform int n_out;
layout(location = 2) uniform int inner;
layout(location = 3) uniform int outer;
#define MG_RESTRICT
#include "multigrid.glsl"

void main() {
  int f = int(Field()), in0 = f * outer * n_in * inner, out0 = f * outer * n_out * inner;
  for (uint e = ThreadIndex(); e < uint(outer * n_out * inner); e += Stride())
    ST(dst, out0 + int(e), RestrictValue(int(e), n_in, n_out, inner, in0, 0, 0, 0));
}
