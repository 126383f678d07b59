// Differential rendering from the reconstruction (Gruber et al. 2015 §5.4, eq. 13-15): the virtual
// objects rasterised into the real geometry buffer G_r (-> G_r'), the per-pixel radiance transfer
// of both buffers by the scene light's SSDO (probeless_light's TransferComputer, §5.1 eq. 6-9, and
// its one-bounce term, §5.3 eq. 10-12), and the change they make to the camera image:
//   I_d = I_c (1 + T(R'_d) - T(R_d))      (eq. 13, linear RGB, T a tone mapper)
//   I_final = I_d + I_i                    (eq. 15, I_i from R'_i and R_i, eq. 14)
// on the real pixels. R'_d differs from R_d only where an SSDO sample of a pixel can land on a
// virtual pixel: within the objects' screen footprint dilated by the SSDO radius, so both are
// computed only in that window (TransferComputer::ComputeRegion) and every other pixel keeps the
// camera byte. The virtual pixels themselves are left to the GL renderer (Renderer::Render draws
// the baked objects over the result, hidden behind G_r).
//
// Frames: the camera optical frame (x right, y down, z forward), pixel (0, 0) the centre of the
// top-left pixel (light::Intrinsics). Light: msgs::ShLight's RGB coefficients in the camera frame.
// See docs/render.md ("Differential rendering from G_r").
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "probeless/light/transfer.h"
#include "probeless/raytrace/geometry.h"
#include "probeless/raytrace/mesh.h"
#include "probeless/render/renderer.h"

namespace probeless::render {

// One virtual object to rasterise into G_r: its mesh (positions and unit normals in the object
// frame, counter-clockwise seen from outside, optional linear vertex colours) placed in the
// camera frame.
struct RasterObject {
  const raytrace::Mesh* mesh = nullptr;
  raytrace::Transform object_to_camera;
  raytrace::Vec3 albedo{1, 1, 1};  // linear, times the vertex colours
  bool cull_back_faces = true;     // as VirtualObject::cull_back_faces
};

// G_r' = G_r with the virtual objects: the planes of light::GeometryView (depth in metres along z,
// 0 = none; unit camera-frame normals facing the camera; sRGB colour bytes = the albedo of the
// indirect term, 255 where G_r has no colour) plus which object each pixel shows.
struct VirtualGeometry {
  int width = 0;
  int height = 0;
  std::vector<float> depth;
  std::vector<float> normals;
  std::vector<uint8_t> colour;
  // 0 = real (G_r), i + 1 = objects[i] of RasteriseObjects.
  std::vector<uint16_t> object_id;
  // The bounding box of the pixels with object_id != 0 (empty when no object is visible) and the
  // nearest virtual depth there (metres; 0 when empty).
  light::PixelRect footprint;
  float min_virtual_depth = 0;
  // The view of G_r' (borrowing the vectors above) with `intrinsics`.
  light::GeometryView View(const light::Intrinsics& intrinsics) const {
    return {width, height, intrinsics, depth, normals, colour};
  }
};

// Rasterises `objects` (CPU, a z-buffer against G_r's depth: a virtual fragment replaces the real
// pixel where it is nearer or G_r has no depth; pixel centres sampled, perspective-correct normals
// and colours, triangles with a vertex closer than 1 cm to the camera plane skipped) into a copy
// of `real` -> `out`. Throws RenderError for a null mesh, a mesh without normals or with
// out-of-range indices, and LightError (light::ValidateGeometryView) for an invalid `real`.
void RasteriseObjects(const light::GeometryView& real, std::span<const RasterObject> objects,
                      VirtualGeometry* out);

// G_r of a face for face-mode differential rendering (no reconstruction there): `head` (the face
// frame of msgs::FaceObservation, e.g. prt::ProxyHead; unit normals) placed by `face_to_camera`
// and rasterised (no back-face culling) into an empty width x height buffer, with the camera
// image's sRGB colour at its pixels (the observed colour, as fusion's G_r has; 255 where
// `camera_rgb` is empty). All pixels are real (object_id 0, empty footprint); out->View(k) is the
// `real` of a DifferentialFrame and its depth hides virtual fragments behind the head. Throws
// RenderError for a mesh without normals, a camera image that is not width x height x 3 bytes or
// a size outside 1..8192.
void RasteriseHead(const raytrace::Mesh& head, const raytrace::Transform& face_to_camera,
                   const light::Intrinsics& k, int width, int height,
                   std::span<const uint8_t> camera_rgb, VirtualGeometry* out);

// The tone mapper T of eq. 13.
enum class DifferentialTone {
  // The camera's response as the virtual objects get it (ToneMapping: exposure e, clamp or
  // extended Reinhard), the same T for both buffers.
  kFixed,
  // Gruber §5.4 after Reinhard et al. 2002 eq. 1-3: per buffer, R scaled by key / (the log-average
  // luminance of that buffer over its surface pixels), then x / (1 + x).
  kAverageKey,
  // T(R'_d) - T(R_d) = (R'_d - R_d) / R_d per pixel, i.e. I_d = I_c R'_d / R_d: Debevec's
  // differential rendering with the real pixel's albedo taken as I_c / R_d. Equals kFixed with a
  // linear T where e R_d = 1 (the camera maps the estimated shading to full scale), and stays
  // right when the estimated light is dimmer or brighter than the image (factor clamped to
  // [0, 2]).
  kRatio,
};

struct DifferentialOptions {
  // The SSDO of both buffers: the scene light's (scene_light's params bands, directions, radius,
  // seed; max_occluder_distance_m = 2 radius_m there). subsample is ignored (the window is
  // computed at every `step`-th pixel).
  light::TransferOptions transfer;
  // Every step-th pixel of the window (and of the virtual footprint) in x and y, the rest filled
  // bilinearly (virtual pixels: the nearest sample of the same object); 1 = every pixel, 2 =
  // OursFast-style, about 3x faster (render_bench).
  int step = 1;
  // Edge-aware separable box of this radius (samples) over the per-sample factors and I_i (real
  // pixels with depth within 3 % only): SSDO's 32 jittered directions leave a per-pixel dither
  // that a composite shows; 0 = none.
  int smooth_radius = 2;
  DifferentialTone tone = DifferentialTone::kFixed;
  float key = 0.18f;     // kAverageKey: Reinhard's middle grey a
  int average_step = 8;  // kAverageKey: the log-averages over every 8th pixel in x and y
  bool indirect = true;  // eq. 14-15 when a dominant light is given
  // The virtual pixels too, for Renderer::Render's FrameInputs::virtual_*: the real scene's
  // occlusion of them (R'_d of G_r' over R_v of the objects alone; off when their bake already
  // had the real scene as occluder) and its bounce light onto them (R'_i - R_v,i).
  bool virtual_occlusion = true;
  bool virtual_bounce = true;
  // The crisp cast shadow of the light's directional part (needs tone kRatio and
  // DifferentialFrame::objects): a sun or a spot lamp is a delta in direction, which an SH light
  // of 3-4 bands and SSDO's radius turn into a soft contact shadow. The light is split into
  // L_sun = a Y(d) (d the frame's dominant direction; a per channel the amplitude of the
  // delta pattern Y(d) in bands 2 and up and in band 1, the smaller of the two: a smooth sky
  // gradient has band 1 but no higher bands, so it gets no crisp shadow) and the rest. The rest
  // keeps the SSDO of eq. 13; the sun's part is seen through the objects' visibility V along d
  // (an orthographic depth map of their triangles along d, 3 x 3 percentage-closer filtered) at
  // every real pixel, not only in the SSDO window:
  //   factor = (T' L - T' L_sun + V T L_sun) / (T L)
  // (in the SSDO window; outside it T' = T, unoccluded analytic transfer).
  bool sun_shadow = false;
  int sun_map_size = 256;     // texels per side of the depth map along d
  float sun_bias_m = 0.004f;  // a receiver is shadowed by a surface more than this nearer the sun
};

// One frame's input. `real` and `with_virtual` must have the same size and intrinsics.
struct DifferentialFrame {
  light::GeometryView real;
  const VirtualGeometry* with_virtual = nullptr;
  ShLightRgb light;  // camera frame
  // The dominant light of eq. 10 (msgs::ShLight dominant_direction, intensity; camera frame);
  // intensity 0 = no indirect term.
  light::DominantLight dominant;
  ToneMapping camera_tone;  // kFixed's T, and the response applied to I_i
  // The camera image I_c (3 sRGB bytes per pixel): the albedo of a real pixel for I_i is
  // I_c / T(R_d) (clamped to [0, 1]); empty = albedo 1.
  std::span<const uint8_t> camera_rgb;
  // The objects of with_virtual (as given to RasteriseObjects): the occluders of
  // DifferentialOptions::sun_shadow (empty: no crisp shadow).
  std::span<const RasterObject> objects;
};

// The result on the window: per pixel of `window` (row-major within it), the factor of eq. 13
// (1 + T(R'_d) - T(R_d), RGB) and the I_i added after it (eq. 15, linear RGB in the camera's
// response). Virtual pixels (drawn by the renderer) and pixels whose samples and their smoothing
// neighbourhood have R'_d == R_d and R'_i == R_i get exactly 1 and 0.
struct DifferentialResult {
  light::PixelRect window;  // empty: nothing changes
  std::vector<float> factor;
  std::vector<float> indirect;
  // The virtual pixels (virtual_occlusion or virtual_bounce; footprint rect, row-major within it, 3
  // floats per pixel): their radiance factor clamp((R'_d . L) / (R_v . L), 0, 1) and the added
  // radiance per unit albedo max(0, R'_i - R_v,i), with R_v the SSDO of the objects alone (G_r'
  // without the real pixels); 1 and 0 elsewhere in the rect. Empty when no object is visible.
  light::PixelRect virtual_rect;
  std::vector<float> virtual_modulation;
  std::vector<float> virtual_indirect;
  double ms_transfer = 0;  // wall time of the SSDO buffers (R_d, R'_d with R_i, R'_i, R_v)
  // sun_shadow: the directional part's amplitude a (RGB; 0 = no crisp shadow this frame) and the
  // real pixels with visibility V < 1.
  std::array<float, 3> sun_amplitude{0, 0, 0};
  int sun_shadow_pixels = 0;
  // Window pixels whose factor is not 1 or whose I_i is not 0, and the smallest factor (red).
  int changed_pixels = 0;
  float min_factor = 1;
  double ms_total = 0;
  // The log-average luminances of kAverageKey (0 for kFixed).
  float average_real = 0;
  float average_with_virtual = 0;
};

// The SSDO reach in pixels around the footprint: a real point x is changed only if one of its
// sample points y = x + omega r' (r' <= radius) projects onto a virtual pixel in front of y; at
// depth z that is at most f radius / sqrt(z^2 - radius^2) pixels away (times 1 + tan^2 of the
// ray's angle towards the image corners), and x lies deeper than the nearest virtual depth minus
// radius. Returns the footprint dilated by that bound (clamped to the image, empty for an empty
// footprint); DifferentialRenderer also skips the window's pixels beyond their own bound.
light::PixelRect DifferentialWindow(const VirtualGeometry& g, const light::Intrinsics& k,
                                    const light::TransferOptions& options);

// Computes R_d, R'_d (and R_i, R'_i) on the window and eq. 13-14. Holds the SSDO computer and
// scratch buffers; not re-entrant.
class DifferentialRenderer {
 public:
  // Throws LightError for invalid transfer options, RenderError for step < 1, key <= 0,
  // average_step < 1 or smooth_radius < 0.
  explicit DifferentialRenderer(const DifferentialOptions& options);
  ~DifferentialRenderer();
  DifferentialRenderer(const DifferentialRenderer&) = delete;
  DifferentialRenderer& operator=(const DifferentialRenderer&) = delete;

  const DifferentialOptions& options() const { return options_; }

  // Throws RenderError for a missing or mismatched with_virtual or camera image, LightError for
  // an invalid real view.
  void Compute(const DifferentialFrame& frame, DifferentialResult* out);

 private:
  DifferentialOptions options_;
  std::unique_ptr<light::TransferComputer> computer_;
  light::TransferResult real_, with_;
  std::vector<uint8_t> real_colour_;
  std::vector<uint8_t> mask_;         // the window's samples within reach of a virtual pixel
  std::vector<float> virtual_depth_;  // G_r' depth with the real pixels removed (R_v)
  std::vector<uint8_t> virtual_mask_;
  light::TransferResult virtual_with_, virtual_only_;
  std::vector<float> sun_map_;         // the objects' largest coordinate along d per texel
  std::vector<float> sun_visibility_;  // V per pixel (1 = lit), sun_shadow
};

// Applies `result` to the camera image in place (width x height x 3 sRGB bytes): c = sRGB(lin(c) *
// factor + indirect) on the window's pixels whose factor is not 1 or indirect not 0; every other
// byte is left as it is. Throws RenderError for a size mismatch.
void ApplyDifferential(const DifferentialResult& result, int width, int height,
                       std::span<uint8_t> camera_rgb);

// The AR hit test (ARKit's raycast): the translation (world frame) that makes `meshes` (anchor =
// world frame, as placed so far), taken as one group, rest on the reconstructed surface seen at
// pixel (u, v) of G_r: the surface point x (the pixel's depth, else the nearest pixel with depth
// within 2 px) and its normal n (the mean of the valid normals within 2 px, facing the camera) in
// the world frame; the group's bounding-box centre c moves to x + n h, h = max over vertices of
// (c - v) . n (so its lowest point along n touches the surface). nullopt when there is no surface
// there. Throws RenderError for a pixel outside the image, no meshes or no vertices, LightError for
// an invalid view.
// The bounding-box centre of `meshes` taken as one group: the point PlaceOnSurface puts x + n h
// (so the group's world position after that move is this centre plus its translation). Throws
// RenderError for no meshes or no vertices.
raytrace::Vec3 GroupCentre(std::span<const raytrace::Mesh* const> meshes);

std::optional<raytrace::Transform> PlaceOnSurface(const light::GeometryView& g, double u, double v,
                                                  const raytrace::Transform& camera_to_world,
                                                  std::span<const raytrace::Mesh* const> meshes);

}  // namespace probeless::render
