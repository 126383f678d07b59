// The AR renderer (Knorr & Kurz 2014 §4.3, Gruber et al. 2015 §5.4): virtual objects with baked
// per-vertex transfer (probeless/prt) shaded by an SH light, composited over the camera image with
// differential rendering, on OpenGL 4.5 core (3.3 core fallback) through one of two back-ends: an
// OSMesa offscreen context (headless; tests and benchmarks) or a GLFW window (the live viewer). GL,
// GLFW and OSMesa headers stay in src/ (pimpl). See docs/render.md.
//
// Frames: the camera frame is x right, y down, z forward (msgs convention). A face-anchored object
// lives in the face frame of msgs::FaceObservation (placed by the head pose, face -> camera); a
// world-anchored object in the world frame (placed by the camera pose, camera -> world). Baked
// transfer is expressed in the object's anchor frame, so the renderer rotates the camera-frame SH
// light into that frame every frame (prt::ShRotationMatrix).
//
// Shading (K&K §4.3): radiance of a vertex = albedo * sum_k T_k L_k per colour channel (T from the
// bake, L the light in the anchor frame), interpolated over the triangle, times the optional albedo
// texture, tone-mapped (ToneMapping) and sRGB-encoded like the camera image.
//
// Differential rendering (Gruber eq. 13-15): two shading buffers of the real scene, R_d (real only)
// and R'_d (real with the virtual objects as occluders), from shadow receivers (proxy meshes of the
// real scene with two baked transfer sets, e.g. the proxy head baked with and without a virtual
// object) and/or per-pixel transfer buffers (msgs::TransferBuffer, from the scene-light node), give
//   I_d = I_c (1 + T(R'_d) - T(R_d))      (eq. 13, linear RGB, T the tone mapper)
//   I_final = I_d + I_i                    (eq. 15, I_i the indirect buffer after eq. 14)
// Pixels where R'_d == R_d and I_i == 0 keep the camera image bit-exactly. Virtual objects are then
// drawn over I_final where they are not hidden by the real scene (depth test against the real depth
// G_r and the receivers' depth).
//
// Errors: bad arguments at this boundary throw RenderError with a one-line message.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "probeless/error/error.h"
#include "probeless/prt/prt.h"
#include "probeless/raytrace/geometry.h"
#include "probeless/raytrace/scene.h"
#include "probeless/render/viewer_click.h"

namespace probeless::render {

class RenderError : public InputError {
 public:
  using InputError::InputError;
};

// Which GL context the renderer creates.
enum class Backend {
  kOffscreen,  // OSMesa (llvmpipe), no display needed
  kWindow,     // GLFW window (needs a display, e.g. xvfb-run)
};

// "offscreen" / "window"; BackendFromName throws RenderError for other names.
std::string BackendName(Backend backend);
Backend BackendFromName(const std::string& name);

// Tone mapping of linear radiance x (1 = full scale) before sRGB encoding, shared by the virtual
// objects and the differential buffers. kClamp: min(1, e x). kReinhard (extended Reinhard 2002,
// eq. 4): y = e x (1 + e x / w^2) / (1 + e x), so y(w / e) = 1.
enum class ToneOperator { kClamp, kReinhard };
struct ToneMapping {
  ToneOperator op = ToneOperator::kClamp;
  float exposure = 1;  // e > 0
  float white = 4;     // w > 0 (kReinhard): the radiance (times e) that maps to full scale
  // Applies the operator to one value (the CPU reference of the shaders).
  float Apply(float x) const;
};

// Where a virtual object is attached.
enum class Anchor { kFace, kWorld };

// A pinhole camera (msgs::CameraInfo without distortion): pixel u = fx X / Z + cx, v = fy Y / Z +
// cy, (0, 0) the centre of the top-left pixel.
struct Intrinsics {
  int width = 640;
  int height = 480;
  double fx = 525, fy = 525, cx = 319.5, cy = 239.5;
  double near_m = 0.01, far_m = 50;  // depth range of the rasteriser
  // Throws RenderError unless width, height in 1..8192, fx, fy > 0, 0 < near < far.
  void Validate() const;
};

// A virtual object: a baked mesh (transfer in the anchor frame, bands 1..4) and its material.
struct VirtualObject {
  prt::TransferMesh mesh;
  Anchor anchor = Anchor::kFace;
  raytrace::Transform object_to_anchor;  // placement of the baked mesh in its anchor frame
  raytrace::Vec3 albedo{1, 1, 1};        // times the vertex colours (if any) and the texture
  std::shared_ptr<const raytrace::Texture> texture;  // optional, needs mesh.mesh.uvs
  bool visible = true;
  // Skip triangles facing away from the camera (closed meshes wound counter-clockwise seen from
  // outside, the raytrace convention); false for open or inconsistently wound meshes.
  bool cull_back_faces = true;
};

// A proxy of the real scene for differential rendering: its pixels get R_d from transfer_real and
// R'_d from transfer_with_virtual (both per vertex, bands^2 each, in the anchor frame). It also
// hides virtual objects behind it (a phantom occluder) but is never drawn itself.
struct ShadowReceiver {
  raytrace::Mesh mesh;  // anchor frame
  int bands = 3;
  std::vector<float> transfer_real;
  std::vector<float> transfer_with_virtual;
  Anchor anchor = Anchor::kFace;
  bool visible = true;
  bool cull_back_faces = true;  // as VirtualObject::cull_back_faces
};

// An RGB SH light (msgs::ShLight layout): coefficients[k][c], bands 1..5 (bands 5 is truncated to
// 4 by the renderer), in the camera frame.
struct ShLightRgb {
  int bands = 3;
  std::array<std::array<float, 3>, 25> coefficients{};
};

// One frame's inputs. Empty spans = absent.
struct FrameInputs {
  Intrinsics camera;
  // The camera image I_c: width * height * 3 sRGB bytes, row-major, top row first; empty = black.
  std::span<const uint8_t> camera_rgb;
  ShLightRgb light;                     // camera frame
  raytrace::Transform face_to_camera;   // head pose (msgs::FaceObservation::head_pose)
  bool face_valid = false;              // false: face-anchored content is hidden
  raytrace::Transform camera_to_world;  // camera pose (scene mode)
  // Real depth G_r (metres along z, 0 = none), width * height floats: hides virtual fragments
  // behind the real scene.
  std::span<const float> real_depth;
  // Per-pixel transfer of the real scene (msgs::TransferBuffer interleaved layout, camera frame,
  // transfer_count = bands^2 per pixel): real only and real + virtual occluders (Gruber's R_d, R'_d
  // before the light). Both or neither.
  std::span<const float> transfer_real;
  std::span<const float> transfer_with_virtual;
  int transfer_count = 0;
  // Indirect buffer I_i (linear RGB, width * height * 3, already selected by eq. 14).
  std::span<const float> indirect_rgb;
  // Shading of the virtual pixels from G_r' (render/differential.h) on the pixel rect [x0, x1) x
  // [y0, y1): a virtual fragment's radiance becomes radiance * modulation + albedo * indirect (3
  // floats per rect pixel each, row-major in the rect): the real scene's shadow on the objects and
  // its bounce light onto them. Empty = unchanged.
  std::array<int, 4> virtual_rect{0, 0, 0, 0};
  std::span<const float> virtual_modulation;
  std::span<const float> virtual_indirect;
};

// The composite: width * height * 3 sRGB bytes, top row first; coverage = 1 where a virtual object
// is visible (width * height bytes).
struct Composite {
  int width = 0;
  int height = 0;
  std::vector<uint8_t> rgb;
  std::vector<uint8_t> coverage;
};

struct RendererOptions {
  Backend backend = Backend::kOffscreen;
  int width = 640;  // initial framebuffer size (grows with the frames)
  int height = 480;
  std::string title = "probeless renderer";  // window title
  bool window_visible = true;
  ToneMapping tone;
};

// One inset image of the live viewer (sRGB rgb8), drawn at pixel rect (x, y, w, h) of the window
// (top-left origin) over the composite.
struct Panel {
  int width = 0;
  int height = 0;
  std::vector<uint8_t> rgb;
  int x = 0, y = 0, w = 0, h = 0;
};

class Renderer {
 public:
  // Creates the GL context (4.5 core, else 3.3 core), shaders and buffers. Throws RenderError if
  // no context can be created (e.g. no display for kWindow) or a shader fails to compile.
  explicit Renderer(const RendererOptions& options);
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  // Uploads an object; returns its index. Throws RenderError for an invalid mesh, bands > 4, or a
  // texture without uvs.
  int AddObject(const VirtualObject& object);
  // Shows or hides object `index` (throws std::out_of_range for a bad index).
  void SetObjectVisible(int index, bool visible);
  // Moves object `index` within its anchor frame (throws std::out_of_range for a bad index).
  void SetObjectPlacement(int index, const raytrace::Transform& object_to_anchor);
  // Objects added so far.
  int object_count() const;
  // Uploads a shadow receiver; returns its index. Throws RenderError for size mismatches.
  int AddReceiver(const ShadowReceiver& receiver);
  // Shows or hides receiver `index` (throws std::out_of_range for a bad index).
  void SetReceiverVisible(int index, bool visible);
  // Replaces receiver `index`'s transfer sets (same sizes). Throws RenderError otherwise.
  void SetReceiverTransfer(int index, std::span<const float> real,
                           std::span<const float> with_virtual);

  // The tone mapping of the next frames. Throws RenderError unless exposure and white are > 0.
  void set_tone_mapping(const ToneMapping& tone);
  const ToneMapping& tone_mapping() const;

  // Renders one frame into `out` (resized). Throws RenderError for inconsistent input sizes.
  void Render(const FrameInputs& inputs, Composite& out);

  // GL_VERSION, e.g. "4.5 (Core Profile) Mesa 22.3.6", and GL_RENDERER (e.g. "llvmpipe ...").
  std::string gl_version() const;
  std::string gl_renderer() const;
  // The back-end the context was created with.
  Backend backend() const;

  // --- Window back-end only (throw RenderError for kOffscreen) ---
  // Shows the last composite scaled to the window plus `panels`, swaps buffers and polls events.
  // With `capture`, the window's back buffer (rgb8, top row first) is read into it before the swap.
  void Present(const std::vector<Panel>& panels, Composite* capture = nullptr);
  // Keys pressed since the last call (GLFW key codes; letters are 'A'..'Z', Escape 256).
  std::vector<int> TakeKeys();
  // Left-button clicks on the shown composite since the last call, oldest first, in pixels of the
  // frame the last Present showed (WindowToImagePixel: letterboxing and a resized or scaled window
  // accounted for; clicks on the black bars or on a panel are not reported; at most
  // ClickQueue::kCapacity, the newest). Polls the window's events. Empty before the first Present
  // and for the offscreen back-end (no window, no clicks; it does not throw, so a caller need not
  // know the back-end).
  std::vector<ViewerClick> TakeClicks();
  // True once the user closed the window (or pressed Escape).
  bool WindowClosed() const;
  // Window back-end: the X display has gone (server died or closed the connection); false for
  // offscreen. Thread-safe: a watcher thread may poll it while the renderer idles. Drawing on a
  // lost display ends the process with exit code 1 and one line on stderr instead of hanging.
  bool DisplayLost() const;
  // Window framebuffer size in pixels.
  std::array<int, 2> WindowSize() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// CPU reference of the shading (tests, and the differential buffers of per-pixel transfer):
// sum_k transfer[k] * light[k][c] for c = 0..2, count = min(transfer.size(), light bands^2).
std::array<float, 3> ShadeTransfer(std::span<const float> transfer, const ShLightRgb& light);

// The light rotated from the camera frame into an anchor frame: `anchor_to_camera` rotates anchor
// directions into the camera frame.
ShLightRgb RotateLight(const ShLightRgb& light, const raytrace::Mat3& anchor_to_camera);

}  // namespace probeless::render
