// The distant light's direction from cast shadows (beyond Gruber et al. 2015; docs/light.md,
// "Cast shadows"): for a candidate direction l the shadow mask follows from the depth map alone
// (screen-space shadow rays), and l is scored by how much of the image's variation inside groups
// of equal albedo and orientation the predicted lit / shadowed split explains. The idea of
// explaining observed shadows by the light is Sato, Sato & Ikeuchi 2003 ("Illumination from
// shadows", PAMI 25(3)) and Panagopoulos, Samaras & Paragios 2009 ("Robust shadow and
// illumination estimation using a mixture model", CVPR); here the occluders come from the depth
// image instead of a known or coarse 3D model. Needs depth but only coarse normals, so it stays
// usable where the per-pixel normals of quantised sensor depth are too poor for §5.2's fit.
#pragma once

#include <span>

#include "probeless/light/estimate.h"
#include "probeless/light/transfer.h"

namespace probeless::light {

struct ShadowOptions {
  // EstimateSceneLight: refine the distant estimate's direction (on in the library; off in the
  // scene_light node: docs/light.md "Where it runs"; measured in docs/benchmarks/scene_light.md,
  // "Round 4").
  bool enabled = true;
  // Pixel strides of the points (both >= 1): the global pass over the sphere and the refinement.
  int coarse_stride = 16;
  int stride = 8;
  int coarse_directions = 64;  // Fibonacci directions over the whole sphere (16..1024)
  int candidates = 2;          // best coarse directions (>= 20 deg apart) refined (>= 1)
  float refine_start_deg = 6;  // first refinement step; halved refine_levels times
  int refine_levels = 4;       // >= 0
  // Shadow rays: march_steps samples at geometrically growing distances march_start_m ..
  // march_max_m from the point towards the light (metres, camera frame).
  int march_steps = 32;
  float march_start_m = 0.04f;
  float march_max_m = 3.0f;
  // A sample is occluded when it lies behind the depth-map surface it projects to by more than
  // depth_bias_m + depth_bias_rel * z and by less than max(thickness_m, thickness_steps x the
  // step length) (surfaces are assumed this thick); a ray that leaves the image, passes the
  // camera plane or reaches march_max_m unoccluded is lit.
  float depth_bias_m = 0.005f;
  float depth_bias_rel = 0.002f;
  float thickness_m = 0.4f;
  float thickness_steps = 1.5f;  // ... or this many step lengths, if more
  // A ray that passed behind a surface by more than the thickness and hit nothing is unknown
  // (left out of that direction's score) instead of lit.
  bool unknown_behind = true;
  // Groups: chromaticity cells per axis (with a colour image; 0 = one albedo) x normal
  // orientation bins (cube-map faces x 3 x 3 cells); groups with fewer than min_group_points
  // points are left out.
  int chroma_cells = 12;
  int min_group_points = 8;
  // Acceptance (no light -> no shadows -> no direction): the explained fraction must reach
  // min_score and exceed the same score without shadows (the unshadowed shading of the coarse
  // normals alone) by min_gain.
  float min_score = 0.15f;
  float min_gain = 0.1f;
  // ... and the lit / shadowed intensity ratio inside groups must reach min_contrast (a sky or
  // ambient occlusion darkens far less than a sun's cast shadow).
  float min_contrast = 2.0f;
  // ... and the best refined candidate at least 20 deg away (candidates >= 2) must score at most
  // max_runner_up x the best (else the shadows are ambiguous).
  float max_runner_up = 0.9f;
  // Image cues (off by default: the library's and fusion's G_r path; on for raw sensor depth,
  // RawDepthShadowOptions; docs/light.md "Cast shadows"). The observed shadow mask: a point is
  // observed dark below mask_dark_ratio x its group's lit level, the group's lit_quantile
  // intensity (same chromaticity and normal bin: same albedo, less light). A point observed dark
  // that a direction predicts lit weighs unexplained_dark_weight in that direction's fit and
  // total (it may lie in the shadow of an occluder out of view or missing from the depth, which
  // no direction should gain by explaining with a wrong occluder), and the score is multiplied
  // by min(1, b / boundary_ref), b the fraction of the predicted shadow boundaries (lattice
  // neighbours of one group with n.l > mask_min_cos, one predicted lit, one shadowed) where the
  // lit point is brighter than boundary_ratio x the shadowed one ((seen + 1) / (pairs + 2)).
  bool image_cues = false;
  float mask_dark_ratio = 0.5f;
  float lit_quantile = 0.8f;
  float mask_min_cos = 0.2f;
  float unexplained_dark_weight = 0.25f;  // [0, 1]
  float boundary_ratio = 1.5f;            // > 1
  float boundary_ref = 0.3f;              // (0, 1]; larger = stricter
  // With an initial direction (the SH estimate): the result is the direction closest to it, on
  // the arc towards the best shadow direction, whose score is >= keep_ratio x the best score
  // (0 = the best shadow direction itself).
  float keep_ratio = 0.9f;
  // keep_ratio when image_cues is on: a direction whose shadows the image confirms is followed
  // further (raw sensor depth, 18 frames: courtyard_grey sensor 6.1 -> 4.8 deg, fused 6.8 -> 6.4;
  // docs/light.md "Cast shadows").
  float cue_keep_ratio = 0.95f;
  int threads = 2;  // directions are scored in parallel (results do not depend on it)
};

// Predicted vs observed shadow mask under one direction (ShadowMaskAgreement).
struct MaskAgreement {
  float precision = 0;  // of the points predicted shadowed, the fraction observed dark
  float recall = 0;     // of the points observed dark, the fraction predicted shadowed
  int predicted = 0;    // points predicted shadowed (front-facing, visibility known)
  int observed = 0;     // points observed dark
  // Predicted shadow boundaries (lattice neighbours of one group, one predicted lit, one
  // shadowed) and the fraction of them where the lit one is observed brighter by boundary_ratio.
  int boundaries = 0;
  float boundary_precision = 0;
};

struct ShadowEstimate {
  bool valid = false;  // a direction was found and accepted
  // Unit, towards the light, camera frame: the best shadow direction, or (valid and an initial
  // direction given) the one kept by keep_ratio.
  Vec3f direction{0, 0, 0};
  float score = 0;             // explained fraction of the within-group variance, [0, 1]
  float score_unshadowed = 0;  // the same for the best direction without shadows
  float contrast = 1;          // lit / shadowed intensity ratio under the best direction
  float runner_up = 0;         // score of the best other refined candidate (0: none)
  int points = 0;              // points in usable groups (refinement stride)
  int groups = 0;              // usable groups
  int evaluations = 0;         // directions scored (both passes)
};

// Searches the light direction that best explains the cast shadows: a global pass over
// options.coarse_directions (plus `initial`, e.g. the SH estimate's direction, if given), then a
// coarse-to-fine pattern search around the best options.candidates. Score of l (per group g of
// points with equal chromaticity and normal bin, p = V_l(x) max(0, n(x).l), V_l the screen-space
// visibility): the model I = a_g + b_g p with b_g > 0 fitted by least squares in every group;
// score = sum of the groups' explained sums of squares / sum of their total sums of squares;
// with options.image_cues weighted and scaled by the observed shadow mask (ShadowOptions).
// `intensity`: linear grey (width * height); `colour` optional sRGB bytes (3 per pixel). Throws
// LightError for mismatched sizes, non-finite intrinsics or invalid options.
ShadowEstimate EstimateShadowDirection(const GeometryView& g, std::span<const float> intensity,
                                       const ShadowOptions& options,
                                       std::span<const uint8_t> colour = {},
                                       const Vec3f* initial = nullptr);

// The score of one direction (EstimateShadowDirection's, points at options.stride; shadows false:
// the unshadowed shading alone). Throws as EstimateShadowDirection.
float ShadowScore(const GeometryView& g, std::span<const float> intensity,
                  const ShadowOptions& options, std::span<const uint8_t> colour,
                  const Vec3f& direction, bool shadows = true);

// The image cue for one direction (points at options.stride), a diagnostic: the points with
// n.l > options.mask_min_cos whose visibility is known, split by the predicted shadow mask
// (screen-space shadow rays) and by the observed one (ShadowOptions' image cues), and the
// predicted shadow boundaries seen in the image. Throws as EstimateShadowDirection.
MaskAgreement ShadowMaskAgreement(const GeometryView& g, std::span<const float> intensity,
                                  const ShadowOptions& options, std::span<const uint8_t> colour,
                                  const Vec3f& direction);

// ShadowOptions for raw sensor depth (the node's depth mode): `base` with the image cues on.
ShadowOptions RawDepthShadowOptions(ShadowOptions base = {});

// Moves the light to the shadow direction: the SH coefficients are rotated by the rotation that
// takes light->dominant_direction to `direction` (the light keeps its shape and power), and the
// dominant direction is set to `direction` (unit). No-op for an invalid light.
void RotateLightTo(const Vec3f& direction, LightEstimate* light);

// EstimateShadowDirection seeded with light->dominant_direction; when its result is valid the
// light is rotated to it (RotateLightTo). Returns the shadow estimate.
ShadowEstimate RefineLightWithShadows(const GeometryView& g, std::span<const float> intensity,
                                      const ShadowOptions& options, std::span<const uint8_t> colour,
                                      LightEstimate* light);

}  // namespace probeless::light
