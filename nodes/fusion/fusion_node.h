// fusion's state between frames and its handlers: the pipeline and its checkpoint, the latest
// camera info, the depth waiting for its image, the latest image, the poses by stamp for
// scene/light, the tracking state of the log lines and the counters of the summary at exit.
// main.cpp reads the params, constructs it and spins it.
#pragma once

#include <cstdint>
#include <optional>
#include <vector>

#include "outputs.h"
#include "params.h"
#include "probeless/bus/bus.h"
#include "probeless/msgs/msgs.h"
#include "probeless/node/node.h"
#include "probeless/node/stamp_cache.h"
#include "probeless/recon/checkpoint.h"
#include "probeless/recon/msgs_io.h"
#include "probeless/recon/pipeline.h"

namespace probeless::fusion {

class FusionNode {
 public:
  // Creates the pipeline, resumes params.checkpoint_path when a checkpoint is there (an info
  // line; throws ReconError for a file that is not a valid checkpoint for these volume params),
  // then subscribes, in this order, camera/depth, camera/image, camera/camera_info and ~/reset,
  // creates the publishers (FusionOutputs) and, with publish_aux and aux_light, subscribes
  // scene/light. Throws ReconError for invalid pipeline options.
  FusionNode(node::Node& node, const FusionParams& params);
  FusionNode(const FusionNode&) = delete;  // the handlers hold `this`
  FusionNode& operator=(const FusionNode&) = delete;

  // The start-up info line, node::Node::Spin over the handlers until shutdown, then the depth
  // still waiting (without colour), the final checkpoint, the mesh and the summary lines. Returns
  // the exit code: 3 when fail_on_lost_ratio is exceeded, else 1 when the final checkpoint could
  // not be written, else 0.
  int Spin();

 private:
  // Handlers (a bad sample throws msgs::MessageError or ReconError, rejected by Spin).
  void HoldCameraInfo(bus::Sample&& s);
  void OnDepth(bus::Sample&& s);
  void OnImage(bus::Sample&& s);
  void OnReset(bus::Sample&& s);
  void OnLight(bus::Sample&& s);
  // The pipeline on one frame (`image` nullptr: without colour), the counts, the state-change
  // log line and the outputs in their order.
  void Process(const recon::DepthFrame& d, const recon::ColourFrame* image);
  // One line per change of the tracking state, not per frame.
  void LogStateChange(const recon::FrameResult& r);
  // Hands the map to the checkpoint writer; a failed earlier write is reported, not fatal.
  void SaveCheckpoint();
  // Resumes the pipeline from the checkpoint file if there is one (before any subscriber) and
  // returns its writer; none without a checkpoint path.
  std::optional<recon::CheckpointWriter> OpenCheckpoint();

  node::Node& node_;
  const FusionParams params_;
  recon::FusionPipeline pipeline_;
  // Declared in their creation order (the constructor's contract).
  std::optional<recon::CheckpointWriter> checkpoint_;
  bus::Subscriber depth_sub_;
  bus::Subscriber image_sub_;
  bus::Subscriber info_sub_;
  bus::Subscriber reset_sub_;
  FusionOutputs outputs_;
  std::optional<bus::Subscriber> light_sub_;

  int integrated_since_checkpoint_ = 0;
  // Poses of the last frames by stamp (to bring scene/light's camera-frame direction into the
  // world) and the light direction in the world (none until scene/light brings one).
  node::StampCache<recon::Pose> recent_poses_{32};
  std::optional<recon::Vec3f> light_world_;
  std::optional<msgs::CameraInfo> info_;
  std::optional<recon::DepthFrame> pending_depth_;      // waiting for its image
  node::StampCache<recon::ColourFrame> last_image_{1};  // the latest image, taken by exact stamp
  recon::TrackingCounts counts_;
  recon::TrackingState last_state_ = recon::TrackingState::kTracking;
  uint64_t lost_since_ = 0;  // frame number of the first lost frame of the current loss
  std::vector<double> total_ms_;
};

}  // namespace probeless::fusion
