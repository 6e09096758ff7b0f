// SPDX-License-Identifier: MIT
// Coarsest-level solve x = M b with M the explicit inverse of the (tiny) coarsest operator,
// computed on the host after each coefficient update. One thread per row; double sums.
// Batched: b and x hold one field per work-group z.
layout(std430, binding = 0) readonly buffer Minv { float minv[]; };
layout(std430, binding = 1) readonly buffer B { float b[]; };
layout(std430, binding = 2) writeonly buffer X { float x[]; };
layout(location = 0) uniform int n;

void main() {
  uint i = ThreadIndex();
  if (i >= uint(n)) return;
  int o = int(Field()) * n;
  double s = 0.0LF;
  for (int j = 0; j < n; ++j) s += double(minv[int(i) * n + j]) * double(b[o + j]);
  x[o + int(i)] = float(s);
}
