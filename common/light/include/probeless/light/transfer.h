// Per-pixel radiance transfer in spherical harmonics by screen-space directional occlusion
// (Gruber, Ventura, Schmalstieg 2015, "Image-space illumination for augmented reality in dynamic
// environments", §5.1 eq. 6-9), the one-bounce indirect term (§5.3 eq. 10-12) and the OursFast
// variant (4x4 image-space subsampling, bicubic upsampling). Frames and SH: see docs/light.md and
// probeless/sh/sh.h (the project's one SH convention).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "probeless/light/directions.h"

namespace probeless::light {

// Pinhole intrinsics of the main view (msgs::CameraInfo): a camera-frame point (X, Y, Z) (metres,
// x right, y down, z forward) projects to u = fx X / Z + cx, v = fy Y / Z + cy (pixels, (0, 0) the
// centre of the top-left pixel).
struct Intrinsics {
  double fx = 0;
  double fy = 0;
  double cx = 0;
  double cy = 0;

  // The camera-frame point (metres; x right, y down, z forward) seen at pixel (u, v) at depth z.
  void BackProject(int u, int v, float z, float out[3]) const {
    out[0] = z * static_cast<float>((u - cx) / fx);
    out[1] = z * static_cast<float>((v - cy) / fy);
    out[2] = z;
  }
};

// The filtered geometry buffer G_r of the current view, in the camera frame (borrowed spans).
struct GeometryView {
  int width = 0;
  int height = 0;
  Intrinsics intrinsics;
  std::span<const float> depth;    // width * height, z along the optical axis in metres; 0 = none
  std::span<const float> normals;  // 3 * width * height, unit normal (camera frame) facing the
                                   // camera; (0, 0, 0) = none
  // Optional 3 * width * height sRGB bytes (albedo or observed colour) used as the reflector's
  // colour A(s_j) of the indirect term; empty = grey 1.
  std::span<const uint8_t> colour;
};

// What an auxiliary buffer shows (documentation and logging only; every view is used the same
// way).
enum class AuxiliaryRole { kLeft, kRight, kTop, kLight, kOther };

// An auxiliary orthographic depth view of the reconstruction (the paper's left / right / top
// buffers and the one from the dominant light direction), so that surfaces hidden in G_r still
// occlude. Contract (for the ray tracer in tests and for recon):
//  - the view frame: x right, y down, z = viewing direction (into the scene), origin on the image
//    plane; pixel (u, v) (u = column) sees the ray through view point
//    ((u - (width - 1) / 2) * pixel_size_m, (v - (height - 1) / 2) * pixel_size_m, 0) along +z;
//  - depth[v * width + u] = z (metres, view frame) of the first surface on that ray, 0 = none;
//  - view_to_camera maps view-frame points to the current main camera frame:
//    p_camera = rotation * p_view + translation, rotation row-major (recon computes it as
//    inverse(camera pose) * view pose, both in its world frame);
//  - normals (optional, 3 per pixel, view frame) are not used yet.
struct OrthographicView {
  AuxiliaryRole role = AuxiliaryRole::kOther;
  int width = 0;
  int height = 0;
  float pixel_size_m = 0;
  std::array<float, 9> rotation{1, 0, 0, 0, 1, 0, 0, 0, 1};
  Vec3f translation{0, 0, 0};
  std::span<const float> depth;
  std::span<const float> normals;
};

// The auxiliary buffers of one frame (any number, typically left, right, top and light).
struct AuxiliaryBuffers {
  std::vector<OrthographicView> views;
};

struct TransferOptions {
  int bands = 4;        // SH bands of T (1..5); 4 = 16 coefficients as in the paper
  int directions = 32;  // N sampling directions over the sphere (8..kMaxDirections)
  uint64_t seed = 1;    // direction jitter and the 2x2 block offsets
  // Sample points y_j = x + omega_j * radius_m * r, r from a fixed table of 4 x N values in
  // [0.1, 1] (one row per pixel of a 2x2 block, §5.1 "random offsets for 2x2 pixels").
  float radius_m = 0.3f;
  // Occluders s_j farther than this from x are ignored (SSDO range check; metres).
  float max_occluder_distance_m = 0.6f;
  // s_j occludes y_j when depth(s_j) < z(y_j) - (depth_bias_m + depth_bias_rel * z(y_j)).
  float depth_bias_m = 0.01f;
  float depth_bias_rel = 0.005f;
  // 1 = every pixel (Ours); 4 = every 4th pixel in x and y, upsampled bicubically (OursFast).
  // The per-2x2-block sample offsets (seed) are keyed by the full-resolution pixel, so a sparse
  // sample's T equals Ours' at that pixel; with an even subsample all samples (pixels s*i + s/2)
  // share one offset set — as do the full variant's fit rows at stride 4 — so the offsets' noise
  // is a common bias rather than interleaved (docs/light.md "OursFast").
  int subsample = 1;
  int threads = 2;  // worker threads (>= 1; the caller's thread is one of them)
  // true: T = (A_l / pi) Y_n(n) - sum_j (1 - K_j) (omega_j . n) W_jn, i.e. the exact projection
  // of the unoccluded clamped cosine (Ramamoorthi & Hanrahan) minus the sampled occlusion (a
  // control variate of eq. 6 with the same limit); false: eq. 6 as printed, sum_j K_j (omega_j .
  // n) W_jn. With N = 32 the printed sum's quadrature error of the clamped cosine alone is up to
  // ~20 % of the shading, depending on the normal and the light direction (docs/light.md).
  bool analytic_unoccluded = true;
};

// The dominant light for the indirect term: unit direction towards the light in the camera frame
// and its irradiance on a surface facing it (msgs::ShLight dominant_direction / intensity).
struct DominantLight {
  Vec3f direction{0, 0, 0};
  float intensity = 0;
};

// Output of TransferComputer::Compute, full resolution (width x height of the input).
struct TransferResult {
  int width = 0;
  int height = 0;
  int coefficient_count = 0;
  // Pixel-major transfer vectors (msgs::TransferBuffer kInterleavedFloat32 layout): radiance
  // towards the camera for albedo 1 = sum_n T[n] l_n, l in the camera frame; 0 where invalid.
  std::vector<float> transfer;
  std::vector<uint8_t> valid;  // width * height, 1 = surface with depth and normal
  // One-bounce indirect radiance (eq. 10-12), linear RGB per pixel, for albedo 1 at the pixel
  // (the renderer multiplies by its albedo); empty unless Compute got a DominantLight.
  std::vector<float> indirect;
  // OursFast (subsample > 1): T as computed on the sparse grid, before the fill and upsampling.
  // Sample (i, j) belongs to full-resolution pixel (min(i * sample_step + sample_step / 2,
  // width - 1), min(j * sample_step + sample_step / 2, height - 1)); same layout as `transfer`.
  // EstimateLight fits to these exact samples instead of interpolated pixels. Empty (and
  // sample_step 1) for the full variant.
  int sample_step = 1;
  int sample_width = 0;
  int sample_height = 0;
  std::vector<float> samples;
  std::vector<uint8_t> sample_valid;
};

// A rectangle of pixels of the main view: columns [x0, x1), rows [y0, y1) (pixel (0, 0) the
// top-left one).
struct PixelRect {
  int x0 = 0;
  int y0 = 0;
  int x1 = 0;
  int y1 = 0;
  int width() const { return x1 - x0; }
  int height() const { return y1 - y0; }
  bool empty() const { return x1 <= x0 || y1 <= y0; }
};

// Computes T (and optionally R_i) per pixel. Holds the direction set, the 2x2 offset table and
// scratch buffers; one instance per thread of use (Compute is not re-entrant).
class TransferComputer {
 public:
  // Throws LightError for invalid options (bands, directions, radius, subsample, threads).
  explicit TransferComputer(const TransferOptions& options);
  ~TransferComputer();
  TransferComputer(const TransferComputer&) = delete;
  TransferComputer& operator=(const TransferComputer&) = delete;

  const TransferOptions& options() const { return options_; }
  const DirectionSet& directions() const { return directions_; }

  // T for every pixel of `g` (every options.subsample-th pixel, upsampled), visibility tested in
  // G_r and in every auxiliary view; R_i too when `light` is given (and its intensity > 0).
  // Throws LightError for an invalid view (sizes, missing normals, non-finite or non-positive
  // intrinsics) or auxiliary view.
  void Compute(const GeometryView& g, const AuxiliaryBuffers& aux, const DominantLight* light,
               TransferResult* out);

  // T (and R_i with `light`) of the pixels of `rect` only, every `step`-th: output sample (i, j)
  // is pixel (min(rect.x0 + i step + step / 2, width - 1), min(rect.y0 + j step + step / 2,
  // height - 1)), `out` sized ceil(rect.width / step) x ceil(rect.height / step) (transfer,
  // valid, indirect; no sparse samples), every value bit-identical to what Compute with subsample
  // 1 gives at that pixel (the 2x2 offsets are keyed by the full-resolution pixel), whatever the
  // options' subsample. The differential renderer's window (Gruber §5.4: R'_d differs from R_d
  // only near the virtual objects) and sparse averages. A non-empty `mask` (one byte per output
  // sample) skips the samples where it is 0: they get valid 0, T and R_i 0. Throws LightError as
  // Compute, and for a rect not inside the view or empty, step < 1 or a mask of another size.
  void ComputeRegion(const GeometryView& g, const AuxiliaryBuffers& aux, const DominantLight* light,
                     const PixelRect& rect, int step, TransferResult* out,
                     std::span<const uint8_t> mask = {});

 private:
  // Output rows [row_begin, row_end) of out_width samples: sample (c, r) is pixel
  // (min(x0 + c step + step / 2, w - 1), min(y0 + r step + step / 2, h - 1)); samples whose
  // `mask` byte is 0 are skipped (mask null: none).
  void ComputeRows(const GeometryView& g, const AuxiliaryBuffers& aux, const DominantLight* light,
                   int step, int x0, int y0, int out_width, int row_begin, int row_end,
                   float* transfer, uint8_t* valid, float* indirect,
                   const uint8_t* mask = nullptr) const;
  // out[k] += (A_l / pi) Y_k(n) for unit n (the unoccluded transfer; analytic_unoccluded).
  void AddClampedCosine(float x, float y, float z, float* out) const;
  TransferOptions options_;
  DirectionSet directions_;
  int n_padded_ = 0;                   // N rounded up to a multiple of 8 (the SIMD kernel's width)
  std::vector<float> offsets_;         // 4 rows of n_padded_: N values in [0.1, 1], then zeros
  std::vector<float> directions_soa_;  // x, y, z rows of n_padded_ (zero-padded)
  // (A_l / pi) x the normalisation of Y_lm at index l (l + 1) + m, m >= 0 (analytic_unoccluded).
  std::array<float, 25> clamped_{};
  std::vector<float> low_indirect_;
  std::vector<float> low_merged_;  // OursFast: low-resolution transfer (+ indirect), holes filled
};

// Throws LightError("light::<where>: ...") unless `g` is usable: width, height >= 1, depth size
// w*h, normals size 3*w*h ("missing normals" when empty), colour empty or 3*w*h, intrinsics finite
// with fx, fy > 0.
void ValidateGeometryView(const GeometryView& g, const char* where);

// Camera-frame unit normals (facing the camera) from a depth image (metres, 0 = none) by central
// differences of the back-projected points `step` pixels apart (one-sided at holes); (0, 0, 0)
// where a pixel or both neighbours on an axis are missing or the depth jumps by more than
// max_jump_rel * step * z. Raw Kinect-like depth (quantised to ~q z^2) needs step ~4 for usable
// normals. `normals` gets 3 * width * height values. Throws LightError for size mismatches, bad
// intrinsics or step < 1.
void NormalsFromDepth(std::span<const float> depth, int width, int height,
                      const Intrinsics& intrinsics, std::vector<float>* normals,
                      float max_jump_rel = 0.05f, int step = 1);

// Which pixels' normals FilterNormals keeps: the light fit trusts every normal it gets, and the
// orientation balancing of the estimator (EstimateOptions::balance_normals) gives the few pixels
// of a rare orientation the most weight — exactly where the bad normals of sensor depth are
// (depth edges, creases, grazing surfaces). Measured on courtyard_sun with sensor effects:
// clean normals with the sensor's depth 3.9 degrees, the sensor's normals with clean depth 33
// degrees (docs/light.md, "Sensor input").
struct NormalFilterOptions {
  // Neighbours `radius` pixels away on both axes (4 of them) must lie within
  // max_plane_distance_rel * z of the pixel's tangent plane and have a normal within
  // max_neighbour_angle_deg of it; one that fails (or is a hole or off the image) drops the
  // pixel. radius 0 = no such test.
  int radius = 4;
  float max_plane_distance_rel = 0.02f;
  float max_neighbour_angle_deg = 20.0f;
  // Drops surfaces seen at more than this angle between the normal and the ray to the camera
  // (degrees; >= 90 = no test): quantisation and noise tilt grazing normals most.
  float max_view_angle_deg = 75.0f;
};

// Sets the normals of unreliable pixels (NormalFilterOptions) to (0, 0, 0) in place; the depth
// stays (the pixel still occludes, it only stops being a receiver / a row of the fit).
// Throws LightError for size mismatches or bad intrinsics.
void FilterNormals(std::span<const float> depth, int width, int height,
                   const Intrinsics& intrinsics, const NormalFilterOptions& options,
                   std::span<float> normals);

// Edge-aware separable box filter of a depth image (metres, 0 = none) in place: each pixel becomes
// the mean of the valid pixels within `radius` along x, then along y, whose depth is within
// max_rel * z of its own. Holes stay holes. Quantised sensor depth (Kinect: steps ~0.0029 z^2)
// needs it before NormalsFromDepth; the reconstruction's G_r does not. Throws LightError for a
// size mismatch or radius < 0.
void SmoothDepth(std::span<float> depth, int width, int height, int radius, float max_rel = 0.03f);

// Linear grey intensity (mean of the linear R, G, B) of sRGB bytes: out[i] in [0, 1].
void SrgbToLinearGrey(std::span<const uint8_t> rgb, std::vector<float>* out);
// Linear value of one sRGB byte.
float SrgbToLinear(uint8_t v);

}  // namespace probeless::light
