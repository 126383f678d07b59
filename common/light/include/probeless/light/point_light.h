// Near-field scene light (beyond Gruber et al. 2015, §5): point lamps inside the scene, fitted to
// the same inputs as the distant estimator (G_r: camera-frame depth and normals, intrinsics, the
// linear grey image, optionally the colour image and the transfer T), and the choice between the
// distant (§5.2) and the point model (LightModel, EstimateSceneLight). Model and measurements:
// docs/light.md, "Near-field lamps".
#pragma once

#include <cmath>
#include <span>
#include <string_view>
#include <vector>

#include "probeless/light/estimate.h"
#include "probeless/light/shadow.h"
#include "probeless/light/transfer.h"

namespace probeless::light {

// Which light model the scene estimate uses: the distant SH light of §5.2, K point lamps
// (EstimatePointLight), or the one the model-selection rule of EstimatePointLight prefers.
enum class LightModel { kDistant, kPoint, kAuto };

// "distant" | "point" | "auto". Throws LightError("light::ParseLightModel: ...") otherwise.
LightModel ParseLightModel(std::string_view name);
const char* LightModelName(LightModel model);

struct PointLightOptions {
  int max_lamps = 1;  // K: 1 or 2 lamps (the second is kept only if it pays, second_lamp_gain)
  // Rows of the fit (about): every k-th usable pixel in x and y, k = max(2, ceil(sqrt(usable /
  // max_rows))).
  int max_rows = 2000;
  float min_intensity = 0.004f;  // pixels darker (noise floor) or
  float max_intensity = 0.98f;   // brighter (saturated) than this are left out (linear grey)
  float albedo = 0.6f;           // mean albedo (the scale the light is reported in)
  // Chromaticity cells per axis as EstimateOptions::albedo_groups (0 = one albedo): each group
  // with >= 16 rows gets its own albedo, fitted jointly with the light; the rest share one.
  int albedo_groups = 32;
  bool albedo_invariant = false;      // as EstimateOptions::albedo_invariant
  int huber_iterations = 2;           // robust reweightings after the plain fit: Huber (k = 1.345),
  int tukey_iterations = 3;           // then Tukey's biweight (c = 4.685); MAD scale
  int lm_iterations = 8;              // Levenberg-Marquardt iterations per (re)weighted solve
  float min_lamp_distance_m = 0.05f;  // a lamp closer than this to a row's point does not light it
  // A second lamp is kept when it lowers the median absolute residual by at least this fraction.
  float second_lamp_gain = 0.1f;
  // Model selection (PointLightEstimate::prefers_point): the point model is preferred when its
  // median absolute residual is at least auto_min_gain (fraction) below the nested distant
  // model's on the same rows, and the dominant lamp's direction varies over the visible surface
  // by at least auto_min_spread_deg (p90 angle from the mean direction); otherwise the lamp is
  // effectively distant and the distant model (better conditioned) is kept. Calibrated on the
  // four evaluation scenarios (docs/light.md): room_dynamic gain >= 0.51 and spread >= 45 deg;
  // the distant-light scenes gain <= 0.31 where the spread is >= 10 deg, spread <= 3.5 deg
  // where the gain is >= 0.45.
  float auto_min_gain = 0.45f;
  float auto_min_spread_deg = 10.0f;
  // false: the nested distant fit (about a third of the cost) is skipped; prefers_point is then
  // false and median_residual_distant 0 (EstimateSceneLight sets it for kAuto only).
  bool select_model = true;
  int surface_stride = 8;  // every surface_stride-th pixel with depth is a point of the SH average
  // Screen (select_model, cold starts only; docs/light.md "Cost"): the whole selection (point and
  // distant fits) first runs on every k-th row, about screen_rows of them (if the fit has at least
  // 2 x screen_rows rows), with one Huber and one Tukey reweighting and screen_lm_iterations per
  // LM solve; the full fit follows only if the screen's gain is >= screen_min_gain and its spread
  // (over the rows' points) is >= screen_min_spread_deg, otherwise the point model is rejected
  // there (PointLightEstimate::screened_out). The screen can only turn "point" into "distant",
  // never the reverse: a distant result stays bit-identical. Its gain can lie far below the full
  // fit's (a worse local minimum on fewer rows), so it rejects only where the point model does not
  // beat the distant one at all (gain < 0) or the lamp is effectively distant. 0 rows = no screen.
  int screen_rows = 400;
  int screen_lm_iterations = 4;
  float screen_min_gain = 0.0f;
  float screen_min_spread_deg = 5.0f;
  // Warm start (a PointLightTracker holding the previous frame's lamp): no coarse search and no
  // screen; the robust fit starts from the previous lamp with warm_lm_iterations per LM solve (also
  // used by the nested distant fit of that frame). If its median |residual| exceeds
  // warm_max_residual_ratio x the previous frame's (+ 1e-3), the cold search runs as well and the
  // better (lower median |residual|) fit is kept.
  int warm_lm_iterations = 2;
  float warm_max_residual_ratio = 1.5f;
};

// The lamps of the previous frame of one stream, for warm starts (PointLightOptions::warm_*).
// Owned by the caller (one per image stream, e.g. the node, one per evaluated input), passed to
// every frame; EstimatePointLight / EstimateSceneLight fill it after a point fit that is used
// (valid, and preferred when selecting) and reset it otherwise, so a stream that turns distant
// starts cold again. Positions in the camera frame of that frame (metres): the camera's motion
// between frames is left to the fit. The warm start seeds the strongest lamp only; with max_lamps 2
// the second lamp is searched cold every frame.
struct PointLightTracker {
  std::vector<float> position;   // 3 per lamp, strongest first; empty = no lamp (cold start)
  std::vector<float> intensity;  // per lamp (PointLamp::intensity)
  float ambient = 0;
  double median_residual = 0;  // the fit's median |residual| (image units)
  bool Active() const { return !intensity.empty(); }
  void Reset() { *this = PointLightTracker{}; }
};

// A point lamp: position in the camera frame (metres; x right, y down, z forward) and intensity =
// the irradiance it gives at 1 m (grey, in the units of msgs::ShLight: an irradiance E from
// direction w is the SH light E Y(w)), scaled like the distant estimate (mean albedo
// PointLightOptions::albedo).
struct PointLamp {
  Vec3f position{0, 0, 0};
  float intensity = 0;
};

struct PointLightEstimate {
  // false: too few usable rows (< 32), screened out (auto), no lamp irradiance on the surface, or
  // no surface point for the SH average.
  bool valid = false;
  // Strongest first (mean irradiance over the visible surface points).
  std::vector<PointLamp> lamps;
  float ambient = 0;  // band-0 SH coefficient of a uniform ambient light
  // The light at the scene for the rest of the system: SH (the bands asked for) = the mean over the
  // visible surface points of the lamps' SH plus the ambient term (as SurfaceLightingTruth), the
  // dominant direction = the normalised mean over those points of irradiance x unit direction to
  // the strongest lamp, intensity = that lamp's mean irradiance, confidence = R^2 of the robust fit
  // x row-count saturation, rms_residual in image units.
  LightEstimate light;
  // Model selection on the same rows: the median absolute residual (image units) of the point
  // model and of the nested distant model (I = a (max(0, n.q) / pi + c T_0), fitted the same way).
  double median_residual_point = 0;
  double median_residual_distant = 0;
  float spread_deg = 0;  // p90 angle between the strongest lamp's direction at a point and the mean
  bool prefers_point = false;  // the auto rule (PointLightOptions::auto_min_gain / _spread_deg)
  int rows = 0;                // rows of the fit
  // The screen rejected the point model (PointLightOptions::screen_rows): no full fit ran, valid is
  // false, the median residuals and spread_deg are the screen's (its subset of rows).
  bool screened_out = false;
  float screen_gain = NAN, screen_spread_deg = NAN;  // the screen's figures (NAN: it did not run)
  bool warm_started = false;  // started from a PointLightTracker's lamp (and kept that fit)
};

// Fits options.max_lamps point lamps, a uniform ambient term and per-group albedos to the image by
// robust Levenberg-Marquardt (docs/light.md): I(x) = a_g(x) (sum_k P_k max(0, n.(p_k - x)) /
// (pi |p_k - x|^3) + c T_0(x)), x the back-projected pixel, n its normal, T_0 the band-0 transfer
// (the unoccluded 1 / (2 sqrt(pi)) without `transfer`). Initialised by a coarse search over
// positions around the visible surface (and along `initial_direction`, e.g. the distant
// estimate's dominant direction, camera frame, if given). `bands` (1..5) of the output SH light.
// `colour`: optional sRGB bytes (3 per pixel) for the albedo groups; `transfer` optional, same
// size as `g`. `tracker` (optional): warm start from its lamp and updated afterwards (see
// PointLightTracker). Throws LightError("light::EstimatePointLight: ...") for an invalid view (see
// ValidateGeometryView: sizes, missing normals, non-finite intrinsics), sizes that do not match,
// bad options, or no pixel with depth and normal at all.
PointLightEstimate EstimatePointLight(const GeometryView& g, std::span<const float> intensity,
                                      const PointLightOptions& options, int bands,
                                      const TransferResult* transfer = nullptr,
                                      std::span<const uint8_t> colour = {},
                                      const Vec3f* initial_direction = nullptr,
                                      PointLightTracker* tracker = nullptr);

struct SceneLightOptions {
  // auto by default: on the four evaluation scenarios it picks the distant model in every frame of
  // the three distant-light scenes and the point model in every room_dynamic frame (docs/light.md).
  LightModel model = LightModel::kAuto;
  EstimateOptions distant;
  PointLightOptions point;
  // Cast shadows (shadow.h; on by default): when the distant model is chosen, its direction is
  // refined by RefineLightWithShadows (`light`; `distant` stays EstimateLight's).
  ShadowOptions shadow;
};

struct SceneLightResult {
  LightEstimate light;                     // the chosen model's estimate
  LightModel used = LightModel::kDistant;  // kDistant or kPoint
  LightEstimate distant;                   // EstimateLight's
  PointLightEstimate point;                // valid only if the point model ran (model != kDistant)
  ShadowEstimate shadow;                   // valid only if shadow.enabled found a direction
  double point_thread_cpu_ms = NAN;        // the point fit's thread CPU time (NAN: it did not run)
};

// EstimateLight, then (model kPoint / kAuto, and the distant fit had enough pixels) the point fit
// initialised from its dominant direction; kPoint uses the point estimate when it is valid, kAuto
// when PointLightEstimate::prefers_point. `tracker` (optional, one per stream): warm starts of
// the point fit across frames, reset when the point model is not used. `distant_weights`
// (optional, width * height): the distant fit's row weights (EstimateLight's `reliability`).
// Throws LightError as EstimateLight and EstimatePointLight.
SceneLightResult EstimateSceneLight(const GeometryView& g, const TransferResult& transfer,
                                    std::span<const float> intensity,
                                    const SceneLightOptions& options,
                                    std::span<const uint8_t> colour = {},
                                    PointLightTracker* tracker = nullptr,
                                    std::span<const float> distant_weights = {});

}  // namespace probeless::light
