// SPDX-License-Identifier: MIT
// The grid transfer between level `level` and the next coarser one in one dispatch
// (multigrid.glsl's Restrict3Value / Prolong3Value over the packed transfers mg_idx, mg_wts):
// by default the restriction dst = R src (src: the level's values, dst: the coarse level's);
// with PROLONG defined the prolongation dst (+)= P src (add != 0 adds into dst). A grid-stride
// loop over the output values. Batched: one field of each level per work-group z, or four
// under FIELDS4 (common.glsl). Under QUARTERS (level 0 of a single field's solve) the fine
// level's values are its quarter rows of mg_qw (common.glsl), the coarse level's plain.
#if defined(QUARTERS) && !defined(PROLONG)
VEC4S(0, In, mg_src, readonly);
#define MG_FINE_QUARTERS
#else
VALUES(0, In, mg_src, readonly);
#endif
#if defined(QUARTERS) && defined(PROLONG)
VEC4S(1, Out, dst, restrict);
#else
VALUES(1, Out, dst, restrict);
#endif
INTS(2, Idx, mg_idx, readonly);
FLOATS(3, Wts, mg_wts, readonly);
layout(location = 0) uniform int level;
layout(location = 1) uniform int add;
layout(location = 2) uniform int mg_qw;
#define MG_TRANSFER
#include "multigrid.glsl"

void main() {
  MgAxis X = MgLoadAxis(level, 0), Y = MgLoadAxis(level, 1), Z = MgLoadAxis(level, 2);
  int fine = X.n_fine * Y.n_fine * Z.n_fine, coarse = X.n_coarse * Y.n_coarse * Z.n_coarse;
  int f = int(Field());
#if defined(QUARTERS) && defined(PROLONG)
  // One packed node (four fine nodes of a row) per pass.
  int nq = mg_qw * Y.n_fine * Z.n_fine;
  for (uint e = ThreadIndex(); e < uint(nq); e += Stride()) {
    int r = Div(int(e), mg_qw), i = int(e) - r * mg_qw, k = Div(r, Y.n_fine);
    MgRow row = ProlongRow(r - k * Y.n_fine, k, X, Y, Z);
    float a[4];
    for (int c = 0; c < 4; ++c) {
      int x = c * mg_qw + i;
      a[c] = x < X.n_fine ? ProlongAt(x, row, X, 0) : 0.0;
    }
    vec4 s = vec4(a[0], a[1], a[2], a[3]);
    ST(dst, int(e), add != 0 ? LD4(dst, int(e)) + s : s);
  }
#elif defined(PROLONG)
  for (uint e = ThreadIndex(); e < uint(fine); e += Stride()) {
    int d = f * fine + int(e);
    MG_VALUE s = Prolong3Value(int(e), X, Y, Z, f * coarse);
    ST(dst, d, add != 0 ? MG_LDV(dst, d) + s : s);
  }
#else
  for (uint e = ThreadIndex(); e < uint(coarse); e += Stride())
    ST(dst, f * coarse + int(e), Restrict3Value(int(e), X, Y, Z, f * fine));
#endif
}
