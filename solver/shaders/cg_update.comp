// SPDX-License-Identifier: MIT
// The vector updates of batched conjugate gradients, with each field's coefficient taken from
// the per-field scalars on the GPU (common.glsl's kCg* slots), so the host reads nothing back:
//   default:   x += alpha p, r -= alpha q,  alpha = rz / pq, 0 for a frozen field
//              (buffers x [double], r, p, q, scalars)
//   DIRECTION: p = z + beta p,  beta = rz_new / rz   (buffers p, z, -, -, scalars)
//   ADD:       x += p on active fields (the full-multigrid start; buffers x, -, p, -, scalars)
// x, r, p, q, z hold one field of n values per work-group z, or under FIELDS4 four fields per
// vec4 (x: four consecutive doubles per node) with one coefficient per field of the group;
// fields past `fields` take 0; under QUARTERS (common.glsl) the four components are one field's
// nodes and take its coefficient. A grid-stride loop (common.glsl).
DOUBLES(4, Scal, scal, readonly);
layout(location = 0) uniform int n;
layout(location = 1) uniform int fields;
#ifdef DIRECTION
VALUES(0, P, p, restrict);
VALUES(1, Z, z, readonly);
#else
DOUBLES(0, X, x, restrict);
VALUES(1, R, r, restrict);
VALUES(2, P, p, readonly);
VALUES(3, Q, q, readonly);
#endif

#ifdef FIELDS4
#define K 4
#else
#define K 1
#endif

// Slot `slot` of component c's field, or false past the last field.
bool Slot(int c, int slot, out double v) {
#ifdef QUARTERS
  int f = int(Field());
#else
  int f = int(Field()) * K + c;
#endif
  v = f < fields ? LDD(scal, f * kCgStride + slot) : 0.0LF;
  return f < fields;
}

void main() {
  uint o = Field() * uint(n);
  double cs[K];
  for (int c = 0; c < K; ++c) {
    double v0, v1, on;
    double s = 0.0LF;
#ifdef DIRECTION
    if (Slot(c, kCgRz, v0) && v0 != 0.0LF && Slot(c, kCgRzNew, v1)) s = v1 / v0;  // beta
#elif defined(ADD)
    if (Slot(c, kCgActive, on) && on != 0.0LF) s = 1.0LF;
#else
    if (Slot(c, kCgActive, on) && on != 0.0LF && Slot(c, kCgPq, v0) && v0 != 0.0LF &&
        Slot(c, kCgRz, v1))
      s = v1 / v0;  // alpha
#endif
    cs[c] = s;
  }
#ifdef FIELDS4
  dvec4 coef = dvec4(cs[0], cs[1], cs[2], cs[3]);
#else
  double coef = cs[0];
#endif
#if defined(ADD) && !defined(FIELDS4)
  if (coef == 0.0LF) return;
#endif
  for (uint e = o + ThreadIndex(); e < o + uint(n); e += Stride()) {
#ifdef DIRECTION
    ST(p, e, MG_LDV(z, e) + MG_VALUE(coef) * MG_LDV(p, e));
#else
#ifdef FIELDS4
    vec4 pe = LD4(p, e);
    for (int c = 0; c < 4; ++c)
      if (cs[c] != 0.0LF) STD(x, 4u * e + uint(c), LDD(x, 4u * e + uint(c)) + cs[c] * double(pe[c]));
#else
    STD(x, e, LDD(x, e) + coef * double(LD(p, e)));
#endif
#ifndef ADD
    ST(r, e, MG_LDV(r, e) - MG_VALUE(coef) * MG_LDV(q, e));
#endif
#endif
  }
}
