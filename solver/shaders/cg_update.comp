// SPDX-License-Identifier: MIT
// The vector updates of batched conjugate gradients, with each field's coefficient taken from
// the per-field scalars on the GPU (common.glsl's kCg* slots), so the host reads nothing back:
//   default:   x += alpha p, r -= alpha q,  alpha = rz / pq, 0 for a frozen field
//              (buffers x [double], r, p, q, scalars)
//   DIRECTION: p = z + beta p,  beta = rz_new / rz   (buffers p, z, -, -, scalars)
//   ADD:       x += p on active fields (the full-multigrid start; buffers x, -, p, -, scalars)
// x, r, p, q, z hold one field of n values per work-group z; a grid-stride loop (common.glsl).
DOUBLES(4, Scal, scal, readonly);
layout(location = 0) uniform int n;
#ifdef DIRECTION
FLOATS(0, P, p, restrict);
FLOATS(1, Z, z, readonly);
#else
DOUBLES(0, X, x, restrict);
FLOATS(1, R, r, restrict);
FLOATS(2, P, p, readonly);
FLOATS(3, Q, q, readonly);
#endif

void main() {
  uint f = Field(), s = f * uint(kCgStride), o = f * uint(n);
#ifdef DIRECTION
  double rz = LDD(scal, s + kCgRz);
  float beta = rz != 0.0LF ? float(LDD(scal, s + kCgRzNew) / rz) : 0.0;
  for (uint e = o + ThreadIndex(); e < o + uint(n); e += Stride())
    ST(p, e, LD(z, e) + beta * LD(p, e));
#elif defined(ADD)
  if (LDD(scal, s + kCgActive) == 0.0LF) return;
  for (uint e = o + ThreadIndex(); e < o + uint(n); e += Stride())
    STD(x, e, LDD(x, e) + double(LD(p, e)));
#else
  double pq = LDD(scal, s + kCgPq);
  double alpha = LDD(scal, s + kCgActive) != 0.0LF && pq != 0.0LF ? LDD(scal, s + kCgRz) / pq
                                                                  : 0.0LF;
  for (uint e = o + ThreadIndex(); e < o + uint(n); e += Stride()) {
    STD(x, e, LDD(x, e) + alpha * double(LD(p, e)));
    ST(r, e, LD(r, e) - float(alpha) * LD(q, e));
  }
#endif
}
