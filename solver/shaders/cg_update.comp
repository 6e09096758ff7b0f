// SPDX-License-Identifier: MIT
// The vector updates of batched conjugate gradients, with each field's coefficient taken from
// the per-field scalars on the GPU (common.glsl's kCg* slots), so the host reads nothing back:
//   default:   x += alpha p, r -= alpha q,  alpha = rz / pq, 0 for a frozen field
//              (buffers x [double], r, p, q, scalars)
//   DIRECTION: p = z + beta p,  beta = rz_new / rz   (buffers p, z, -, -, scalars)
// x, r, p, q, z hold one field of n values per work-group z.
layout(std430, binding = 4) readonly buffer Scal { double scal[]; };
layout(location = 0) uniform int n;
#ifdef DIRECTION
layout(std430, binding = 0) buffer P { float p[]; };
layout(std430, binding = 1) readonly buffer Z { float z[]; };
#else
layout(std430, binding = 0) buffer X { double x[]; };
layout(std430, binding = 1) buffer R { float r[]; };
layout(std430, binding = 2) readonly buffer P { float p[]; };
layout(std430, binding = 3) readonly buffer Q { float q[]; };
#endif

void main() {
  uint i = ThreadIndex();
  if (i >= uint(n)) return;
  uint f = Field(), o = f * uint(n) + i, s = f * uint(kCgStride);
#ifdef DIRECTION
  double rz = scal[s + kCgRz];
  float beta = rz != 0.0LF ? float(scal[s + kCgRzNew] / rz) : 0.0;
  p[o] = z[o] + beta * p[o];
#else
  double pq = scal[s + kCgPq];
  double alpha = scal[s + kCgActive] != 0.0LF && pq != 0.0LF ? scal[s + kCgRz] / pq : 0.0LF;
  x[o] += alpha * double(p[o]);
  r[o] -= float(alpha) * q[o];
#endif
}
