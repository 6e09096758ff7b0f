// SPDX-License-Identifier: MIT
// Between the two layouts of a batch's field values (common.glsl): one field per n values
// (per_field: the conjugate-gradient vectors) and four fields per vec4 (grouped: a FIELDS4
// V-cycle's level buffers, field 4 g + c in component c of group g's n vec4). Packs
// per_field into grouped, or with UNPACK the reverse; fields past `fields` are packed as 0 and
// not unpacked. With DOUBLE both hold doubles, grouped four consecutive ones per node
// (common.glsl's LDD4). Work-group z: the group of four fields; a grid-stride loop over the n
// nodes. With QUARTERS, between one field's values (nx per row) and its quarter rows
// (common.glsl: n packed nodes of qw; padding packed as 0): the finest level's values and
// coefficients of a single field's solve.
#ifdef DOUBLE
DOUBLES(0, PerField, per_field, restrict);
DOUBLES(1, Packed, grouped, restrict);
#else
FLOATS(0, PerField, per_field, restrict);
VEC4S(1, Packed, grouped, restrict);
#endif
layout(location = 0) uniform int n;
layout(location = 1) uniform int fields;
#ifdef QUARTERS
layout(location = 2) uniform int nx;
layout(location = 3) uniform int qw;
#endif

// Where component c of packed node e comes from in per_field, or -1 (padding): field
// 4 g + c's node e (FIELDS4), or under QUARTERS the one field's node (c qw + i, row) for packed
// node i + qw row (common.glsl), n then the packed node count.
int Source(int g, int e, int c) {
#ifdef QUARTERS
  int row = Div(e, qw), x = c * qw + e - row * qw;
  return x < nx ? x + nx * row : -1;
#else
  int f = 4 * g + c;
  return f < fields ? f * n + e : -1;
#endif
}

void main() {
  int g = int(Field());
  for (uint e = ThreadIndex(); e < uint(n); e += Stride()) {
    int at = g * n + int(e);
#ifdef DOUBLE
    for (int c = 0; c < 4; ++c) {
      int from = Source(g, int(e), c);
#ifdef UNPACK
      if (from >= 0) STD(per_field, from, LDD(grouped, 4 * at + c));
#else
      STD(grouped, 4 * at + c, from >= 0 ? LDD(per_field, from) : 0.0LF);
#endif
    }
#elif defined(UNPACK)
    vec4 v = LD4(grouped, at);
    for (int c = 0; c < 4; ++c) {
      int from = Source(g, int(e), c);
      if (from >= 0) ST(per_field, from, v[c]);
    }
#else
    float v[4];
    for (int c = 0; c < 4; ++c) {
      int from = Source(g, int(e), c);
      v[c] = from >= 0 ? LD(per_field, from) : 0.0;
    }
    ST(grouped, at, vec4(v[0], v[1], v[2], v[3]));
#endif
  }
}
