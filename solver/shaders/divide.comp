// SPDX-License-Identifier: MIT
// x /= y element-wise: turns restricted kappa or mu into averages (y = R applied to ones).
FLOATS(0, X, x, restrict);
FLOATS(1, Y, y, readonly);
layout(location = 0) uniform int n;

void main() {
  for (uint i = ThreadIndex(); i < uint(n); i += Stride()) ST(x, i, LD(x, i) / LD(y, i));
}
