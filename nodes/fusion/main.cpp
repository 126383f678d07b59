// fusion: real-time CPU KinectFusion and the image-space depth merge (Gruber et al. 2015 §4) as a
// node. Subscribes camera/depth (depth16 or float32), camera/image (rgb8, bgr8 or mono8; used as
// the merge's intensity guidance, assumed registered to the depth), camera/camera_info and
// ~/reset (any probeless_msgs/Header: forget the map). Publishes, per frame and in this order,
// scene/tracking (TrackingStatus: the tracking-quality verdict, recon/tracking_quality.h, with
// running counts), scene/pose (camera -> world, parent param world_frame; tracked and uncertain
// frames only, none for a lost frame) and scene/gbuffer (G_r: merged depth, normals, colour;
// GeometryBuffer in the depth camera's frame; for uncertain and lost frames the raw depth merged
// without the volume). A change of the tracking state is logged once (a warning when it leaves
// "tracked", an info line when it comes back), not every frame. At shutdown one summary line
// on stdout: "fusion: frames=N tracked=T uncertain=U lost=L relocalised=R", plus a warning
// naming the lost share when L > 0.
//
// Params: volume_size (2.0 m), volume_resolution (256), volume_origin ([-1, -1.2, 0.5] m, in the
// first camera's frame), truncation (0.03 m), max_weight (64), threads (2), depth_min (0.3),
// depth_max (4.0), merge (true), merge_k (20), lambda_i (7), lambda_d (0.05 m), smooth_k (8),
// smooth_lambda_i (7), denoise_k (2), lambda_d_sigmas (3: the merge's agreement threshold is
// min(lambda_d, lambda_d_sigmas sigma(z)); 0 = the paper's lambda_d), depth_noise ([0.0012,
// 0.0019, 0.4]: sigma(z) = a + b (z - z0)^2 m), depth_quantisation (0 per m; see
// recon::MergeOptions), icp_iterations ([4, 5, 10], fine to coarse), mesh_out (""
// or a .ply path written at shutdown), world_frame ("world"), normals (G_r's normals: "depth" =
// from D''', "volume" = the TSDF gradient where D''' agrees with the volume; see
// recon::FusionOptions::normal_source), normal_gap (0.03 m), normal_gradient_step (1 voxel),
// publish_aux (false: publish the auxiliary orthographic views of §5.1 on scene/aux, an
// AuxiliaryViews with the G_r's header, before the G_r; left, right, top), aux_pixels (128 per
// side), aux_light (false: also the view from the light: subscribes scene/light, the ShLight
// scene_light publishes in the camera frame of a G_r, turns its dominant direction into the world
// with the pose of that G_r's stamp and adds the light view to every later frame's views). Reset:
// publish any probeless_msgs/Header on ~/reset (/fusion/reset). fail_on_lost_ratio (-1 = off):
// exit 3 at shutdown when lost / frames exceeds it (0: any lost frame). checkpoint ("" = off, or
// a file path): the map survives a restart - at start-up a checkpoint found there is resumed (the
// first frame relocalises against it; a file that is not a valid checkpoint for these volume
// params is a bad param, exit 2), every checkpoint_frames (30) integrated frames and at shutdown
// the map is written there atomically (recon/checkpoint.h, on a thread of its own), and a reset
// removes it.
//
// A frame is processed when its depth and its image (same header.stamp_ns) have both arrived, or
// on the depth alone when no image with that stamp comes before the next depth. Exit: 0 on
// SIGINT/SIGTERM, 3 then when fail_on_lost_ratio is exceeded, 2 on bad params (and a bad
// checkpoint), 1 otherwise (also when the checkpoint at shutdown cannot be written).
#include <chrono>
#include <cmath>
#include <cstdio>
#include <optional>
#include <string>
#include <vector>

#include "outputs.h"
#include "params.h"
#include "probeless/msgs/msgs.h"
#include "probeless/node/node.h"
#include "probeless/node/stamp_cache.h"
#include "probeless/recon/checkpoint.h"
#include "probeless/recon/msgs_io.h"
#include "probeless/recon/pipeline.h"

namespace {

using namespace probeless;

struct PendingDepth {
  int64_t stamp_ns = 0;
  recon::DepthImage depth;
  recon::Intrinsics intrinsics;
  msgs::Header header;
};

struct PendingImage {
  msgs::Image image;
  std::vector<std::byte> payload;
  recon::GreyImage grey;
};

int Run(int argc, char** argv) {
  node::Node node(argc, argv, "fusion");
  const fusion::FusionParams params = fusion::ReadParams(node);
  const recon::FusionOptions& options = params.options;
  const std::string& mesh_out = params.mesh_out;
  const std::string& world_frame = params.world_frame;
  const bool publish_aux = params.publish_aux;
  const int aux_pixels = params.aux_pixels;
  const bool aux_light = params.aux_light;
  const double fail_on_lost_ratio = params.fail_on_lost_ratio;
  const std::string& checkpoint_path = params.checkpoint_path;
  const int checkpoint_frames = params.checkpoint_frames;
  recon::FusionPipeline pipeline(options);
  std::optional<recon::CheckpointWriter> checkpoint;
  if (!checkpoint_path.empty()) {
    if (const auto bytes = recon::ReadFileIfExists(checkpoint_path)) {
      pipeline.Resume(*bytes, "checkpoint '" + checkpoint_path + "'");
      node.Info() << "resumed the map from " << checkpoint_path << " ("
                  << pipeline.volume().ObservedBricks()
                  << " bricks); the first frame relocalises against it";
    }
    checkpoint.emplace(checkpoint_path);
  }
  int integrated_since_checkpoint = 0;
  // Hands the map to the checkpoint writer; a failed earlier write is reported, not fatal.
  auto save_checkpoint = [&] {
    integrated_since_checkpoint = 0;
    try {
      const auto t0 = std::chrono::steady_clock::now();
      std::vector<std::byte> bytes = pipeline.Checkpoint();
      node.Debug() << "checkpoint of " << bytes.size() << " bytes serialised in "
                   << std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() -
                                                                t0)
                          .count()
                   << " ms";
      checkpoint->Submit(std::move(bytes));
    } catch (const recon::ReconError& e) {
      node.Error() << e.what() << " (the map is not checkpointed)";
    }
  };

  bus::Subscriber depth_sub = node.CreateSubscriber<msgs::Image>("camera/depth");
  bus::Subscriber image_sub = node.CreateSubscriber<msgs::Image>("camera/image");
  bus::Subscriber info_sub = node.CreateSubscriber<msgs::CameraInfo>("camera/camera_info");
  bus::Subscriber reset_sub = node.CreateSubscriber<msgs::Header>("~/reset");
  fusion::FusionOutputs outputs(node, world_frame, publish_aux ? aux_pixels : 0);
  std::optional<bus::Subscriber> light_sub;
  if (publish_aux && aux_light) {
    light_sub.emplace(node.CreateSubscriber<msgs::ShLight>("scene/light"));
  }
  // Poses of the last frames by stamp (to bring scene/light's camera-frame direction into the
  // world) and the light direction in the world (none until scene/light brings one).
  node::StampCache<recon::Pose> recent_poses(32);
  std::optional<recon::Vec3f> light_world;

  std::optional<msgs::CameraInfo> info;
  std::optional<PendingDepth> pending_depth;
  node::StampCache<PendingImage> last_image(1);  // the latest image, taken by exact stamp
  uint64_t frames = 0, tracked_frames = 0, uncertain_frames = 0, lost_frames = 0,
           relocalisations = 0;
  recon::TrackingState last_state = recon::TrackingState::kTracking;
  uint64_t lost_since = 0;  // frame number of the first lost frame of the current loss
  std::vector<double> total_ms;

  auto process = [&](PendingDepth& d, const PendingImage* image) {
    const recon::GreyImage* grey = nullptr;
    if (image != nullptr && image->grey.width == d.depth.width &&
        image->grey.height == d.depth.height) {
      grey = &image->grey;
    }
    const recon::FrameResult r =
        pipeline.Process(d.depth, d.intrinsics, grey, nullptr, d.header.stamp_ns);
    ++frames;
    total_ms.push_back(r.timings.total_ms);
    tracked_frames += r.state == recon::TrackingState::kTracking;
    uncertain_frames += r.state == recon::TrackingState::kUncertain;
    lost_frames += r.state == recon::TrackingState::kLost;
    relocalisations += r.relocalised;
    if (checkpoint && r.integrated && ++integrated_since_checkpoint >= checkpoint_frames) {
      save_checkpoint();
    }
    // One line per change of state, not per frame.
    if (r.state != last_state) {
      if (r.state == recon::TrackingState::kLost) {
        lost_since = frames;
        node.Warn() << "tracking lost at frame " << frames << ": " << r.quality.text
                    << " (not integrating; relocalising against the last good pose)";
      } else if (r.state == recon::TrackingState::kUncertain) {
        node.Warn() << "tracking uncertain at frame " << frames << ": " << r.quality.text
                    << " (pose published, not integrating)";
      } else if (r.relocalised) {
        node.Info() << "tracking resumed at frame " << frames << ": relocalised after "
                    << frames - lost_since << " lost frame(s)";
      } else {
        node.Info() << "tracking resumed at frame " << frames;
      }
      last_state = r.state;
    }
    outputs.PublishTracking(
        d.header, r, {frames, tracked_frames, uncertain_frames, lost_frames, relocalisations});
    if (r.state != recon::TrackingState::kLost) {
      outputs.PublishPose(d.header, r.camera_to_world);
      recent_poses.Add(d.header.stamp_ns, r.camera_to_world);
      if (outputs.has_aux()) {
        outputs.PublishAux(
            d.header, r.camera_to_world,
            recon::RaycastAuxiliaryViews(pipeline.volume(), r.camera_to_world, aux_pixels,
                                         light_world ? &*light_world : nullptr, pipeline.pool()));
      }
    }
    if (options.merge_enabled) {
      outputs.PublishGeometry(
          d.header, static_cast<uint32_t>(d.depth.width), static_cast<uint32_t>(d.depth.height),
          pipeline.merged().denoised, pipeline.merged_normals(), image ? &image->image : nullptr,
          image ? std::span<const std::byte>(image->payload) : std::span<const std::byte>());
    }
  };

  auto on_depth = [&](bus::Sample&& s) {
    const auto m = msgs::ReadMessage<msgs::Image>(s.data());
    if (!info) {
      node.Warn() << "depth before camera_info: skipped";
      return;
    }
    // A depth still waiting for its image is processed without colour now.
    // Taken out of pending_depth before processing: a frame whose processing throws (rejected
    // by Spin with one error line) is not processed a second time with the next depth.
    if (pending_depth) {
      PendingDepth waiting = std::move(*pending_depth);
      pending_depth.reset();
      process(waiting, nullptr);
    }
    PendingDepth d;
    d.stamp_ns = m->header.stamp_ns;
    d.header = m->header;
    d.intrinsics = recon::IntrinsicsFromCameraInfo(*info);
    recon::DepthFromImage(*m, m.payload, info->depth_scale, options.preprocess.depth_min_m,
                          options.preprocess.depth_max_m, d.depth);
    if (const PendingImage* image = last_image.Exact(d.stamp_ns)) {
      process(d, image);
    } else {
      pending_depth = std::move(d);
    }
  };
  auto on_image = [&](bus::Sample&& s) {
    const auto m = msgs::ReadMessage<msgs::Image>(s.data());
    PendingImage img;
    img.image = *m;
    recon::GreyFromImage(*m, m.payload, img.grey);
    img.payload.assign(m.payload.begin(), m.payload.begin() + m->PayloadBytes());
    last_image.Add(m->header.stamp_ns, std::move(img));
    const PendingImage* image = pending_depth ? last_image.Exact(pending_depth->stamp_ns) : nullptr;
    if (image != nullptr) {
      PendingDepth waiting = std::move(*pending_depth);
      pending_depth.reset();
      process(waiting, image);
    }
  };
  std::vector<node::Handler> handlers = {
      {&info_sub,
       [&](bus::Sample&& s) {
         const auto m = msgs::ReadMessage<msgs::CameraInfo>(s.data());
         recon::IntrinsicsFromCameraInfo(*m);  // validates
         info = *m;
       }},
      {&image_sub, on_image},
      {&depth_sub, on_depth},
      {&reset_sub,
       [&](bus::Sample&&) {
         pipeline.Reset();
         if (checkpoint) {
           checkpoint->Discard();  // the old map must not come back on a restart
           integrated_since_checkpoint = 0;
         }
         pending_depth.reset();
         recent_poses.Clear();
         light_world.reset();
         last_state = recon::TrackingState::kTracking;  // a new map starts tracked
         node.Info() << "reset: map cleared";
       }},
  };
  if (light_sub) {
    handlers.push_back({&*light_sub, [&](bus::Sample&& s) {
                          const auto m = msgs::ReadMessage<msgs::ShLight>(s.data());
                          const float* dir = m->dominant_direction;
                          const float len2 = dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2];
                          if (!(len2 > 1e-6f) || !std::isfinite(len2)) return;  // none
                          if (const recon::Pose* pose = recent_poses.Exact(m->header.stamp_ns)) {
                            light_world = recon::Normalized(pose->Rotate({dir[0], dir[1], dir[2]}));
                            return;
                          }
                          node.Debug() << "scene/light for an unknown stamp: ignored";
                        }});
  }
  node.Info() << "fusion: " << options.volume.resolution << "^3 voxels over "
              << options.volume.size_m << " m, " << options.threads << " threads";
  node.Spin(handlers);
  if (pending_depth) process(*pending_depth, nullptr);
  bool checkpoint_failed = false;
  if (checkpoint) {
    try {
      checkpoint->Submit(pipeline.Checkpoint());
      checkpoint->Flush();
      node.Info() << "map checkpointed to " << checkpoint_path << " ("
                  << pipeline.volume().ObservedBricks() << " bricks, " << checkpoint->written()
                  << " checkpoints this run)";
    } catch (const recon::ReconError& e) {
      node.Error() << e.what();
      checkpoint_failed = true;
    }
  }
  std::sort(total_ms.begin(), total_ms.end());
  node.Info() << "processed " << frames << " frames, median "
              << (total_ms.empty() ? 0.0 : total_ms[total_ms.size() / 2]) << " ms";
  if (!mesh_out.empty()) {
    const recon::Mesh mesh = pipeline.volume().ExtractMesh(pipeline.pool());
    recon::WritePly(mesh, mesh_out);
    node.Info() << "wrote " << mesh.indices.size() / 3 << " triangles to " << mesh_out;
  }
  // The run's summary: one line a launch log or a test can read.
  std::printf("fusion: frames=%llu tracked=%llu uncertain=%llu lost=%llu relocalised=%llu\n",
              static_cast<unsigned long long>(frames),
              static_cast<unsigned long long>(tracked_frames),
              static_cast<unsigned long long>(uncertain_frames),
              static_cast<unsigned long long>(lost_frames),
              static_cast<unsigned long long>(relocalisations));
  std::fflush(stdout);
  const double lost_ratio = frames > 0 ? static_cast<double>(lost_frames) / frames : 0.0;
  if (lost_frames > 0) {
    node.Warn() << "map unreliable: " << lost_frames << " of " << frames << " frames lost ("
                << 100.0 * lost_ratio << " %), " << uncertain_frames << " uncertain, "
                << relocalisations << " relocalisations";
  }
  if (fail_on_lost_ratio >= 0 && lost_ratio > fail_on_lost_ratio) {
    node.Error() << "lost " << lost_frames << " of " << frames << " frames, more than "
                 << "fail_on_lost_ratio " << fail_on_lost_ratio;
    return 3;
  }
  return checkpoint_failed ? 1 : 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return Run(argc, argv);
  } catch (const probeless::node::NodeError& e) {
    std::fprintf(stderr, "[error] [fusion] %s\n", e.what());
    return 2;
  } catch (const probeless::recon::ReconError& e) {
    std::fprintf(stderr, "[error] [fusion] %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "[error] [fusion] %s\n", e.what());
    return 1;
  }
}
