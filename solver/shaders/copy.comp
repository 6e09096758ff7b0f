// SPDX-License-Identifier: MIT
// dst = src: the bandwidth reference for `bench forward --backend gl`.
layout(std430, binding = 0) readonly buffer Src { vec4 src[]; };
layout(std430, binding = 1) writeonly buffer Dst { vec4 dst[]; };
layout(location = 0) uniform int n4;

void main() {
  uint i = ThreadIndex();
  if (i < uint(n4)) dst[i] = src[i];
}
