// Per-pixel reliability of normals computed from a depth image (beyond Gruber et al. 2015: the
// light fit of §5.2 trusts every normal, and the orientation balancing of EstimateLight gives the
// rare orientations the most weight — exactly those of the few pixels whose normal stencil
// straddles a depth edge or a crease), edge-aware normals from depth, the depth image's measured
// noise and the depth mode's choice of normals. The reliability is EstimateLight's optional
// `reliability`; docs/light.md, "Normals from depth".
#pragma once

#include <span>
#include <vector>

#include "probeless/light/transfer.h"

namespace probeless::light {

struct NormalReliabilityOptions {
  // Expected standard deviation of the depth the test runs on (metres) at depth z:
  // noise_m + noise_quadratic * z^2. Defaults: millimetre depth16 (quantisation 1 mm / sqrt(12)).
  // Raw Kinect-like depth measures k ~ 0.0012-0.0014 (DepthNoiseQuadratic: the simulated sensor
  // and 7-Scenes); smoothed or fused depth (G_r) is used with 0.001 (scene_light_eval, the node).
  float noise_m = 0.0003f;
  float noise_quadratic = 0.0f;
  // Second differences are taken `spacing` pixels apart (>= 1): a pixel q is a discontinuity if,
  // along x, y or a diagonal, its depth departs from the plane through its two neighbours
  // (harmonic mean of their depths: exact for any plane under perspective) by more than
  // threshold_sigma * sqrt(1.5) * sigma(z) + L^2 / (2 * min_radius_m), L the neighbours' lateral
  // distance (a sphere of radius min_radius_m passes).
  int spacing = 1;
  float threshold_sigma = 3.0f;
  float min_radius_m = 0.02f;
  // A pixel's reliability falls with the largest such ratio r within `window` pixels (the
  // normal's support: NormalsFromDepth step + SmoothDepth radius): 1 / (1 + r^4) (1 on smooth
  // surfaces, 0.5 at the threshold, 0.06 at twice it).
  int window = 1;
  // Normals seen at more than this angle from the ray to the camera get reliability 0 (degrees;
  // >= 90 = no test).
  float max_view_angle_deg = 85.0f;
};

// Reliability in [0, 1] of every pixel's normal (0 where there is no depth or no normal), from
// the depth image the normals were computed from (metres, 0 = none; raw or smoothed, with the
// matching noise model). `out` gets width * height values. Throws LightError for size
// mismatches, bad intrinsics or spacing / window < 1 / < 0.
void NormalReliability(std::span<const float> depth, int width, int height,
                       const Intrinsics& intrinsics, std::span<const float> normals,
                       const NormalReliabilityOptions& options, std::vector<float>* out);

// Edge-aware normals from a depth image with their reliability (the depth mode's alternative to
// NormalsFromDepth; docs/light.md, "Normals from depth"). Per pixel and image axis the tangent is
// the central difference of the back-projected points `step` pixels away when the three points
// lie on a plane up to noise and curvature (second difference of 1/z, which is affine in (u, v)
// on any plane under perspective, below threshold_sigma * sqrt(6) * sigma(z) + L^2 / min_radius_m,
// L = step * z / f); otherwise the one-sided difference whose side continues the pixel's surface
// (the smaller second difference over the pixel and the next two samples on that side) — so
// normals next to a depth edge or a crease come from the pixel's own surface. The reliability is
// 1 / (1 + r^4), r the largest ratio of the chosen difference's second difference to that
// allowance over the two axes (1 on planes and spheres larger than min_radius_m, 0.5 at the
// threshold; a one-sided difference whose third sample is missing — a hole or the border — counts
// as at the threshold), 0 beyond max_view_angle_deg or without a normal.
struct DepthNormalOptions {
  int step = 1;  // pixels between the samples (>= 1)
  // sigma(z) = noise_m + noise_quadratic * z^2, the depth's noise (metres); the default: mm depth16
  float noise_m = 0.0003f;
  float noise_quadratic = 0.0f;
  float threshold_sigma = 3.0f;
  float min_radius_m = 0.02f;
  float max_view_angle_deg = 85.0f;
};

// `normals` gets 3 * width * height values (camera frame, facing the camera; (0, 0, 0) where a
// pixel has no depth or no neighbour on an axis), `reliability` width * height values in [0, 1].
// Throws LightError for size mismatches, bad intrinsics or bad options.
void NormalsWithReliability(std::span<const float> depth, int width, int height,
                            const Intrinsics& intrinsics, const DepthNormalOptions& options,
                            std::vector<float>* normals, std::vector<float>* reliability);

// The depth image's noise as sigma(z) ~ k z^2 (quantised disparity: Kinect-like sensors ~0.001;
// millimetre depth16 of a noise-free render ~0.0001): k = RMS(e / z^2) / sqrt(6) over pixels
// beyond 1.5 m (where mm rounding is < 0.0002 z^2) with both horizontal neighbours, e the
// departure of the pixel's depth from the plane through its neighbours (second difference of
// 1/z, times z^2), 1e-5 z < |e| < 0.02 z (depth edges left out, and the zeros of quantisation
// plateaus and planes: quantisation counts with its step however rarely a step occurs); every
// 2nd row. NaN (not measured) when fewer than 1000 pixels beyond 1.5 m qualify (edges aside), 0
// when fewer than 1000 of them depart from their neighbours' plane (plateaus and planes: a clean
// image). Throws LightError for a size mismatch.
float DepthNoiseQuadratic(std::span<const float> depth, int width, int height);

// Which normals the depth mode computes (DepthGeometry).
enum class DepthNormals {
  // By the measured noise (DepthNoiseQuadratic): a clean depth image (below
  // fine_noise_quadratic) gets kEdge's normals, a noisy one kCentral's. Measured
  // (docs/benchmarks/scene_light.md): on noise-free depth edge-aware normals are what makes the
  // estimate work (courtyard_sun 60 -> 5 degrees); on Kinect-like depth they help two scenes and
  // not room_daylight, so noisy depth keeps round 2's normals.
  kAuto,
  kEdge,     // NormalsWithReliability (edge-aware) at the scale of the measured noise
  kCentral,  // SmoothDepth + NormalsFromDepth (central differences; round 2's depth mode)
};

// How the depth mode turns a raw depth image into the G-buffer (DepthGeometry).
struct DepthGeometryOptions {
  DepthNormals normals_from = DepthNormals::kAuto;
  // -1 = by the scale: kEdge on a clean image (measured noise below fine_noise_quadratic) no
  // smoothing and step max(1, width / 320) (2 at 640 x 480), on a noisy one SmoothDepth radius
  // max(1, width / 160) and step max(2, width / 160) (4 and 4); kCentral radius width / 80, step
  // max(2, width / 160) (8 and 4).
  int smooth_radius = -1;
  int step = -1;
  float fine_noise_quadratic = 0.0004f;
  // The noise model of the edge test (DepthNormalOptions::noise_*): noise_quadratic -1 = the
  // measured k for a clean image, smoothed_noise_quadratic for a smoothed one.
  float smoothed_noise_quadratic = 0.001f;
  DepthNormalOptions normals{.noise_quadratic = -1.0f};  // step (and noise) set as above
};

// The depth mode's G-buffer from raw depth (metres, 0 = none): smooths `depth` in place
// (SmoothDepth, when the scale calls for it), fills `normals` (3 per pixel) and, if not null,
// `reliability` (NormalsWithReliability's; with central differences all 1 where there is a
// normal). Returns the measured noise k (DepthNoiseQuadratic; NaN if not measured — then the image
// counts as noisy, and kEdge uses smoothed_noise_quadratic). Throws LightError for a null
// `normals`, smooth_radius < -1, step 0 or < -1, bad noise thresholds, and as
// NormalsWithReliability / NormalsFromDepth.
float DepthGeometry(std::span<float> depth, int width, int height, const Intrinsics& intrinsics,
                    const DepthGeometryOptions& options, std::vector<float>* normals,
                    std::vector<float>* reliability = nullptr);

}  // namespace probeless::light
