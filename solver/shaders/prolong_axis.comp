// SPDX-License-Identifier: MIT
// Linear interpolation along one axis from n_in coarse to n_out fine nodes (multigrid.glsl's
// ProlongValue); add != 0 adds into dst. Batched: one field (outer n_in inner values in, outer
// n_out inner out) per work-group z.
FLOATS(0, In, mg_src, readonly);
FLOATS(1, Out, dst, restrict);
INTS(2, LoHi, mg_lohi, readonly);
FLOATS(3, W, mg_w, readonly);
layout(location = 0) uniform int n_in;
layout(location = 1) uniform int n_out;
layout(location = 2) uniform int inner;
layout(location = 3) uniform int outer;
layout(location = 4) uniform int add;
#define MG_PROLONG
#include "multigrid.glsl"

void main() {
  int field = int(Field()), in0 = field * outer * n_in * inner, out0 = field * outer * n_out * inner;
  for (uint e = ThreadIndex(); e < uint(outer * n_out * inner); e += Stride()) {
    int d = out0 + int(e);
    float s = ProlongValue(int(e), n_in, n_out, inner, in0, 0, 0);
    ST(dst, d, add != 0 ? LD(dst, d) + s : s);
  }
}
