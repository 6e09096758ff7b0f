// SPDX-License-Identifier: MIT
// Between the two layouts of a batch's field values (common.glsl): one field per n values
// (per_field: the conjugate-gradient vectors) and four fields per vec4 (grouped: a FIELDS4
// V-cycle's level buffers, field 4 g + c in component c of group g's n vec4). Packs
// per_field into grouped, or with UNPACK the reverse; fields past `fields` are packed as 0 and
// not unpacked. With DOUBLE both hold doubles, grouped four consecutive ones per node
// (common.glsl's LDD4). Work-group z: the group of four fields; a grid-stride loop over the n
// nodes.
#ifdef DOUBLE
DOUBLES(0, PerField, per_field, restrict);
DOUBLES(1, Packed, grouped, restrict);
#else
FLOATS(0, PerField, per_field, restrict);
VEC4S(1, Packed, grouped, restrict);
#endif
layout(location = 0) uniform int n;
layout(location = 1) uniform int fields;

void main() {
  int g = int(Field());
  for (uint e = ThreadIndex(); e < uint(n); e += Stride()) {
#ifdef DOUBLE
    for (int c = 0; c < 4; ++c) {
      int f = 4 * g + c, at = 4 * (g * n + int(e)) + c;
#ifdef UNPACK
      if (f < fields) STD(per_field, f * n + int(e), LDD(grouped, at));
#else
      STD(grouped, at, f < fields ? LDD(per_field, f * n + int(e)) : 0.0LF);
#endif
    }
#elif defined(UNPACK)
    vec4 v = LD4(grouped, g * n + int(e));
    for (int c = 0; c < 4; ++c)
      if (4 * g + c < fields) ST(per_field, (4 * g + c) * n + int(e), v[c]);
#else
    vec4 v = vec4(0.0);
    for (int c = 0; c < 4; ++c)
      if (4 * g + c < fields) v[c] = LD(per_field, (4 * g + c) * n + int(e));
    ST(grouped, g * n + int(e), v);
#endif
  }
}
