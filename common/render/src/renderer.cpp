#include "probeless/render/renderer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <glm/gtc/type_ptr.hpp>
#include <glm/mat4x4.hpp>
#include <string>

#include "context.h"
#include "gl_functions.h"
#include "probeless/raytrace/render.h"
#include "shaders.h"

namespace probeless::render {

namespace {

using internal::Gl;
using raytrace::Mat3;
using raytrace::Transform;
using raytrace::Vec3;

constexpr int kMaxRendererBands = 4;
constexpr int kPadded = 16;  // transfer floats per vertex on the GPU

// Column-major 4x4 of a rigid transform (for glUniformMatrix4fv).
// The 4x4 matrix of a rigid transform (GLM, column-major as glUniformMatrix4fv expects).
glm::mat4 ToGl(const Transform& t) {
  glm::mat4 m(1.0f);
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) m[c][r] = static_cast<float>(t.rotation.m[r][c]);
    m[3][r] = static_cast<float>(t.translation[r]);
  }
  return m;
}

// Light uniforms: per channel 4 vec4 = 16 coefficients, zero beyond the light's count.
struct LightUniforms {
  std::array<float, 16> r{}, g{}, b{};
};
LightUniforms ToUniforms(const ShLightRgb& light) {
  LightUniforms u;
  const int count =
      std::min(light.bands, kMaxRendererBands) * std::min(light.bands, kMaxRendererBands);
  for (int k = 0; k < count; ++k) {
    u.r[k] = light.coefficients[k][0];
    u.g[k] = light.coefficients[k][1];
    u.b[k] = light.coefficients[k][2];
  }
  return u;
}

// Pads a vertex-major transfer array (count per vertex) to kPadded floats per vertex.
std::vector<float> PadTransfer(std::span<const float> transfer, int count, size_t vertices) {
  std::vector<float> padded(vertices * kPadded, 0.0f);
  for (size_t v = 0; v < vertices; ++v) {
    std::copy_n(transfer.data() + v * count, count, padded.data() + v * kPadded);
  }
  return padded;
}

}  // namespace

std::string BackendName(Backend backend) {
  return backend == Backend::kWindow ? "window" : "offscreen";
}

Backend BackendFromName(const std::string& name) {
  if (name == "offscreen" || name == "osmesa") return Backend::kOffscreen;
  if (name == "window" || name == "glfw") return Backend::kWindow;
  throw RenderError("unknown render backend '" + name + "' (expected offscreen or window)");
}

float ToneMapping::Apply(float x) const {
  const float e = std::max(x, 0.0f) * exposure;
  if (op == ToneOperator::kReinhard) return e * (1.0f + e / (white * white)) / (1.0f + e);
  return std::min(e, 1.0f);
}

void Intrinsics::Validate() const {
  if (width < 1 || height < 1 || width > 8192 || height > 8192) {
    throw RenderError("intrinsics: image size " + std::to_string(width) + "x" +
                      std::to_string(height) + " out of range 1..8192");
  }
  if (!(fx > 0) || !(fy > 0)) throw RenderError("intrinsics: fx and fy must be > 0");
  if (!(near_m > 0) || !(far_m > near_m)) {
    throw RenderError("intrinsics: need 0 < near_m < far_m");
  }
}

std::array<float, 3> ShadeTransfer(std::span<const float> transfer, const ShLightRgb& light) {
  std::array<float, 3> out{};
  const size_t count = std::min(
      transfer.size(), static_cast<size_t>(light.bands) * static_cast<size_t>(light.bands));
  for (size_t k = 0; k < count; ++k) {
    for (int c = 0; c < 3; ++c) out[c] += transfer[k] * light.coefficients[k][c];
  }
  return out;
}

ShLightRgb RotateLight(const ShLightRgb& light, const Mat3& anchor_to_camera) {
  if (light.bands < 1 || light.bands > 5) {
    throw RenderError("light: bands " + std::to_string(light.bands) + " out of range 1..5");
  }
  const int count = light.bands * light.bands;
  const std::vector<double> m = prt::ShRotationMatrix(anchor_to_camera, light.bands);
  ShLightRgb out;
  out.bands = light.bands;
  for (int n = 0; n < count; ++n) {
    for (int c = 0; c < 3; ++c) {
      double sum = 0;
      for (int k = 0; k < count; ++k) sum += m[n * count + k] * light.coefficients[k][c];
      out.coefficients[n][c] = static_cast<float>(sum);
    }
  }
  return out;
}

struct Renderer::Impl {
  RendererOptions options;
  std::unique_ptr<internal::Context> context;
  Gl gl;
  std::string version, renderer_name;

  GLuint object_program = 0, receiver_program = 0, depth_program = 0, blit_program = 0;
  GLuint composite_programs[8] = {};  // by HAS_CAMERA | HAS_DIFFERENTIAL << 1 | HAS_INDIRECT << 2
  GLuint empty_vao = 0;

  struct GpuObject {
    GLuint vao = 0, vbo_position = 0, vbo_color = 0, vbo_uv = 0, vbo_transfer = 0, ebo = 0;
    GLsizei index_count = 0;
    Anchor anchor = Anchor::kFace;
    Transform object_to_anchor;
    Vec3 albedo{1, 1, 1};
    GLuint texture = 0;
    bool visible = true;
    bool cull = true;
  };
  std::vector<GpuObject> objects;

  struct GpuReceiver {
    GLuint vao = 0, vbo_position = 0, vbo_real = 0, vbo_with = 0, ebo = 0;
    GLsizei index_count = 0;
    size_t vertices = 0;
    int count = 0;
    Anchor anchor = Anchor::kFace;
    bool visible = true;
    bool cull = true;
  };
  std::vector<GpuReceiver> receivers;

  // Back-face culling: image rows are framebuffer rows (a y flip), so counter-clockwise seen from
  // outside becomes clockwise in window coordinates.
  void SetCulling(bool cull) {
    if (cull) {
      gl.Enable(GL_CULL_FACE);
      gl.FrontFace(GL_CW);
      gl.CullFace(GL_BACK);
    } else {
      gl.Disable(GL_CULL_FACE);
    }
  }

  // Framebuffers of the current size.
  int width = 0, height = 0;
  GLuint virtual_depth = 0;
  GLuint diff_real = 0, diff_with = 0;
  GLuint out_fbo = 0, out_color = 0;
  GLuint camera_tex = 0, real_depth_tex = 0, indirect_tex = 0;
  GLuint virtual_mod_tex = 0, virtual_add_tex = 0;
  std::vector<uint8_t> readback;
  std::vector<float> cpu_real, cpu_with;
  std::vector<GLuint> panel_textures;
  // What the last Present showed, for TakeClicks: the composite's size and the panels' rects.
  int presented_width = 0, presented_height = 0;
  std::vector<PixelRect> presented_panels;

  GLuint Compile(GLenum type, const std::string& source, const char* name) {
    const GLuint s = gl.CreateShader(type);
    const char* text = source.c_str();
    gl.ShaderSource(s, 1, &text, nullptr);
    gl.CompileShader(s);
    GLint ok = 0;
    gl.GetShaderiv(s, GL_COMPILE_STATUS, &ok);
    if (!ok) {
      char log[2048] = {};
      gl.GetShaderInfoLog(s, sizeof(log), nullptr, log);
      std::string line(log);
      std::replace(line.begin(), line.end(), '\n', ' ');
      throw RenderError(std::string("shader ") + name + " does not compile: " + line);
    }
    return s;
  }

  GLuint Program(const char* vs, const char* fs, const char* name,
                 const std::string& defines = "") {
    const std::string header = "#version 330 core\n" + defines;
    const GLuint v = Compile(GL_VERTEX_SHADER, header + internal::kProjectGlsl + vs, name);
    const GLuint f = Compile(GL_FRAGMENT_SHADER,
                             header + internal::kCommonGlsl + internal::kProjectGlsl + fs, name);
    const GLuint p = gl.CreateProgram();
    gl.AttachShader(p, v);
    gl.AttachShader(p, f);
    gl.LinkProgram(p);
    gl.DeleteShader(v);
    gl.DeleteShader(f);
    GLint ok = 0;
    gl.GetProgramiv(p, GL_LINK_STATUS, &ok);
    if (!ok) {
      char log[2048] = {};
      gl.GetProgramInfoLog(p, sizeof(log), nullptr, log);
      throw RenderError(std::string("program ") + name + " does not link: " + log);
    }
    return p;
  }

  GLint Loc(GLuint program, const char* name) { return gl.GetUniformLocation(program, name); }

  GLuint CompositeProgram(bool camera, bool differential, bool indirect) {
    const int key = (camera ? 1 : 0) | (differential ? 2 : 0) | (indirect ? 4 : 0);
    if (composite_programs[key] == 0) {
      const std::string defines = std::string("#define HAS_CAMERA ") + (camera ? "1" : "0") +
                                  "\n#define HAS_DIFFERENTIAL " + (differential ? "1" : "0") +
                                  "\n#define HAS_INDIRECT " + (indirect ? "1" : "0") + "\n";
      composite_programs[key] =
          Program(internal::kFullscreenVs, internal::kCompositeFs, "composite", defines);
    }
    return composite_programs[key];
  }

  GLuint MakeTexture(GLint internal_format, int w, int h, GLenum format, GLenum type,
                     GLint filter = GL_NEAREST) {
    GLuint t = 0;
    gl.GenTextures(1, &t);
    gl.BindTexture(GL_TEXTURE_2D, t);
    gl.TexImage2D(GL_TEXTURE_2D, 0, internal_format, w, h, 0, format, type, nullptr);
    gl.TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, filter);
    gl.TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, filter);
    gl.TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    gl.TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    return t;
  }

  void CheckFbo(const char* name) {
    const GLenum status = gl.CheckFramebufferStatus(GL_FRAMEBUFFER);
    if (status != GL_FRAMEBUFFER_COMPLETE) {
      throw RenderError(std::string("framebuffer ") + name + " incomplete (status " +
                        std::to_string(status) + ")");
    }
  }

  void ReleaseTargets() {
    gl.DeleteFramebuffers(1, &out_fbo);
    const GLuint textures[] = {virtual_depth, diff_real,       diff_with,
                               out_color,     camera_tex,      real_depth_tex,
                               indirect_tex,  virtual_mod_tex, virtual_add_tex};
    gl.DeleteTextures(9, textures);
  }

  void EnsureSize(int w, int h) {
    if (w == width && h == height) return;
    if (width != 0) ReleaseTargets();
    width = w;
    height = h;
    virtual_depth = MakeTexture(GL_DEPTH_COMPONENT24, w, h, GL_DEPTH_COMPONENT, GL_UNSIGNED_INT);

    // R_d and R'_d of per-pixel transfer buffers (computed on the CPU, uploaded).
    diff_real = MakeTexture(GL_RGBA32F, w, h, GL_RGBA, GL_FLOAT);
    diff_with = MakeTexture(GL_RGBA32F, w, h, GL_RGBA, GL_FLOAT);

    out_color = MakeTexture(GL_RGBA8, w, h, GL_RGBA, GL_UNSIGNED_BYTE, GL_LINEAR);
    gl.GenFramebuffers(1, &out_fbo);
    gl.BindFramebuffer(GL_FRAMEBUFFER, out_fbo);
    gl.FramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, out_color, 0);
    gl.FramebufferTexture2D(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_TEXTURE_2D, virtual_depth, 0);
    CheckFbo("output");

    camera_tex = MakeTexture(GL_RGB8, w, h, GL_RGB, GL_UNSIGNED_BYTE);
    real_depth_tex = MakeTexture(GL_R32F, w, h, GL_RED, GL_FLOAT);
    indirect_tex = MakeTexture(GL_RGB32F, w, h, GL_RGB, GL_FLOAT);
    virtual_mod_tex = MakeTexture(GL_RGB32F, w, h, GL_RGB, GL_FLOAT);
    virtual_add_tex = MakeTexture(GL_RGB32F, w, h, GL_RGB, GL_FLOAT);
    gl.BindFramebuffer(GL_FRAMEBUFFER, 0);
  }

  GLuint Buffer(GLenum target, const void* data, size_t bytes) {
    GLuint b = 0;
    gl.GenBuffers(1, &b);
    gl.BindBuffer(target, b);
    gl.BufferData(target, static_cast<GLsizeiptr>(bytes), data, GL_STATIC_DRAW);
    return b;
  }

  void Attrib(GLuint location, GLuint buffer, int components, GLsizei stride, size_t offset) {
    gl.BindBuffer(GL_ARRAY_BUFFER, buffer);
    gl.EnableVertexAttribArray(location);
    gl.VertexAttribPointer(location, components, GL_FLOAT, GL_FALSE, stride,
                           reinterpret_cast<const void*>(offset));
  }

  void SetCommonUniforms(GLuint program, const Intrinsics& k) {
    gl.UseProgram(program);
    const float w = static_cast<float>(k.width), h = static_cast<float>(k.height);
    gl.Uniform4f(Loc(program, "u_proj"), static_cast<float>(2 * k.fx / w),
                 static_cast<float>((2 * k.cx + 1) / w - 1), static_cast<float>(2 * k.fy / h),
                 static_cast<float>((2 * k.cy + 1) / h - 1));
    const double n = k.near_m, f = k.far_m;
    gl.Uniform2f(Loc(program, "u_depth"), static_cast<float>((f + n) / (f - n)),
                 static_cast<float>(-2 * f * n / (f - n)));
    gl.Uniform1i(Loc(program, "u_tone_op"), options.tone.op == ToneOperator::kReinhard ? 1 : 0);
    gl.Uniform2f(Loc(program, "u_tone"), options.tone.exposure, options.tone.white);
  }

  void SetLight(GLuint program, const ShLightRgb& light) {
    const LightUniforms u = ToUniforms(light);
    gl.Uniform4fv(Loc(program, "u_light_r"), 4, u.r.data());
    gl.Uniform4fv(Loc(program, "u_light_g"), 4, u.g.data());
    gl.Uniform4fv(Loc(program, "u_light_b"), 4, u.b.data());
  }

  void BindTexture(GLuint program, const char* name, int unit, GLuint texture) {
    gl.ActiveTexture(GL_TEXTURE0 + unit);
    gl.BindTexture(GL_TEXTURE_2D, texture);
    gl.Uniform1i(Loc(program, name), unit);
  }
};

Renderer::Renderer(const RendererOptions& options) : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.options = options;
  if (!(options.tone.exposure > 0) || !(options.tone.white > 0)) {
    throw RenderError("tone mapping: exposure and white must be > 0");
  }
  const int w = std::max(1, options.width), h = std::max(1, options.height);
  m.context = options.backend == Backend::kWindow
                  ? internal::CreateGlfwContext(w, h, options.title, options.window_visible)
                  : internal::CreateOsMesaContext(w, h);
#define PROBELESS_GL_LOAD(type, name)                                 \
  m.gl.name = reinterpret_cast<type>(m.context->GetProc("gl" #name)); \
  if (m.gl.name == nullptr) throw RenderError("OpenGL function gl" #name " missing");
  PROBELESS_GL_FUNCTIONS(PROBELESS_GL_LOAD)
#undef PROBELESS_GL_LOAD
  auto text = [&](GLenum what) {
    const GLubyte* s = m.gl.GetString(what);
    return s != nullptr ? std::string(reinterpret_cast<const char*>(s)) : std::string();
  };
  m.version = text(GL_VERSION);
  m.renderer_name = text(GL_RENDERER);
  m.object_program = m.Program(internal::kObjectVs, internal::kObjectFs, "object");
  m.receiver_program = m.Program(internal::kReceiverVs, internal::kReceiverFs, "receiver");
  m.depth_program = m.Program(internal::kFullscreenVs, internal::kDepthFs, "depth");
  m.blit_program = m.Program(internal::kFullscreenVs, internal::kBlitFs, "blit");
  m.gl.GenVertexArrays(1, &m.empty_vao);
  m.gl.PixelStorei(GL_UNPACK_ALIGNMENT, 1);
  m.gl.PixelStorei(GL_PACK_ALIGNMENT, 1);
  m.EnsureSize(w, h);
}

Renderer::~Renderer() {
  Impl& m = *impl_;
  for (auto& o : m.objects) {
    const GLuint buffers[] = {o.vbo_position, o.vbo_color, o.vbo_uv, o.vbo_transfer, o.ebo};
    m.gl.DeleteBuffers(5, buffers);
    m.gl.DeleteVertexArrays(1, &o.vao);
    if (o.texture) m.gl.DeleteTextures(1, &o.texture);
  }
  for (auto& r : m.receivers) {
    const GLuint buffers[] = {r.vbo_position, r.vbo_real, r.vbo_with, r.ebo};
    m.gl.DeleteBuffers(4, buffers);
    m.gl.DeleteVertexArrays(1, &r.vao);
  }
  m.ReleaseTargets();
  if (!m.panel_textures.empty()) {
    m.gl.DeleteTextures(static_cast<GLsizei>(m.panel_textures.size()), m.panel_textures.data());
  }
  for (GLuint p : {m.object_program, m.receiver_program, m.depth_program, m.blit_program}) {
    m.gl.DeleteProgram(p);
  }
  for (GLuint p : m.composite_programs) {
    if (p) m.gl.DeleteProgram(p);
  }
  m.gl.DeleteVertexArrays(1, &m.empty_vao);
}

int Renderer::AddObject(const VirtualObject& object) {
  Impl& m = *impl_;
  try {
    object.mesh.Validate("renderer object");
  } catch (const prt::PrtError& e) {
    throw RenderError(e.what());
  }
  if (object.mesh.bands > kMaxRendererBands) {
    throw RenderError("renderer object: " + std::to_string(object.mesh.bands) +
                      " bands, the renderer supports up to 4 (16 coefficients)");
  }
  const raytrace::Mesh& mesh = object.mesh.mesh;
  if (object.texture && mesh.uvs.size() != mesh.positions.size()) {
    throw RenderError("renderer object: an albedo texture needs per-vertex uvs");
  }
  const size_t n = mesh.positions.size();
  Impl::GpuObject o;
  o.anchor = object.anchor;
  o.object_to_anchor = object.object_to_anchor;
  o.albedo = object.albedo;
  o.visible = object.visible;
  o.cull = object.cull_back_faces;
  m.gl.GenVertexArrays(1, &o.vao);
  m.gl.BindVertexArray(o.vao);
  o.vbo_position = m.Buffer(GL_ARRAY_BUFFER, mesh.positions.data(), n * sizeof(Vec3));
  m.Attrib(0, o.vbo_position, 3, 0, 0);
  std::vector<Vec3> colours =
      mesh.colors.size() == n ? mesh.colors : std::vector<Vec3>(n, {1, 1, 1});
  o.vbo_color = m.Buffer(GL_ARRAY_BUFFER, colours.data(), n * sizeof(Vec3));
  m.Attrib(1, o.vbo_color, 3, 0, 0);
  std::vector<raytrace::Vec2> uvs =
      mesh.uvs.size() == n ? mesh.uvs : std::vector<raytrace::Vec2>(n);
  o.vbo_uv = m.Buffer(GL_ARRAY_BUFFER, uvs.data(), n * sizeof(raytrace::Vec2));
  m.Attrib(2, o.vbo_uv, 2, 0, 0);
  const std::vector<float> padded =
      PadTransfer(object.mesh.transfer, object.mesh.coefficient_count(), n);
  o.vbo_transfer = m.Buffer(GL_ARRAY_BUFFER, padded.data(), padded.size() * sizeof(float));
  for (int i = 0; i < 4; ++i) m.Attrib(3 + i, o.vbo_transfer, 4, kPadded * sizeof(float), i * 16);
  o.ebo = m.Buffer(GL_ELEMENT_ARRAY_BUFFER, mesh.triangles.data(),
                   mesh.triangles.size() * sizeof(mesh.triangles[0]));
  o.index_count = static_cast<GLsizei>(mesh.triangles.size() * 3);
  m.gl.BindVertexArray(0);
  if (object.texture) {
    const raytrace::Texture& t = *object.texture;
    o.texture = m.MakeTexture(GL_RGB32F, t.width, t.height, GL_RGB, GL_FLOAT, GL_LINEAR);
    m.gl.TexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, t.width, t.height, GL_RGB, GL_FLOAT,
                       t.linear_rgb.data());
    m.gl.TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_REPEAT);
    m.gl.TexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_REPEAT);
  }
  m.objects.push_back(o);
  return static_cast<int>(m.objects.size()) - 1;
}

void Renderer::SetObjectVisible(int index, bool visible) {
  impl_->objects.at(static_cast<size_t>(index)).visible = visible;
}

void Renderer::SetObjectPlacement(int index, const Transform& object_to_anchor) {
  impl_->objects.at(static_cast<size_t>(index)).object_to_anchor = object_to_anchor;
}

int Renderer::object_count() const { return static_cast<int>(impl_->objects.size()); }

int Renderer::AddReceiver(const ShadowReceiver& receiver) {
  Impl& m = *impl_;
  try {
    receiver.mesh.Validate("shadow receiver");
  } catch (const raytrace::RaytraceError& e) {
    throw RenderError(e.what());
  }
  if (receiver.bands < 1 || receiver.bands > kMaxRendererBands) {
    throw RenderError("shadow receiver: bands " + std::to_string(receiver.bands) +
                      " out of range 1..4");
  }
  const size_t n = receiver.mesh.positions.size();
  const size_t count = static_cast<size_t>(receiver.bands * receiver.bands);
  if (receiver.transfer_real.size() != n * count ||
      receiver.transfer_with_virtual.size() != n * count) {
    throw RenderError("shadow receiver: transfer sets need " + std::to_string(n * count) +
                      " values each (vertices x bands^2)");
  }
  Impl::GpuReceiver r;
  r.vertices = n;
  r.count = static_cast<int>(count);
  r.anchor = receiver.anchor;
  r.visible = receiver.visible;
  r.cull = receiver.cull_back_faces;
  m.gl.GenVertexArrays(1, &r.vao);
  m.gl.BindVertexArray(r.vao);
  r.vbo_position = m.Buffer(GL_ARRAY_BUFFER, receiver.mesh.positions.data(), n * sizeof(Vec3));
  m.Attrib(0, r.vbo_position, 3, 0, 0);
  const std::vector<float> real = PadTransfer(receiver.transfer_real, r.count, n);
  const std::vector<float> with = PadTransfer(receiver.transfer_with_virtual, r.count, n);
  r.vbo_real = m.Buffer(GL_ARRAY_BUFFER, real.data(), real.size() * sizeof(float));
  for (int i = 0; i < 4; ++i) m.Attrib(1 + i, r.vbo_real, 4, kPadded * sizeof(float), i * 16);
  r.vbo_with = m.Buffer(GL_ARRAY_BUFFER, with.data(), with.size() * sizeof(float));
  for (int i = 0; i < 4; ++i) m.Attrib(5 + i, r.vbo_with, 4, kPadded * sizeof(float), i * 16);
  r.ebo = m.Buffer(GL_ELEMENT_ARRAY_BUFFER, receiver.mesh.triangles.data(),
                   receiver.mesh.triangles.size() * sizeof(receiver.mesh.triangles[0]));
  r.index_count = static_cast<GLsizei>(receiver.mesh.triangles.size() * 3);
  m.gl.BindVertexArray(0);
  m.receivers.push_back(r);
  return static_cast<int>(m.receivers.size()) - 1;
}

void Renderer::SetReceiverVisible(int index, bool visible) {
  impl_->receivers.at(static_cast<size_t>(index)).visible = visible;
}

void Renderer::SetReceiverTransfer(int index, std::span<const float> real,
                                   std::span<const float> with_virtual) {
  Impl& m = *impl_;
  Impl::GpuReceiver& r = m.receivers.at(static_cast<size_t>(index));
  if (real.size() != r.vertices * r.count || with_virtual.size() != r.vertices * r.count) {
    throw RenderError("shadow receiver: transfer sets need " +
                      std::to_string(r.vertices * r.count) + " values each");
  }
  const std::vector<float> a = PadTransfer(real, r.count, r.vertices);
  const std::vector<float> b = PadTransfer(with_virtual, r.count, r.vertices);
  m.gl.BindBuffer(GL_ARRAY_BUFFER, r.vbo_real);
  m.gl.BufferSubData(GL_ARRAY_BUFFER, 0, static_cast<GLsizeiptr>(a.size() * sizeof(float)),
                     a.data());
  m.gl.BindBuffer(GL_ARRAY_BUFFER, r.vbo_with);
  m.gl.BufferSubData(GL_ARRAY_BUFFER, 0, static_cast<GLsizeiptr>(b.size() * sizeof(float)),
                     b.data());
}

void Renderer::set_tone_mapping(const ToneMapping& tone) {
  if (!(tone.exposure > 0) || !(tone.white > 0)) {
    throw RenderError("tone mapping: exposure and white must be > 0");
  }
  impl_->options.tone = tone;
}
const ToneMapping& Renderer::tone_mapping() const { return impl_->options.tone; }

void Renderer::Render(const FrameInputs& in, Composite& out) {
  Impl& m = *impl_;
  Gl& gl = m.gl;
  in.camera.Validate();
  const int w = in.camera.width, h = in.camera.height;
  const size_t pixels = static_cast<size_t>(w) * h;
  auto check = [&](size_t got, size_t want, const char* what) {
    if (got != 0 && got != want) {
      throw RenderError(std::string("frame: ") + what + " has " + std::to_string(got) +
                        " values, expected " + std::to_string(want) + " for " + std::to_string(w) +
                        "x" + std::to_string(h));
    }
  };
  check(in.camera_rgb.size(), pixels * 3, "camera image");
  check(in.real_depth.size(), pixels, "real depth");
  check(in.indirect_rgb.size(), pixels * 3, "indirect buffer");
  const bool pixel_transfer = !in.transfer_real.empty() || !in.transfer_with_virtual.empty();
  if (pixel_transfer) {
    if (in.transfer_count < 1 || in.transfer_count > 25) {
      throw RenderError("frame: transfer_count must be 1..25");
    }
    if (in.transfer_real.size() != pixels * in.transfer_count ||
        in.transfer_with_virtual.size() != pixels * in.transfer_count) {
      throw RenderError("frame: transfer buffers need " +
                        std::to_string(pixels * in.transfer_count) + " values each");
    }
  }
  if (in.light.bands < 1 || in.light.bands > 5) {
    throw RenderError("frame: light bands " + std::to_string(in.light.bands) +
                      " out of range 1..5");
  }
  const auto& vr = in.virtual_rect;
  const bool virtual_shading = !in.virtual_modulation.empty();
  if (virtual_shading) {
    const size_t rect =
        static_cast<size_t>(std::max(0, vr[2] - vr[0])) * std::max(0, vr[3] - vr[1]);
    if (vr[0] < 0 || vr[1] < 0 || vr[2] > w || vr[3] > h || rect == 0 ||
        in.virtual_modulation.size() != 3 * rect || in.virtual_indirect.size() != 3 * rect) {
      throw RenderError(
          "frame: virtual shading needs a rect inside the image and 3 values per "
          "rect pixel in both buffers");
    }
  }
  m.EnsureSize(w, h);

  // Anchor frames: lights rotated into them, and their camera placements.
  const Transform world_to_camera = in.camera_to_world.Inverse();
  ShLightRgb light_face, light_world;
  bool have_face = false, have_world = false;
  auto anchor_light = [&](Anchor a) -> const ShLightRgb& {
    if (a == Anchor::kFace) {
      if (!have_face)
        light_face = RotateLight(in.light, in.face_to_camera.rotation), have_face = true;
      return light_face;
    }
    if (!have_world)
      light_world = RotateLight(in.light, world_to_camera.rotation), have_world = true;
    return light_world;
  };
  auto anchor_pose = [&](Anchor a) {
    return a == Anchor::kFace ? in.face_to_camera : world_to_camera;
  };
  auto shown = [&](Anchor a, bool visible) {
    return visible && (a == Anchor::kWorld || in.face_valid);
  };

  // PROBELESS_RENDER_PROFILE=1: per-pass times (glFinish after each pass) on stderr.
  static const bool profile = std::getenv("PROBELESS_RENDER_PROFILE") != nullptr;
  auto t_last = std::chrono::steady_clock::now();
  std::string profile_line;
  auto mark = [&](const char* name) {
    if (!profile) return;
    gl.Finish();
    const auto now = std::chrono::steady_clock::now();
    profile_line += std::string(" ") + name + "=" +
                    std::to_string(std::chrono::duration<double, std::milli>(now - t_last).count());
    t_last = now;
  };
  gl.Viewport(0, 0, w, h);
  gl.Disable(GL_CULL_FACE);
  gl.Disable(GL_BLEND);

  // Uploads.
  if (!in.indirect_rgb.empty()) {
    gl.BindTexture(GL_TEXTURE_2D, m.indirect_tex);
    gl.TexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, w, h, GL_RGB, GL_FLOAT, in.indirect_rgb.data());
  }
  bool any_receiver = false;
  for (const auto& r : m.receivers) any_receiver |= shown(r.anchor, r.visible);
  const bool indirect = !in.indirect_rgb.empty();
  const bool full_screen = pixel_transfer || indirect;
  const bool have_camera = !in.camera_rgb.empty();
  if (have_camera && (full_screen || any_receiver)) {
    gl.BindTexture(GL_TEXTURE_2D, m.camera_tex);
    gl.TexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, w, h, GL_RGB, GL_UNSIGNED_BYTE, in.camera_rgb.data());
  }

  // Pass 1: the real image into the output (alpha 1 = no virtual object): the camera bytes as is,
  // or Gruber's eq. 13-15 by a full-screen pass when per-pixel transfer buffers (R_d, R'_d = T . L
  // on the CPU) or an indirect buffer are given.
  gl.BindFramebuffer(GL_FRAMEBUFFER, m.out_fbo);
  gl.ColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
  gl.Disable(GL_DEPTH_TEST);
  m.SetCulling(false);
  if (full_screen) {
    if (pixel_transfer) {
      m.cpu_real.assign(pixels * 4, 0.0f);
      m.cpu_with.assign(pixels * 4, 0.0f);
      const size_t count = static_cast<size_t>(in.transfer_count);
      for (size_t p = 0; p < pixels; ++p) {
        const auto a = ShadeTransfer(in.transfer_real.subspan(p * count, count), in.light);
        const auto b = ShadeTransfer(in.transfer_with_virtual.subspan(p * count, count), in.light);
        for (int c = 0; c < 3; ++c) m.cpu_real[p * 4 + c] = a[c], m.cpu_with[p * 4 + c] = b[c];
      }
      gl.BindTexture(GL_TEXTURE_2D, m.diff_real);
      gl.TexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, w, h, GL_RGBA, GL_FLOAT, m.cpu_real.data());
      gl.BindTexture(GL_TEXTURE_2D, m.diff_with);
      gl.TexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, w, h, GL_RGBA, GL_FLOAT, m.cpu_with.data());
    }
    const GLuint program = m.CompositeProgram(have_camera, pixel_transfer, indirect);
    m.SetCommonUniforms(program, in.camera);
    gl.Uniform1i(m.Loc(program, "u_flip"), 0);
    m.BindTexture(program, "u_camera", 0, m.camera_tex);
    m.BindTexture(program, "u_real", 1, m.diff_real);
    m.BindTexture(program, "u_with", 2, m.diff_with);
    m.BindTexture(program, "u_indirect", 3, m.indirect_tex);
    gl.BindVertexArray(m.empty_vao);
    gl.DrawArrays(GL_TRIANGLES, 0, 3);
  } else if (have_camera) {
    // RGB into the RGBA8 target: alpha becomes 1.
    gl.BindTexture(GL_TEXTURE_2D, m.out_color);
    gl.TexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, w, h, GL_RGB, GL_UNSIGNED_BYTE, in.camera_rgb.data());
  } else {
    gl.ClearColor(0, 0, 0, 1);
    gl.Clear(GL_COLOR_BUFFER_BIT);
  }
  mark("real");

  // Pass 2: shadow receivers: Gruber eq. 13 on their own pixels (R_d, R'_d from their two transfer
  // sets, the camera texel under each fragment); their depth makes them phantom occluders.
  gl.ClearDepth(1.0);
  gl.Clear(GL_DEPTH_BUFFER_BIT);
  gl.Enable(GL_DEPTH_TEST);
  gl.DepthMask(GL_TRUE);
  gl.DepthFunc(GL_LESS);
  if (any_receiver) {
    m.SetCommonUniforms(m.receiver_program, in.camera);
    gl.Uniform1i(m.Loc(m.receiver_program, "u_has_camera"), have_camera ? 1 : 0);
    m.BindTexture(m.receiver_program, "u_camera", 0, m.camera_tex);
    for (const auto& r : m.receivers) {
      if (!shown(r.anchor, r.visible)) continue;
      m.SetLight(m.receiver_program, anchor_light(r.anchor));
      const auto mv = ToGl(anchor_pose(r.anchor));
      gl.UniformMatrix4fv(m.Loc(m.receiver_program, "u_model_view"), 1, GL_FALSE,
                          glm::value_ptr(mv));
      m.SetCulling(r.cull);
      gl.BindVertexArray(r.vao);
      gl.DrawElements(GL_TRIANGLES, r.index_count, GL_UNSIGNED_INT, nullptr);
    }
    m.SetCulling(false);
  }
  mark("receivers");

  // Pass 3: the real depth G_r (kept where nearer than a receiver), then the virtual objects.
  if (!in.real_depth.empty()) {
    gl.ColorMask(GL_FALSE, GL_FALSE, GL_FALSE, GL_FALSE);
    gl.BindTexture(GL_TEXTURE_2D, m.real_depth_tex);
    gl.TexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, w, h, GL_RED, GL_FLOAT, in.real_depth.data());
    m.SetCommonUniforms(m.depth_program, in.camera);
    gl.Uniform1i(m.Loc(m.depth_program, "u_flip"), 0);
    m.BindTexture(m.depth_program, "u_real_depth", 0, m.real_depth_tex);
    gl.BindVertexArray(m.empty_vao);
    gl.DrawArrays(GL_TRIANGLES, 0, 3);
    gl.ColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
  }
  m.SetCommonUniforms(m.object_program, in.camera);
  gl.Uniform1i(m.Loc(m.object_program, "u_has_virtual"), virtual_shading ? 1 : 0);
  if (virtual_shading) {
    const int rw = vr[2] - vr[0], rh = vr[3] - vr[1];
    gl.BindTexture(GL_TEXTURE_2D, m.virtual_mod_tex);
    gl.TexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, rw, rh, GL_RGB, GL_FLOAT,
                     in.virtual_modulation.data());
    gl.BindTexture(GL_TEXTURE_2D, m.virtual_add_tex);
    gl.TexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, rw, rh, GL_RGB, GL_FLOAT, in.virtual_indirect.data());
    gl.Uniform4i(m.Loc(m.object_program, "u_virtual_rect"), vr[0], vr[1], vr[2], vr[3]);
    m.BindTexture(m.object_program, "u_virtual_mod", 1, m.virtual_mod_tex);
    m.BindTexture(m.object_program, "u_virtual_add", 2, m.virtual_add_tex);
  }
  for (const auto& o : m.objects) {
    if (!shown(o.anchor, o.visible)) continue;
    m.SetLight(m.object_program, anchor_light(o.anchor));
    const auto mv = ToGl(anchor_pose(o.anchor) * o.object_to_anchor);
    gl.UniformMatrix4fv(m.Loc(m.object_program, "u_model_view"), 1, GL_FALSE, glm::value_ptr(mv));
    gl.Uniform3f(m.Loc(m.object_program, "u_albedo"), o.albedo.x, o.albedo.y, o.albedo.z);
    gl.Uniform1i(m.Loc(m.object_program, "u_has_texture"), o.texture ? 1 : 0);
    if (o.texture) m.BindTexture(m.object_program, "u_texture", 0, o.texture);
    m.SetCulling(o.cull);
    gl.BindVertexArray(o.vao);
    gl.DrawElements(GL_TRIANGLES, o.index_count, GL_UNSIGNED_INT, nullptr);
  }
  gl.BindVertexArray(0);
  gl.Disable(GL_DEPTH_TEST);
  m.SetCulling(false);
  mark("virtual");
  // Read back (rows are image rows: row 0 = top).
  m.readback.resize(pixels * 4);
  gl.ReadBuffer(GL_COLOR_ATTACHMENT0);
  gl.ReadPixels(0, 0, w, h, GL_RGBA, GL_UNSIGNED_BYTE, m.readback.data());
  out.width = w;
  out.height = h;
  out.rgb.resize(pixels * 3);
  out.coverage.resize(pixels);
  for (size_t p = 0; p < pixels; ++p) {
    out.rgb[p * 3] = m.readback[p * 4];
    out.rgb[p * 3 + 1] = m.readback[p * 4 + 1];
    out.rgb[p * 3 + 2] = m.readback[p * 4 + 2];
    out.coverage[p] = m.readback[p * 4 + 3] < 128 ? 1 : 0;
  }
  gl.BindFramebuffer(GL_FRAMEBUFFER, 0);
  mark("readback");
  if (profile) std::fprintf(stderr, "[render profile ms]%s\n", profile_line.c_str());
  const GLenum error = gl.GetError();
  if (error != GL_NO_ERROR)
    throw RenderError("OpenGL error " + std::to_string(error) + " in Render");
}

std::string Renderer::gl_version() const { return impl_->version; }
std::string Renderer::gl_renderer() const { return impl_->renderer_name; }
Backend Renderer::backend() const { return impl_->options.backend; }

void Renderer::Present(const std::vector<Panel>& panels, Composite* capture) {
  Impl& m = *impl_;
  if (!m.context->is_window()) throw RenderError("Present needs the window back-end");
  Gl& gl = m.gl;
  const auto [ww, wh] = m.context->FramebufferSize();
  gl.BindFramebuffer(GL_FRAMEBUFFER, 0);
  gl.DrawBuffer(GL_BACK);
  gl.Viewport(0, 0, ww, wh);
  gl.ClearColor(0, 0, 0, 1);
  gl.Clear(GL_COLOR_BUFFER_BIT);
  gl.Disable(GL_DEPTH_TEST);
  gl.UseProgram(m.blit_program);
  gl.Uniform1i(m.Loc(m.blit_program, "u_flip"), 1);
  gl.BindVertexArray(m.empty_vao);
  // The composite, letterboxed to keep its aspect ratio (the rect WindowToImagePixel inverts).
  const PixelRect shown = LetterboxRect(m.width, m.height, ww, wh);
  if (shown.w > 0 && shown.h > 0) {
    gl.Viewport(shown.x, wh - shown.y - shown.h, shown.w, shown.h);
    m.BindTexture(m.blit_program, "u_image", 0, m.out_color);
    gl.DrawArrays(GL_TRIANGLES, 0, 3);
  }
  m.presented_width = m.width;
  m.presented_height = m.height;
  m.presented_panels.clear();
  for (const Panel& p : panels) m.presented_panels.push_back({p.x, p.y, p.w, p.h});
  while (m.panel_textures.size() < panels.size()) {
    m.panel_textures.push_back(m.MakeTexture(GL_RGB8, 1, 1, GL_RGB, GL_UNSIGNED_BYTE, GL_LINEAR));
  }
  for (size_t i = 0; i < panels.size(); ++i) {
    const Panel& p = panels[i];
    if (p.width < 1 || p.height < 1 ||
        p.rgb.size() != static_cast<size_t>(p.width) * p.height * 3) {
      throw RenderError("panel " + std::to_string(i) + ": rgb size does not match width x height");
    }
    gl.BindTexture(GL_TEXTURE_2D, m.panel_textures[i]);
    gl.TexImage2D(GL_TEXTURE_2D, 0, GL_RGB8, p.width, p.height, 0, GL_RGB, GL_UNSIGNED_BYTE,
                  p.rgb.data());
    gl.Viewport(p.x, wh - p.y - p.h, p.w, p.h);
    m.BindTexture(m.blit_program, "u_image", 0, m.panel_textures[i]);
    gl.DrawArrays(GL_TRIANGLES, 0, 3);
  }
  gl.BindVertexArray(0);
  if (capture != nullptr) {
    std::vector<uint8_t> rgba(static_cast<size_t>(ww) * wh * 4);
    gl.ReadBuffer(GL_BACK);
    gl.ReadPixels(0, 0, ww, wh, GL_RGBA, GL_UNSIGNED_BYTE, rgba.data());
    capture->width = ww;
    capture->height = wh;
    capture->rgb.resize(static_cast<size_t>(ww) * wh * 3);
    capture->coverage.assign(static_cast<size_t>(ww) * wh, 0);
    for (int y = 0; y < wh; ++y) {
      const uint8_t* src = rgba.data() + static_cast<size_t>(wh - 1 - y) * ww * 4;
      uint8_t* dst = capture->rgb.data() + static_cast<size_t>(y) * ww * 3;
      for (int x = 0; x < ww; ++x) std::memcpy(dst + x * 3, src + x * 4, 3);
    }
  }
  m.context->SwapAndPoll();
  const GLenum error = gl.GetError();
  if (error != GL_NO_ERROR)
    throw RenderError("OpenGL error " + std::to_string(error) + " in Present");
}

std::vector<int> Renderer::TakeKeys() {
  if (!impl_->context->is_window()) throw RenderError("TakeKeys needs the window back-end");
  return impl_->context->TakeKeys();
}

std::vector<ViewerClick> Renderer::TakeClicks() {
  Impl& m = *impl_;
  std::vector<ViewerClick> clicks;
  for (const WindowClick& c : m.context->TakeClicks()) {
    const auto pixel =
        WindowToImagePixel(c, m.presented_width, m.presented_height, m.presented_panels);
    if (pixel) clicks.push_back(*pixel);
  }
  return clicks;
}

bool Renderer::WindowClosed() const { return impl_->context->Closed(); }

bool Renderer::DisplayLost() const { return impl_->context->DisplayLost(); }

std::array<int, 2> Renderer::WindowSize() const { return impl_->context->FramebufferSize(); }

}  // namespace probeless::render
