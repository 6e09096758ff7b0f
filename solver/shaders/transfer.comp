// SPDX-License-Identifier: MIT
// The grid transfer between level `level` and the next coarser one in one dispatch
// (multigrid.glsl's Restrict3Value / Prolong3Value over the packed transfers mg_idx, mg_wts):
// by default the restriction dst = R src (src: the level's values, dst: the coarse level's);
// with PROLONG defined the prolongation dst (+)= P src (add != 0 adds into dst). A grid-stride
// loop over the output values. Batched: one field of each level per work-group z, or four
// under FIELDS4 (common.glsl).
VALUES(0, In, mg_src, readonly);
VALUES(1, Out, dst, restrict);
INTS(2, Idx, mg_idx, readonly);
FLOATS(3, Wts, mg_wts, readonly);
layout(location = 0) uniform int level;
layout(location = 1) uniform int add;
#define MG_TRANSFER
#include "multigrid.glsl"

void main() {
  MgAxis X = MgLoadAxis(level, 0), Y = MgLoadAxis(level, 1), Z = MgLoadAxis(level, 2);
  int fine = X.n_fine * Y.n_fine * Z.n_fine, coarse = X.n_coarse * Y.n_coarse * Z.n_coarse;
  int f = int(Field());
#ifdef PROLONG
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
