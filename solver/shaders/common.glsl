// SPDX-License-Identifier: MIT
// Prepended to every compute shader, after "#version 430" (gl_solver.cc). Dispatches are 1-D
// over `count` threads per field, tiled into 2-D work-group grids where a dimension would
// exceed 65535 groups. Batched dispatches (several right-hand sides of one operator) add a
// third dimension: work-group z is the field index, and every per-field buffer holds its
// fields back to back (field f of a level with n nodes occupies [f n, (f + 1) n)).
// TL_GROUP invocations per work group: 256, or what the host defines (64 on llvmpipe, where the
// invocations of a mostly idle group of a small level still cost).
#ifndef TL_GROUP
#define TL_GROUP 256
#endif
layout(local_size_x = TL_GROUP) in;

uint ThreadIndex() {
  return gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * uint(TL_GROUP);
}

// The field (right-hand side) this invocation works on, 0 in unbatched dispatches.
uint Field() { return gl_WorkGroupID.z; }

// Invocations per field: the step of a grid-stride loop `for (e = ThreadIndex(); e < n; e +=
// Stride())`. The host launches one invocation per element on a GPU (one pass of the loop) and
// a few work groups per field on llvmpipe (gl_internal.h, Tuning).
uint Stride() { return gl_NumWorkGroups.x * gl_NumWorkGroups.y * uint(TL_GROUP); }

// a / b for 0 <= a < 2^31, b > 0. llvmpipe scalarises integer division (one divide per SIMD
// lane); there it is a vector double division, exact for these ranges.
int Div(int a, int b) {
#ifdef TL_IMAGES
  return int(double(a) / double(b));
#else
  return a / b;
#endif
}

// Per-node kernels walk a level's nodes in z-columns of kz nodes (kz a uniform from the host:
// 1 on a GPU, one node per invocation; nz on llvmpipe, whose fixed cost per invocation is
// high). Invocation t covers i = t % nx, j = (t / nx) % ny, k = k0 .. k1 - 1 with
// k0 = kz (t / (nx ny)), so neighbouring invocations take neighbouring i (coalesced).
// ColumnAt takes the invocation's index t from the caller (tail.comp's loops within a group).
bool ColumnAt(int t, int nx, int ny, int nz, int kz, out int i, out int j, out int k0, out int k1) {
  int nxy = nx * ny, c = Div(t, nxy), r = t - c * nxy;
  j = Div(r, nx);
  i = r - j * nx;
  k0 = c * kz;
  k1 = min(k0 + kz, nz);
  return k0 < nz;
}
bool Column(int nx, int ny, int nz, int kz, out int i, out int j, out int k0, out int k1) {
  return ColumnAt(int(ThreadIndex()), nx, ny, nz, kz, i, j, k0, k1);
}

// Arrays: FLOATS(binding, Block, name, qualifier) declares name[] (qualifier readonly, writeonly
// or restrict), read with LD(name, e) / written with ST(name, e, v); DOUBLES with LDD / STD,
// INTS with LD, VEC4S (four floats per element) with LD4 / ST. Under TL_IMAGES (the host's
// choice on llvmpipe, gl_internal.h) they are image buffers (r32f, rg32ui holding a double's two
// halves, r32i, rgba32f) at image unit `binding`, else shader storage blocks at binding `binding`.
#ifdef TL_IMAGES
#define FLOATS(b, B, a, q) layout(binding = b, r32f) q uniform imageBuffer a
#define INTS(b, B, a, q) layout(binding = b, r32i) q uniform iimageBuffer a
#define DOUBLES(b, B, a, q) layout(binding = b, rg32ui) q uniform uimageBuffer a
#define VEC4S(b, B, a, q) layout(binding = b, rgba32f) q uniform imageBuffer a
#define LD(a, e) imageLoad(a, int(e)).x
#define LD4(a, e) imageLoad(a, int(e))
#define LDD(a, e) packDouble2x32(imageLoad(a, int(e)).xy)
#define ST(a, e, v) imageStore(a, int(e), vec4(v))
#define STD(a, e, v) imageStore(a, int(e), uvec4(unpackDouble2x32(v), 0u, 0u))
#else
#define FLOATS(b, B, a, q) layout(std430, binding = b) q buffer B { float a[]; }
#define INTS(b, B, a, q) layout(std430, binding = b) q buffer B { int a[]; }
#define DOUBLES(b, B, a, q) layout(std430, binding = b) q buffer B { double a[]; }
#define VEC4S(b, B, a, q) layout(std430, binding = b) q buffer B { vec4 a[]; }
#define LD(a, e) a[e]
#define LD4(a, e) a[e]
#define LDD(a, e) a[e]
#define ST(a, e, v) a[e] = (v)
#define STD(a, e, v) a[e] = (v)
#endif

// Component c (0..3, not a constant) of a double vector. NVIDIA's compiler (driver 580) has no
// variable index into double vectors ("can't find __setVectorIndex function in stdlib" at link
// time), so shaders read them through DComp and build vectors from arrays (float ones too,
// to be safe).
double DComp(dvec4 v, int c) { return c == 0 ? v.x : c == 1 ? v.y : c == 2 ? v.z : v.w; }

// FIELDS4 (the host's define for a batch, Tuning::pack_fields): the field values come four
// fields to a vec4 per node, work-group z counting groups of four fields (field 4 g + c in
// component c of group g; a buffer's group holds n vec4). The coefficients stay one float per
// node, read once for four fields. VALUES declares a value array (VEC4S or FLOATS); MG_VALUE,
// MG_DVALUE and MG_LDV are its type, double type and load (multigrid.glsl). Double values
// (the CG iterate) come four fields to four consecutive doubles: LDD4 reads node e's four.
#ifdef FIELDS4
#define VALUES VEC4S
#define MG_VALUE vec4
#define MG_DVALUE dvec4
#define MG_LDV LD4
#define LDD4(a, e) dvec4(LDD(a, 4 * (e)), LDD(a, 4 * (e) + 1), LDD(a, 4 * (e) + 2), LDD(a, 4 * (e) + 3))
#else
#define VALUES FLOATS
#define MG_VALUE float
#define MG_DVALUE double
#define MG_LDV LD
#endif

// QUARTERS (with FIELDS4; the host's define for the finest level of a single field's solve,
// Tuning::quarters): the level's x-rows are cut into four quarters of qw nodes (qw even, the
// last quarter padded), and node (q qw + i, j, k) is component q of packed node i + qw (j + ny k).
// One load then brings four nodes of a row, as FIELDS4 brings four fields. The coefficients
// come packed the same way (COEFS, MG_COEF, LDC; padding nodes have all coefficients 0), and a
// node's x-neighbour across a quarter's edge is the next component of the packed node at the
// row's other end: FromLeft / FromRight shift the components (component 0 of the first quarter
// and 3 of the last get 0, where the coupling is 0 too). The colours of the zebra sweeps agree
// because qw is even.
#ifdef QUARTERS
#define COEFS VEC4S
#define MG_COEF vec4
#define LDC LD4
vec4 FromLeft(vec4 v) { return vec4(0.0, v.xyz); }
vec4 FromRight(vec4 v) { return vec4(v.yzw, 0.0); }
dvec4 FromLeft(dvec4 v) { return dvec4(0.0LF, v.xyz); }
dvec4 FromRight(dvec4 v) { return dvec4(v.yzw, 0.0LF); }
#else
#define COEFS FLOATS
#define MG_COEF float
#define LDC LD
#endif

// Per-field conjugate-gradient scalars (double), kCgStride per field, field f at f * kCgStride
// (gl_internal.h mirrors these slots): rz = r.z, pq = p.A p, rr = r.r, rz_new = the next r.z,
// bb = b.b, active = 1 while the field iterates (0: frozen, alpha = 0), iterations done, and
// tol2 = (tolerance ||b||)^2.
const int kCgRz = 0, kCgPq = 1, kCgRr = 2, kCgRzNew = 3, kCgBb = 4, kCgActive = 5, kCgIter = 6,
          kCgTol2 = 7, kCgStride = 8;
