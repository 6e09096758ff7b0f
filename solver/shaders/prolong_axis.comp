// SPDX-License-Identifier: MIT
// Linear interpolation along one axis from n_in coarse to n_out fine nodes: fine node f is
// w[2f] * coarse[lohi[2f]] + w[2f+1] * coarse[lohi[2f+1]]; add != 0 adds into dst. Batched:
// one field (outer n_in inner values in, outer n_out inner out) per work-group z.
layout(std430, binding = 0) readonly buffer In { float src[]; };
layout(std430, binding = 1) buffer Out { float dst[]; };
layout(std430, binding = 2) readonly buffer LoHi { int lohi[]; };
layout(std430, binding = 3) readonly buffer W { float w[]; };
layout(location = 0) uniform int n_in;
layout(location = 1) uniform int n_out;
layout(location = 2) uniform int inner;
layout(location = 3) uniform int outer;
layout(location = 4) uniform int add;

void main() {
  uint e = ThreadIndex();
  if (e >= uint(outer * n_out * inner)) return;
  int v = int(e) % inner, f = (int(e) / inner) % n_out, o = int(e) / (inner * n_out);
  int field = int(Field()), in0 = field * outer * n_in * inner;
  int d = field * outer * n_out * inner + int(e);
  float s = w[2 * f] * src[in0 + (o * n_in + lohi[2 * f]) * inner + v] +
            w[2 * f + 1] * src[in0 + (o * n_in + lohi[2 * f + 1]) * inner + v];
  dst[d] = add != 0 ? dst[d] + s : s;
}
