// SPDX-License-Identifier: MIT
// Linear interpolation along one axis from n_in coarse to n_out fine nodes: fine node f is
// w[2f] * coarse[lohi[2f]] + w[2f+1] * coarse[lohi[2f+1]]; add != 0 adds into dst. Batched:
// one field (outer n_in inner values in, outer n_out inner out) per work-group z.
FLOATS(0, In, src, readonly);
FLOATS(1, Out, dst, restrict);
INTS(2, LoHi, lohi, readonly);
FLOATS(3, W, w, readonly);
layout(location = 0) uniform int n_in;
layout(location = 1) uniform int n_out;
layout(location = 2) uniform int inner;
layout(location = 3) uniform int outer;
layout(location = 4) uniform int add;

void main() {
  int field = int(Field()), in0 = field * outer * n_in * inner;
  for (uint e = ThreadIndex(); e < uint(outer * n_out * inner); e += Stride()) {
    int ef = Div(int(e), inner), v = int(e) - ef * inner, o = Div(ef, n_out), f = ef - o * n_out;
    int d = field * outer * n_out * inner + int(e), base = in0 + o * n_in * inner + v;
    float s = LD(w, 2 * f) * LD(src, base + LD(lohi, 2 * f) * inner) +
              LD(w, 2 * f + 1) * LD(src, base + LD(lohi, 2 * f + 1) * inner);
    ST(dst, d, add != 0 ? LD(dst, d) + s : s);
  }
}
