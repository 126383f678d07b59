// scene_light_eval: evaluates probeless_light's full (Ours) and fast (OursFast) variants.
// Every variant on every input runs light::ScenePipeline, the object nodes/scene_light runs (one
// per input stream and variant: clean = a given G-buffer, sensor = the node's depth mode, fused =
// its gbuffer mode on fusion's G_r with the frame's depth image), so what is measured is what
// ships; the flags below are ScenePipelineOptions (docs/light.md "Scene pipeline").
//
//   scene_light_eval [--sim SCENARIO.yaml | --log FILE.mcap] --json OUT [--plots DIR]
//                    [--frames N] [--directions N] [--bands B] [--aux] [--threads T]
//                    [--camera-truth] [--grey-world] [--quadrature] [--fused] [--mix] ...
//
// --sim (default data/scenarios/room_dynamic.yaml): N frames (default 12) spread evenly over the
// scenario are rendered in-process; each variant runs on the noise-free render (depth, normals,
// colour: the estimator in isolation) — the top-level `full` / `fast` objects — and on the sensor
// output (depth16 with noise, quantisation and holes, normals from depth, noisy rgb8) — the
// `with_sensor_noise` object. --log reads /camera/camera_info, /camera/image, /camera/depth and
// /groundtruth/light from an MCAP log (sensor data only; normals from depth), matched by
// header.stamp_ns (ROS 2 logs carry no sequence). --aux adds left/right/top orthographic views
// traced from the scene (--sim) to the clean and sensor runs; with --fused the fused run gets the
// reconstruction's own views instead (recon::RaycastAuxiliaryViews of the volume at the tracked
// pose, 128 x 128, through a msgs::AuxiliaryViews message as fusion publish_aux -> scene_light
// use_aux; none for a lost frame), their raycast time in `fused_aux_raycast_ms_median`.
// Experiments on the traced views (docs/benchmarks/scene_light.md "Auxiliary views over the bus"):
// --aux-roles STR keeps the views whose letter (l, r, t) is in STR, --aux-top-camera traces the top
// view along the camera's +y (recon's convention), --aux-standoff M moves the view planes M before
// the look-at point (extent 2 M + 1.6 m), --aux-resolution N their pixels per side (128); each
// implies --aux.
// Ground truth (--sim): light::SurfaceLightingTruth, the light averaged over the visible surface
// points (what a distant-light fit to those surfaces can recover; equal to the light at the
// camera for distant lights); --camera-truth scores against the light at the camera
// (/groundtruth/light, the only truth a --log has). Errors: the angle between the estimated and
// the true dominant direction (frames whose truth has an enabled light: a switched-off interval
// without any light is left out), the same against the light at the camera
// (dominant_dir_error_vs_camera_light_deg_median), and |l - l_true| / |l_true| over bands 0-2 of
// the grey (mean RGB) truth. --grey-world: one uniform albedo (no chromaticity groups);
// --albedo-groups N: chromaticity cells per axis (EstimateOptions / PointLightOptions
// ::albedo_groups, default 32); --invariant-albedo: the illuminant-invariant groups
// (::albedo_invariant);
// --quadrature: eq. 6 as printed (no analytic unoccluded transfer) — ablations. Timings are per
// frame at the stream's resolution with --threads workers (default 2): wall ms, process CPU ms of
// the transfer (all threads) and thread CPU ms of the estimate (the fit, the point fit and the
// shadow search: ScenePipelineTimings). Output: one JSON object; plots as PNG (lat-long maps,
// error over time, estimated and true direction over time).
//
// Real-like input (--sim): `geometry_vs_clean` (coverage of the rendered surface, normal error
// against the rendered normals) for the sensor and fused G-buffers. --fused also runs every
// --fused-step-th frame (default 1) through recon::FusionPipeline as launch/demo_scene.yaml's
// fusion node does (6 m volume, 256^3, ICP tracking; --fused-known-pose: the simulator's pose)
// and scores the variants on its G_r (merged depth + normals, the image's colour) -> `fused`;
// --fused-volume uses G_v (the TSDF raycast) instead, --fused-normal-step S recomputes the
// normals from G_r's depth; fusion config: --fused-size M, --fused-origin X,Y,Z,
// --fused-resolution N, --fused-truncation M (defaults: the demo's), --fused-normals depth|volume
// (FusionOptions::normal_source), --fused-normal-gap M, --fused-gradient-step V. --mix scores
// hybrids of clean and sensor inputs (which sensor effect costs what; printed). Estimator switches:
// --normal-filter (light::FilterNormals; --filter-radius,
// --filter-angle, --filter-view, --filter-jump), --temporal N / --forgetting F
// (light::TemporalLightEstimator fed with the N - 1 frames before each evaluated one, camera
// rotation from the simulator), --smooth-radius / --normal-step (normals of the sensor depth),
// --no-balance. --prior-weight W: the light prior's weight (0 = off; default the node's);
// --no-shadows-override-prior: ScenePipelineOptions::shadows_override_prior false (the shadow
// search refines the prior's fit).
// --light-model distant|point|auto (light::EstimateSceneLight; default auto;
// --temporal implies distant):
// the near-field point-lamp fit (docs/light.md, "Near-field lamps"), --lamps K (1 or 2),
// --point-rows N (rows of the point fit, PointLightOptions::max_rows); adds
// per series `point_chosen_frames`, `point_screened_out_frames` / `point_warm_frames`
// (PointLightEstimate::screened_out / warm_started; --no-screen: PointLightOptions::screen_rows 0,
// --cold: ScenePipelineOptions::point_warm_start false, every frame starts cold; --screen-rows
// N, --screen-lm N, --warm-lm N set PointLightOptions::screen_rows / screen_lm_iterations /
// warm_lm_iterations), `cpu_ms_point_median` (the point fit's thread CPU time, SceneLightResult::
// point_thread_cpu_ms) and `lamp_position_error_m_median` (the chosen model's strongest lamp to the
// nearest enabled true lamp, --sim; point frames only); --plots adds scene_light_lamps.png.
// The sensor path's normals are the node's depth mode's (light::DepthGeometry,
// kAuto); --legacy-normals / --edge-normals force round 2's / the edge-aware ones
// (--edge-noise-quad,
// --edge-threshold, --edge-radius, --edge-view: light::DepthNormalOptions); --reliability uses
// the normals' reliability as the estimator's row weights (ScenePipelineOptions::
// reliability_weights; sensor and fused inputs; --log runs the sensor pipeline, so the sensor
// flags apply to it). A noise-free-depth run: a scenario
// without its `sensor:` block (the "sensor" path then sees millimetre depth16 without noise).
// --fused-shadows raw|gr: the fused input's shadow search on the frame's own depth image with
// the raw-depth options (raw, the node's shadow_depth default) or on G_r
// (ScenePipelineOptions::shadow_geometry).
// Cast shadows (round 4, on by default for the full variant, --fast-shadows for OursFast too;
// --no-shadows: off) refine the distant light's direction
// (light::RefineLightWithShadows in the pipeline when the distant model is used, timed
// apart); not with --temporal. Per series `shadow_accepted_frames`, `shadow_dir_error_deg_median`
// (the search's direction, accepted or not) and `cpu_ms_shadow_median` (process CPU, both
// threads); per frame the search's figures are printed. Tuning flags: the comment on
// Options::shadows.
#include "probeless/node/main.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <numbers>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "probeless/light/estimate.h"
#include "probeless/light/messages.h"
#include "probeless/light/pipeline.h"
#include "probeless/light/point_light.h"
#include "probeless/light/reliability.h"
#include "probeless/light/shadow.h"
#include "probeless/light/sim_buffers.h"
#include "probeless/light/transfer.h"
#include "probeless/msgs/msgs.h"
#include "probeless/node/flags.h"
#include "probeless/parse/number.h"
#include "probeless/recon/msgs_io.h"
#include "probeless/recon/pipeline.h"
#include "probeless/replay/sources.h"
#include "probeless/sh/sh.h"
#include "probeless/sim/scenario.h"
#include "probeless/sim/simulator.h"

namespace {

using namespace probeless;
using Clock = std::chrono::steady_clock;

struct Options {
  std::string sim = "data/scenarios/room_dynamic.yaml";
  std::string log;
  std::string json;
  std::string plots;
  int frames = 12;
  int directions = 32;
  uint64_t seed = 1;  // --seed S: TransferOptions::seed (the SSDO jitter)
  int bands = 4;
  int threads = 2;
  bool aux = false;
  // --aux-roles STR: keep only the traced views whose letter is in STR (l, r, t); --aux-top-camera:
  // the traced top view along the camera's +y (recon's convention) instead of world -y.
  std::string aux_roles = "lrt";
  bool aux_top_camera = false;
  float aux_standoff = -1;        // --aux-standoff M: traced views' standoff (extent 2 M + 1.6)
  int aux_resolution = 128;       // --aux-resolution N: traced views' pixels per side
  bool camera_truth = false;      // --camera-truth: score against the light at the camera
  bool grey_world = false;        // --grey-world: one uniform albedo (no chromaticity groups)
  bool fused_shadows_raw = true;  // --fused-shadows raw|gr (raw, as the node): the search's depth
  bool invariant_albedo = false;  // --invariant-albedo: EstimateOptions::albedo_invariant
  int albedo_groups = -1;         // --albedo-groups N: EstimateOptions::albedo_groups (and point's)
  bool quadrature = false;        // --quadrature: eq. 6 as printed (no analytic unoccluded part)
  bool fused = false;             // --fused: also run on fusion's G_r (in-process FusionPipeline)
  bool fused_known_pose = false;  // --fused-known-pose: the simulator's pose instead of ICP
  int fused_step = 1;             // --fused-step S: integrate every S-th frame
  // Normal filter on sensor and fused G-buffers (light::FilterNormals): --normal-filter,
  // --filter-radius R, --filter-angle DEG, --filter-view DEG, --filter-jump REL.
  bool normal_filter = false;
  light::NormalFilterOptions filter;
  int smooth_radius = -1;     // --smooth-radius R: sensor depth smoothing (-1: DepthGeometry's)
  int normal_step = -1;       // --normal-step S: normal step (-1: DepthGeometry's)
  bool fused_volume = false;  // --fused-volume: G_v (the TSDF raycast, depth and normals) not G_r
  int fused_normal_step = 0;  // --fused-normal-step S: normals from G_r's depth (0: fusion's)
  // Fusion configuration (defaults: launch/demo_scene.yaml's fusion node): --fused-size M,
  // --fused-origin X,Y,Z (metres, first camera's frame), --fused-resolution N, --fused-truncation
  // M,
  // --fused-normals depth|volume (FusionOptions::normal_source), --fused-normal-gap M,
  // --fused-gradient-step V.
  float fused_size = 6.0f;
  float fused_origin[3] = {-3.0f, -3.0f, 0.3f};
  int fused_resolution = 256;
  float fused_truncation = 0.08f;
  bool fused_volume_normals = false;
  float fused_normal_gap = 0.03f;
  float fused_gradient_step = 1.0f;
  int temporal = 1;          // --temporal N: TemporalLightEstimator over N consecutive frames
  float forgetting = 0.5f;   // --forgetting F
  bool no_balance = false;   // --no-balance: no normal-orientation balancing (ablation)
  double prior_weight = -1;  // --prior-weight W: LightPrior::weight (-1 = the node's default)
  bool shadows_override_prior = true;  // --no-shadows-override-prior: false
  bool mix = false;  // --mix: hybrids of clean and sensor inputs (which sensor effect costs what)
  light::LightModel light_model = light::LightModel::kAuto;  // --light-model
  bool light_model_set = false;                              // --light-model given
  int lamps = 1;                                             // --lamps K
  int point_rows = 0;        // --point-rows N: PointLightOptions::max_rows (0 = its default)
  bool point_screen = true;  // --no-screen: PointLightOptions::screen_rows = 0
  bool point_warm = true;    // --cold: ScenePipelineOptions::point_warm_start false
  int screen_rows = -1;      // --screen-rows N: PointLightOptions::screen_rows (-1 = default)
  int screen_lm = -1;        // --screen-lm N: PointLightOptions::screen_lm_iterations
  int warm_lm = -1;          // --warm-lm N: PointLightOptions::warm_lm_iterations
  // Depth-mode geometry of the sensor path (light::DepthGeometry, default kAuto: edge-aware on
  // clean depth, round 2's normals on noisy depth): --legacy-normals (always round 2's SmoothDepth
  // w/80 + NormalsFromDepth), --edge-normals (always edge-aware, at the scale of the measured
  // noise), --smooth-radius R / --normal-step S (override the scale), --edge-noise-quad Q,
  // --edge-threshold T, --edge-radius M, --edge-view DEG (light::DepthNormalOptions).
  light::DepthGeometryOptions depth_geometry;
  // --reliability: the normals' reliability as the estimator's row weights (sensor:
  // DepthGeometry's; fused: light::NormalReliability of G_r, or NormalsWithReliability's with
  // --fused-normal-step).
  bool reliability = false;
  // Cast shadows refine the distant light's direction (light::ShadowOptions, on by default;
  // --no-shadows: off). Tuning: --shadow-stride, --shadow-coarse-stride, --shadow-directions,
  // --shadow-candidates, --shadow-steps, --shadow-bias, --shadow-bias-rel, --shadow-thickness,
  // --shadow-thickness-steps, --shadow-behind-lit, --shadow-chroma, --shadow-min-score,
  // --shadow-min-gain, --shadow-min-contrast, --shadow-max-runner-up, --shadow-keep,
  // --shadow-cue-keep (ShadowOptions::cue_keep_ratio).
  bool shadows = light::ShadowOptions{}.enabled;
  bool fast_shadows = false;  // --fast-shadows: the shadow search for OursFast too
  light::ShadowOptions shadow;
  // The search's image cues (ShadowOptions::image_cues; round 5) for which inputs: `depth` (the
  // default, as the node: raw sensor depth, light::RawDepthShadowOptions), `all` (also the clean
  // render and fused G_r), `none` (round 4). Tuning: --shadow-dark-weight, --shadow-dark-ratio,
  // --shadow-boundary-ref, --shadow-boundary-ratio.
  std::string shadow_cues = "depth";
};

// One evaluated frame of one variant.
struct Sample {
  double time_s = 0;
  double dir_error_deg = NAN;         // NAN when the ground truth has no dominant light
  double dir_error_camera_deg = NAN;  // against the light at the camera (--sim only)
  double sh_rel_error = NAN;
  double ms_transfer = 0;
  double ms_estimate = 0;
  double cpu_ms_transfer = 0;     // process CPU time of the transfer call (all threads)
  double cpu_ms_estimate = 0;     // CPU time of the estimate (one thread)
  std::vector<double> estimate;   // coefficients
  std::array<float, 27> truth{};  // 9 x RGB
  std::array<float, 3> estimate_dir{0, 0, 0}, truth_dir{0, 0, 0};  // camera frame, 0 = none
  // --light-model point|auto: whether the point model was chosen, the point fit's CPU ms, its
  // strongest lamp and the true enabled lamps (camera frame), the lamp error (m).
  bool point_chosen = false;
  double cpu_ms_point = NAN;
  std::array<float, 3> lamp{NAN, NAN, NAN};
  std::vector<std::array<float, 3>> true_lamps;
  double lamp_error_m = NAN;
  double point_gain = NAN, spread_deg = NAN;        // the auto rule's inputs (PointLightEstimate)
  bool screened_out = false, warm_started = false;  // PointLightEstimate's
  double screen_gain = NAN, screen_spread_deg = NAN;
  // Cast shadows: whether the search accepted a direction, its score, the score without shadows,
  // the lit / shadowed contrast, the runner-up's score, the score of the true direction, the
  // error of its direction (accepted or not) and its process CPU ms (both threads).
  bool shadow_valid = false;
  double shadow_score = NAN, shadow_unshadowed = NAN, shadow_dir_error_deg = NAN;
  double shadow_contrast = NAN, shadow_truth_score = NAN, shadow_runner_up = NAN;
  double cpu_ms_shadow = NAN;
  // The image cue (light::MaskAgreement) under the search's direction and under the truth.
  light::MaskAgreement shadow_mask, shadow_truth_mask;
};

struct Series {
  std::vector<Sample> samples;
};

double Quantile(std::vector<double> v, double q) {
  v.erase(std::remove_if(v.begin(), v.end(), [](double x) { return std::isnan(x); }), v.end());
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const double pos = q * (v.size() - 1);
  const size_t i = static_cast<size_t>(pos);
  const double f = pos - i;
  return i + 1 < v.size() ? v[i] * (1 - f) + v[i + 1] * f : v[i];
}

std::string Num(double v) {
  if (std::isnan(v)) return "null";
  std::ostringstream s;
  s.precision(5);
  s << v;
  return s.str();
}

std::string SeriesJson(const Series& s) {
  std::vector<double> dir, dir_cam, sh_err, ms_t, ms_e, cpu_t, cpu_e, cpu_p, lamp_err;
  std::vector<double> shadow_dir, cpu_s;
  int point_chosen = 0, screened_out = 0, warm_started = 0, shadow_accepted = 0;
  for (const auto& x : s.samples) {
    screened_out += x.screened_out ? 1 : 0;
    warm_started += x.warm_started ? 1 : 0;
    shadow_dir.push_back(x.shadow_dir_error_deg);
    cpu_s.push_back(x.cpu_ms_shadow);
    shadow_accepted += x.shadow_valid ? 1 : 0;
    cpu_p.push_back(x.cpu_ms_point);
    lamp_err.push_back(x.lamp_error_m);
    point_chosen += x.point_chosen ? 1 : 0;
    dir.push_back(x.dir_error_deg);
    dir_cam.push_back(x.dir_error_camera_deg);
    sh_err.push_back(x.sh_rel_error);
    ms_t.push_back(x.ms_transfer);
    ms_e.push_back(x.ms_estimate);
    cpu_t.push_back(x.cpu_ms_transfer);
    cpu_e.push_back(x.cpu_ms_estimate);
  }
  std::ostringstream o;
  o << "{\"frames\": " << s.samples.size()
    << ", \"dominant_dir_error_deg_median\": " << Num(Quantile(dir, 0.5))
    << ", \"dominant_dir_error_deg_p90\": " << Num(Quantile(dir, 0.9))
    << ", \"sh_rel_error_median\": " << Num(Quantile(sh_err, 0.5))
    << ", \"ms_transfer_median\": " << Num(Quantile(ms_t, 0.5))
    << ", \"ms_estimate_median\": " << Num(Quantile(ms_e, 0.5))
    << ", \"cpu_ms_transfer_median\": " << Num(Quantile(cpu_t, 0.5))
    << ", \"cpu_ms_estimate_median\": " << Num(Quantile(cpu_e, 0.5))
    << ", \"dominant_dir_error_vs_camera_light_deg_median\": " << Num(Quantile(dir_cam, 0.5))
    << ", \"point_chosen_frames\": " << point_chosen
    << ", \"point_screened_out_frames\": " << screened_out
    << ", \"point_warm_frames\": " << warm_started
    << ", \"cpu_ms_point_median\": " << Num(Quantile(cpu_p, 0.5))
    << ", \"lamp_position_error_m_median\": " << Num(Quantile(lamp_err, 0.5))
    << ", \"shadow_accepted_frames\": " << shadow_accepted
    << ", \"shadow_dir_error_deg_median\": " << Num(Quantile(shadow_dir, 0.5))
    << ", \"cpu_ms_shadow_median\": " << Num(Quantile(cpu_s, 0.5)) << "}";
  return o.str();
}

// One evaluated variant (full = Ours, fast = OursFast): one light::ScenePipeline per input stream,
// the object the node runs, each with the state of its stream (warm starts, temporal history).
struct Variant {
  std::optional<light::ScenePipeline> clean_pipeline, sensor_pipeline, fused_pipeline;
  // --mix: the hybrids of clean and sensor inputs, as given G-buffers without state (no warm
  // start, no temporal history).
  std::optional<light::ScenePipeline> mix_pipeline;
  Series clean, noisy, fused;
  std::array<Series, 7> mix;  // --mix: clean geometry + sensor colour; sensor geometry + clean
                              // colour; clean normals and depth where the sensor has depth;
                              // sensor depth + clean normals; clean depth + sensor normals
};

// Geometry error of a G-buffer against the noise-free render of the same frame: the share of the
// rendered surface pixels it covers, the median and p90 angle between its normals and the rendered
// ones (pixels both have) and the median |depth difference| (m).
struct GeometryError {
  double coverage = 0, normal_deg_median = NAN, normal_deg_p90 = NAN, depth_m_median = NAN;
};

GeometryError CompareGeometry(const light::GeometryView& g, const light::GeometryView& clean) {
  GeometryError e;
  std::vector<double> angles, depths;
  size_t surface = 0, covered = 0;
  for (size_t i = 0; i < clean.depth.size(); i += 3) {
    if (clean.depth[i] <= 0) continue;
    ++surface;
    const float* n = &g.normals[3 * i];
    if (g.depth[i] <= 0 || (n[0] == 0 && n[1] == 0 && n[2] == 0)) continue;
    ++covered;
    const float* c = &clean.normals[3 * i];
    const double dot = n[0] * c[0] + n[1] * c[1] + n[2] * c[2];
    angles.push_back(std::acos(std::clamp(dot, -1.0, 1.0)) * 180 / std::numbers::pi);
    depths.push_back(std::abs(g.depth[i] - clean.depth[i]));
  }
  e.coverage = surface > 0 ? static_cast<double>(covered) / surface : 0;
  e.normal_deg_median = Quantile(angles, 0.5);
  e.normal_deg_p90 = Quantile(angles, 0.9);
  e.depth_m_median = Quantile(depths, 0.5);
  return e;
}

// The pipeline's input for a G-buffer (`g`: depth, normals, colour, and the image's grey and
// colour), stamp = the frame index.
light::SceneFrame GBufferFrame(const light::GeometryStorage& g, int64_t stamp,
                               const light::AuxiliaryBuffers* aux) {
  light::SceneFrame f;
  f.stamp_ns = stamp;
  f.width = g.width;
  f.height = g.height;
  f.intrinsics = g.intrinsics;
  f.grey = g.grey;
  f.colour = g.colour;
  f.gbuffer_depth = g.depth;
  f.gbuffer_normals = g.normals;
  f.gbuffer_colour = g.colour;
  f.aux = aux;
  return f;
}

// The sensor's images of a simulated frame as a camera delivers them: the depth16 in metres, the
// noisy rgb8 and its linear grey (the inputs of the node's depth mode).
struct SensorImages {
  int width = 0, height = 0;
  light::Intrinsics intrinsics;
  std::vector<float> depth;
  std::vector<uint8_t> colour;
  std::vector<float> grey;
};

SensorImages SensorImagesOf(const sim::SimFrame& frame) {
  SensorImages s;
  s.width = frame.render.width;
  s.height = frame.render.height;
  s.intrinsics = {frame.camera.fx, frame.camera.fy, frame.camera.cx, frame.camera.cy};
  s.depth.resize(static_cast<size_t>(s.width) * s.height);
  for (size_t i = 0; i < s.depth.size(); ++i) s.depth[i] = frame.depth_mm[i] * 0.001f;
  s.colour = frame.rgb;
  light::SrgbToLinearGrey(s.colour, &s.grey);
  return s;
}

light::SceneFrame DepthFrame(const SensorImages& s, int64_t stamp,
                             const light::AuxiliaryBuffers* aux) {
  light::SceneFrame f;
  f.stamp_ns = stamp;
  f.width = s.width;
  f.height = s.height;
  f.intrinsics = s.intrinsics;
  f.grey = s.grey;
  f.colour = s.colour;
  f.depth_image = s.depth;
  f.aux = aux;
  return f;
}

// Scores one pipeline result (of the frame `in`) against the ground truth.
Sample Score(const light::ScenePipeline& p, const light::ScenePipelineResult& r,
             const light::SceneFrame& in, const msgs::ShLight& truth, double time_s,
             const msgs::ShLight* camera_truth = nullptr,
             const std::vector<std::array<float, 3>>* true_lamps = nullptr) {
  Sample s;
  s.time_s = time_s;
  s.ms_transfer = r.timings.ms_transfer;
  s.cpu_ms_transfer = r.timings.cpu_ms_transfer;
  s.ms_estimate = r.timings.ms_estimate;
  s.cpu_ms_estimate = r.timings.cpu_ms_estimate;
  s.cpu_ms_point = r.timings.cpu_ms_point;
  s.cpu_ms_shadow = r.timings.cpu_ms_shadow;
  const light::LightEstimate& e = r.light;
  if (p.options().light_model != light::LightModel::kDistant) {
    // The point path ran (EstimateSceneLight): its model-selection figures.
    s.point_chosen = r.used == light::LightModel::kPoint;
    if (r.point.median_residual_distant > 0) {
      s.point_gain = 1 - r.point.median_residual_point / r.point.median_residual_distant;
    }
    s.spread_deg = r.point.spread_deg;
    s.screened_out = r.point.screened_out;
    s.warm_started = r.point.warm_started;
    s.screen_gain = r.point.screen_gain;
    s.screen_spread_deg = r.point.screen_spread_deg;
    if (s.point_chosen && !r.point.lamps.empty()) {
      s.lamp = r.point.lamps[0].position;
      if (true_lamps != nullptr) {
        s.true_lamps = *true_lamps;
        for (const auto& l : *true_lamps) {
          const double d = std::hypot(l[0] - s.lamp[0], l[1] - s.lamp[1], l[2] - s.lamp[2]);
          if (std::isnan(s.lamp_error_m) || d < s.lamp_error_m) s.lamp_error_m = d;
        }
      }
    }
  }
  s.estimate = e.coefficients;
  for (int n = 0; n < 9; ++n) {
    for (int c = 0; c < 3; ++c) s.truth[n * 3 + c] = truth.coefficients[n][c];
  }
  auto angle = [&](const float* d) {
    if (!e.valid || (d[0] == 0 && d[1] == 0 && d[2] == 0)) return NAN * 1.0;
    const double dot = e.dominant_direction[0] * d[0] + e.dominant_direction[1] * d[1] +
                       e.dominant_direction[2] * d[2];
    return std::acos(std::clamp(dot, -1.0, 1.0)) * 180 / std::numbers::pi;
  };
  s.dir_error_deg = angle(truth.dominant_direction);
  if (r.shadow_ran) {
    // On the search's own geometry and options (the raw depth with --fused-shadows raw).
    const light::ShadowEstimate& shadow = r.shadow;
    const light::GeometryView& sg = r.shadow_geometry;
    const light::ShadowOptions& so = r.shadow_options;
    const float* d = truth.dominant_direction;
    if (d[0] != 0 || d[1] != 0 || d[2] != 0) {
      const double dot =
          shadow.direction[0] * d[0] + shadow.direction[1] * d[1] + shadow.direction[2] * d[2];
      s.shadow_dir_error_deg = std::acos(std::clamp(dot, -1.0, 1.0)) * 180 / std::numbers::pi;
    }
    s.shadow_valid = shadow.valid;
    s.shadow_score = shadow.score;
    s.shadow_unshadowed = shadow.score_unshadowed;
    s.shadow_contrast = shadow.contrast;
    s.shadow_runner_up = shadow.runner_up;
    if (d[0] != 0 || d[1] != 0 || d[2] != 0) {
      s.shadow_truth_score = light::ShadowScore(sg, in.grey, so, in.colour, {d[0], d[1], d[2]});
      s.shadow_truth_mask =
          light::ShadowMaskAgreement(sg, in.grey, so, in.colour, {d[0], d[1], d[2]});
    }
    const light::Vec3f& sd = shadow.direction;
    if (sd[0] != 0 || sd[1] != 0 || sd[2] != 0) {
      s.shadow_mask = light::ShadowMaskAgreement(sg, in.grey, so, in.colour, sd);
    }
  }
  for (int k = 0; k < 3; ++k) {
    s.truth_dir[k] = truth.dominant_direction[k];
    if (e.valid) s.estimate_dir[k] = e.dominant_direction[k];
  }
  if (camera_truth != nullptr) s.dir_error_camera_deg = angle(camera_truth->dominant_direction);
  if (e.valid) {
    double num = 0, den = 0;
    for (int n = 0; n < 9 && n < static_cast<int>(e.coefficients.size()); ++n) {
      const double grey_truth =
          (truth.coefficients[n][0] + truth.coefficients[n][1] + truth.coefficients[n][2]) / 3;
      num += (e.coefficients[n] - grey_truth) * (e.coefficients[n] - grey_truth);
      den += grey_truth * grey_truth;
    }
    if (den > 0) s.sh_rel_error = std::sqrt(num / den);
  }
  return s;
}

constexpr int kMapWidth = 256, kMapHeight = 128;

std::vector<float> LatLongValues(const std::vector<float>& coefficients, int bands) {
  std::vector<float> out(kMapWidth * kMapHeight);
  sh::RenderLatLong(coefficients, bands, 1, kMapWidth, kMapHeight, out);
  return out;
}

// Colour-mapped lat-long map, 0 .. `max` -> black .. yellow (inferno).
cv::Mat LatLongImage(const std::vector<float>& values, float max) {
  cv::Mat img(kMapHeight, kMapWidth, CV_8UC1);
  for (int i = 0; i < kMapWidth * kMapHeight; ++i) {
    img.data[i] = static_cast<uint8_t>(std::clamp(values[i] / max * 255.0f, 0.0f, 255.0f));
  }
  cv::Mat colour;
  cv::applyColorMap(img, colour, cv::COLORMAP_INFERNO);
  return colour;
}

void WritePlots(const std::string& dir, const Series& full, const Series& fast) {
  std::filesystem::create_directories(dir);
  // Lat-long maps, truth over estimate, for up to 4 frames of the full variant.
  std::vector<cv::Mat> columns;
  const size_t n = full.samples.size();
  for (size_t k = 0; k < std::min<size_t>(4, n); ++k) {
    const Sample& s = full.samples[k * n / std::min<size_t>(4, n)];
    std::vector<float> truth(9), est;
    for (int i = 0; i < 9; ++i) {
      truth[i] = (s.truth[3 * i] + s.truth[3 * i + 1] + s.truth[3 * i + 2]) / 3;
    }
    for (double c : s.estimate) est.push_back(static_cast<float>(c));
    if (est.empty()) continue;
    const int bands = static_cast<int>(std::lround(std::sqrt(est.size())));
    const auto tv = LatLongValues(truth, 3), ev = LatLongValues(est, bands);
    const float max = std::max(1e-6f, *std::max_element(tv.begin(), tv.end()));
    cv::Mat a = LatLongImage(tv, max), b = LatLongImage(ev, max), col;
    cv::putText(a, "truth t=" + Num(s.time_s) + "s", {4, 14}, cv::FONT_HERSHEY_SIMPLEX, 0.4,
                {255, 255, 255});
    cv::putText(b, "estimate (full)", {4, 14}, cv::FONT_HERSHEY_SIMPLEX, 0.4, {255, 255, 255});
    cv::vconcat(a, b, col);
    columns.push_back(col);
  }
  if (!columns.empty()) {
    cv::Mat sheet;
    cv::hconcat(columns, sheet);
    cv::imwrite(dir + "/scene_light_latlong.png", sheet);
  }
  // Dominant-direction error over time.
  const int W = 640, H = 280, m = 40;
  cv::Mat plot(H, W, CV_8UC3, cv::Scalar(255, 255, 255));
  double t_max = 0;
  for (const auto& s : full.samples) t_max = std::max(t_max, s.time_s);
  if (t_max <= 0) t_max = 1;
  const double e_max = 60;
  cv::rectangle(plot, {m, 10}, {W - 10, H - m}, {0, 0, 0});
  for (double e = 0; e <= e_max; e += 10) {
    const int y = static_cast<int>(H - m - e / e_max * (H - m - 10));
    cv::line(plot, {m, y}, {W - 10, y}, {220, 220, 220});
    cv::putText(plot, Num(e), {4, y + 4}, cv::FONT_HERSHEY_SIMPLEX, 0.35, {0, 0, 0});
  }
  auto draw = [&](const Series& s, cv::Scalar colour) {
    cv::Point prev(-1, -1);
    for (const auto& x : s.samples) {
      if (std::isnan(x.dir_error_deg)) {
        prev = {-1, -1};
        continue;
      }
      const cv::Point p(
          static_cast<int>(m + x.time_s / t_max * (W - m - 10)),
          static_cast<int>(H - m - std::min(x.dir_error_deg, e_max) / e_max * (H - m - 10)));
      cv::circle(plot, p, 3, colour, cv::FILLED);
      if (prev.x >= 0) cv::line(plot, prev, p, colour);
      prev = p;
    }
  };
  draw(full, {200, 80, 0});
  draw(fast, {0, 120, 255});
  cv::putText(plot, "dominant direction error (deg) vs time (s); blue = full, orange = fast",
              {m, H - 12}, cv::FONT_HERSHEY_SIMPLEX, 0.4, {0, 0, 0});
  cv::imwrite(dir + "/scene_light_error.png", plot);

  // Estimated and true dominant direction over time: elevation (towards the camera's up, -y) and
  // azimuth (atan2(x, z), 0 = straight ahead) in the camera frame.
  const int PH = 200;
  cv::Mat dirs(2 * PH + 30, W, CV_8UC3, cv::Scalar(255, 255, 255));
  auto panel = [&](int top, const char* name, double lo, double hi, auto value) {
    cv::rectangle(dirs, {m, top + 5}, {W - 10, top + PH - 15}, {0, 0, 0});
    for (double a = lo; a <= hi; a += 45) {
      const int y = static_cast<int>(top + PH - 15 - (a - lo) / (hi - lo) * (PH - 20));
      cv::line(dirs, {m, y}, {W - 10, y}, {220, 220, 220});
      cv::putText(dirs, Num(a), {2, y + 4}, cv::FONT_HERSHEY_SIMPLEX, 0.35, {0, 0, 0});
    }
    cv::putText(dirs, name, {m + 4, top + 18}, cv::FONT_HERSHEY_SIMPLEX, 0.4, {0, 0, 0});
    auto draw_series = [&](const Series& series, bool truth, cv::Scalar colour) {
      for (const auto& x : series.samples) {
        const auto& d = truth ? x.truth_dir : x.estimate_dir;
        if (d[0] == 0 && d[1] == 0 && d[2] == 0) continue;
        const double v = std::clamp(value(d), lo, hi);
        const cv::Point p(static_cast<int>(m + x.time_s / t_max * (W - m - 10)),
                          static_cast<int>(top + PH - 15 - (v - lo) / (hi - lo) * (PH - 20)));
        if (truth) {
          cv::drawMarker(dirs, p, colour, cv::MARKER_CROSS, 10, 2);
        } else {
          cv::circle(dirs, p, 3, colour, cv::FILLED);
        }
      }
    };
    draw_series(full, true, {0, 0, 0});
    draw_series(full, false, {200, 80, 0});
    draw_series(fast, false, {0, 120, 255});
  };
  constexpr double kDeg = 180 / std::numbers::pi;
  panel(0, "elevation (deg)", -90, 90, [&](const std::array<float, 3>& d) {
    return std::asin(std::clamp(-d[1], -1.0f, 1.0f)) * kDeg;
  });
  panel(PH, "azimuth (deg)", -180, 180,
        [&](const std::array<float, 3>& d) { return std::atan2(d[0], d[2]) * kDeg; });
  cv::putText(dirs,
              "dominant direction vs time, camera frame: black + truth, blue full, orange fast",
              {m, 2 * PH + 20}, cv::FONT_HERSHEY_SIMPLEX, 0.4, {0, 0, 0});
  cv::imwrite(dir + "/scene_light_direction.png", dirs);

  // --light-model point|auto: the strongest estimated lamp (full blue, fast orange dots) and the
  // true enabled lamps (black +) over time, camera-frame x, y, z (m).
  bool any_lamp = false;
  for (const auto& x : full.samples) any_lamp = any_lamp || std::isfinite(x.lamp[0]);
  if (!any_lamp) return;
  const int LH = 160;
  cv::Mat lamps(3 * LH + 30, W, CV_8UC3, cv::Scalar(255, 255, 255));
  const char* axes[3] = {"lamp x (m, right)", "lamp y (m, down)", "lamp z (m, forward)"};
  const double lo[3] = {-3, -3, 0}, hi[3] = {3, 1, 5};
  for (int a = 0; a < 3; ++a) {
    const int top = a * LH;
    auto to_y = [&](double v) {
      return static_cast<int>(top + LH - 15 -
                              (std::clamp(v, lo[a], hi[a]) - lo[a]) / (hi[a] - lo[a]) * (LH - 20));
    };
    cv::rectangle(lamps, {m, top + 5}, {W - 10, top + LH - 15}, {0, 0, 0});
    for (double v = lo[a]; v <= hi[a]; v += 1) {
      cv::line(lamps, {m, to_y(v)}, {W - 10, to_y(v)}, {220, 220, 220});
      cv::putText(lamps, Num(v), {2, to_y(v) + 4}, cv::FONT_HERSHEY_SIMPLEX, 0.35, {0, 0, 0});
    }
    cv::putText(lamps, axes[a], {m + 4, top + 18}, cv::FONT_HERSHEY_SIMPLEX, 0.4, {0, 0, 0});
    auto x_of = [&](double t) { return static_cast<int>(m + t / t_max * (W - m - 10)); };
    for (const auto& x : full.samples) {
      for (const auto& l : x.true_lamps) {
        cv::drawMarker(lamps, {x_of(x.time_s), to_y(l[a])}, {0, 0, 0}, cv::MARKER_CROSS, 10, 2);
      }
    }
    for (const auto* series : {&full, &fast}) {
      for (const auto& x : series->samples) {
        if (!std::isfinite(x.lamp[a])) continue;
        cv::circle(lamps, {x_of(x.time_s), to_y(x.lamp[a])}, 3,
                   series == &full ? cv::Scalar(200, 80, 0) : cv::Scalar(0, 120, 255), cv::FILLED);
      }
    }
  }
  cv::putText(lamps, "strongest estimated lamp (blue full, orange fast) and true lamps (black +)",
              {m, 3 * LH + 20}, cv::FONT_HERSHEY_SIMPLEX, 0.4, {0, 0, 0});
  cv::imwrite(dir + "/scene_light_lamps.png", lamps);
}

constexpr const char* kDescription =
    "evaluates probeless_light's full (Ours) and fast (OursFast) variants through\n"
    "light::ScenePipeline on simulated scenes (--sim) or a log (--log); --json OUT is required.\n"
    "Every option in detail: the comment at the top of tools/scene_light_eval/main.cpp;\n"
    "docs/light.md.";

int Run(int argc, char** argv) {
  Options o;
  node::FlagParser flags("scene_light_eval", kDescription);
  // Input and output.
  flags.Add("--sim", &o.sim, "SCENARIO.yaml", "render N frames of this scenario in-process");
  flags.Add("--log", &o.log, "FILE.mcap", "sensor data and /groundtruth/light from a log instead");
  flags.Add("--json", &o.json, "OUT", "the figures (required)");
  flags.Add("--plots", &o.plots, "DIR", "lat-long maps and error / direction plots (PNG)");
  flags.Add("--frames", &o.frames, "N", "frames spread evenly over the scenario");
  flags.Add("--directions", &o.directions, "N", "SSDO directions (TransferOptions)");
  flags.Add("--seed", &o.seed, "S", "TransferOptions::seed (the SSDO jitter)");
  flags.Add("--bands", &o.bands, "B", "SH bands");
  flags.Add("--threads", &o.threads, "T", "worker threads");
  // Auxiliary views.
  flags.Add("--aux", &o.aux, "add left/right/top orthographic views traced from the scene");
  flags.AddCallback(
      "--aux-roles", "STR", "keep the traced views whose letter (l, r, t) is in STR; implies --aux",
      [&](const std::string& v) {
        o.aux = true;
        o.aux_roles = v;
      },
      o.aux_roles);
  flags.AddSwitch(
      "--aux-top-camera", [&] { o.aux = o.aux_top_camera = true; },
      "the top view along the camera's +y; implies --aux");
  flags.AddCallback(
      "--aux-resolution", "N", "traced views' pixels per side (1..4096); implies --aux",
      [&](const std::string& v) {
        o.aux = true;
        o.aux_resolution = parse::ParseInteger<int>("--aux-resolution", v);
      },
      std::to_string(o.aux_resolution));
  flags.AddCallback(
      "--aux-standoff", "M", "traced views' standoff (extent 2 M + 1.6 m); implies --aux",
      [&](const std::string& v) {
        o.aux = true;
        o.aux_standoff = static_cast<float>(node::ParseNumberOption("--aux-standoff", v));
      });
  // Truth, albedo, transfer.
  flags.Add("--camera-truth", &o.camera_truth, "score against the light at the camera");
  flags.Add("--grey-world", &o.grey_world, "one uniform albedo (no chromaticity groups)");
  flags.AddCallback(
      "--fused-shadows", "raw|gr",
      "the fused input's shadow search on the raw depth (the node's) or on G_r",
      [&](const std::string& v) {
        if (v != "raw" && v != "gr") throw node::UsageError("--fused-shadows must be raw or gr");
        o.fused_shadows_raw = v == "raw";
      },
      "raw");
  flags.Add("--invariant-albedo", &o.invariant_albedo, "EstimateOptions::albedo_invariant");
  flags.Add("--albedo-groups", &o.albedo_groups, "N",
            "chromaticity cells per axis (-1: the default, 32)");
  flags.Add("--quadrature", &o.quadrature, "eq. 6 as printed (no analytic unoccluded transfer)");
  // Fusion.
  flags.Add("--fused", &o.fused,
            "also run on fusion's G_r (in-process FusionPipeline; needs --sim)");
  flags.AddSwitch(
      "--fused-known-pose", [&] { o.fused = o.fused_known_pose = true; },
      "--fused with the simulator's pose");
  // Normals and temporal fit.
  flags.Add("--normal-filter", &o.normal_filter,
            "light::FilterNormals on sensor and fused G-buffers");
  flags.Add("--filter-radius", &o.filter.radius, "R", "NormalFilterOptions::radius");
  flags.Add("--filter-angle", &o.filter.max_neighbour_angle_deg, "DEG",
            "NormalFilterOptions::max_neighbour_angle_deg");
  flags.Add("--filter-view", &o.filter.max_view_angle_deg, "DEG",
            "NormalFilterOptions::max_view_angle_deg");
  flags.Add("--filter-jump", &o.filter.max_plane_distance_rel, "REL",
            "NormalFilterOptions::max_plane_distance_rel");
  flags.Add("--smooth-radius", &o.smooth_radius, "R",
            "sensor depth smoothing (-1: DepthGeometry's)");
  flags.Add("--normal-step", &o.normal_step, "S",
            "normal step of the sensor depth (-1: DepthGeometry's)");
  flags.AddSwitch(
      "--fused-volume", [&] { o.fused = o.fused_volume = true; },
      "--fused on G_v (the TSDF raycast) instead of G_r");
  flags.Add("--fused-normal-step", &o.fused_normal_step, "S",
            "normals from G_r's depth (0: fusion's)");
  flags.Add("--temporal", &o.temporal, "N", "TemporalLightEstimator over N consecutive frames");
  flags.Add("--forgetting", &o.forgetting, "F", "the temporal estimator's forgetting factor");
  flags.Add("--no-balance", &o.no_balance, "no normal-orientation balancing (ablation)");
  flags.AddCallback(
      "--prior-weight", "W", "the light prior's weight (0 = off; -1: the node's)",
      [&](const std::string& v) {
        o.prior_weight = node::ParseNumberOption("--prior-weight", v);
        if (!(o.prior_weight >= 0)) throw node::UsageError("--prior-weight must be >= 0");
      },
      "-1");
  flags.AddSwitch(
      "--no-shadows-override-prior", [&] { o.shadows_override_prior = false; },
      "ScenePipelineOptions::shadows_override_prior false");
  flags.Add("--mix", &o.mix, "score hybrids of clean and sensor inputs");
  // Light model and point lamps.
  flags.AddCallback(
      "--light-model", "distant|point|auto",
      "light::EstimateSceneLight's model (--temporal implies distant)",
      [&](const std::string& v) {
        try {
          o.light_model = light::ParseLightModel(v);
          o.light_model_set = true;
        } catch (const light::LightError&) {
          throw node::UsageError("--light-model must be distant, point or auto, got '" + v + "'");
        }
      },
      "auto");
  // Cast shadows.
  flags.AddSwitch(
      "--no-shadows", [&] { o.shadows = false; }, "no cast-shadow refinement");
  flags.AddSwitch(
      "--shadows", [&] { o.shadows = true; }, "cast-shadow refinement (the default)");
  flags.Add("--fast-shadows", &o.fast_shadows, "the shadow search for OursFast too");
  flags.Add("--shadow-stride", &o.shadow.stride, "N", "ShadowOptions::stride");
  flags.Add("--shadow-directions", &o.shadow.coarse_directions, "N",
            "ShadowOptions::coarse_directions");
  flags.Add("--shadow-min-score", &o.shadow.min_score, "X", "ShadowOptions::min_score");
  flags.Add("--shadow-min-gain", &o.shadow.min_gain, "X", "ShadowOptions::min_gain");
  flags.Add("--shadow-keep", &o.shadow.keep_ratio, "X", "ShadowOptions::keep_ratio");
  flags.Add("--shadow-cue-keep", &o.shadow.cue_keep_ratio, "X", "ShadowOptions::cue_keep_ratio");
  flags.Add("--shadow-min-contrast", &o.shadow.min_contrast, "X", "ShadowOptions::min_contrast");
  flags.AddSwitch(
      "--shadow-behind-lit", [&] { o.shadow.unknown_behind = false; },
      "ShadowOptions::unknown_behind false");
  flags.Add("--shadow-steps", &o.shadow.march_steps, "N", "ShadowOptions::march_steps");
  flags.Add("--shadow-thickness-steps", &o.shadow.thickness_steps, "X",
            "ShadowOptions::thickness_steps");
  flags.Add("--shadow-candidates", &o.shadow.candidates, "N", "ShadowOptions::candidates");
  flags.Add("--shadow-coarse-stride", &o.shadow.coarse_stride, "N", "ShadowOptions::coarse_stride");
  flags.Add("--shadow-max-runner-up", &o.shadow.max_runner_up, "X", "ShadowOptions::max_runner_up");
  flags.Add("--shadow-bias", &o.shadow.depth_bias_m, "M", "ShadowOptions::depth_bias_m");
  flags.Add("--shadow-bias-rel", &o.shadow.depth_bias_rel, "X", "ShadowOptions::depth_bias_rel");
  flags.Add("--shadow-thickness", &o.shadow.thickness_m, "M", "ShadowOptions::thickness_m");
  flags.AddCallback(
      "--shadow-cues", "depth|all|none",
      "the image cues of the search: raw sensor depth (the node), all inputs, none",
      [&](const std::string& v) {
        o.shadow_cues = v;
        if (o.shadow_cues != "depth" && o.shadow_cues != "all" && o.shadow_cues != "none") {
          throw node::UsageError("--shadow-cues must be depth, all or none, got '" + o.shadow_cues +
                                 "'");
        }
      },
      o.shadow_cues);
  flags.Add("--shadow-dark-ratio", &o.shadow.mask_dark_ratio, "X",
            "ShadowOptions::mask_dark_ratio");
  flags.Add("--shadow-dark-weight", &o.shadow.unexplained_dark_weight, "X",
            "ShadowOptions::unexplained_dark_weight");
  flags.Add("--shadow-boundary-ref", &o.shadow.boundary_ref, "X", "ShadowOptions::boundary_ref");
  flags.Add("--shadow-boundary-ratio", &o.shadow.boundary_ratio, "X",
            "ShadowOptions::boundary_ratio");
  flags.Add("--shadow-chroma", &o.shadow.chroma_cells, "N", "ShadowOptions::chroma_cells");
  flags.Add("--lamps", &o.lamps, "K", "point lamps (1 or 2)");
  flags.Add("--point-rows", &o.point_rows, "N", "PointLightOptions::max_rows (0 = its default)");
  // Depth-mode geometry.
  flags.AddSwitch(
      "--legacy-normals", [&] { o.depth_geometry.normals_from = light::DepthNormals::kCentral; },
      "always round 2's normals");
  flags.AddSwitch(
      "--edge-normals", [&] { o.depth_geometry.normals_from = light::DepthNormals::kEdge; },
      "always the edge-aware normals");
  flags.Add("--edge-noise-quad", &o.depth_geometry.normals.noise_quadratic, "Q",
            "DepthNormalOptions::noise_quadratic");
  flags.Add("--edge-threshold", &o.depth_geometry.normals.threshold_sigma, "T",
            "DepthNormalOptions::threshold_sigma");
  flags.Add("--edge-radius", &o.depth_geometry.normals.min_radius_m, "M",
            "DepthNormalOptions::min_radius_m");
  flags.Add("--edge-view", &o.depth_geometry.normals.max_view_angle_deg, "DEG",
            "DepthNormalOptions::max_view_angle_deg");
  flags.Add("--reliability", &o.reliability,
            "the normals' reliability as the estimator's row weights");
  flags.AddSwitch(
      "--no-screen", [&] { o.point_screen = false; }, "PointLightOptions::screen_rows 0");
  flags.AddSwitch(
      "--cold", [&] { o.point_warm = false; }, "ScenePipelineOptions::point_warm_start false");
  flags.Add("--screen-rows", &o.screen_rows, "N", "PointLightOptions::screen_rows (-1 = default)");
  flags.Add("--screen-lm", &o.screen_lm, "N",
            "PointLightOptions::screen_lm_iterations (-1 = default)");
  flags.Add("--warm-lm", &o.warm_lm, "N", "PointLightOptions::warm_lm_iterations (-1 = default)");
  // Fusion configuration (defaults: launch/demo_scene.yaml's fusion node).
  flags.Add("--fused-size", &o.fused_size, "M", "volume side (m)");
  flags.Add("--fused-resolution", &o.fused_resolution, "N", "voxels per side");
  flags.Add("--fused-truncation", &o.fused_truncation, "M", "TSDF truncation (m)");
  flags.Add("--fused-normal-gap", &o.fused_normal_gap, "M", "FusionOptions normal gap (m)");
  flags.Add("--fused-gradient-step", &o.fused_gradient_step, "V",
            "FusionOptions gradient step (voxels)");
  flags.AddCallback(
      "--fused-origin", "X,Y,Z", "volume corner (m, the first camera's frame)",
      [&](const std::string& v) {
        const std::vector<double> xyz = parse::ParseDoubleList("--fused-origin", v, 3, 3);
        for (int k = 0; k < 3; ++k) o.fused_origin[k] = static_cast<float>(xyz[k]);
      },
      "-3,-3,0.3");
  flags.AddCallback(
      "--fused-normals", "depth|volume", "FusionOptions::normal_source",
      [&](const std::string& v) {
        if (v != "depth" && v != "volume") {
          throw node::UsageError("--fused-normals must be depth or volume, got '" + v + "'");
        }
        o.fused_volume_normals = v == "volume";
      },
      "depth");
  flags.Add("--fused-step", &o.fused_step, "S", "integrate every S-th frame");
  if (!flags.Parse(argc, argv)) return 0;
  if (o.json.empty()) throw node::UsageError("--json OUT is required");
  if (o.frames < 1) throw node::UsageError("--frames must be >= 1");
  if (o.fused_step < 1) throw node::UsageError("--fused-step must be >= 1");
  if (o.aux_resolution < 1 || o.aux_resolution > 4096) {
    throw node::UsageError("--aux-resolution must be in 1..4096");
  }
  if (o.fused && !o.log.empty()) throw node::UsageError("--fused needs --sim");
  if (o.lamps < 1 || o.lamps > 2) throw node::UsageError("--lamps must be 1 or 2");
  if (o.light_model != light::LightModel::kDistant && o.temporal > 1) {
    if (o.light_model_set) throw node::UsageError("--temporal needs --light-model distant");
    o.light_model = light::LightModel::kDistant;  // the accumulator is a distant-light fit
  }
  if (o.light_model != light::LightModel::kDistant && o.reliability) {
    if (o.light_model_set) throw node::UsageError("--reliability needs --light-model distant");
    o.light_model = light::LightModel::kDistant;  // the row weights are EstimateLight's
  }
  light::EstimateOptions eo =
      light::ScenePipelineOptions{}.estimate;  // the node's (light prior on)
  if (o.grey_world) eo.albedo_groups = 0;
  eo.albedo_invariant = o.invariant_albedo;
  if (o.albedo_groups >= 0) eo.albedo_groups = o.albedo_groups;
  if (o.no_balance) eo.balance_normals = false;
  if (o.prior_weight >= 0) eo.prior.weight = o.prior_weight;
  light::DepthGeometryOptions dgo = o.depth_geometry;
  dgo.smooth_radius = o.smooth_radius;
  dgo.step = o.normal_step;
  // Every variant and input runs light::ScenePipeline, the node's object; what differs between
  // them are options the node has too (docs/light.md "Scene pipeline").
  light::ScenePipelineOptions base;
  base.transfer.directions = o.directions;
  base.transfer.bands = o.bands;
  base.transfer.threads = o.threads;
  base.transfer.seed = o.seed;
  base.transfer.analytic_unoccluded = !o.quadrature;
  base.estimate = eo;
  base.depth_geometry = dgo;
  base.filter = o.filter;
  base.temporal.frames = o.temporal;
  base.temporal.forgetting = o.forgetting;
  base.light_model = o.light_model;
  base.point.max_lamps = o.lamps;
  if (o.point_rows > 0) base.point.max_rows = o.point_rows;
  if (o.screen_rows >= 0) base.point.screen_rows = o.screen_rows;
  if (o.screen_lm > 0) base.point.screen_lm_iterations = o.screen_lm;
  if (o.warm_lm > 0) base.point.warm_lm_iterations = o.warm_lm;
  if (!o.point_screen) base.point.screen_rows = 0;
  base.point_warm_start = o.point_warm;
  base.shadows_override_prior = o.shadows_override_prior;
  base.shadow = o.shadow;
  base.shadow.threads = o.threads;
  // --shadow-cues: `all` also on G-buffers (the clean render, fused G_r), `none` not even on depth.
  base.shadow.image_cues = o.shadow_cues == "all";
  base.depth_image_cues = o.shadow_cues != "none";
  Variant full, fast;
  for (Variant* v : {&full, &fast}) {
    light::ScenePipelineOptions vo = base;
    if (v == &fast) vo.transfer.subsample = 4;
    // OursFast keeps its 15 ms budget: shadows only with --fast-shadows (as the node's default).
    vo.shadow.enabled = o.shadows && (v == &full || o.fast_shadows);
    // Clean: the rendered G-buffer as it is (its normals exact; no filter, no reliability).
    light::ScenePipelineOptions clean = vo;
    clean.shadow_geometry = light::ShadowGeometry::kGeometryBuffer;
    v->clean_pipeline.emplace(clean);
    // Sensor: the node's depth mode on the sensor's depth image.
    light::ScenePipelineOptions sensor = vo;
    sensor.source = light::SceneGeometrySource::kDepthImage;
    sensor.normal_filter = o.normal_filter;
    sensor.reliability_weights = o.reliability;
    v->sensor_pipeline.emplace(sensor);
    // Fused: the node's gbuffer mode on fusion's G_r (--fused-normal-step: normals recomputed
    // from its depth, edge-aware unless --legacy-normals), the shadow search on the frame's own
    // depth image (--fused-shadows raw, the node's shadow_depth default) or on G_r.
    light::ScenePipelineOptions fused = vo;
    if (o.fused_normal_step > 0) {
      fused.gbuffer_normals = o.depth_geometry.normals_from != light::DepthNormals::kCentral
                                  ? light::GBufferNormals::kEdge
                                  : light::GBufferNormals::kCentral;
      fused.gbuffer_normal_step = o.fused_normal_step;
      fused.gbuffer_smooth_radius = std::max(0, o.smooth_radius);
    }
    fused.normal_filter = o.normal_filter;
    fused.reliability_weights = o.reliability;
    fused.shadow_geometry = o.fused_shadows_raw ? light::ShadowGeometry::kDepthImage
                                                : light::ShadowGeometry::kGeometryBuffer;
    v->fused_pipeline.emplace(fused);
    // --mix: given G-buffers, no state carried between them.
    light::ScenePipelineOptions mix = clean;
    mix.temporal.frames = 1;
    mix.point_warm_start = false;
    v->mix_pipeline.emplace(mix);
  }
  std::vector<GeometryError> sensor_geometry, fused_geometry;  // per evaluated frame (--sim)
  std::vector<double> fused_aux_ms;    // --aux --fused: wall ms of the 3 orthographic raycasts
  std::vector<double> measured_noise;  // DepthGeometry's measured noise k per evaluated frame
  const auto start = Clock::now();
  std::string source_name;
  if (o.log.empty()) {
    std::string path = o.sim;
    if (!std::filesystem::exists(path)) path = std::string(PROBELESS_SOURCE_TREE) + "/" + o.sim;
    source_name = o.sim;
    sim::Simulator simulator(sim::LoadScenario(path), o.threads);
    const uint64_t total = simulator.scenario().frames;
    const int count = static_cast<int>(std::min<uint64_t>(o.frames, total));
    // --fused: every fused_step-th frame up to the last evaluated one goes through the
    // reconstruction as in the fusion node of launch/demo_scene.yaml (depth in metres, grey
    // guidance, ICP or the known pose; 6 m volume at (-3, -3, 0.3), mu 0.08 m, depth <= 6 m); each
    // evaluated frame is integrated too and then also runs on G_r (the merged depth and normals).
    std::optional<recon::FusionPipeline> fusion;
    recon::FrameResult last_fusion;
    uint64_t next_fused = 0;
    recon::Pose first_pose_inverse;
    if (o.fused) {
      recon::FusionOptions fo;
      fo.volume.size_m = o.fused_size;
      fo.volume.origin = {o.fused_origin[0], o.fused_origin[1], o.fused_origin[2]};
      fo.volume.resolution = o.fused_resolution;
      fo.volume.truncation_m = o.fused_truncation;
      fo.normal_source =
          o.fused_volume_normals ? recon::NormalSource::kVolume : recon::NormalSource::kDepth;
      fo.volume_normal_max_gap_m = o.fused_normal_gap;
      fo.volume_normal_step_voxels = o.fused_gradient_step;
      fo.preprocess.depth_max_m = 6.0f;
      fo.threads = o.threads;
      fusion.emplace(fo);
    }
    auto to_recon_pose = [](const raytrace::Transform& t) {
      recon::Pose p;
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) p.r[r * 3 + c] = t.rotation.m[r][c];
        p.t[r] = t.translation[r];
      }
      return p;
    };
    auto integrate = [&](const sim::SimFrame& f) {
      const int w = f.render.width, h = f.render.height;
      recon::DepthImage depth;
      depth.Resize(w, h);
      for (size_t i = 0; i < depth.data.size(); ++i) {
        const float z = f.depth_mm[i] * 0.001f;
        depth.data[i] = z >= 0.3f && z <= 6.0f ? z : 0.0f;
      }
      recon::GreyImage grey;
      grey.Resize(w, h);
      for (size_t i = 0; i < grey.data.size(); ++i) {
        grey.data[i] = static_cast<uint8_t>(
            (f.rgb[3 * i] * 299 + f.rgb[3 * i + 1] * 587 + f.rgb[3 * i + 2] * 114) / 1000);
      }
      const recon::Intrinsics k{w,
                                h,
                                static_cast<float>(f.camera.fx),
                                static_cast<float>(f.camera.fy),
                                static_cast<float>(f.camera.cx),
                                static_cast<float>(f.camera.cy)};
      const recon::Pose c2w = to_recon_pose(f.camera.camera_to_world);
      if (f.index == 0) first_pose_inverse = c2w.Inverse();
      const recon::Pose known = first_pose_inverse * c2w;
      last_fusion = fusion->Process(depth, k, &grey, o.fused_known_pose ? &known : nullptr);
      if (last_fusion.state == recon::TrackingState::kLost && !last_fusion.icp.failure.empty()) {
        std::fprintf(stderr, "fusion lost at frame %llu: %s\n",
                     static_cast<unsigned long long>(f.index), last_fusion.icp.failure.c_str());
      }
    };
    // Mix inputs only (--mix): the sensor's G-buffer as the node's depth mode makes it.
    auto sensor_geometry_of = [&](const sim::SimFrame& frame) {
      light::GeometryStorage g = light::GeometryFromSimFrame(frame, true, dgo);
      if (o.normal_filter) {
        light::FilterNormals(g.depth, g.width, g.height, g.intrinsics, o.filter, g.normals);
      }
      g.reliability.clear();
      return g;
    };
    // G_r of the last integrated frame as scene_light receives it in gbuffer mode: the merged
    // depth and its normals (or G_v with --fused-volume), with the camera image's grey and
    // colour; the pipeline recomputes, filters and weighs its normals as the node does.
    auto fused_input_of = [&](const SensorImages& sensor) {
      light::GeometryStorage g;
      g.width = sensor.width;
      g.height = sensor.height;
      g.intrinsics = sensor.intrinsics;
      g.colour = sensor.colour;
      g.grey = sensor.grey;
      const auto& d = fusion->merged().denoised;
      const auto& n = fusion->merged_normals();
      g.depth.assign(d.data.begin(), d.data.end());
      g.normals.resize(3 * n.data.size());
      for (size_t i = 0; i < n.data.size(); ++i) {
        g.normals[3 * i] = n.data[i].x;
        g.normals[3 * i + 1] = n.data[i].y;
        g.normals[3 * i + 2] = n.data[i].z;
      }
      if (o.fused_volume) {
        // G_v: the volume raycast at the tracking level (nearest-upsampled to the input size).
        const auto& vv = fusion->volume_view();
        const int sx = std::max(1, g.width / std::max(1, vv.normals.width));
        for (int y = 0; y < g.height; ++y) {
          for (int x = 0; x < g.width; ++x) {
            const size_t p = static_cast<size_t>(y) * g.width + x;
            const int lx = std::min(vv.normals.width - 1, x / sx),
                      ly = std::min(vv.normals.height - 1, y / sx);
            const auto nv = vv.normals.At(lx, ly);
            const float z = vv.depth.At(lx, ly);
            g.depth[p] = z;
            g.normals[3 * p] = z > 0 ? nv.x : 0;
            g.normals[3 * p + 1] = z > 0 ? nv.y : 0;
            g.normals[3 * p + 2] = z > 0 ? nv.z : 0;
          }
        }
      }
      return g;
    };
    auto pose_of = [](const sim::SimFrame& frame) {
      const raytrace::Mat3& r = frame.camera.camera_to_world.rotation;
      std::array<double, 9> m;
      for (int a = 0; a < 3; ++a) {
        for (int b = 0; b < 3; ++b) m[a * 3 + b] = r.m[a][b];
      }
      return m;
    };
    // --temporal: a frame that does not follow the previous one starts the accumulators afresh
    // (the pipelines rotate the history by the simulator's camera rotation between frames).
    int64_t last_fed = -2;
    auto advance = [&](const sim::SimFrame& frame) {
      if (static_cast<int64_t>(frame.index) != last_fed + 1) {
        for (Variant* v : {&full, &fast}) {
          v->clean_pipeline->Reset();
          v->sensor_pipeline->Reset();
          v->fused_pipeline->Reset();
        }
      }
      last_fed = static_cast<int64_t>(frame.index);
    };
    // Feeds a frame before an evaluated one to the accumulators (not scored; no auxiliary views).
    auto feed = [&](const sim::SimFrame& frame) {
      advance(frame);
      const int64_t stamp = static_cast<int64_t>(frame.index);
      const light::GeometryStorage clean = light::GeometryFromSimFrame(frame, false);
      const SensorImages sensor = SensorImagesOf(frame);
      std::optional<light::GeometryStorage> fused;
      if (fusion) fused = fused_input_of(sensor);
      for (Variant* v : {&full, &fast}) {
        light::SceneFrame in = GBufferFrame(clean, stamp, nullptr);
        in.camera_to_world_rotation = pose_of(frame);
        v->clean_pipeline->Process(in);
        in = DepthFrame(sensor, stamp, nullptr);
        in.camera_to_world_rotation = pose_of(frame);
        v->sensor_pipeline->Process(in);
        if (fused) {
          in = GBufferFrame(*fused, stamp, nullptr);
          in.depth_image = sensor.depth;
          in.camera_to_world_rotation = pose_of(frame);
          v->fused_pipeline->Process(in);
        }
      }
    };
    int fused_lost = 0;
    for (int k = 0; k < count; ++k) {
      const uint64_t index = static_cast<uint64_t>(k) * total / count;
      if (fusion) {
        for (; next_fused < index; next_fused += o.fused_step) {
          const sim::SimFrame fr = simulator.Render(next_fused);
          integrate(fr);
          if (last_fusion.state == recon::TrackingState::kLost) ++fused_lost;
          if (o.temporal > 1 && next_fused + o.temporal > index) feed(fr);
        }
      } else if (o.temporal > 1) {
        const uint64_t first =
            index >= static_cast<uint64_t>(o.temporal - 1) ? index - o.temporal + 1 : 0;
        for (uint64_t j = first; j < index; ++j) feed(simulator.Render(j));
      }
      const sim::SimFrame f = simulator.Render(index);
      if (o.temporal > 1) advance(f);
      const int64_t stamp = static_cast<int64_t>(index);
      if (fusion) {
        integrate(f);
        if (last_fusion.state == recon::TrackingState::kLost) ++fused_lost;
        if (next_fused == index) next_fused += o.fused_step;
      }
      auto to_msg = [](const raytrace::LightingGroundTruth& l) {
        msgs::ShLight m;
        for (int n = 0; n < 9; ++n) {
          m.coefficients[n][0] = l.sh[n].x;
          m.coefficients[n][1] = l.sh[n].y;
          m.coefficients[n][2] = l.sh[n].z;
        }
        m.dominant_direction[0] = l.dominant_direction.x;
        m.dominant_direction[1] = l.dominant_direction.y;
        m.dominant_direction[2] = l.dominant_direction.z;
        return m;
      };
      const msgs::ShLight camera_truth = to_msg(f.light);
      // The enabled point lamps in the camera frame (lamp position error).
      std::vector<std::array<float, 3>> true_lamps;
      {
        const raytrace::Transform& c2w = f.camera.camera_to_world;
        const raytrace::Mat3 w2c = c2w.rotation.Transposed();
        for (const auto& l : simulator.scene().point_lights()) {
          if (!l.enabled) continue;
          const raytrace::Vec3 d =
              w2c * (l.position - raytrace::Vec3{static_cast<float>(c2w.translation[0]),
                                                 static_cast<float>(c2w.translation[1]),
                                                 static_cast<float>(c2w.translation[2])});
          true_lamps.push_back({d.x, d.y, d.z});
        }
      }
      const msgs::ShLight truth =
          o.camera_truth ? camera_truth : to_msg(light::SurfaceLightingTruth(simulator.scene(), f));
      light::AuxiliaryStorage aux;
      if (o.aux) {
        light::AuxiliaryViewOptions ao;
        ao.top_along_camera_y = o.aux_top_camera;
        ao.resolution = o.aux_resolution;
        if (o.aux_standoff > 0) {
          ao.standoff_m = o.aux_standoff;
          ao.extent_m = 2 * o.aux_standoff + 1.6f;
        }
        aux = light::RenderAuxiliaryViews(simulator.scene(), f.camera, ao);
        std::erase_if(aux.buffers.views, [&](const light::OrthographicView& v) {
          const char c = v.role == light::AuxiliaryRole::kLeft    ? 'l'
                         : v.role == light::AuxiliaryRole::kRight ? 'r'
                                                                  : 't';
          return o.aux_roles.find(c) == std::string::npos;
        });
      }
      const light::GeometryStorage clean_g = light::GeometryFromSimFrame(f, false);
      if (o.mix) {
        const light::GeometryStorage noisy_g = sensor_geometry_of(f);
        light::GeometryStorage m0 = clean_g, m1 = noisy_g, m2 = clean_g;
        m0.grey = noisy_g.grey;
        m0.colour = noisy_g.colour;
        m1.grey = clean_g.grey;
        m1.colour = clean_g.colour;
        for (size_t i = 0; i < m2.depth.size(); ++i) {
          if (noisy_g.depth[i] <= 0) {
            m2.depth[i] = 0;
            m2.normals[3 * i] = m2.normals[3 * i + 1] = m2.normals[3 * i + 2] = 0;
          }
        }
        light::GeometryStorage m3 = noisy_g, m4 = noisy_g;
        m3.grey = m4.grey = clean_g.grey;
        m3.colour = m4.colour = clean_g.colour;
        for (size_t i = 0; i < m3.depth.size(); ++i) {
          if (noisy_g.depth[i] <= 0 || clean_g.depth[i] <= 0) continue;
          for (int c = 0; c < 3; ++c) m3.normals[3 * i + c] = clean_g.normals[3 * i + c];
          m4.depth[i] = clean_g.depth[i];
        }
        // Oracles: the sensor's normals only where within 5 degrees of the clean ones; the
        // clean normals only where the sensor's normals are kept (the same pixels).
        light::GeometryStorage m5 = m1, m6 = m1;
        for (size_t i = 0; i < m5.depth.size(); ++i) {
          const float* a = &noisy_g.normals[3 * i];
          const float* c = &clean_g.normals[3 * i];
          const bool keep = a[0] * c[0] + a[1] * c[1] + a[2] * c[2] > std::cos(5 * 3.14159f / 180);
          for (int q = 0; q < 3; ++q) {
            if (!keep) m5.normals[3 * i + q] = 0;
            m6.normals[3 * i + q] = keep ? c[q] : 0;
          }
        }
        const light::GeometryStorage* ms[7] = {&m0, &m1, &m2, &m3, &m4, &m5, &m6};
        for (int j = 0; j < 7; ++j) {
          for (Variant* v : {&full, &fast}) {
            const light::SceneFrame in = GBufferFrame(*ms[j], stamp, &aux.buffers);
            v->mix[j].samples.push_back(Score(*v->mix_pipeline, v->mix_pipeline->Process(in), in,
                                              truth, f.time_s, &camera_truth));
          }
        }
      }
      const SensorImages sensor = SensorImagesOf(f);
      for (Variant* v : {&full, &fast}) {
        light::SceneFrame in = GBufferFrame(clean_g, stamp, &aux.buffers);
        in.camera_to_world_rotation = pose_of(f);
        v->clean.samples.push_back(Score(*v->clean_pipeline, v->clean_pipeline->Process(in), in,
                                         truth, f.time_s, &camera_truth, &true_lamps));
      }
      for (Variant* v : {&full, &fast}) {
        light::SceneFrame in = DepthFrame(sensor, stamp, &aux.buffers);
        in.camera_to_world_rotation = pose_of(f);
        const light::ScenePipelineResult& r = v->sensor_pipeline->Process(in);
        v->noisy.samples.push_back(
            Score(*v->sensor_pipeline, r, in, truth, f.time_s, &camera_truth, &true_lamps));
        if (v == &full) {
          // The G-buffer the node's depth mode made of the sensor depth (both variants make the
          // same).
          sensor_geometry.push_back(CompareGeometry(r.geometry, clean_g.View()));
          measured_noise.push_back(r.measured_noise_quadratic);
        }
      }
      if (fusion) {
        const light::GeometryStorage g = fused_input_of(sensor);
        // --aux: the reconstruction's own views, through the bus message (fusion publish_aux ->
        // scene_light use_aux); none for a lost frame, as in the node.
        light::AuxiliaryBuffers fused_aux;
        std::unique_ptr<std::byte, decltype(&std::free)> aux_slot(nullptr, &std::free);
        if (o.aux && last_fusion.state != recon::TrackingState::kLost) {
          const auto t0 = Clock::now();
          const std::vector<recon::AuxiliaryRaycast> views = recon::RaycastAuxiliaryViews(
              fusion->volume(), last_fusion.camera_to_world, 128, nullptr, fusion->pool());
          fused_aux_ms.push_back(
              std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
          const size_t bytes = msgs::AuxiliaryViews::MessageBytesFor(3, 128, 128);
          aux_slot.reset(static_cast<std::byte*>(std::aligned_alloc(64, bytes)));
          auto m =
              msgs::WriteMessage<msgs::AuxiliaryViews>(std::span<std::byte>(aux_slot.get(), bytes));
          recon::WriteAuxiliaryViews(last_fusion.camera_to_world, views, *m, m.payload);
          fused_aux = light::AuxiliaryFromMessage(*m, m.payload);
        }
        for (Variant* v : {&full, &fast}) {
          // The frame's own depth image goes along as in the node (camera/depth with the G_r's
          // stamp): the shadow search runs on it with --fused-shadows raw.
          light::SceneFrame in = GBufferFrame(g, stamp, &fused_aux);
          in.depth_image = sensor.depth;
          in.camera_to_world_rotation = pose_of(f);
          const light::ScenePipelineResult& r = v->fused_pipeline->Process(in);
          v->fused.samples.push_back(
              Score(*v->fused_pipeline, r, in, truth, f.time_s, &camera_truth));
          if (v == &full) fused_geometry.push_back(CompareGeometry(r.geometry, clean_g.View()));
        }
      }
      std::fprintf(stderr, "frame %llu (%d/%d): full %.1f deg, fast %.1f deg; sensor %.1f / %.1f",
                   static_cast<unsigned long long>(index), k + 1, count,
                   full.clean.samples.back().dir_error_deg, fast.clean.samples.back().dir_error_deg,
                   full.noisy.samples.back().dir_error_deg,
                   fast.noisy.samples.back().dir_error_deg);
      if (fusion) {
        std::fprintf(stderr, "; fused %.1f / %.1f (lost %d)",
                     full.fused.samples.back().dir_error_deg,
                     fast.fused.samples.back().dir_error_deg, fused_lost);
      }
      {
        const Sample& c = full.clean.samples.back();
        const Sample& n = full.noisy.samples.back();
        std::fprintf(
            stderr,
            "\n  direction truth (%.2f %.2f %.2f) clean (%.2f %.2f %.2f) sensor (%.2f %.2f %.2f)",
            c.truth_dir[0], c.truth_dir[1], c.truth_dir[2], c.estimate_dir[0], c.estimate_dir[1],
            c.estimate_dir[2], n.estimate_dir[0], n.estimate_dir[1], n.estimate_dir[2]);
        if (o.shadows) {
          const Sample* f =
              o.fused && !full.fused.samples.empty() ? &full.fused.samples.back() : nullptr;
          for (const Sample* x : {&c, &n, f}) {
            if (x == nullptr) continue;
            std::fprintf(stderr,
                         "\n  shadows %s: %s score %.3f unshadowed %.3f contrast %.2f, shadow dir "
                         "%.1f deg off, %.1f ms, score at truth %.3f, runner-up %.3f, mask "
                         "precision / recall %.2f / %.2f (at truth %.2f / %.2f) boundary %.2f "
                         "%d (at truth %.2f %d)",
                         x == &c   ? "clean"
                         : x == &n ? "sensor"
                                   : "fused",
                         x->shadow_valid ? "accepted" : "rejected", x->shadow_score,
                         x->shadow_unshadowed, x->shadow_contrast, x->shadow_dir_error_deg,
                         x->cpu_ms_shadow, x->shadow_truth_score, x->shadow_runner_up,
                         x->shadow_mask.precision, x->shadow_mask.recall,
                         x->shadow_truth_mask.precision, x->shadow_truth_mask.recall,
                         x->shadow_mask.boundary_precision, x->shadow_mask.boundaries,
                         x->shadow_truth_mask.boundary_precision, x->shadow_truth_mask.boundaries);
          }
        }
        if (o.light_model != light::LightModel::kDistant) {
          std::fprintf(stderr,
                       "\n  point model: clean %s%s (screen %.2f / %.1f deg; gain %.2f, spread "
                       "%.1f deg), lamp (%.2f %.2f %.2f) %.2f m off",
                       c.point_chosen ? "chosen" : "not chosen",
                       c.screened_out ? ", screened out" : (c.warm_started ? ", warm" : ""),
                       c.screen_gain, c.screen_spread_deg, c.point_gain, c.spread_deg, c.lamp[0],
                       c.lamp[1], c.lamp[2], c.lamp_error_m);
          std::fprintf(stderr,
                       "; sensor %s%s (screen %.2f / %.1f deg; gain %.2f, spread %.1f deg), lamp "
                       "%.2f m off; "
                       "true lamps",
                       n.point_chosen ? "chosen" : "not chosen",
                       n.screened_out ? ", screened out" : (n.warm_started ? ", warm" : ""),
                       n.screen_gain, n.screen_spread_deg, n.point_gain, n.spread_deg,
                       n.lamp_error_m);
          for (const auto& l : c.true_lamps) {
            std::fprintf(stderr, " (%.2f %.2f %.2f)", l[0], l[1], l[2]);
          }
        }
      }
      std::fprintf(stderr,
                   "\n  normals vs clean, median / p90 deg (coverage): sensor %.1f / %.1f (%.2f)",
                   sensor_geometry.back().normal_deg_median, sensor_geometry.back().normal_deg_p90,
                   sensor_geometry.back().coverage);
      if (fusion) {
        std::fprintf(stderr, ", fused %.1f / %.1f (%.2f)", fused_geometry.back().normal_deg_median,
                     fused_geometry.back().normal_deg_p90, fused_geometry.back().coverage);
      }
      std::fprintf(stderr, "\n");
    }
  } else {
    source_name = o.log;
    auto source = replay::OpenMcapSource(o.log);
    std::map<int64_t, msgs::ShLight> truths;
    struct Pending {
      std::vector<float> depth;  // metres (light::DepthFromImage), the pipeline's depth image
      light::Intrinsics k;
      int w = 0, h = 0;
      double time_s = 0;
    };
    std::map<int64_t, Pending> frames;
    std::optional<msgs::CameraInfo> info;
    std::map<int64_t, std::vector<float>> greys;
    std::map<int64_t, std::vector<uint8_t>> colours;
    while (auto m = source->Next()) {
      const auto& topic = source->topics()[m->topic_index];
      const auto bytes = m->message.bytes();
      if (topic.topic == "/camera/camera_info") {
        info = *msgs::ReadMessage<msgs::CameraInfo>(bytes);
      } else if (topic.topic == "/camera/image") {
        const auto img = msgs::ReadMessage<msgs::Image>(bytes);
        light::GreyFromImage(*img, img.payload, img->width, img->height,
                             &greys[img->header.stamp_ns], &colours[img->header.stamp_ns]);
      } else if (topic.topic == "/camera/depth" && info) {
        const auto d = msgs::ReadMessage<msgs::Image>(bytes);
        Pending p;
        light::DepthFromImage(*d, d.payload, *info, &p.depth);
        p.k = light::IntrinsicsFrom(*info, d->width, d->height);
        p.w = d->width;
        p.h = d->height;
        p.time_s = m->log_time_ns * 1e-9;
        frames[d->header.stamp_ns] = std::move(p);
      } else if (topic.topic == "/groundtruth/light") {
        const auto l = msgs::ReadMessage<msgs::ShLight>(bytes);
        truths[l->header.stamp_ns] = *l;
      }
    }
    std::vector<int64_t> usable;
    for (const auto& [seq, p] : frames) {
      if (truths.count(seq) && greys.count(seq)) usable.push_back(seq);
    }
    const int count = std::min<int>(o.frames, usable.size());
    for (int k = 0; k < count; ++k) {
      const int64_t seq = usable[static_cast<size_t>(k) * usable.size() / count];
      const Pending& p = frames[seq];
      // A log's depth is the sensor's: the node's depth mode (the sensor pipelines).
      light::SceneFrame in;
      in.stamp_ns = seq;
      in.width = p.w;
      in.height = p.h;
      in.intrinsics = p.k;
      in.grey = greys[seq];
      in.colour = colours[seq];
      in.depth_image = p.depth;
      for (Variant* v : {&full, &fast}) {
        v->noisy.samples.push_back(
            Score(*v->sensor_pipeline, v->sensor_pipeline->Process(in), in, truths[seq], p.time_s));
      }
    }
    // A log carries sensor data only: report it as both the top level and with_sensor_noise.
    full.clean = full.noisy;
    fast.clean = fast.noisy;
  }
  const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
  std::ofstream out(o.json);
  if (!out) throw node::UsageError("cannot write '" + o.json + "'");
  out << "{\n  \"source\": \"" << source_name << "\",\n  \"directions\": " << o.directions
      << ",\n  \"bands\": " << o.bands << ",\n  \"threads\": " << o.threads
      << ",\n  \"aux_views\": " << (o.aux ? "true" : "false");
  if (!fused_aux_ms.empty()) {
    std::vector<double> ms = fused_aux_ms;
    std::nth_element(ms.begin(), ms.begin() + ms.size() / 2, ms.end());
    out << ",\n  \"fused_aux_raycast_ms_median\": " << ms[ms.size() / 2];
  }
  out << ",\n  \"truth\": \"" << (o.log.empty() && !o.camera_truth ? "surface" : "camera") << "\""
      << ",\n  \"albedo_groups\": " << eo.albedo_groups
      << ",\n  \"albedo_invariant\": " << (eo.albedo_invariant ? "true" : "false")
      << ",\n  \"analytic_unoccluded\": " << (o.quadrature ? "false" : "true")
      << ",\n  \"max_rows_per_bin\": " << eo.max_rows_per_bin << ",\n  \"light_model\": \""
      << light::LightModelName(o.light_model) << "\",\n  \"lamps\": " << o.lamps
      << ",\n  \"shadows\": " << (o.shadows ? "true" : "false") << ",\n  \"shadow_cues\": \""
      << o.shadow_cues << "\""
      << ",\n  \"temporal_frames\": " << o.temporal << ",\n  \"forgetting\": " << Num(o.forgetting)
      << ",\n  \"normal_filter\": "
      << (o.normal_filter
              ? "{\"radius\": " + std::to_string(o.filter.radius) +
                    ", \"max_neighbour_angle_deg\": " + Num(o.filter.max_neighbour_angle_deg) +
                    ", \"max_view_angle_deg\": " + Num(o.filter.max_view_angle_deg) +
                    ", \"max_plane_distance_rel\": " + Num(o.filter.max_plane_distance_rel) + "}"
              : std::string("null"))
      << ",\n  \"depth_normals\": {\"from\": \""
      << (o.depth_geometry.normals_from == light::DepthNormals::kAuto   ? "auto"
          : o.depth_geometry.normals_from == light::DepthNormals::kEdge ? "edge"
                                                                        : "central")
      << "\""
      << ", \"smooth_radius\": " << o.smooth_radius << ", \"step\": " << o.normal_step
      << ", \"reliability_weights\": " << (o.reliability ? "true" : "false")
      << ", \"measured_noise_quadratic_median\": " << Num(Quantile(measured_noise, 0.5)) << "}"
      << ",\n  \"full\": " << SeriesJson(full.clean) << ",\n  \"fast\": " << SeriesJson(fast.clean)
      << ",\n  \"with_sensor_noise\": {\"full\": " << SeriesJson(full.noisy)
      << ", \"fast\": " << SeriesJson(fast.noisy) << "}";
  auto geometry_json = [](const std::vector<GeometryError>& v) {
    std::vector<double> cov, med, p90, dep;
    for (const auto& x : v) {
      cov.push_back(x.coverage);
      med.push_back(x.normal_deg_median);
      p90.push_back(x.normal_deg_p90);
      dep.push_back(x.depth_m_median);
    }
    return "{\"coverage_median\": " + Num(Quantile(cov, 0.5)) +
           ", \"normal_error_deg_median\": " + Num(Quantile(med, 0.5)) +
           ", \"normal_error_deg_p90_median\": " + Num(Quantile(p90, 0.5)) +
           ", \"depth_error_m_median\": " + Num(Quantile(dep, 0.5)) + "}";
  };
  if (!sensor_geometry.empty()) {
    out << ",\n  \"geometry_vs_clean\": {\"sensor\": " << geometry_json(sensor_geometry);
    if (!fused_geometry.empty()) out << ", \"fused\": " << geometry_json(fused_geometry);
    out << "}";
  }
  if (o.fused) {
    out << ",\n  \"fused\": {\"known_pose\": " << (o.fused_known_pose ? "true" : "false")
        << ", \"step\": " << o.fused_step << ", \"volume_size_m\": " << Num(o.fused_size)
        << ", \"volume_resolution\": " << o.fused_resolution
        << ", \"truncation_m\": " << Num(o.fused_truncation) << ", \"normals\": \""
        << (o.fused_volume_normals ? "volume" : "depth")
        << "\", \"full\": " << SeriesJson(full.fused) << ", \"fast\": " << SeriesJson(fast.fused)
        << "}";
  }
  out << ",\n  \"seconds\": " << Num(seconds) << "\n}\n";
  if (!o.plots.empty()) WritePlots(o.plots, full.clean, fast.clean);
  std::printf("full %s\nfast %s\nwith sensor noise: full %s\n                   fast %s\n",
              SeriesJson(full.clean).c_str(), SeriesJson(fast.clean).c_str(),
              SeriesJson(full.noisy).c_str(), SeriesJson(fast.noisy).c_str());
  if (o.mix) {
    const char* names[7] = {"clean geometry + sensor colour", "sensor geometry + clean colour",
                            "clean geometry, sensor holes",   "sensor depth + clean normals",
                            "clean depth + sensor normals",   "sensor normals within 5 deg",
                            "clean normals at those pixels"};
    for (int j = 0; j < 7; ++j) {
      std::printf("mix %s: full %s\n    fast %s\n", names[j], SeriesJson(full.mix[j]).c_str(),
                  SeriesJson(fast.mix[j]).c_str());
    }
  }
  if (o.fused) {
    std::printf("fused (G_r): full %s\n             fast %s\n", SeriesJson(full.fused).c_str(),
                SeriesJson(fast.fused).c_str());
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return node::RunMain("scene_light_eval", [&] { return Run(argc, argv); });
}
