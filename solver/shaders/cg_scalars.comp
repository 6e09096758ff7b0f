// SPDX-License-Identifier: MIT
// The end of one batched conjugate-gradient iteration, one thread per field (common.glsl's
// kCg* slots): an active field records rr in its history (hist[f * max_iterations + it]),
// counts the iteration and freezes once rr <= tol2; every field moves rz_new into rz (after
// cg_update.comp's DIRECTION pass has used both).
layout(std430, binding = 0) buffer Scal { double scal[]; };
layout(std430, binding = 1) writeonly buffer Hist { double hist[]; };
layout(location = 0) uniform int fields;
layout(location = 1) uniform int max_iterations;

void main() {
  uint f = ThreadIndex();
  if (f >= uint(fields)) return;
  int s = int(f) * kCgStride;
  if (scal[s + kCgActive] != 0.0LF) {
    int it = int(scal[s + kCgIter]);
    if (it < max_iterations) hist[int(f) * max_iterations + it] = scal[s + kCgRr];
    scal[s + kCgIter] = double(it + 1);
    if (scal[s + kCgRr] <= scal[s + kCgTol2]) scal[s + kCgActive] = 0.0LF;
  }
  scal[s + kCgRz] = scal[s + kCgRzNew];
}
