// SPDX-License-Identifier: MIT
// Restriction (transpose of linear interpolation) along one axis: `outer` blocks of n_in nodes
// of `inner` contiguous values become blocks of n_out nodes. Coarse node c gathers fine nodes
// gidx[gstart[c] .. gstart[c+1]) with weights gw (solver/multigrid_hierarchy.h). Batched: one
// field (outer n_in inner values in, outer n_out inner out) per work-group z.
FLOATS(0, In, src, readonly);
FLOATS(1, Out, dst, writeonly);
INTS(2, GStart, gstart, readonly);
INTS(3, GIdx, gidx, readonly);
FLOATS(4, GW, gw, readonly);
layout(location = 0) uniform int n_in;
layout(location = 1) uniform int n_out;
layout(location = 2) uniform int inner;
layout(location = 3) uniform int outer;

void main() {
  int f = int(Field()), in0 = f * outer * n_in * inner, out0 = f * outer * n_out * inner;
  for (uint e = ThreadIndex(); e < uint(outer * n_out * inner); e += Stride()) {
    int ec = Div(int(e), inner), v = int(e) - ec * inner, o = Div(ec, n_out), c = ec - o * n_out;
    int base = in0 + o * n_in * inner + v;
    float s = 0.0;
    for (int g = LD(gstart, c); g < LD(gstart, c + 1); ++g)
      s += LD(gw, g) * LD(src, base + LD(gidx, g) * inner);
    ST(dst, out0 + int(e), s);
  }
}
