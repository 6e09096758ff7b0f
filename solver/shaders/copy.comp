// SPDX-License-Identifier: MIT
// dst = src: the bandwidth reference for `bench forward --backend gl` (a grid-stride loop),
// and Buffer::CopyFrom under Tuning::shader_clear; with ZERO, dst = 0 (Buffer::Zero; src unread).
#ifdef TL_IMAGES
layout(binding = 0, rgba32f) readonly uniform imageBuffer src;
layout(binding = 1, rgba32f) writeonly uniform imageBuffer dst;
#else
layout(std430, binding = 0) readonly buffer Src { uvec4 src[]; };  // (raw bits: any element type)
layout(std430, binding = 1) writeonly buffer Dst { uvec4 dst[]; };
#endif
layout(location = 0) uniform int n4;

void main() {
  for (uint i = ThreadIndex(); i < uint(n4); i += Stride()) {
#if defined(ZERO) && defined(TL_IMAGES)
#error ZERO is for storage buffers (image buffers clear with glClearBufferData)
#elif defined(ZERO)
    dst[i] = uvec4(0u);
#elif defined(TL_IMAGES)
    imageStore(dst, int(i), imageLoad(src, int(i)));
#else
    dst[i] = src[i];
#endif
  }
}
