// SPDX-License-Identifier: MIT
// Restriction (transpose of linear interpolation) along one axis: `outer` blocks of n_in nodes
// of `inner` contiguous values become blocks of n_out nodes. Coarse node c gathers fine nodes
// gidx[gstart[c] .. gstart[c+1]) with weights gw (solver/multigrid_hierarchy.h). Batched: one
// field (outer n_in inner values in, outer n_out inner out) per work-group z.
layout(std430, binding = 0) readonly buffer In { float src[]; };
layout(std430, binding = 1) writeonly buffer Out { float dst[]; };
layout(std430, binding = 2) readonly buffer GStart { int gstart[]; };
layout(std430, binding = 3) readonly buffer GIdx { int gidx[]; };
layout(std430, binding = 4) readonly buffer GW { float gw[]; };
layout(location = 0) uniform int n_in;
layout(location = 1) uniform int n_out;
layout(location = 2) uniform int inner;
layout(location = 3) uniform int outer;

void main() {
  uint e = ThreadIndex();
  if (e >= uint(outer * n_out * inner)) return;
  int v = int(e) % inner, c = (int(e) / inner) % n_out, o = int(e) / (inner * n_out);
  int f = int(Field()), in0 = f * outer * n_in * inner;
  float s = 0.0;
  for (int g = gstart[c]; g < gstart[c + 1]; ++g) s += gw[g] * src[in0 + (o * n_in + gidx[g]) * inner + v];
  dst[f * outer * n_out * inner + int(e)] = s;
}
