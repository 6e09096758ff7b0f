// SPDX-License-Identifier: MIT
// The end of one batched conjugate-gradient iteration, one thread per field (common.glsl's
// kCg* slots): an active field records rr in its history (hist[f * max_iterations + it]),
// counts the iteration and freezes once rr <= tol2; every field moves rz_new into rz (after
// cg_update.comp's DIRECTION pass has used both).
DOUBLES(0, Scal, scal, restrict);
DOUBLES(1, Hist, hist, writeonly);
layout(location = 0) uniform int fields;
layout(location = 1) uniform int max_iterations;

void main() {
  uint f = ThreadIndex();
  if (f >= uint(fields)) return;
  int s = int(f) * kCgStride;
  double rr = LDD(scal, s + kCgRr);
  if (LDD(scal, s + kCgActive) != 0.0LF) {
    int it = int(LDD(scal, s + kCgIter));
    if (it < max_iterations) STD(hist, int(f) * max_iterations + it, rr);
    STD(scal, s + kCgIter, double(it + 1));
    if (rr <= LDD(scal, s + kCgTol2)) STD(scal, s + kCgActive, 0.0LF);
  }
  STD(scal, s + kCgRz, LDD(scal, s + kCgRzNew));
}
