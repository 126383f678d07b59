// scene_light: per-pixel SH radiance transfer by screen-space directional occlusion and the scene
// light estimated from it (Gruber et al. 2015 §5; probeless_light, docs/light.md). A thin node:
// params -> light::ScenePipelineOptions, messages -> light::SceneFrame (light::SceneFrameBuilder),
// light::ScenePipeline (the same object scene_light_eval measures) -> messages; the state between
// frames and the handlers are scene_light::SceneLightNode (scene_light_node.h).
//
// Inputs (relative names, remap them in launch files):
//   mode gbuffer (default): `scene/gbuffer` (msgs::GeometryBuffer, G_r from fusion) triggers a
//       frame; depth and normals come from it. With shadows and shadow_depth raw (default) also
//       `camera/depth`: the depth image with the G_r's stamp is the shadow search's geometry.
//   mode depth: `camera/depth` (msgs::Image depth16 or float32) triggers a frame; normals are
//       computed from the depth (light::DepthGeometry: edge-aware on clean depth, smoothed
//       central differences on noisy depth; no reconstruction needed).
//   Both: `camera/camera_info` (msgs::CameraInfo, latest) and `camera/image` (msgs::Image rgb8 /
//       bgr8 / mono8, latest; I_c of the estimation; a debug line if its sequence differs).
// Outputs: `scene/light` (msgs::ShLight, camera frame, in the illuminant colour by the grey-world
//   assumption unless grey_world_colour is false, bands = param bands,
//   dominant direction, intensity, confidence; header of the triggering message) and, with
//   publish_transfer, `scene/transfer` (msgs::TransferBuffer, the per-pixel T for differential
//   rendering), and with publish_indirect `scene/indirect` (msgs::Image rgb32f, the one-bounce
//   indirect light of eq. 10-12 from the previous frame's dominant light: linear RGB radiance for
//   albedo 1; from the second frame on, none after a frame without an estimated light). A frame
//   without camera info or image yet is skipped (one warning).
// Params: mode (gbuffer), bands (4), directions (32), subsample (1; 4 = OursFast), radius (0.3 m),
//   seed (1), threads (2), albedo (0.25), stride (4), robust (true), non_negative (false),
//   direction_bands (2), albedo_groups (32 = per-material albedos from the image's chromaticity;
//   0 = one uniform albedo), max_rows_per_bin (100), max_intensity (0.98: brighter pixels are left
//   out of the fit), fill_clipped_chroma (false: ScenePipelineOptions::fill_clipped_chroma),
//   analytic_unoccluded (true; false = eq. 6 as printed), publish_transfer (true),
//   gbuffer_normals ("fusion": G_r's normals; "depth": recomputed from G_r's depth, step
//   max(2, w / 160)), normal_filter (false: light::FilterNormals on the normals), temporal_frames
//   (1 = off; light::TemporalLightEstimator over that many frames, the history rotated by the
//   camera's rotation from scene/pose), forgetting (0.5), temporal_reset_ratio (1.3), light_model
//   ("auto" = the point model when its selection rule prefers it, else §5.2's; "distant" = §5.2;
//   "point" = near-field point lamps; light::EstimateSceneLight; temporal_frames > 1 or
//   reliability_weights imply distant and reject an explicit point / auto), lamps (1; 2 = up to two
//   lamps), publish_indirect (false); depth mode: depth_normals ("auto": "edge" for a clean depth
//   image, "central" for a noisy one, by light::DepthNoiseQuadratic; "edge":
//   light::NormalsWithReliability; "central": SmoothDepth w / 80 + NormalsFromDepth), smooth_radius
//   / normal_step (-1 = from the measured depth noise); reliability_weights (false: the normals'
//   reliability as the estimator's row weights; gbuffer mode: light::NormalReliability of G_r),
//   shadows (false; true: the distant light's direction refined by cast shadows,
//   light::RefineLightWithShadows; not with temporal_frames > 1), shadow_image_cues (true in depth
//   mode: ShadowOptions::image_cues, light::RawDepthShadowOptions), shadow_stride (8),
//   shadow_min_contrast (2: ShadowOptions::min_contrast),
//   shadows_override_prior (true: an accepted shadow direction overrides the light prior,
//   light::ScenePipelineOptions::shadows_override_prior), confidence_calibration (knots: fit
//   confidence, expected error in degrees; default light::DefaultSceneConfidenceKnots of the mode),
//   raw_confidence (false: publish the fit confidence uncalibrated), shadow_depth (raw; gbuffer
//   mode: the search on the frame's depth image with the image cues, or on G_r without them:
//   "gbuffer"), use_aux (false; gbuffer mode: the auxiliary orthographic views fusion publishes
//   with publish_aux on `scene/aux` (msgs::AuxiliaryViews) take part in the transfer's occlusion
//   test; the views with the G_r's stamp are used, waiting at most aux_wait_ms (50) for them;
//   without a match the frame runs without views (one warning, counted at exit), and a malformed
//   message is one error line and the frame runs without views). The lamp positions are not in
//   msgs::ShLight: they go to the debug log. The point fit starts from the previous frame's lamp
//   while the point model is in use (light::PointLightTracker).
// Exit: 0 on SIGINT/SIGTERM, 2 on bad params (one line on stderr), 1 otherwise. A bad input
// message is rejected with one error line and counted (node::Node::Spin); the node goes on.
#include "probeless/node/main.h"

#include <chrono>
#include <string>
#include <utility>
#include <vector>

#include "params.h"
#include "probeless/light/pipeline.h"
#include "probeless/node/node.h"
#include "scene_light_node.h"

namespace {

using namespace probeless;

int Run(int argc, char** argv) {
  node::Node node(argc, argv, "scene_light");
  scene_light::NodeParams params;
  params.mode = node.Param("mode", "gbuffer", {.choices = {"gbuffer", "depth"}});
  const light::ScenePipelineOptions po = scene_light::OptionsFromParams(node, params.mode);
  params.publish_transfer = node.Param("publish_transfer", true);
  params.use_aux = node.Param("use_aux", false);
  params.aux_wait =
      std::chrono::milliseconds(node.Param("aux_wait_ms", 50, {.unit = "ms", .min = 0.0}));
  if (params.use_aux && params.mode != "gbuffer") {
    throw node::UsageError("scene_light: use_aux needs mode gbuffer (the views come from fusion)");
  }
  light::ScenePipeline pipeline(po);  // throws LightError for bad options (checked before focus)
  // The inserted objects' point (the pose's parent frame, fusion's world); the camera poses carry
  // it into each frame's camera frame.
  params.focus = node.Param("focus", std::vector<double>{});
  if (!params.focus.empty() && params.focus.size() != 3) {
    throw node::UsageError("scene_light: focus must be [x, y, z] in metres (or empty), got " +
                           std::to_string(params.focus.size()) + " values");
  }
  scene_light::SceneLightNode scene_light_node(node, params, std::move(pipeline));
  scene_light_node.Spin();
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return node::RunMain("scene_light", [&] { return Run(argc, argv); });
}
