// scene_light: per-pixel SH radiance transfer by screen-space directional occlusion and the scene
// light estimated from it (Gruber et al. 2015 §5; probeless_light, docs/light.md). A thin node:
// params -> light::ScenePipelineOptions, messages -> light::SceneFrame, light::ScenePipeline (the
// same object scene_light_eval measures) -> messages.
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
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "aux_views.h"
#include "outputs.h"
#include "params.h"
#include "probeless/light/messages.h"
#include "probeless/light/pipeline.h"
#include "probeless/msgs/msgs.h"
#include "probeless/node/node.h"
#include "probeless/node/stamp_cache.h"

namespace {

using namespace probeless;

int Run(int argc, char** argv) {
  node::Node node(argc, argv, "scene_light");
  const std::string mode = node.Param("mode", "gbuffer", {.choices = {"gbuffer", "depth"}});
  const light::ScenePipelineOptions po = scene_light::OptionsFromParams(node, mode);
  const bool publish_transfer = node.Param("publish_transfer", true);
  const bool use_aux = node.Param("use_aux", false);
  const int aux_wait_ms = node.Param("aux_wait_ms", 50, {.unit = "ms", .min = 0.0});
  if (use_aux && mode != "gbuffer") {
    throw node::UsageError("scene_light: use_aux needs mode gbuffer (the views come from fusion)");
  }
  const bool raw_shadows = mode == "gbuffer" && po.shadow.enabled &&
                           po.shadow_geometry == light::ShadowGeometry::kDepthImage;
  light::ScenePipeline pipeline(po);  // throws LightError for bad options
  // The inserted objects' point (the pose's parent frame, fusion's world) and the camera poses
  // that carry it into each frame's camera frame.
  const std::vector<double> focus = node.Param("focus", std::vector<double>{});
  if (!focus.empty() && focus.size() != 3) {
    throw node::UsageError("scene_light: focus must be [x, y, z] in metres (or empty), got " +
                           std::to_string(focus.size()) + " values");
  }
  std::optional<bus::Subscriber> pose_sub;
  const bool temporal = po.temporal.frames > 1;  // its history is rotated by the poses
  if (!focus.empty() || temporal) {
    pose_sub.emplace(node.CreateSubscriber<msgs::Pose>("scene/pose", {.queue_depth = 8}));
  }
  node::StampCache<msgs::Pose> poses(8);  // the latest camera poses
  int64_t focus_used = 0, focus_missing = 0, rotated = 0, rotation_missing = 0;
  auto hold_pose = [&](bus::Sample&& s) {
    const msgs::Pose pose = *msgs::ReadMessage<msgs::Pose>(s.data());
    poses.Add(pose.header.stamp_ns, pose);
  };

  bus::Subscriber info_sub = node.CreateSubscriber<msgs::CameraInfo>("camera/camera_info");
  bus::Subscriber image_sub = node.CreateSubscriber<msgs::Image>("camera/image");
  bus::Subscriber trigger_sub = mode == "gbuffer"
                                    ? node.CreateSubscriber<msgs::GeometryBuffer>("scene/gbuffer")
                                    : node.CreateSubscriber<msgs::Image>("camera/depth");
  // raw_shadows: the latest depth images (copies of the messages), matched to a G_r by stamp.
  std::optional<bus::Subscriber> raw_depth_sub;
  if (raw_shadows) {
    raw_depth_sub.emplace(node.CreateSubscriber<msgs::Image>("camera/depth", {.queue_depth = 8}));
  }
  // Copies not yet matched (older than a processed G_r: dropped).
  node::StampCache<node::HeldMessage> raw_depths(8);
  std::vector<float> raw_depth_m;
  int64_t raw_used = 0, raw_missing = 0, raw_size_mismatch = 0;
  auto hold_depth = [&](bus::Sample&& s) {
    const auto d = msgs::ReadMessage<msgs::Image>(s.data());
    raw_depths.Add(d->header.stamp_ns, node::HeldMessage(s.data()));
  };
  // Takes (and acks, as Spin would) the samples of `sub` Spin has not handed over yet; a bad one
  // is rejected under its own topic, as Spin would, and the G_r goes on without it.
  auto take_queued = [&](bus::Subscriber& sub, auto& hold) {
    while (auto s = sub.TryTake()) {
      const bus::MessageInfo received = s->info();
      node.Ack(sub, received);
      try {
        hold(std::move(*s));
      } catch (const msgs::MessageError& e) {
        node.RejectSample(sub.topic(), e.what());
      }
    }
  };
  // Taken in the G_r's handler (matched by stamp), not by Spin.
  std::optional<scene_light::AuxViewQueue> aux_views;
  if (use_aux) aux_views.emplace(node, std::chrono::milliseconds(aux_wait_ms));
  scene_light::SceneOutputs outputs(node, publish_transfer);

  std::optional<msgs::CameraInfo> info;
  std::optional<bus::Sample> image;  // the latest image sample (held)
  std::vector<float> grey, depth;
  std::vector<uint8_t> rgb;  // the image's sRGB bytes for the albedo groups
  int64_t frames = 0, published = 0;
  int64_t last_stamp = std::numeric_limits<int64_t>::min();  // the last processed frame's
  bool warned = false;

  auto process = [&](bus::Sample&& sample) {
    msgs::Header header;
    light::SceneFrame frame;
    if (mode == "gbuffer") {
      const auto g = msgs::ReadMessage<msgs::GeometryBuffer>(sample.data());
      if (!info || !image) {
        if (!warned) node.Warn() << "skipping frames until camera_info and image arrive";
        warned = true;
        return;
      }
      header = g->header;
      const light::GeometryView view = light::ViewOfGeometryBuffer(*g, g.payload, *info);
      frame.width = view.width;
      frame.height = view.height;
      frame.intrinsics = view.intrinsics;
      frame.gbuffer_depth = view.depth;
      frame.gbuffer_normals = view.normals;
      frame.gbuffer_colour = view.colour;
    } else {
      const auto d = msgs::ReadMessage<msgs::Image>(sample.data());
      if (!info || !image) {
        if (!warned) node.Warn() << "skipping frames until camera_info and image arrive";
        warned = true;
        return;
      }
      header = d->header;
      light::DepthFromImage(*d, d.payload, *info, &depth);
      frame.width = static_cast<int>(d->width);
      frame.height = static_cast<int>(d->height);
      frame.intrinsics = light::IntrinsicsFrom(*info, d->width, d->height);
      frame.depth_image = depth;
    }
    frame.stamp_ns = header.stamp_ns;
    const auto img = msgs::ReadMessage<msgs::Image>(image->data());
    if (img->header.sequence != header.sequence) {
      node.Debug() << "image sequence " << img->header.sequence << " used for frame "
                   << header.sequence;
    }
    light::GreyFromImage(*img, img.payload, frame.width, frame.height, &grey, &rgb);
    frame.grey = grey;
    frame.colour = rgb;
    // Stamps going backwards (a restarted source): what is held for the old stream never matches
    // (the pipeline resets its own state).
    if (header.stamp_ns < last_stamp) {
      if (aux_views) aux_views->Clear();
      raw_depths.Clear();
    }
    last_stamp = header.stamp_ns;
    scene_light::FrameAuxViews aux;  // held until the frame is done
    if (aux_views) {
      aux_views->ForFrame(header, &aux);
      frame.aux = &aux.buffers;
    }
    if (raw_shadows) {
      // The shadow search's geometry: the depth image with the G_r's stamp (else G_r). Depth
      // images Spin has not handed over yet are taken here.
      take_queued(*raw_depth_sub, hold_depth);
      const node::HeldMessage* held = raw_depths.Exact(header.stamp_ns);
      if (held == nullptr) {
        if (raw_missing == 0) {
          node.Warn() << "no camera/depth with the G_r's stamp " << header.stamp_ns
                      << ": the shadow search uses G_r for such frames";
        }
        ++raw_missing;
      } else if (const auto d = msgs::ReadMessage<msgs::Image>(held->bytes());
                 static_cast<int>(d->width) != frame.width ||
                 static_cast<int>(d->height) != frame.height) {
        if (raw_size_mismatch == 0) {
          node.Warn() << "camera/depth is " << d->width << "x" << d->height << ", the G_r "
                      << frame.width << "x" << frame.height
                      << ": the shadow search uses G_r for such frames";
        }
        ++raw_size_mismatch;
        ++raw_missing;
      } else {
        light::DepthFromImage(*d, d.payload, *info, &raw_depth_m);
        frame.depth_image = raw_depth_m;
        ++raw_used;
      }
      // Depth images up to this G_r's stamp can match no later G_r.
      raw_depths.DropUpTo(header.stamp_ns);
    }
    if (pose_sub) {
      take_queued(*pose_sub, hold_pose);
      // The focus: the pose of this frame (fusion publishes it before its G_r), else the newest
      // older one (the objects stay put while tracking is lost).
      if (!focus.empty()) {
        if (const msgs::Pose* pose = poses.LatestAtOrBefore(header.stamp_ns)) {
          frame.focus = light::WorldPointInCamera(pose->transform, {focus[0], focus[1], focus[2]});
          ++focus_used;
        } else {
          if (focus_missing == 0) {
            node.Warn() << "no scene/pose up to stamp " << header.stamp_ns
                        << ": frames without one are fitted without the focus";
          }
          ++focus_missing;
        }
      }
      // The temporal fit: only this frame's own pose (fusion publishes none for a lost frame; an
      // older one would pass for a camera at rest).
      if (temporal) {
        if (const msgs::Pose* pose = poses.Exact(header.stamp_ns)) {
          frame.camera_to_world_rotation = light::CameraToWorldRotation(pose->transform);
          ++rotated;
        } else {
          if (rotation_missing == 0) {
            node.Warn() << "no scene/pose with stamp " << header.stamp_ns
                        << ": frames without their own pose are taken as not rotated by the "
                           "temporal fit";
          }
          ++rotation_missing;
        }
      }
    }
    const light::ScenePipelineResult& r = pipeline.Process(frame);
    if (r.used == light::LightModel::kPoint && !r.point.lamps.empty()) {
      const auto& p = r.point.lamps[0].position;
      node.Debug() << "frame " << header.sequence << ": point model, lamp at (" << p[0] << ", "
                   << p[1] << ", " << p[2] << ") m, camera frame";
    }
    if (r.shadow_ran) {
      const light::ShadowEstimate& sh = r.shadow;
      node.Debug() << "stamp " << header.stamp_ns << ": shadow search "
                   << (sh.valid ? "accepted" : "rejected") << ", score " << sh.score
                   << " (unshadowed " << sh.score_unshadowed << ", runner-up " << sh.runner_up
                   << "), contrast " << sh.contrast << ", " << sh.groups << " groups, direction ("
                   << sh.direction[0] << ", " << sh.direction[1] << ", " << sh.direction[2] << "), "
                   << r.clipped_filled << " clipped pixels given their surface's colour";
    }
    ++frames;
    published += outputs.Publish(header, r);
  };

  std::vector<node::Handler> handlers{
      {&info_sub,
       [&](bus::Sample&& s) {
         const auto m = msgs::ReadMessage<msgs::CameraInfo>(s.data());
         m->Validate();
         info = *m;
       }},
      {&image_sub, [&](bus::Sample&& s) { image.emplace(std::move(s)); }},
      {&trigger_sub, process}};
  if (raw_depth_sub) handlers.push_back({&*raw_depth_sub, hold_depth});
  if (pose_sub) handlers.push_back({&*pose_sub, hold_pose});
  // Views that arrive while no G_r is being processed (e.g. before camera_info) are taken and
  // acked by Spin too, so lock-step replay never waits on an unacked view.
  if (aux_views) {
    handlers.push_back(
        {&aux_views->subscriber(), [&](bus::Sample&& s) { aux_views->Hold(std::move(s)); }});
  }
  node.Spin(handlers);
  node.Info() << "published " << published << " lights for " << frames << " frames";
  if (raw_shadows) {
    node.Info() << "shadow search on the frame's depth image for " << raw_used
                << " frames, on G_r for " << raw_missing;
  }
  if (pose_sub) {
    if (!focus.empty()) {
      node.Info() << "focus: used for " << focus_used << " frames, no pose for " << focus_missing;
    }
    if (temporal) {
      node.Info() << "temporal fit: rotated by scene/pose for " << rotated
                  << " frames, no pose of their own for " << rotation_missing;
    }
  }
  if (aux_views) aux_views->LogSummary();
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return node::RunMain("scene_light", [&] { return Run(argc, argv); });
}
