// scene_light's state between frames and its handlers: the latest camera info and image, the depth
// images and camera poses matched to a frame by stamp, the auxiliary views, the pipeline and the
// counters of the summary lines at exit. main.cpp reads the params, constructs it and spins it.
#pragma once

#include <chrono>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "aux_views.h"
#include "outputs.h"
#include "probeless/bus/bus.h"
#include "probeless/light/messages.h"
#include "probeless/light/pipeline.h"
#include "probeless/msgs/msgs.h"
#include "probeless/node/node.h"
#include "probeless/node/stamp_cache.h"

namespace probeless::scene_light {

// The node's own params (docs/nodes.md "scene_light"); the pipeline's are its options.
struct NodeParams {
  std::string mode = "gbuffer";  // "gbuffer" (scene/gbuffer triggers) or "depth" (camera/depth)
  bool publish_transfer = true;  // also scene/transfer for every frame
  bool use_aux = false;          // scene/aux's views in the transfer (mode gbuffer only)
  std::chrono::milliseconds aux_wait{50};  // longest wait for a G_r's views
  // The inserted objects' point in metres in scene/pose's parent frame (fusion's world): [x, y, z]
  // or empty (none).
  std::vector<double> focus;
};

class SceneLightNode {
 public:
  // Subscribes, in this order, scene/pose (with a focus or a temporal fit), camera/camera_info,
  // camera/image, the trigger of params.mode, camera/depth (gbuffer mode with the shadow search
  // on the raw depth) and scene/aux (use_aux), and creates the publishers (SceneOutputs).
  // `params` are checked by the caller (mode one of the two, use_aux only in gbuffer mode, focus
  // of 0 or 3 values); `pipeline` runs every frame.
  SceneLightNode(node::Node& node, const NodeParams& params, light::ScenePipeline pipeline);
  SceneLightNode(const SceneLightNode&) = delete;  // the handlers hold `this`
  SceneLightNode& operator=(const SceneLightNode&) = delete;

  // node::Node::Spin over the handlers until shutdown, then the summary lines (info).
  void Spin();

 private:
  // Handlers (a bad sample throws msgs::MessageError, rejected by Spin).
  void HoldCameraInfo(bus::Sample&& s);
  void HoldPose(bus::Sample&& s);
  void HoldDepth(bus::Sample&& s);
  // One frame of the trigger: the SceneFrame, the matched inputs, the pipeline, the outputs.
  void ProcessFrame(bus::Sample&& sample);
  // Whether camera info or image is still missing (the first time one warning).
  bool WaitingForInputs();
  // Takes (and acks, as Spin would) the samples of `sub` Spin has not handed over yet; a bad one
  // is rejected under its own topic, as Spin would, and the frame goes on without it.
  void TakeQueued(bus::Subscriber& sub, void (SceneLightNode::*hold)(bus::Sample&&));
  // The shadow search's geometry: the depth image with the G_r's stamp (else G_r itself).
  void MatchShadowDepth(const msgs::Header& header, light::SceneFrame* frame);
  // The focus and the camera rotation of the frame from the held poses.
  void MatchPose(const msgs::Header& header, light::SceneFrame* frame);
  // Debug lines of a frame's point model and shadow search.
  void LogResult(const msgs::Header& header, const light::ScenePipelineResult& r) const;
  // The info lines at exit: lights and frames, then the counts of each input matched by stamp.
  void LogSummary() const;

  node::Node& node_;
  const bool gbuffer_;  // mode gbuffer: a G_r triggers a frame; else a depth image
  const std::vector<double> focus_;
  light::ScenePipeline pipeline_;
  const bool temporal_;     // its history is rotated by the poses
  const bool raw_shadows_;  // the shadow search on the depth image with the G_r's stamp
  // Declared in their creation order (the constructor's contract).
  std::optional<bus::Subscriber> pose_sub_;
  bus::Subscriber info_sub_;
  bus::Subscriber image_sub_;
  bus::Subscriber trigger_sub_;
  std::optional<bus::Subscriber> raw_depth_sub_;
  // Taken in the G_r's handler (matched by stamp), not by Spin.
  std::optional<AuxViewQueue> aux_views_;
  SceneOutputs outputs_;

  light::SceneFrameBuilder frame_builder_;
  node::StampCache<msgs::Pose> poses_{8};  // the latest camera poses
  // raw_shadows_: copies of the depth images not yet matched (older than a processed G_r:
  // dropped).
  node::StampCache<node::HeldMessage> raw_depths_{8};
  std::optional<msgs::CameraInfo> info_;
  std::optional<bus::Sample> image_;                          // the latest image sample (held)
  int64_t last_stamp_ = std::numeric_limits<int64_t>::min();  // the last processed frame's
  bool warned_ = false;                                       // about missing info / image
  int64_t frames_ = 0, published_ = 0;
  int64_t focus_used_ = 0, focus_missing_ = 0, rotated_ = 0, rotation_missing_ = 0;
  int64_t raw_used_ = 0, raw_missing_ = 0, raw_size_mismatch_ = 0;
};

}  // namespace probeless::scene_light
