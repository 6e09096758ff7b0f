// SPDX-License-Identifier: MIT
// Coarsest-level solve x = M b with M the explicit inverse of the (tiny) coarsest operator,
// computed on the host after each coefficient update. One thread per row; double sums.
// Batched: b and x hold one field per work-group z.
FLOATS(0, Minv, minv, readonly);
FLOATS(1, B, b, readonly);
FLOATS(2, X, x, writeonly);
layout(location = 0) uniform int n;

void main() {
  uint i = ThreadIndex();
  if (i >= uint(n)) return;
  int o = int(Field()) * n;
  double s = 0.0LF;
  for (int j = 0; j < n; ++j) s += double(LD(minv, int(i) * n + j)) * double(LD(b, o + j));
  ST(x, o + int(i), float(s));
}
