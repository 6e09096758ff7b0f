// SPDX-License-Identifier: MIT
// Shared by raster.comp, incident.comp and shade.comp: render_gl::Program puts this file after
// "#version 430" and before the shader's own text. The formulas are those of
// render/render_passes.h (PassView::Project, FresnelTransmittance, RenderPasses::Incident).

// A view: eye.w its near plane, p = (ortho ? 1 : 0, scale, width, height); see PassView.
struct View { vec4 eye; vec4 right; vec4 up; vec4 forward; vec4 p; };
// A light sample: v.xyz the direction towards a directional light or a point light's position
// (mm), v.w 0 for a directional light, 1 for a point light with one map, 2 + f for face f of a
// point light's cube map (LightSample::cube_face); E.rgb the irradiance at normal incidence,
// E.w |v - centre|^2 (a point light's falloff numerator); the view of its shadow map. The
// camera is appended after the light samples for the shading pass.
struct Sample { vec4 v; vec4 E; View view; };
// A mesh vertex or a boundary node: position (mm) and unit normal.
struct Vertex { vec4 p; vec4 n; };

layout(std430, binding = 0) readonly buffer Samples { Sample samples[]; };
// Depth rasters, float bits (positive floats order as their bits): the shadow maps one after
// the other (S x S texels each, row y at y * S), or the camera's raster.
layout(std430, binding = 1) buffer Depth { uint depth[]; };

const float kPi = 3.14159265358979323846;

// The index of this invocation (dispatches are tiled over x and y; render_gl::Dispatch).
int invocation() { return int(gl_WorkGroupID.y * gl_NumWorkGroups.x * 256u + gl_GlobalInvocationID.x); }

// Screen x, y (pixels) and depth (mm) of p in view vw.
vec3 project(View vw, vec3 p) {
  vec3 d = p - vw.eye.xyz;
  float x = dot(d, vw.right.xyz), y = dot(d, vw.up.xyz), z = dot(d, vw.forward.xyz);
  float aspect = vw.p.z / vw.p.w;
  float k = vw.p.x != 0.0 ? vw.p.y : vw.p.y / max(z, 1e-9);
  return vec3(0.5 * vw.p.z * (1.0 + x * k / aspect), 0.5 * vw.p.w * (1.0 - y * k), z);
}

// PassView::Homogeneous: (x w, y w, w, depth) with w = 1 (ortho) or the depth (perspective).
vec4 homogeneous(View vw, vec3 p) {
  vec3 d = p - vw.eye.xyz;
  float x = dot(d, vw.right.xyz), y = dot(d, vw.up.xyz), z = dot(d, vw.forward.xyz);
  float w = vw.p.x != 0.0 ? 1.0 : z;
  float aspect = vw.p.z / vw.p.w;
  return vec4(0.5 * vw.p.z * (w + x * vw.p.y / aspect), 0.5 * vw.p.w * (w - y * vw.p.y), w, z);
}

// RasterTriangle::Hit (render_passes.h): the barycentrics (xyz) and depth (w) of the point of the
// triangle with homogeneous vertices a, b, c on the line of sight through screen position q;
// covered(): the line meets the triangle deeper than the view's near plane.
vec4 hit(vec4 a, vec4 b, vec4 c, vec2 q) {
  vec2 da = a.xy - a.z * q, db = b.xy - b.z * q, dc = c.xy - c.z * q;
  vec3 e = vec3(db.x * dc.y - dc.x * db.y, dc.x * da.y - da.x * dc.y, da.x * db.y - db.x * da.y);
  float sum = e.x + e.y + e.z;
  if (sum == 0.0) return vec4(-1.0);
  vec3 l = e / sum;
  return vec4(l, l.x * a.w + l.y * b.w + l.z * c.w);
}
bool covered(vec4 h, float near) { return min(h.x, min(h.y, h.z)) >= 0.0 && h.w > near; }

// 1 - F_r for unpolarised light entering a dielectric of relative index eta at cosine cos_i.
float fresnel_t(float cos_i, float eta) {
  cos_i = clamp(cos_i, 0.0, 1.0);
  float sin_t2 = (1.0 - cos_i * cos_i) / (eta * eta);
  if (sin_t2 >= 1.0) return 0.0;
  float cos_t = sqrt(1.0 - sin_t2);
  float rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
  float rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
  return 1.0 - 0.5 * (rs * rs + rp * rp);
}

// The cube-map face of direction d (CubeFace in render/render_passes.h): 2 a + (d_a < 0) for
// the axis a of d's largest |component|, ties to the lower axis.
int cube_face(vec3 d) {
  vec3 a = abs(d);
  int axis = a.x >= a.y && a.x >= a.z ? 0 : (a.y >= a.z ? 1 : 2);
  return 2 * axis + (d[axis] < 0.0 ? 1 : 0);
}

// Irradiance factor (falloff x visibility) of light sample s at p with normal n, 0 when facing
// away, shadowed in the sample's S x S map (deeper than the map by more than bias, at the texel
// clamped to the map) or, for a cube-map face, outside that face's directions; the cosine cos_i
// and the unit direction l towards the light.
float light(int s, vec3 p, vec3 n, int S, float bias, out float cos_i, out vec3 l) {
  float e = 1.0;
  vec4 v = samples[s].v;
  if (v.w == 0.0) {
    l = v.xyz;
  } else {
    l = v.xyz - p;
    e = samples[s].E.w / max(1e-12, dot(l, l));
    l = normalize(l);
  }
  cos_i = dot(n, l);
  if (cos_i <= 0.0) return 0.0;
  if (v.w >= 2.0 && cube_face(p - v.xyz) != int(v.w) - 2) return 0.0;
  vec3 sp = project(samples[s].view, p);
  int x = int(clamp(sp.x, 0.0, float(S - 1))), y = int(clamp(sp.y, 0.0, float(S - 1)));
  if (sp.z > uintBitsToFloat(depth[s * S * S + y * S + x]) + bias) return 0.0;
  return e;
}
