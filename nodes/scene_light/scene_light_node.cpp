#include "scene_light_node.h"

#include <utility>

namespace probeless::scene_light {

namespace {

// A subscriber of M on `topic` (queue depth 8) if `wanted`, else none.
template <msgs::Message M>
std::optional<bus::Subscriber> SubscribeIf(bool wanted, node::Node& node, const char* topic) {
  if (!wanted) return std::nullopt;
  return node.CreateSubscriber<M>(topic, {.queue_depth = 8});
}

}  // namespace

SceneLightNode::SceneLightNode(node::Node& node, const NodeParams& params,
                               light::ScenePipeline pipeline)
    : node_(node),
      gbuffer_(params.mode == "gbuffer"),
      focus_(params.focus),
      pipeline_(std::move(pipeline)),
      temporal_(pipeline_.options().temporal.frames > 1),
      raw_shadows_(gbuffer_ && pipeline_.options().shadow.enabled &&
                   pipeline_.options().shadow_geometry == light::ShadowGeometry::kDepthImage),
      pose_sub_(SubscribeIf<msgs::Pose>(!focus_.empty() || temporal_, node, "scene/pose")),
      info_sub_(node.CreateSubscriber<msgs::CameraInfo>("camera/camera_info")),
      image_sub_(node.CreateSubscriber<msgs::Image>("camera/image")),
      trigger_sub_(gbuffer_ ? node.CreateSubscriber<msgs::GeometryBuffer>("scene/gbuffer")
                            : node.CreateSubscriber<msgs::Image>("camera/depth")),
      raw_depth_sub_(SubscribeIf<msgs::Image>(raw_shadows_, node, "camera/depth")),
      aux_views_(params.use_aux ? std::optional<AuxViewQueue>(std::in_place, node, params.aux_wait)
                                : std::nullopt),
      outputs_(node, params.publish_transfer) {}

void SceneLightNode::Spin() {
  std::vector<node::Handler> handlers{
      {&info_sub_, [this](bus::Sample&& s) { HoldCameraInfo(std::move(s)); }},
      {&image_sub_, [this](bus::Sample&& s) { image_.emplace(std::move(s)); }},
      {&trigger_sub_, [this](bus::Sample&& s) { ProcessFrame(std::move(s)); }}};
  if (raw_depth_sub_) {
    handlers.push_back({&*raw_depth_sub_, [this](bus::Sample&& s) { HoldDepth(std::move(s)); }});
  }
  if (pose_sub_) {
    handlers.push_back({&*pose_sub_, [this](bus::Sample&& s) { HoldPose(std::move(s)); }});
  }
  // Views that arrive while no G_r is being processed (e.g. before camera_info) are taken and
  // acked by Spin too, so lock-step replay never waits on an unacked view.
  if (aux_views_) {
    handlers.push_back(
        {&aux_views_->subscriber(), [this](bus::Sample&& s) { aux_views_->Hold(std::move(s)); }});
  }
  node_.Spin(handlers);
  LogSummary();
}

void SceneLightNode::HoldCameraInfo(bus::Sample&& s) {
  const auto m = msgs::ReadMessage<msgs::CameraInfo>(s.data());
  m->Validate();
  info_ = *m;
}

void SceneLightNode::HoldPose(bus::Sample&& s) {
  const msgs::Pose pose = *msgs::ReadMessage<msgs::Pose>(s.data());
  poses_.Add(pose.header.stamp_ns, pose);
}

void SceneLightNode::HoldDepth(bus::Sample&& s) {
  const auto d = msgs::ReadMessage<msgs::Image>(s.data());
  raw_depths_.Add(d->header.stamp_ns, node::HeldMessage(s.data()));
}

bool SceneLightNode::WaitingForInputs() {
  if (info_ && image_) return false;
  if (!warned_) node_.Warn() << "skipping frames until camera_info and image arrive";
  warned_ = true;
  return true;
}

void SceneLightNode::TakeQueued(bus::Subscriber& sub, void (SceneLightNode::*hold)(bus::Sample&&)) {
  while (auto s = sub.TryTake()) {
    const bus::MessageInfo received = s->info();
    node_.Ack(sub, received);
    try {
      (this->*hold)(std::move(*s));
    } catch (const msgs::MessageError& e) {
      node_.RejectSample(sub.topic(), e.what());
    }
  }
}

void SceneLightNode::ProcessFrame(bus::Sample&& sample) {
  // The trigger is read before the inputs are checked (a malformed one is rejected even then).
  msgs::Header header;
  light::SceneFrame frame;
  if (gbuffer_) {
    const auto g = msgs::ReadMessage<msgs::GeometryBuffer>(sample.data());
    if (WaitingForInputs()) return;
    header = g->header;
    frame = frame_builder_.FromGeometryBuffer(*g, g.payload, *info_);
  } else {
    const auto d = msgs::ReadMessage<msgs::Image>(sample.data());
    if (WaitingForInputs()) return;
    header = d->header;
    frame = frame_builder_.FromDepthImage(*d, d.payload, *info_);
  }
  const auto img = msgs::ReadMessage<msgs::Image>(image_->data());
  if (img->header.sequence != header.sequence) {
    node_.Debug() << "image sequence " << img->header.sequence << " used for frame "
                  << header.sequence;
  }
  frame_builder_.AddImage(*img, img.payload, &frame);
  // Stamps going backwards (a restarted source): what is held for the old stream never matches
  // (the pipeline resets its own state).
  if (header.stamp_ns < last_stamp_) {
    if (aux_views_) aux_views_->Clear();
    raw_depths_.Clear();
  }
  last_stamp_ = header.stamp_ns;
  FrameAuxViews aux;  // held until the frame is done
  if (aux_views_) {
    aux_views_->ForFrame(header, &aux);
    frame.aux = &aux.buffers;
  }
  if (raw_shadows_) MatchShadowDepth(header, &frame);
  if (pose_sub_) MatchPose(header, &frame);
  const light::ScenePipelineResult& r = pipeline_.Process(frame);
  LogResult(header, r);
  ++frames_;
  published_ += outputs_.Publish(header, r);
}

void SceneLightNode::MatchShadowDepth(const msgs::Header& header, light::SceneFrame* frame) {
  // Depth images Spin has not handed over yet are taken here.
  TakeQueued(*raw_depth_sub_, &SceneLightNode::HoldDepth);
  const node::HeldMessage* held = raw_depths_.Exact(header.stamp_ns);
  if (held == nullptr) {
    if (raw_missing_ == 0) {
      node_.Warn() << "no camera/depth with the G_r's stamp " << header.stamp_ns
                   << ": the shadow search uses G_r for such frames";
    }
    ++raw_missing_;
  } else if (const auto d = msgs::ReadMessage<msgs::Image>(held->bytes());
             static_cast<int>(d->width) != frame->width ||
             static_cast<int>(d->height) != frame->height) {
    if (raw_size_mismatch_ == 0) {
      node_.Warn() << "camera/depth is " << d->width << "x" << d->height << ", the G_r "
                   << frame->width << "x" << frame->height
                   << ": the shadow search uses G_r for such frames";
    }
    ++raw_size_mismatch_;
    ++raw_missing_;
  } else {
    frame_builder_.AddShadowDepth(*d, d.payload, *info_, frame);
    ++raw_used_;
  }
  // Depth images up to this G_r's stamp can match no later G_r.
  raw_depths_.DropUpTo(header.stamp_ns);
}

void SceneLightNode::MatchPose(const msgs::Header& header, light::SceneFrame* frame) {
  TakeQueued(*pose_sub_, &SceneLightNode::HoldPose);
  // The focus: the pose of this frame (fusion publishes it before its G_r), else the newest older
  // one (the objects stay put while tracking is lost).
  if (!focus_.empty()) {
    if (const msgs::Pose* pose = poses_.LatestAtOrBefore(header.stamp_ns)) {
      frame->focus = light::WorldPointInCamera(pose->transform, {focus_[0], focus_[1], focus_[2]});
      ++focus_used_;
    } else {
      if (focus_missing_ == 0) {
        node_.Warn() << "no scene/pose up to stamp " << header.stamp_ns
                     << ": frames without one are fitted without the focus";
      }
      ++focus_missing_;
    }
  }
  // The temporal fit: only this frame's own pose (fusion publishes none for a lost frame; an
  // older one would pass for a camera at rest).
  if (temporal_) {
    if (const msgs::Pose* pose = poses_.Exact(header.stamp_ns)) {
      frame->camera_to_world_rotation = light::CameraToWorldRotation(pose->transform);
      ++rotated_;
    } else {
      if (rotation_missing_ == 0) {
        node_.Warn() << "no scene/pose with stamp " << header.stamp_ns
                     << ": frames without their own pose are taken as not rotated by the "
                        "temporal fit";
      }
      ++rotation_missing_;
    }
  }
}

void SceneLightNode::LogResult(const msgs::Header& header,
                               const light::ScenePipelineResult& r) const {
  if (r.used == light::LightModel::kPoint && !r.point.lamps.empty()) {
    const auto& p = r.point.lamps[0].position;
    node_.Debug() << "frame " << header.sequence << ": point model, lamp at (" << p[0] << ", "
                  << p[1] << ", " << p[2] << ") m, camera frame";
  }
  if (r.shadow_ran) {
    const light::ShadowEstimate& sh = r.shadow;
    node_.Debug() << "stamp " << header.stamp_ns << ": shadow search "
                  << (sh.valid ? "accepted" : "rejected") << ", score " << sh.score
                  << " (unshadowed " << sh.score_unshadowed << ", runner-up " << sh.runner_up
                  << "), contrast " << sh.contrast << ", " << sh.groups << " groups, direction ("
                  << sh.direction[0] << ", " << sh.direction[1] << ", " << sh.direction[2] << "), "
                  << r.clipped_filled << " clipped pixels given their surface's colour";
  }
}

void SceneLightNode::LogSummary() const {
  node_.Info() << "published " << published_ << " lights for " << frames_ << " frames";
  if (raw_shadows_) {
    node_.Info() << "shadow search on the frame's depth image for " << raw_used_
                 << " frames, on G_r for " << raw_missing_;
  }
  if (pose_sub_) {
    if (!focus_.empty()) {
      node_.Info() << "focus: used for " << focus_used_ << " frames, no pose for "
                   << focus_missing_;
    }
    if (temporal_) {
      node_.Info() << "temporal fit: rotated by scene/pose for " << rotated_
                   << " frames, no pose of their own for " << rotation_missing_;
    }
  }
  if (aux_views_) aux_views_->LogSummary();
}

}  // namespace probeless::scene_light
