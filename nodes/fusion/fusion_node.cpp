#include "fusion_node.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>
#include <utility>

namespace probeless::fusion {

FusionNode::FusionNode(node::Node& node, const FusionParams& params)
    : node_(node),
      params_(params),
      pipeline_(params_.options),
      checkpoint_(OpenCheckpoint()),
      depth_sub_(node.CreateSubscriber<msgs::Image>("camera/depth")),
      image_sub_(node.CreateSubscriber<msgs::Image>("camera/image")),
      info_sub_(node.CreateSubscriber<msgs::CameraInfo>("camera/camera_info")),
      reset_sub_(node.CreateSubscriber<msgs::Header>("~/reset")),
      outputs_(node, params_.world_frame, params_.publish_aux ? params_.aux_pixels : 0) {
  if (params_.publish_aux && params_.aux_light) {
    light_sub_.emplace(node.CreateSubscriber<msgs::ShLight>("scene/light"));
  }
}

std::optional<recon::CheckpointWriter> FusionNode::OpenCheckpoint() {
  const std::string& path = params_.checkpoint_path;
  if (path.empty()) return std::nullopt;
  if (const auto bytes = recon::ReadFileIfExists(path)) {
    pipeline_.Resume(*bytes, "checkpoint '" + path + "'");
    node_.Info() << "resumed the map from " << path << " (" << pipeline_.volume().ObservedBricks()
                 << " bricks); the first frame relocalises against it";
  }
  return std::optional<recon::CheckpointWriter>(std::in_place, path);
}

void FusionNode::SaveCheckpoint() {
  integrated_since_checkpoint_ = 0;
  try {
    const auto t0 = std::chrono::steady_clock::now();
    std::vector<std::byte> bytes = pipeline_.Checkpoint();
    node_.Debug()
        << "checkpoint of " << bytes.size() << " bytes serialised in "
        << std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count()
        << " ms";
    checkpoint_->Submit(std::move(bytes));
  } catch (const recon::ReconError& e) {
    node_.Error() << e.what() << " (the map is not checkpointed)";
  }
}

void FusionNode::Process(const recon::DepthFrame& d, const recon::ColourFrame* image) {
  const recon::GreyImage* grey = nullptr;
  if (image != nullptr && image->grey.width == d.depth.width &&
      image->grey.height == d.depth.height) {
    grey = &image->grey;
  }
  const recon::FrameResult r =
      pipeline_.Process(d.depth, d.intrinsics, grey, nullptr, d.header.stamp_ns);
  ++counts_.frames;
  total_ms_.push_back(r.timings.total_ms);
  counts_.tracked += r.state == recon::TrackingState::kTracking;
  counts_.uncertain += r.state == recon::TrackingState::kUncertain;
  counts_.lost += r.state == recon::TrackingState::kLost;
  counts_.relocalisations += r.relocalised;
  if (checkpoint_ && r.integrated && ++integrated_since_checkpoint_ >= params_.checkpoint_frames) {
    SaveCheckpoint();
  }
  LogStateChange(r);
  outputs_.PublishTracking(d.header, r, counts_);
  if (r.state != recon::TrackingState::kLost) {
    outputs_.PublishPose(d.header, r.camera_to_world);
    recent_poses_.Add(d.header.stamp_ns, r.camera_to_world);
    if (outputs_.has_aux()) {
      outputs_.PublishAux(
          d.header, r.camera_to_world,
          recon::RaycastAuxiliaryViews(pipeline_.volume(), r.camera_to_world, params_.aux_pixels,
                                       light_world_ ? &*light_world_ : nullptr, pipeline_.pool()));
    }
  }
  if (params_.options.merge_enabled) {
    outputs_.PublishGeometry(
        d.header, static_cast<uint32_t>(d.depth.width), static_cast<uint32_t>(d.depth.height),
        pipeline_.merged().denoised, pipeline_.merged_normals(), image ? &image->image : nullptr,
        image ? std::span<const std::byte>(image->payload) : std::span<const std::byte>());
  }
}

void FusionNode::LogStateChange(const recon::FrameResult& r) {
  if (r.state == last_state_) return;
  const uint64_t frames = counts_.frames;
  if (r.state == recon::TrackingState::kLost) {
    lost_since_ = frames;
    node_.Warn() << "tracking lost at frame " << frames << ": " << r.quality.text
                 << " (not integrating; relocalising against the last good pose)";
  } else if (r.state == recon::TrackingState::kUncertain) {
    node_.Warn() << "tracking uncertain at frame " << frames << ": " << r.quality.text
                 << " (pose published, not integrating)";
  } else if (r.relocalised) {
    node_.Info() << "tracking resumed at frame " << frames << ": relocalised after "
                 << frames - lost_since_ << " lost frame(s)";
  } else {
    node_.Info() << "tracking resumed at frame " << frames;
  }
  last_state_ = r.state;
}

void FusionNode::HoldCameraInfo(bus::Sample&& s) {
  const auto m = msgs::ReadMessage<msgs::CameraInfo>(s.data());
  recon::IntrinsicsFromCameraInfo(*m);  // validates
  info_ = *m;
}

void FusionNode::OnDepth(bus::Sample&& s) {
  const auto m = msgs::ReadMessage<msgs::Image>(s.data());
  if (!info_) {
    node_.Warn() << "depth before camera_info: skipped";
    return;
  }
  // A depth still waiting for its image is processed without colour now.
  // Taken out of pending_depth_ before processing: a frame whose processing throws (rejected
  // by Spin with one error line) is not processed a second time with the next depth.
  if (pending_depth_) {
    const recon::DepthFrame waiting = std::move(*pending_depth_);
    pending_depth_.reset();
    Process(waiting, nullptr);
  }
  recon::DepthFrame d =
      recon::DepthFrameFromMessages(*m, m.payload, *info_, params_.options.preprocess.depth_min_m,
                                    params_.options.preprocess.depth_max_m);
  if (const recon::ColourFrame* image = last_image_.Exact(d.header.stamp_ns)) {
    Process(d, image);
  } else {
    pending_depth_ = std::move(d);
  }
}

void FusionNode::OnImage(bus::Sample&& s) {
  const auto m = msgs::ReadMessage<msgs::Image>(s.data());
  last_image_.Add(m->header.stamp_ns, recon::ColourFrameFromMessage(*m, m.payload));
  const recon::ColourFrame* image =
      pending_depth_ ? last_image_.Exact(pending_depth_->header.stamp_ns) : nullptr;
  if (image != nullptr) {
    const recon::DepthFrame waiting = std::move(*pending_depth_);
    pending_depth_.reset();
    Process(waiting, image);
  }
}

void FusionNode::OnReset(bus::Sample&&) {
  pipeline_.Reset();
  if (checkpoint_) {
    checkpoint_->Discard();  // the old map must not come back on a restart
    integrated_since_checkpoint_ = 0;
  }
  pending_depth_.reset();
  recent_poses_.Clear();
  light_world_.reset();
  last_state_ = recon::TrackingState::kTracking;  // a new map starts tracked
  node_.Info() << "reset: map cleared";
}

void FusionNode::OnLight(bus::Sample&& s) {
  const auto m = msgs::ReadMessage<msgs::ShLight>(s.data());
  const std::optional<recon::Vec3f> dir = recon::DominantDirection(*m);
  if (!dir) return;  // none
  if (const recon::Pose* pose = recent_poses_.Exact(m->header.stamp_ns)) {
    light_world_ = recon::Normalized(pose->Rotate(*dir));
    return;
  }
  node_.Debug() << "scene/light for an unknown stamp: ignored";
}

int FusionNode::Spin() {
  std::vector<node::Handler> handlers = {
      {&info_sub_, [this](bus::Sample&& s) { HoldCameraInfo(std::move(s)); }},
      {&image_sub_, [this](bus::Sample&& s) { OnImage(std::move(s)); }},
      {&depth_sub_, [this](bus::Sample&& s) { OnDepth(std::move(s)); }},
      {&reset_sub_, [this](bus::Sample&& s) { OnReset(std::move(s)); }},
  };
  if (light_sub_) {
    handlers.push_back({&*light_sub_, [this](bus::Sample&& s) { OnLight(std::move(s)); }});
  }
  const recon::FusionOptions& options = params_.options;
  node_.Info() << "fusion: " << options.volume.resolution << "^3 voxels over "
               << options.volume.size_m << " m, " << options.threads << " threads";
  node_.Spin(handlers);
  if (pending_depth_) Process(*pending_depth_, nullptr);
  bool checkpoint_failed = false;
  if (checkpoint_) {
    try {
      checkpoint_->Submit(pipeline_.Checkpoint());
      checkpoint_->Flush();
      node_.Info() << "map checkpointed to " << params_.checkpoint_path << " ("
                   << pipeline_.volume().ObservedBricks() << " bricks, " << checkpoint_->written()
                   << " checkpoints this run)";
    } catch (const recon::ReconError& e) {
      node_.Error() << e.what();
      checkpoint_failed = true;
    }
  }
  std::sort(total_ms_.begin(), total_ms_.end());
  node_.Info() << "processed " << counts_.frames << " frames, median "
               << (total_ms_.empty() ? 0.0 : total_ms_[total_ms_.size() / 2]) << " ms";
  if (!params_.mesh_out.empty()) {
    const recon::Mesh mesh = pipeline_.volume().ExtractMesh(pipeline_.pool());
    recon::WritePly(mesh, params_.mesh_out);
    node_.Info() << "wrote " << mesh.indices.size() / 3 << " triangles to " << params_.mesh_out;
  }
  // The run's summary: one line a launch log or a test can read.
  std::printf("fusion: frames=%llu tracked=%llu uncertain=%llu lost=%llu relocalised=%llu\n",
              static_cast<unsigned long long>(counts_.frames),
              static_cast<unsigned long long>(counts_.tracked),
              static_cast<unsigned long long>(counts_.uncertain),
              static_cast<unsigned long long>(counts_.lost),
              static_cast<unsigned long long>(counts_.relocalisations));
  std::fflush(stdout);
  const uint64_t frames = counts_.frames, lost = counts_.lost;
  const double lost_ratio = frames > 0 ? static_cast<double>(lost) / frames : 0.0;
  if (lost > 0) {
    node_.Warn() << "map unreliable: " << lost << " of " << frames << " frames lost ("
                 << 100.0 * lost_ratio << " %), " << counts_.uncertain << " uncertain, "
                 << counts_.relocalisations << " relocalisations";
  }
  if (params_.fail_on_lost_ratio >= 0 && lost_ratio > params_.fail_on_lost_ratio) {
    node_.Error() << "lost " << lost << " of " << frames << " frames, more than "
                  << "fail_on_lost_ratio " << params_.fail_on_lost_ratio;
    return 3;
  }
  return checkpoint_failed ? 1 : 0;
}

}  // namespace probeless::fusion
