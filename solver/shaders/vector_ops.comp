// SPDX-License-Identifier: MIT
// Element-wise vector operations of conjugate gradients and coefficient restriction:
//   op 0: x += alpha p, r -= alpha q     (buffers x, r, p, q)
//   op 1: p = z + alpha p                (buffers p, z)      [alpha = beta]
//   op 2: x /= y                         (buffers x, y)
//   op 3: x += y                         (buffers x, y)
// With X_DOUBLE defined, x is double (the conjugate-gradient iterate).
#ifdef X_DOUBLE
layout(std430, binding = 0) buffer X { double x[]; };
#define XT double
#else
layout(std430, binding = 0) buffer X { float x[]; };
#define XT float
#endif
layout(std430, binding = 1) buffer Y { float y[]; };
layout(std430, binding = 2) readonly buffer P { float pv[]; };
layout(std430, binding = 3) readonly buffer Q { float qv[]; };
layout(location = 0) uniform int n;
layout(location = 1) uniform int op;
layout(location = 2) uniform float alpha;

void main() {
  uint i = ThreadIndex();
  if (i >= uint(n)) return;
  if (op == 0) {
    x[i] += XT(alpha) * XT(pv[i]);
    y[i] -= alpha * qv[i];
  } else if (op == 1) {
    x[i] = XT(y[i]) + XT(alpha) * x[i];
  } else if (op == 2) {
    x[i] /= XT(y[i]);
  } else {
    x[i] += XT(y[i]);
  }
}
