// The scene-light pipeline of one image stream (Gruber et al. 2015 §5 and what probeless adds to
// it): geometry (a G-buffer G_r or a raw depth image, normals, their filter and reliability) ->
// radiance transfer by SSDO (eq. 6-9, OursFast, the indirect term of eq. 10-12) -> the light (the
// distant SH fit of §5.2, its temporal accumulation, or the point-lamp model chosen by
// EstimateSceneLight) -> the distant light's direction refined by cast shadows. One object per
// stream holds what carries over between frames (warm starts of the point fit, the temporal
// history, the previous frame's dominant light for the indirect term, the previous pose). The
// node (nodes/scene_light) and the evaluation (tools/scene_light_eval) run this same object, so
// what is measured is what ships (docs/light.md, "Scene pipeline").
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "probeless/light/estimate.h"
#include "probeless/light/point_light.h"
#include "probeless/light/reliability.h"
#include "probeless/light/shadow.h"
#include "probeless/light/transfer.h"
#include "probeless/light/up_direction.h"

namespace probeless::light {

// Where a frame's geometry comes from (the node's `mode`).
enum class SceneGeometrySource {
  kGeometryBuffer,  // SceneFrame::gbuffer_*: a G-buffer with normals (fusion's G_r, a render)
  kDepthImage,      // SceneFrame::depth_image: raw depth, normals by DepthGeometry (no recon)
};

// The default ScenePipelineOptions::confidence_knots of a geometry source (pairs: fit confidence
// ascending, expected error in degrees): the reliability tables of the evaluation world's train and
// validation splits in gbuffer and in depth mode (the two modes' fit confidences mean different
// errors).
std::vector<double> DefaultSceneConfidenceKnots(SceneGeometrySource source);

// The normals of a G-buffer input (the node's `gbuffer_normals`).
enum class GBufferNormals {
  kGiven,    // the buffer's own (fusion's)
  kCentral,  // recomputed from its depth: NormalsFromDepth (central differences)
  kEdge,     // recomputed from its depth: NormalsWithReliability (edge-aware), with reliability
};

// The geometry of the shadow search for a G-buffer input (the node's `shadow_depth`).
enum class ShadowGeometry {
  // SceneFrame::depth_image when given (aligned with the camera image, while G_r's merged depth
  // is not at shadow edges; measured in docs/light.md "Cast shadows"), else the G-buffer.
  kDepthImage,
  kGeometryBuffer,  // always the G-buffer
};

// The fit's rows weighted by their distance to the point where virtual objects stand
// (SceneFrame::focus): the composite needs the light at the inserted object, and indoors the light
// varies across the room (a sun patch on the table, a lamp's fall-off, a dark corner), so the
// surfaces near the object say more about it than the far walls. Row weight
// floor + (1 - floor) exp(-d^2 / (2 radius^2)), d the pixel's 3D distance to the focus (metres).
// The defaults were chosen on the evaluation world's validation split (docs/light.md "Focus").
struct FocusOptions {
  float radius_m = 0.5f;  // the kernel's sigma in metres; 0 = off (every row weighs the same)
  float floor = 0.1f;     // weight far from the focus, in [0, 1]: keeps the room's other normals
};

// Every option of the node and the evaluation; the defaults are the node's (docs/nodes.md,
// scene_light) for subsample 1, except `shadow.enabled` (the library's true; the node's param
// `shadows` defaults to false, docs/light.md "Where it runs").
struct ScenePipelineOptions {
  SceneGeometrySource source = SceneGeometrySource::kGeometryBuffer;
  // SSDO transfer (eq. 6-9); the node sets max_occluder_distance_m = 2 x radius_m (the defaults).
  TransferOptions transfer;
  // The distant fit (§5.2). Its albedo, albedo_groups and albedo_invariant are also the point
  // fit's (point's own are overwritten: one albedo model for both models).
  // The light prior is on (LightPrior; weight and ratios as the node's prior_* params). The
  // assumed mean albedo 0.25 sets the light's level: the level of the light at an inserted object
  // best matched with it on the evaluation world's validation split (docs/light.md "Light level").
  EstimateOptions estimate{.albedo = 0.25f,
                           .prior = {.weight = 3.0, .zonal = {1.0f, 0.9f, 1.06f, 0.0f}}};

  // G-buffer input: its depth first smoothed by SmoothDepth of radius `gbuffer_smooth_radius` (0 =
  // none: G_r is denoised by the merge), its normals kept or recomputed `gbuffer_normal_step`
  // pixels apart (-1 = max(2, width / 160): the step of the node's `gbuffer_normals: depth`).
  GBufferNormals gbuffer_normals = GBufferNormals::kGiven;
  int gbuffer_normal_step = -1;
  int gbuffer_smooth_radius = 0;
  // Depth images (source kDepthImage, and the shadow search's depth image): DepthGeometry's
  // options; depth_geometry.normals also parameterises kEdge above (noise_quadratic < 0 = the
  // smoothed depth's, smoothed_noise_quadratic).
  DepthGeometryOptions depth_geometry;
  // FilterNormals on the fit's normals (after they are computed; the depth stays).
  bool normal_filter = false;
  NormalFilterOptions filter;
  // The normals' reliability as the fit's row weights (DepthGeometry's or NormalsWithReliability's
  // when they made the normals, else NormalReliability with the smoothed-depth noise model).
  // Needs light_model kDistant.
  bool reliability_weights = false;

  // frames > 1: TemporalLightEstimator (the distant fit over the last frames; needs light_model
  // kDistant, no shadow refinement).
  TemporalOptions temporal;
  // EstimateSceneLight's model choice (auto: point lamps when the selection rule prefers them).
  LightModel light_model = LightModel::kAuto;
  PointLightOptions point;
  // Warm starts of the point fit from the previous frame's lamp (PointLightTracker); false: every
  // frame cold (an ablation of the evaluation).
  bool point_warm_start = true;

  // Cast shadows refine the distant light's direction (RefineLightWithShadows) when the distant
  // model is used and temporal.frames == 1. The node's `shadows` param defaults to off
  // (docs/light.md "Where it runs"). `shadow.image_cues` applies to a search on
  // a G-buffer, `depth_image_cues` to one on a depth image (raw sensor depth needs them: without
  // them its quantisation lets a wrong occluder explain a shadow; RawDepthShadowOptions).
  ShadowOptions shadow;
  bool depth_image_cues = true;
  ShadowGeometry shadow_geometry = ShadowGeometry::kDepthImage;
  // With the light prior on (estimate.prior.weight > 0) and the distant model used: the shadow
  // search is seeded with the direction of the fit without the prior, and an accepted shadow
  // direction replaces the prior's light by that prior-free fit rotated to it (cast shadows are
  // direct evidence of the light, which the prior stands in for when the shading alone cannot pin
  // it down). false: the search refines the prior's fit.
  bool shadows_override_prior = true;

  // The light prior's up direction (estimate.prior, used when its weight > 0): estimated per frame
  // from the fit's geometry (EstimateUpDirection); a frame without a horizontal surface in view
  // gets no prior.
  UpDirectionOptions up;
  // The light's colour by the grey-world assumption (the scene's mean albedo is grey, so the
  // mean linear colour of the fit's pixels is the illuminant's): ScenePipelineResult::colour.
  // false: white.
  bool grey_world_colour = true;
  // Clipped pixels (a channel at 254 or 255: the sunlit table that reads white) take the
  // chromaticity of the nearest unclipped pixel on the same surface before the albedo and shadow
  // groups are formed, so that the lit and shadowed parts of one material share a group (the
  // lit part is the evidence of the light). false: they form groups of their own.
  bool fill_clipped_chroma = false;

  // The published confidence on msgs::ShLight's scale (light/fusion.h: c = 1 / (1 + (e / 10
  // deg)^2), e the expected dominant-direction error): knots (fit confidence, median direction
  // error in degrees) of ConfidenceCalibration, applied to the published model's fit confidence
  // (SceneEvidence::fit_confidence). Unset: DefaultSceneConfidenceKnots(source), the reliability
  // table of the evaluation world's train and validation splits
  // (tools/light_prior/fit_confidence.py, docs/light.md "Confidence"); empty = publish the fit
  // confidence itself.
  std::optional<std::vector<double>> confidence_knots;

  // Row weights by the distance to SceneFrame::focus (the distant fits, also the shadow search's
  // prior-free seed; not the point model, whose rows carry the lamp's position themselves).
  FocusOptions focus;

  // The published light as the expected light under its own direction uncertainty: with the
  // calibrated confidence's expected error e (confidence_knots; off while they are empty), band l
  // of the light is scaled by exp(-l (l + 1) sigma^2 / 2), the SH convolution with a spherical
  // Gaussian of angular spread sigma = uncertainty_blur x e / sqrt(2 ln 2) (a Rayleigh-
  // distributed angle whose median is e). A light whose direction is a guess then shades softly,
  // as the average over the directions it may be, instead of confidently from one wrong side.
  // 0 = off; the direction, confidence and intensity stay the fit's.
  float uncertainty_blur = 0;

  // The one-bounce indirect buffer (eq. 10-12) from the previous frame's dominant light: in the
  // result's transfer from the second frame on (none after a frame without a light).
  bool indirect = false;
};

// One frame's input, borrowed: the pipeline keeps nothing of it after Process (the result's views
// may point into it). Frames: the camera optical frame (x right, y down, z forward) of this
// frame.
struct SceneFrame {
  // Header stamp (ns). A stamp before the previous frame's (a restarted source) resets the state
  // (Reset) before the frame is processed.
  int64_t stamp_ns = 0;
  int width = 0;
  int height = 0;
  Intrinsics intrinsics;
  std::span<const float> grey;      // linear grey I_c, width * height (GreyFromImage)
  std::span<const uint8_t> colour;  // sRGB bytes, 3 per pixel, for the albedo groups; empty = none
  // Source kGeometryBuffer: G_r, width x height: depth (metres along z, 0 = none), unit normals
  // (3 per pixel, facing the camera; (0, 0, 0) = none) and optional sRGB colour (3 per pixel; the
  // indirect term's reflector colour A(s_j); empty = grey 1).
  std::span<const float> gbuffer_depth;
  std::span<const float> gbuffer_normals;
  std::span<const uint8_t> gbuffer_colour;
  // Raw depth (metres, 0 = none), width * height: the geometry of source kDepthImage; with
  // kGeometryBuffer and shadow_geometry kDepthImage the shadow search's (empty = the G-buffer's).
  std::span<const float> depth_image;
  // Auxiliary orthographic views for the transfer's occlusion test (§5.1); borrowed.
  const AuxiliaryBuffers* aux = nullptr;
  // Optional camera-to-world rotation (row-major 3 x 3, any fixed world frame): with the previous
  // frame's, the temporal fit rotates its history into this frame (d_now = R_now^T R_prev d_prev);
  // without it the camera is taken as not rotating.
  std::optional<std::array<double, 9>> camera_to_world_rotation;
  // Optional point where virtual objects are inserted (camera frame of this frame, metres):
  // ScenePipelineOptions::focus weights the fit's rows by their distance to it. Unset: no
  // weighting.
  std::optional<std::array<float, 3>> focus;
};

// Per-frame timings (milliseconds).
struct ScenePipelineTimings {
  double ms_geometry = 0;      // wall: normals, filter, reliability, the shadow depth's normals
  double ms_transfer = 0;      // wall: TransferComputer::Compute
  double cpu_ms_transfer = 0;  // process CPU of the transfer (all threads)
  double ms_estimate = 0;      // wall: the fit, the point fit and the shadow search
  double cpu_ms_estimate = 0;  // thread CPU of the same (the calling thread)
  double cpu_ms_point = NAN;   // thread CPU of the point fit (NAN: it did not run)
  double cpu_ms_shadow = NAN;  // process CPU of the shadow search (NAN: it did not run)
};

// What supports a frame's light: the inputs of its confidence (ScenePipelineOptions::
// confidence_calibration).
struct SceneEvidence {
  float fit_confidence = 0;  // the published model's fit: LightEstimate::confidence (R^2 x rows)
  bool shadow_accepted = false;  // cast shadows set the direction (RefineLightWithShadows valid)
  // Angle between the dominant directions of the distant fit with and without the light prior
  // (degrees, [0, 180]): how far the prior had to move the data's answer. Computed when the shadow
  // search ran from the prior-free fit (shadows_override_prior); else 0.
  float prior_shift_deg = 0;
};

// One frame's output. The views, spans and the transfer borrow buffers of the pipeline (or of the
// frame's input): valid until the next Process, and only as long as the input's buffers.
struct ScenePipelineResult {
  int64_t stamp_ns = 0;
  // The light of the frame (camera frame, white, transfer.bands bands): the chosen model's, with
  // the shadow refinement applied; what the node publishes when valid.
  LightEstimate light;
  LightModel used = LightModel::kDistant;  // kDistant or kPoint
  LightEstimate distant;                   // the distant fit before the shadow refinement
  PointLightEstimate point;                // valid only if the point model ran
  // The shadow search: its geometry and options (set whenever shadows are on, also for a frame
  // where the search did not run: the point model chosen, no valid light), shadow_on_depth_image
  // when the geometry is the frame's depth image (else the fit's); shadow_ran when it ran
  // (evaluations > 0), `shadow` its estimate.
  bool shadow_ran = false;
  bool shadow_on_depth_image = false;
  ShadowEstimate shadow;
  ShadowOptions shadow_options;
  GeometryView shadow_geometry;
  // The geometry of the fit and the transfer (after normals, filter), its reliability (empty
  // unless reliability_weights) and DepthGeometry's measured noise of the depth image (NaN: not
  // measured or no depth image).
  GeometryView geometry;
  std::span<const float> reliability;
  float measured_noise_quadratic = NAN;
  // T of the frame (TransferResult::indirect filled when the indirect buffer was computed).
  const TransferResult* transfer = nullptr;
  bool has_indirect = false;
  // Per-channel factors (R, G, B; mean 1) for the white light's coefficients: the illuminant
  // colour (ScenePipelineOptions::grey_world_colour), {1, 1, 1} without a colour image.
  std::array<float, 3> colour{1, 1, 1};
  // Clipped pixels given their surface's chromaticity (fill_clipped_chroma), 0 when off.
  size_t clipped_filled = 0;
  // The up direction of the light prior (valid false: no prior this frame or none asked for).
  UpDirection up;
  SceneEvidence evidence;
  ScenePipelineTimings timings;
};

// The pipeline of one stream. Not thread-safe; one per stream (the evaluation runs one per input
// and variant).
class ScenePipeline {
 public:
  // Throws LightError("light::ScenePipeline: ...") for options that cannot work together or are
  // out of range (and as TransferComputer / TemporalLightEstimator for theirs).
  explicit ScenePipeline(const ScenePipelineOptions& options = {});
  ~ScenePipeline();
  ScenePipeline(ScenePipeline&&) noexcept;
  ScenePipeline& operator=(ScenePipeline&&) noexcept;
  ScenePipeline(const ScenePipeline&) = delete;
  ScenePipeline& operator=(const ScenePipeline&) = delete;

  // The options it was made with (validated).
  const ScenePipelineOptions& options() const;

  // Runs one frame. Throws LightError("light::ScenePipeline::Process: ...") for an input that
  // does not match the options or itself (missing geometry / depth image, sizes), and as the
  // library calls it makes (e.g. ValidateGeometryView's messages). The previous light and pose are
  // updated only by a frame that completes.
  const ScenePipelineResult& Process(const SceneFrame& frame);

  // Forgets everything carried between frames (warm start, temporal history, previous light and
  // pose), e.g. after a cut or tracking loss.
  void Reset();

 private:
  struct State;
  std::unique_ptr<State> state_;
};

}  // namespace probeless::light
