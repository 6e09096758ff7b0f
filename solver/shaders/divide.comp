// SPDX-License-Identifier: MIT
// x /= y element-wise: turns restricted kappa or mu into averages (y = R applied to ones).
layout(std430, binding = 0) buffer X { float x[]; };
layout(std430, binding = 1) readonly buffer Y { float y[]; };
layout(location = 0) uniform int n;

void main() {
  uint i = ThreadIndex();
  if (i < uint(n)) x[i] /= y[i];
}
