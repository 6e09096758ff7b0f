// SPDX-License-Identifier: MIT
// Pass 3, shading (after common.glsl), one invocation per output pixel: the mean over its
// ss x ss samples of the camera raster (ids: nearest triangle, 0x7fffffff where empty) of
//   F_t(cos_o) L_ms + sum_s (Ward(rho_s, alpha) + rho_d / pi) E_s f cos_i V
// (RenderPasses::Shade). L_ms: barycentric over the triangle's vertices, each vertex the
// weighted sum of the radiance at its 4 nearest boundary nodes. The light samples may be
// summed over several dispatches (GlInfo::loop_budget: one invocation loops ss^2 (s1 - s0 + 18)
// times): the one with s0 = 0 writes the image and adds L_ms, the others add their samples.
layout(local_size_x = 256) in;
struct Near { ivec4 idx; vec4 w; };
layout(std430, binding = 2) readonly buffer Verts { Vertex verts[]; };
layout(std430, binding = 3) readonly buffer Tris { int tris[]; };
layout(std430, binding = 4) readonly buffer Ids { int ids[]; };
layout(std430, binding = 5) readonly buffer Nears { Near nears[]; };
layout(std430, binding = 6) buffer Image { float image[]; };  // (y * width + x) * 3 + c
layout(std430, binding = 7) readonly buffer Radiance { float radiance[]; };  // c * num_boundary + b
layout(location = 0) uniform int width;
layout(location = 1) uniform int height;
layout(location = 2) uniform int ss;
layout(location = 3) uniform int num_samples;  // light samples; the camera is samples[num_samples]
layout(location = 4) uniform int map_size;
layout(location = 5) uniform float bias;
layout(location = 6) uniform float eta;
layout(location = 7) uniform float specular;
layout(location = 8) uniform float roughness;
layout(location = 9) uniform float reflectance;
layout(location = 10) uniform int num_boundary;
layout(location = 11) uniform int s0;  // the light samples [s0, s1) of this dispatch
layout(location = 12) uniform int s1;

vec3 vertex_radiance(int v) {
  vec3 r = vec3(0.0);
  for (int k = 0; k < 4; ++k) {
    int b = nears[v].idx[k];
    r += nears[v].w[k] * vec3(radiance[b], radiance[num_boundary + b], radiance[2 * num_boundary + b]);
  }
  return r;
}

void main() {
  int pix = invocation();
  if (pix >= width * height) return;
  int px = pix % width, py = pix / width;
  View cam = samples[num_samples].view;
  int W = width * ss;
  float alpha2 = roughness * roughness;
  vec3 sum = vec3(0.0);
  for (int sy = 0; sy < ss; ++sy)
    for (int sx = 0; sx < ss; ++sx) {
      int x = px * ss + sx, y = py * ss + sy;
      int t = ids[y * W + x];
      if (t == 0x7fffffff) continue;
      int i0 = tris[3 * t], i1 = tris[3 * t + 1], i2 = tris[3 * t + 2];
      vec4 h = hit(homogeneous(cam, verts[i0].p.xyz), homogeneous(cam, verts[i1].p.xyz),
                   homogeneous(cam, verts[i2].p.xyz), vec2(float(x) + 0.5, float(y) + 0.5));
      float w0 = h.x, w1 = h.y, w2 = h.z;
      vec3 p = w0 * verts[i0].p.xyz + w1 * verts[i1].p.xyz + w2 * verts[i2].p.xyz;
      vec3 n = normalize(w0 * verts[i0].n.xyz + w1 * verts[i1].n.xyz + w2 * verts[i2].n.xyz);
      vec3 view = normalize(cam.eye.xyz - p);
      float cos_o = max(0.0, dot(n, view));
      float ft = fresnel_t(cos_o, eta);
      vec3 surface = vec3(0.0);
      if (cos_o > 0.0 && (specular > 0.0 || reflectance > 0.0)) {
        for (int s = s0; s < s1; ++s) {
          float cos_i;
          vec3 l;
          float e = light(s, p, n, map_size, bias, cos_i, l);
          if (e == 0.0) continue;
          vec3 hv = normalize(l + view);
          float cd = clamp(dot(n, hv), 1e-6, 1.0);
          float tan2 = (1.0 - cd * cd) / (cd * cd);
          float ward = specular * exp(-tan2 / alpha2) / (4.0 * kPi * alpha2 * sqrt(cos_i * cos_o));
          surface += ((ward + reflectance / kPi) * e * cos_i) * samples[s].E.rgb;
        }
      }
      vec3 ms = vec3(0.0);
      if (s0 == 0) ms = w0 * vertex_radiance(i0) + w1 * vertex_radiance(i1) + w2 * vertex_radiance(i2);
      sum += ft * ms + surface;
    }
  sum /= float(ss * ss);
  if (s0 > 0) sum += vec3(image[3 * pix], image[3 * pix + 1], image[3 * pix + 2]);
  image[3 * pix] = sum.r;
  image[3 * pix + 1] = sum.g;
  image[3 * pix + 2] = sum.b;
}
