// SPDX-License-Identifier: MIT
// Pass 1, incident light at the boundary nodes (after common.glsl), one invocation per node:
//   q[node * 3 + c] = sum_s E_s,c f cos_i F_t(cos_i) V   (RenderPasses::Incident)
layout(local_size_x = 256) in;
layout(std430, binding = 5) readonly buffer Nodes { Vertex nodes[]; };
layout(std430, binding = 6) writeonly buffer Q { float q[]; };
layout(location = 0) uniform int num_nodes;
layout(location = 1) uniform int num_samples;
layout(location = 2) uniform int map_size;
layout(location = 3) uniform float bias;
layout(location = 4) uniform float eta;

void main() {
  int b = invocation();
  if (b >= num_nodes) return;
  vec3 p = nodes[b].p.xyz, n = nodes[b].n.xyz;
  vec3 acc = vec3(0.0);
  for (int s = 0; s < num_samples; ++s) {
    float cos_i;
    vec3 l;
    float e = light(s, p, n, map_size, bias, cos_i, l);
    if (e == 0.0) continue;
    acc += (e * cos_i * fresnel_t(cos_i, eta)) * samples[s].E.rgb;
  }
  q[3 * b] = acc.r;
  q[3 * b + 1] = acc.g;
  q[3 * b + 2] = acc.b;
}
