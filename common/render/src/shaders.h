// GLSL sources (#version 330 core: runs on 4.5 and on the 3.3 fallback).
#pragma once

namespace probeless::render::internal {

// Shared tone mapping and sRGB encoding (must match ToneMapping::Apply and LinearToSrgb8).
inline constexpr const char* kCommonGlsl = R"(
uniform int u_tone_op;       // 0 clamp, 1 extended Reinhard
uniform vec2 u_tone;         // exposure, white
vec3 ToneMap(vec3 x) {
  vec3 e = max(x, vec3(0.0)) * u_tone.x;
  if (u_tone_op == 1) return e * (1.0 + e / (u_tone.y * u_tone.y)) / (1.0 + e);
  return min(e, vec3(1.0));
}
vec3 SrgbEncode(vec3 c) {
  c = clamp(c, 0.0, 1.0);
  vec3 lo = c * 12.92;
  vec3 hi = 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055;
  return mix(hi, lo, lessThanEqual(c, vec3(0.0031308)));
}
vec3 SrgbDecode(vec3 c) {
  vec3 lo = c / 12.92;
  vec3 hi = pow((c + 0.055) / 1.055, vec3(2.4));
  return mix(hi, lo, lessThanEqual(c, vec3(0.04045)));
}
)";

// Pinhole projection with image rows = framebuffer rows (row 0 = top of the image).
inline constexpr const char* kProjectGlsl = R"(
uniform vec4 u_proj;   // 2fx/W, (2cx+1)/W-1, 2fy/H, (2cy+1)/H-1
uniform vec2 u_depth;  // a, b: clip z = a Z + b
vec4 Project(vec3 p) {
  return vec4(u_proj.x * p.x + u_proj.y * p.z, u_proj.z * p.y + u_proj.w * p.z,
              u_depth.x * p.z + u_depth.y, p.z);
}
)";

inline constexpr const char* kObjectVs = R"(
layout(location = 0) in vec3 a_position;
layout(location = 1) in vec3 a_color;
layout(location = 2) in vec2 a_uv;
layout(location = 3) in vec4 a_t0;
layout(location = 4) in vec4 a_t1;
layout(location = 5) in vec4 a_t2;
layout(location = 6) in vec4 a_t3;
uniform mat4 u_model_view;
uniform vec4 u_light_r[4];
uniform vec4 u_light_g[4];
uniform vec4 u_light_b[4];
uniform vec3 u_albedo;
out vec3 v_radiance;
out vec3 v_albedo;
out vec2 v_uv;
float Dot4(vec4 l[4]) {
  return dot(a_t0, l[0]) + dot(a_t1, l[1]) + dot(a_t2, l[2]) + dot(a_t3, l[3]);
}
void main() {
  vec4 p = u_model_view * vec4(a_position, 1.0);
  gl_Position = Project(p.xyz);
  // Knorr & Kurz 2014 §4.3: per-vertex dot product of baked transfer and SH light.
  v_radiance = u_albedo * a_color * vec3(Dot4(u_light_r), Dot4(u_light_g), Dot4(u_light_b));
  v_albedo = u_albedo * a_color;
  v_uv = a_uv;
}
)";

inline constexpr const char* kObjectFs = R"(
in vec3 v_radiance;
in vec3 v_albedo;
in vec2 v_uv;
uniform sampler2D u_texture;
uniform int u_has_texture;
// Differential rendering from G_r on virtual pixels (render/differential.h): inside the pixel rect
// u_virtual_rect (x0, y0, x1, y1), the radiance times the real scene's extra occlusion (rgb of
// u_virtual_mod) plus the albedo times the bounce from the real scene (u_virtual_add).
uniform int u_has_virtual;
uniform ivec4 u_virtual_rect;
uniform sampler2D u_virtual_mod;
uniform sampler2D u_virtual_add;
layout(location = 0) out vec4 o_color;
void main() {
  vec3 r = v_radiance;
  ivec2 px = ivec2(gl_FragCoord.xy);
  if (u_has_virtual == 1 && px.x >= u_virtual_rect.x && px.y >= u_virtual_rect.y &&
      px.x < u_virtual_rect.z && px.y < u_virtual_rect.w) {
    ivec2 q = px - u_virtual_rect.xy;
    r = r * texelFetch(u_virtual_mod, q, 0).rgb + v_albedo * texelFetch(u_virtual_add, q, 0).rgb;
  }
  if (u_has_texture == 1) r *= texture(u_texture, vec2(v_uv.x, 1.0 - v_uv.y)).rgb;
  o_color = vec4(SrgbEncode(ToneMap(r)), 0.0);  // alpha 0 marks virtual coverage
}
)";

inline constexpr const char* kReceiverVs = R"(
layout(location = 0) in vec3 a_position;
layout(location = 1) in vec4 a_r0;
layout(location = 2) in vec4 a_r1;
layout(location = 3) in vec4 a_r2;
layout(location = 4) in vec4 a_r3;
layout(location = 5) in vec4 a_w0;
layout(location = 6) in vec4 a_w1;
layout(location = 7) in vec4 a_w2;
layout(location = 8) in vec4 a_w3;
uniform mat4 u_model_view;
uniform vec4 u_light_r[4];
uniform vec4 u_light_g[4];
uniform vec4 u_light_b[4];
out vec3 v_real;
out vec3 v_with;
vec3 Shade(vec4 t0, vec4 t1, vec4 t2, vec4 t3) {
  return vec3(dot(t0, u_light_r[0]) + dot(t1, u_light_r[1]) + dot(t2, u_light_r[2]) + dot(t3, u_light_r[3]),
              dot(t0, u_light_g[0]) + dot(t1, u_light_g[1]) + dot(t2, u_light_g[2]) + dot(t3, u_light_g[3]),
              dot(t0, u_light_b[0]) + dot(t1, u_light_b[1]) + dot(t2, u_light_b[2]) + dot(t3, u_light_b[3]));
}
void main() {
  vec4 p = u_model_view * vec4(a_position, 1.0);
  gl_Position = Project(p.xyz);
  v_real = Shade(a_r0, a_r1, a_r2, a_r3);
  v_with = Shade(a_w0, a_w1, a_w2, a_w3);
}
)";

// Gruber eq. 13 on the receiver's own pixels: reads the camera texel under the fragment and writes
// I_d (alpha 1 = no virtual object). Pixels where R'_d == R_d keep the camera byte.
inline constexpr const char* kReceiverFs = R"(
in vec3 v_real;
in vec3 v_with;
uniform sampler2D u_camera;
uniform int u_has_camera;
layout(location = 0) out vec4 o_color;
void main() {
  vec3 c = u_has_camera == 1 ? texelFetch(u_camera, ivec2(gl_FragCoord.xy), 0).rgb : vec3(0.0);
  if (any(notEqual(v_real, v_with))) {
    vec3 d = ToneMap(v_with) - ToneMap(v_real);
    c = SrgbEncode(SrgbDecode(c) * (vec3(1.0) + d));
  }
  o_color = vec4(c, 1.0);
}
)";

// A triangle covering the screen; v_uv (0,0) at framebuffer row 0 (the image's top row).
inline constexpr const char* kFullscreenVs = R"(
out vec2 v_uv;
uniform int u_flip;   // 1: texture row 0 at the top of a window
void main() {
  vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
  v_uv = vec2(p.x, u_flip == 1 ? 1.0 - p.y : p.y);
  gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
)";

// Writes the real depth G_r (metres) into the depth buffer.
inline constexpr const char* kDepthFs = R"(
in vec2 v_uv;
uniform sampler2D u_real_depth;
void main() {
  float z = texture(u_real_depth, v_uv).r;
  if (z <= 0.0) { gl_FragDepth = 1.0; return; }
  float ndc = (u_depth.x * z + u_depth.y) / z;
  gl_FragDepth = clamp(ndc * 0.5 + 0.5, 0.0, 1.0);
}
)";

// Gruber et al. 2015 eq. 13-15 (compiled per combination of HAS_CAMERA, HAS_DIFFERENTIAL and
// HAS_INDIRECT, so llvmpipe runs only what a frame needs). Alpha 1 marks "no virtual object".
inline constexpr const char* kCompositeFs = R"(
in vec2 v_uv;
uniform sampler2D u_camera;
uniform sampler2D u_real;      // R_d
uniform sampler2D u_with;      // R'_d
uniform sampler2D u_indirect;  // I_i
layout(location = 0) out vec4 o_color;
void main() {
#if HAS_CAMERA
  vec3 c = texture(u_camera, v_uv).rgb;
#else
  vec3 c = vec3(0.0);
#endif
#if HAS_DIFFERENTIAL
  vec3 r = texture(u_real, v_uv).rgb;
  vec3 rv = texture(u_with, v_uv).rgb;
  if (any(notEqual(r, rv))) {
    vec3 d = ToneMap(rv) - ToneMap(r);                                  // eq. 13
    c = SrgbEncode(SrgbDecode(c) * (vec3(1.0) + d));
  }
#endif
#if HAS_INDIRECT
  vec3 ii = texture(u_indirect, v_uv).rgb;
  if (any(notEqual(ii, vec3(0.0)))) c = SrgbEncode(SrgbDecode(c) + ii);  // eq. 15
#endif
  o_color = vec4(c, 1.0);
}
)";

// Draws a texture (window back-end: composite and panels).
inline constexpr const char* kBlitFs = R"(
in vec2 v_uv;
uniform sampler2D u_image;
layout(location = 0) out vec4 o_color;
void main() { o_color = vec4(texture(u_image, v_uv).rgb, 1.0); }
)";

}  // namespace probeless::render::internal
