// SPDX-License-Identifier: MIT
// Coarsest-level solve x = M b with M the explicit inverse of the (tiny) coarsest operator,
// computed on the host after each coefficient update (multigrid.glsl's DenseRow). One thread
// per row; double sums. Batched: b and x hold one field per work-group z, or four under
// FIELDS4 (common.glsl).
FLOATS(0, Minv, mg_minv, readonly);
VALUES(1, B, mg_b, readonly);
VALUES(2, X, x, writeonly);
layout(location = 0) uniform int n;
#define MG_DENSE
#include "multigrid.glsl"

void main() {
  uint i = ThreadIndex();
  if (i >= uint(n)) return;
  int o = int(Field()) * n;
  ST(x, o + int(i), DenseRow(int(i), n, 0, o));
}
