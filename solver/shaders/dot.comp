// SPDX-License-Identifier: MIT
// Partial sums of a . b (and, with PAIR defined, of a . c too), accumulated in double, each
// invocation first summing its elements of a grid-stride loop (common.glsl), then one sum per
// work group from a shared-memory tree; with TL_INVOCATION_SUMS (llvmpipe, where barriers are
// coroutine switches) one sum per invocation instead. Batched: a, b, c hold one field of n
// values per work-group z, or four fields per vec4 under FIELDS4 (common.glsl: the sums are
// then dvec4, one component per field); partial sum g of field f (G per field) is at
// partial[(f G + g) W + k], W = 1 or 2 sums, for fields f < `fields` only. Under QUARTERS the
// four components are one field's nodes (common.glsl): their sums add up to its partial sum.
VALUES(0, A, a, readonly);
VALUES(1, B, b, readonly);
DOUBLES(2, Partial, partial, writeonly);
#ifdef FIELDS4
#define DSUM dvec4
#define K 4
#else
#define DSUM double
#define K 1
#endif
#ifdef PAIR
VALUES(3, C, c, readonly);
const uint W = 2u;
shared DSUM sdata1[TL_GROUP];
#else
const uint W = 1u;
#endif
layout(location = 0) uniform int n;
layout(location = 1) uniform int fields;
shared DSUM sdata[TL_GROUP];

// Stores this group's (or invocation's) sums s0, s1 as partial sum g of G of each field.
void Store(uint g, uint G, DSUM s0, DSUM s1) {
#ifdef QUARTERS
  uint at = (Field() * G + g) * W;
  STD(partial, at, (s0.x + s0.y) + (s0.z + s0.w));
#ifdef PAIR
  STD(partial, at + 1u, (s1.x + s1.y) + (s1.z + s1.w));
#endif
  return;
#endif
  for (int c = 0; c < K; ++c) {
    uint f = Field() * uint(K) + uint(c);
    if (f >= uint(fields)) return;
    uint at = (f * G + g) * W;
#ifdef FIELDS4
    STD(partial, at, DComp(s0, c));
#ifdef PAIR
    STD(partial, at + 1u, DComp(s1, c));
#endif
#else
    STD(partial, at, s0);
#ifdef PAIR
    STD(partial, at + 1u, s1);
#endif
#endif
  }
}

void main() {
  uint l = gl_LocalInvocationID.x, f0 = Field() * uint(n);
  DSUM s0 = DSUM(0.0LF), s1 = DSUM(0.0LF);
  for (uint e = ThreadIndex(); e < uint(n); e += Stride()) {
    DSUM ae = DSUM(MG_LDV(a, f0 + e));
    s0 += ae * DSUM(MG_LDV(b, f0 + e));
#ifdef PAIR
    s1 += ae * DSUM(MG_LDV(c, f0 + e));
#endif
  }
#ifdef TL_INVOCATION_SUMS
  Store(ThreadIndex(), Stride(), s0, s1);
  return;
#endif
  sdata[l] = s0;
#ifdef PAIR
  sdata1[l] = s1;
#endif
  barrier();
  for (uint s = uint(TL_GROUP) / 2u; s > 0u; s >>= 1u) {
    if (l < s) {
      sdata[l] += sdata[l + s];
#ifdef PAIR
      sdata1[l] += sdata1[l + s];
#endif
    }
    barrier();
  }
  if (l == 0u) {
    uint groups = gl_NumWorkGroups.x * gl_NumWorkGroups.y;
    uint g = gl_WorkGroupID.x + gl_WorkGroupID.y * gl_NumWorkGroups.x;
#ifdef PAIR
    Store(g, groups, sdata[0], sdata1[0]);
#else
    Store(g, groups, sdata[0], s1);
#endif
  }
}
