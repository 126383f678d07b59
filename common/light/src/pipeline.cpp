#include "probeless/light/pipeline.h"

#include <time.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numbers>
#include <optional>
#include <string>
#include <vector>

#include "albedo_groups.h"
#include "probeless/light/fusion.h"

namespace probeless::light {

namespace {

using Clock = std::chrono::steady_clock;

double ProcessCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

double ThreadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

double MsSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

std::vector<double> KnotsOf(const ScenePipelineOptions& o) {
  return o.confidence_knots ? *o.confidence_knots : DefaultSceneConfidenceKnots(o.source);
}

void Validate(const ScenePipelineOptions& o) {
  const std::string what = "light::ScenePipeline: ";
  try {
    ConfidenceCalibration calibration(KnotsOf(o));
  } catch (const FusionError& e) {
    throw LightError(what + "confidence_knots: " + e.what());
  }
  if (o.light_model != LightModel::kDistant && o.temporal.frames > 1) {
    // The temporal accumulator is a distant-light fit.
    throw LightError(what + "temporal.frames > 1 needs light_model distant, got " +
                     LightModelName(o.light_model));
  }
  if (o.light_model != LightModel::kDistant && o.reliability_weights) {
    // The row weights are the distant fit's (EstimateLight).
    throw LightError(what + "reliability_weights needs light_model distant, got " +
                     LightModelName(o.light_model));
  }
  if (o.point.max_lamps < 1 || o.point.max_lamps > 2) {
    throw LightError(what + "point.max_lamps must be 1 or 2, got " +
                     std::to_string(o.point.max_lamps));
  }
  if (o.shadow.stride < 1 || o.shadow.coarse_stride < 1) {
    throw LightError(what + "shadow.stride and shadow.coarse_stride must be >= 1, got " +
                     std::to_string(o.shadow.stride) + " and " +
                     std::to_string(o.shadow.coarse_stride));
  }
  if (o.gbuffer_normal_step == 0 || o.gbuffer_normal_step < -1) {
    throw LightError(what + "gbuffer_normal_step must be -1 (max(2, width / 160)) or >= 1, got " +
                     std::to_string(o.gbuffer_normal_step));
  }
  if (o.gbuffer_smooth_radius < 0) {
    throw LightError(what + "gbuffer_smooth_radius must be >= 0, got " +
                     std::to_string(o.gbuffer_smooth_radius));
  }
  if (o.depth_geometry.step == 0 || o.depth_geometry.step < -1) {
    throw LightError(what + "depth_geometry.step must be -1 (by the noise) or >= 1, got " +
                     std::to_string(o.depth_geometry.step));
  }
  if (!(o.focus.radius_m >= 0) || !(o.focus.floor >= 0 && o.focus.floor <= 1)) {
    throw LightError(what + "focus.radius_m must be >= 0 and focus.floor in [0, 1], got " +
                     std::to_string(o.focus.radius_m) + " and " + std::to_string(o.focus.floor));
  }
  if (!(o.uncertainty_blur >= 0)) {
    throw LightError(what + "uncertainty_blur must be >= 0, got " +
                     std::to_string(o.uncertainty_blur));
  }
  if (o.depth_geometry.smooth_radius < -1) {
    throw LightError(what + "depth_geometry.smooth_radius must be -1 (by the noise) or >= 0, got " +
                     std::to_string(o.depth_geometry.smooth_radius));
  }
}

}  // namespace

std::vector<double> DefaultSceneConfidenceKnots(SceneGeometrySource source) {
  // tools/light_prior/fit_confidence.py on the train and validation splits (docs/light.md
  // "Confidence").
  if (source == SceneGeometrySource::kDepthImage) {
    return {0.003, 66.2, 0.199, 48.3, 0.334, 44.5, 0.671, 31.8};
  }
  return {0.151, 58.5, 0.316, 43.2, 0.557, 31.1};
}

struct ScenePipeline::State {
  explicit State(const ScenePipelineOptions& o)
      : options(o), computer(o.transfer), temporal(o.temporal), confidence(KnotsOf(o)) {
    scene.model = o.light_model;
    scene.distant = o.estimate;
    scene.point = o.point;
    // One albedo model for both fits (the node's and the evaluation's settings).
    scene.point.albedo = o.estimate.albedo;
    scene.point.albedo_groups = o.estimate.albedo_groups;
    scene.point.albedo_invariant = o.estimate.albedo_invariant;
    // The shadow refinement runs here, on the geometry chosen for it (shadow_geometry).
    scene.shadow = o.shadow;
    scene.shadow.enabled = false;
  }

  ScenePipelineOptions options;
  SceneLightOptions scene;
  TransferComputer computer;
  TemporalLightEstimator temporal;
  ConfidenceCalibration confidence;
  PointLightTracker tracker;
  // Carried between frames: the last light's dominant part (eq. 10's L_D, E_D), the last pose.
  std::optional<DominantLight> previous_light;
  std::optional<std::array<double, 9>> previous_rotation;
  int64_t last_stamp = std::numeric_limits<int64_t>::min();
  // Per-frame buffers (reused).
  std::vector<float> depth, normals, reliability;   // the fit's geometry
  std::vector<float> row_weights;                   // reliability x focus weights
  std::vector<float> shadow_depth, shadow_normals;  // the shadow search's depth image
  std::vector<uint8_t> group_colour;                // colour of the groups (fill_clipped_chroma)
  TransferResult transfer;
  ScenePipelineResult result;
};

ScenePipeline::ScenePipeline(const ScenePipelineOptions& options) {
  Validate(options);
  state_ = std::make_unique<State>(options);  // TransferComputer / temporal validate theirs
}

ScenePipeline::~ScenePipeline() = default;
ScenePipeline::ScenePipeline(ScenePipeline&&) noexcept = default;
ScenePipeline& ScenePipeline::operator=(ScenePipeline&&) noexcept = default;

const ScenePipelineOptions& ScenePipeline::options() const { return state_->options; }

void ScenePipeline::Reset() {
  State& s = *state_;
  s.temporal.Reset();
  s.tracker.Reset();
  s.previous_light.reset();
  s.previous_rotation.reset();
  s.last_stamp = std::numeric_limits<int64_t>::min();
}

const ScenePipelineResult& ScenePipeline::Process(const SceneFrame& f) {
  State& s = *state_;
  const ScenePipelineOptions& o = s.options;
  const std::string what = "light::ScenePipeline::Process: ";
  const int w = f.width, h = f.height;
  if (w < 1 || h < 1) {
    throw LightError(what + "frame size " + std::to_string(w) + "x" + std::to_string(h));
  }
  const size_t pixels = static_cast<size_t>(w) * h;
  const std::string size = std::to_string(w) + "x" + std::to_string(h);
  if (f.grey.size() != pixels) {
    throw LightError(what + "grey has " + std::to_string(f.grey.size()) + " values, expected " +
                     size);
  }
  if (!f.colour.empty() && f.colour.size() != 3 * pixels) {
    throw LightError(what + "colour has " + std::to_string(f.colour.size()) +
                     " bytes, expected 3 x " + size);
  }
  if (!f.depth_image.empty() && f.depth_image.size() != pixels) {
    throw LightError(what + "depth image has " + std::to_string(f.depth_image.size()) +
                     " values, expected " + size);
  }
  if (o.source == SceneGeometrySource::kGeometryBuffer) {
    if (f.gbuffer_depth.empty()) {
      throw LightError(what + "source geometry buffer, but the frame has no G-buffer depth");
    }
    // Sizes of depth, normals, colour and the intrinsics ("light::ScenePipeline::Process: ...").
    ValidateGeometryView({w, h, f.intrinsics, f.gbuffer_depth, f.gbuffer_normals, f.gbuffer_colour},
                         "ScenePipeline::Process");
  } else if (f.depth_image.empty()) {
    throw LightError(what + "source depth image, but the frame has none");
  }
  // A restarted source: nothing held for the old stream applies.
  if (f.stamp_ns < s.last_stamp) Reset();

  ScenePipelineResult& r = s.result;
  r = ScenePipelineResult{};
  r.stamp_ns = f.stamp_ns;
  r.transfer = &s.transfer;

  // Geometry of the fit and the transfer.
  const auto t_geometry = Clock::now();
  GeometryView view;
  bool reliability_done = false;  // the normals came with their reliability
  if (o.source == SceneGeometrySource::kGeometryBuffer) {
    view = {w, h, f.intrinsics, f.gbuffer_depth, f.gbuffer_normals, f.gbuffer_colour};
    const bool recompute = o.gbuffer_normals != GBufferNormals::kGiven;
    if (recompute || o.normal_filter || o.gbuffer_smooth_radius > 0) {
      s.depth.assign(view.depth.begin(), view.depth.end());
      if (o.gbuffer_smooth_radius > 0) SmoothDepth(s.depth, w, h, o.gbuffer_smooth_radius);
      const int step = o.gbuffer_normal_step >= 1 ? o.gbuffer_normal_step : std::max(2, w / 160);
      if (o.gbuffer_normals == GBufferNormals::kCentral) {
        // G_r is already denoised by the merge: central differences without smoothing.
        NormalsFromDepth(s.depth, w, h, f.intrinsics, &s.normals, 0.05f, step);
      } else if (o.gbuffer_normals == GBufferNormals::kEdge) {
        DepthNormalOptions no = o.depth_geometry.normals;
        no.step = step;
        if (no.noise_quadratic < 0) no.noise_quadratic = o.depth_geometry.smoothed_noise_quadratic;
        NormalsWithReliability(s.depth, w, h, f.intrinsics, no, &s.normals, &s.reliability);
        reliability_done = true;
      } else {
        s.normals.assign(view.normals.begin(), view.normals.end());
      }
      view.depth = s.depth;
      view.normals = s.normals;
    }
  } else {
    s.depth.assign(f.depth_image.begin(), f.depth_image.end());
    // Smooths s.depth in place when the measured noise calls for it.
    r.measured_noise_quadratic =
        DepthGeometry(s.depth, w, h, f.intrinsics, o.depth_geometry, &s.normals,
                      o.reliability_weights ? &s.reliability : nullptr);
    reliability_done = true;
    // No reflector colour: the depth mode's indirect term takes grey 1 (as the node always did).
    view = {w, h, f.intrinsics, s.depth, s.normals, {}};
  }
  if (o.normal_filter) {
    // view.normals is s.normals here (copied above for a G-buffer).
    FilterNormals(view.depth, w, h, f.intrinsics, o.filter, s.normals);
  }
  if (o.reliability_weights && !reliability_done) {
    // G_r (or a recomputed buffer) is denoised: the smoothed-depth noise model.
    NormalReliabilityOptions ro;
    ro.noise_quadratic = o.depth_geometry.smoothed_noise_quadratic;
    NormalReliability(view.depth, w, h, f.intrinsics, view.normals, ro, &s.reliability);
  }
  std::span<const float> weights =
      o.reliability_weights ? std::span<const float>(s.reliability) : std::span<const float>();
  r.geometry = view;
  r.reliability = weights;
  if (f.focus && o.focus.radius_m > 0) {
    // Rows near the inserted object count most (FocusOptions).
    s.row_weights.assign(pixels, 0.0f);
    const float inv = 1.0f / (2 * o.focus.radius_m * o.focus.radius_m);
    const auto& c = *f.focus;
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        const size_t i = static_cast<size_t>(y) * w + x;
        const float z = view.depth[i];
        if (!(z > 0)) continue;
        float p[3];
        f.intrinsics.BackProject(x, y, z, p);
        const float d2 = (p[0] - c[0]) * (p[0] - c[0]) + (p[1] - c[1]) * (p[1] - c[1]) +
                         (p[2] - c[2]) * (p[2] - c[2]);
        const float wf = o.focus.floor + (1 - o.focus.floor) * std::exp(-d2 * inv);
        s.row_weights[i] = weights.empty() ? wf : wf * weights[i];
      }
    }
    weights = s.row_weights;
  }
  // The shadow search's geometry: the fit's, or the frame's own depth image (shadow_geometry).
  const bool temporal = o.temporal.frames > 1;
  const bool shadows = o.shadow.enabled && !temporal;
  r.shadow_options = o.shadow;
  r.shadow_geometry = view;
  if (shadows && o.source == SceneGeometrySource::kDepthImage) {
    r.shadow_options.image_cues = o.depth_image_cues;
    r.shadow_on_depth_image = true;
  } else if (shadows && o.shadow_geometry == ShadowGeometry::kDepthImage &&
             !f.depth_image.empty()) {
    s.shadow_depth.assign(f.depth_image.begin(), f.depth_image.end());
    DepthGeometry(s.shadow_depth, w, h, f.intrinsics, o.depth_geometry, &s.shadow_normals);
    r.shadow_geometry = {w, h, f.intrinsics, s.shadow_depth, s.shadow_normals, {}};
    r.shadow_options.image_cues = o.depth_image_cues;
    r.shadow_on_depth_image = true;
  }
  r.timings.ms_geometry = MsSince(t_geometry);

  // Transfer (eq. 6-9; the indirect term of eq. 10-12 from the previous frame's light).
  const bool indirect = o.indirect && s.previous_light.has_value();
  static const AuxiliaryBuffers kNoAux;
  const double cpu_transfer = ProcessCpuMs();
  const auto t_transfer = Clock::now();
  s.computer.Compute(view, f.aux != nullptr ? *f.aux : kNoAux,
                     indirect ? &*s.previous_light : nullptr, &s.transfer);
  r.timings.ms_transfer = MsSince(t_transfer);
  r.timings.cpu_ms_transfer = ProcessCpuMs() - cpu_transfer;
  r.has_indirect = indirect && !s.transfer.indirect.empty();

  // The illuminant colour by the grey-world assumption, over the fit's unsaturated pixels.
  r.colour = {1, 1, 1};
  if (o.grey_world_colour && f.colour.size() == 3 * static_cast<size_t>(w) * h) {
    double sum[3] = {0, 0, 0};
    for (size_t i = 0; i < static_cast<size_t>(w) * h; i += 3) {
      if (!(view.depth[i] > 0) || f.grey[i] < o.estimate.min_intensity ||
          f.grey[i] > o.estimate.max_intensity) {
        continue;
      }
      for (int c = 0; c < 3; ++c) sum[c] += SrgbToLinear(f.colour[3 * i + c]);
    }
    const double mean = (sum[0] + sum[1] + sum[2]) / 3;
    if (mean > 0) {
      for (int c = 0; c < 3; ++c) r.colour[c] = static_cast<float>(sum[c] / mean);
    }
  }

  // The colour the albedo and shadow groups read.
  std::span<const uint8_t> colour = f.colour;
  if (o.fill_clipped_chroma && f.colour.size() == 3 * pixels) {
    s.group_colour = internal::FillClippedChroma(f.colour, view.depth, view.normals, w, h, 254,
                                                 0.03f, 30.0f, &r.clipped_filled);
    colour = s.group_colour;
  }

  // The light prior's up direction, from the fit's geometry.
  EstimateOptions estimate = o.estimate;
  r.up = {};
  if (estimate.prior.weight > 0) {
    r.up = EstimateUpDirection(view, o.up);
    estimate.prior.up = r.up.valid ? r.up.up : Vec3f{0, 0, 0};
  }
  s.scene.distant.prior.up = estimate.prior.up;

  // The light.
  const auto t_estimate = Clock::now();
  const double cpu_estimate = ThreadCpuMs();
  // With shadows_override_prior the shadow search starts from the fit without the prior, kept
  // for the evidence's prior_shift_deg.
  const bool prior_on = estimate.prior.weight > 0 && estimate.prior.up != Vec3f{};
  std::optional<LightEstimate> free_fit;
  auto shadow_search = [&](LightEstimate* light) {
    const double cpu0 = ProcessCpuMs();
    if (o.shadows_override_prior && prior_on) {
      EstimateOptions no_prior = estimate;
      no_prior.prior.weight = 0;
      free_fit = EstimateLight(s.transfer, f.grey, no_prior, colour, weights);
    }
    if (free_fit && free_fit->valid) {
      LightEstimate seed = *free_fit;  // a copy: the evidence below reads the unrotated fit
      r.shadow = RefineLightWithShadows(r.shadow_geometry, f.grey, r.shadow_options, colour, &seed);
      if (r.shadow.valid) *light = std::move(seed);
    } else {
      r.shadow = RefineLightWithShadows(r.shadow_geometry, f.grey, r.shadow_options, colour, light);
    }
    r.timings.cpu_ms_shadow = ProcessCpuMs() - cpu0;
    r.shadow_ran = r.shadow.evaluations > 0;
  };
  if (temporal) {
    // The history is rotated into this frame by the camera's rotation since the last frame.
    float rotation[9];
    const bool rotated = f.camera_to_world_rotation && s.previous_rotation;
    if (rotated) {
      const auto& now = *f.camera_to_world_rotation;
      const auto& prev = *s.previous_rotation;
      for (int a = 0; a < 3; ++a) {
        for (int b = 0; b < 3; ++b) {
          double x = 0;
          for (int c = 0; c < 3; ++c) x += now[c * 3 + a] * prev[c * 3 + b];  // R_now^T R_prev
          rotation[a * 3 + b] = static_cast<float>(x);
        }
      }
    }
    r.light = s.temporal.Estimate(s.transfer, f.grey, estimate, colour,
                                  rotated ? rotation : nullptr, weights);
    r.distant = r.light;
  } else if (o.light_model == LightModel::kDistant) {
    r.light = EstimateLight(s.transfer, f.grey, estimate, colour, weights);
    r.distant = r.light;
    if (shadows && r.light.valid) shadow_search(&r.light);
  } else {
    SceneLightResult scene = EstimateSceneLight(view, s.transfer, f.grey, s.scene, colour,
                                                o.point_warm_start ? &s.tracker : nullptr, weights);
    r.used = scene.used;
    r.distant = std::move(scene.distant);
    r.point = std::move(scene.point);
    r.light = std::move(scene.light);
    r.timings.cpu_ms_point = scene.point_thread_cpu_ms;
    if (shadows && r.used == LightModel::kDistant && r.light.valid) shadow_search(&r.light);
  }
  // The evidence behind the light (its confidence's inputs).
  r.evidence = {};
  r.evidence.fit_confidence = r.light.confidence;
  r.evidence.shadow_accepted = r.shadow_ran && r.shadow.valid;
  // Only when the shadow search made the prior-free fit: no fit for the evidence alone (OursFast
  // runs no shadow search).
  if (free_fit && free_fit->valid && r.light.valid && r.used == LightModel::kDistant) {
    const Vec3f& a = r.distant.dominant_direction;
    const Vec3f& b = free_fit->dominant_direction;
    const float dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    r.evidence.prior_shift_deg =
        std::acos(std::clamp(dot, -1.0f, 1.0f)) * 180.0f / std::numbers::pi_v<float>;
  }
  if (r.light.valid) {
    r.light.confidence = static_cast<float>(s.confidence.Apply(r.light.confidence));
    if (o.uncertainty_blur > 0 && !s.confidence.identity()) {
      BlurByUncertainty(r.light.coefficients, r.light.confidence, o.uncertainty_blur);
    }
  }
  r.timings.cpu_ms_estimate = ThreadCpuMs() - cpu_estimate;
  r.timings.ms_estimate = MsSince(t_estimate);

  // State for the next frame. The bounce light (eq. 10) only from a light with a direction and
  // power.
  const float* d = r.light.dominant_direction.data();
  if (r.light.valid && r.light.intensity > 0 && d[0] * d[0] + d[1] * d[1] + d[2] * d[2] > 0.5f) {
    s.previous_light = DominantLight{r.light.dominant_direction, r.light.intensity};
  } else {
    s.previous_light.reset();
  }
  s.previous_rotation = f.camera_to_world_rotation;
  s.last_stamp = f.stamp_ns;
  return r;
}

}  // namespace probeless::light
