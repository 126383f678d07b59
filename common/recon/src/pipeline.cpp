#include "probeless/recon/pipeline.h"

#include <algorithm>
#include <chrono>
#include <ctime>

namespace probeless::recon {

namespace {
double MsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}
// Process CPU time (all threads), milliseconds.
double CpuMs() {
  timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}
}  // namespace

void FusionOptions::Validate() const {
  volume.Validate();
  merge.Validate();
  if (threads < 1) throw ReconError("fusion: threads must be >= 1");
  if (track_level < 0 || track_level > 2) throw ReconError("fusion: track_level must be 0..2");
  if (preprocess.levels < 1 || preprocess.levels > 4) {
    throw ReconError("fusion: preprocess.levels must be 1..4");
  }
  if (static_cast<int>(icp.iterations.size()) < preprocess.levels) {
    throw ReconError("fusion: icp.iterations needs one entry per pyramid level (" +
                     std::to_string(preprocess.levels) + ")");
  }
  if (!(preprocess.depth_min_m >= 0) || !(preprocess.depth_max_m > preprocess.depth_min_m)) {
    throw ReconError("fusion: need 0 <= depth_min_m < depth_max_m");
  }
}

FusionPipeline::FusionPipeline(const FusionOptions& options) : options_(options) {
  options_.Validate();
  options_.preprocess.first_level = options_.track_level;
  pool_ = std::make_unique<ThreadPool>(options_.threads);
  volume_ = std::make_unique<TsdfVolume>(options_.volume);
  pose_ = options_.initial_pose;
}

FusionPipeline::~FusionPipeline() = default;

void FusionPipeline::Reset() {
  volume_->Reset();
  state_ = TrackingState::kEmpty;
  pose_ = options_.initial_pose;
}

FrameResult FusionPipeline::ProcessDepth16(const uint16_t* depth_mm, int width, int height,
                                           size_t stride_elements, double metres_per_unit,
                                           const Intrinsics& intrinsics,
                                           const GreyImage* intensity) {
  const auto t0 = std::chrono::steady_clock::now();
  DepthFromUnits(depth_mm, width, height, stride_elements, metres_per_unit,
                 options_.preprocess.depth_min_m, options_.preprocess.depth_max_m, depth_scratch_);
  const double convert_ms = MsSince(t0);
  FrameResult r = Process(depth_scratch_, intrinsics, intensity);
  r.timings.preprocess_ms += convert_ms;
  r.timings.total_ms += convert_ms;
  return r;
}

FrameResult FusionPipeline::Process(const DepthImage& depth, const Intrinsics& intrinsics,
                                    const GreyImage* intensity, const Pose* known_pose) {
  intrinsics.Validate("fusion");
  if (depth.Empty()) throw ReconError("fusion: empty depth image");
  if (depth.width != intrinsics.width || depth.height != intrinsics.height) {
    throw ReconError("fusion: depth is " + std::to_string(depth.width) + "x" +
                     std::to_string(depth.height) + " but the intrinsics are for " +
                     std::to_string(intrinsics.width) + "x" + std::to_string(intrinsics.height));
  }
  if (intensity != nullptr &&
      (intensity->width != depth.width || intensity->height != depth.height)) {
    throw ReconError("fusion: intensity is " + std::to_string(intensity->width) + "x" +
                     std::to_string(intensity->height) + " but the depth is " +
                     std::to_string(depth.width) + "x" + std::to_string(depth.height));
  }
  if (state_ != TrackingState::kEmpty && (frame_.raw_depth.width != intrinsics.width ||
                                          frame_.raw_depth.height != intrinsics.height)) {
    throw ReconError("fusion: frame size changed from " + std::to_string(frame_.raw_depth.width) +
                     "x" + std::to_string(frame_.raw_depth.height) + " (Reset first)");
  }
  ThreadPool* pool = pool_.get();
  FrameResult r;
  auto t = std::chrono::steady_clock::now();
  double c = CpuMs();
  Preprocess(depth, intrinsics, options_.preprocess, frame_, pool);
  r.timings.preprocess_ms = MsSince(t);
  r.timings.preprocess_cpu_ms = CpuMs() - c;

  bool integrate = true;
  if (known_pose != nullptr) {
    pose_ = *known_pose;
    state_ = TrackingState::kTracking;
  } else if (state_ != TrackingState::kEmpty) {
    t = std::chrono::steady_clock::now();
    c = CpuMs();
    IcpOptions icp = options_.icp;
    if (state_ == TrackingState::kLost) {
      // Relocalisation against the model from the last good pose: more coarse iterations.
      for (size_t l = 1; l < icp.iterations.size(); ++l) icp.iterations[l] *= 2;
    }
    r.icp = TrackIcp(frame_, model_, pose_, icp, pool);
    r.timings.icp_ms = MsSince(t);
    r.timings.icp_cpu_ms = CpuMs() - c;
    if (r.icp.ok) {
      r.relocalised = state_ == TrackingState::kLost;
      pose_ = r.icp.camera_to_world;
      state_ = TrackingState::kTracking;
    } else {
      state_ = TrackingState::kLost;
      integrate = false;
    }
  } else {
    state_ = TrackingState::kTracking;
  }
  r.camera_to_world = pose_;
  r.state = state_;

  if (integrate) {
    t = std::chrono::steady_clock::now();
    c = CpuMs();
    volume_->Integrate(frame_.raw_depth, intrinsics, pose_, pool);
    r.timings.integrate_ms = MsSince(t);
    r.timings.integrate_cpu_ms = CpuMs() - c;
    r.integrated = true;
    t = std::chrono::steady_clock::now();
    c = CpuMs();
    const Intrinsics track_k = intrinsics.Level(options_.track_level);
    volume_->Raycast(pose_, track_k, view_, pool);
    BuildModelPyramid(view_, pose_, track_k, options_.preprocess.levels, model_);
    // D_v at the input resolution (nearest neighbour).
    volume_depth_.Resize(intrinsics.width, intrinsics.height);
    const int s = options_.track_level;
    constexpr int kTasks = 8;
    ParallelFor(pool, kTasks, [&](int task) {
      for (int y = intrinsics.height * task / kTasks; y < intrinsics.height * (task + 1) / kTasks;
           ++y) {
        const int vy = std::min(y >> s, view_.depth.height - 1);
        for (int x = 0; x < intrinsics.width; ++x) {
          volume_depth_.At(x, y) = view_.depth.At(std::min(x >> s, view_.depth.width - 1), vy);
        }
      }
    });
    r.timings.raycast_ms = MsSince(t);
    r.timings.raycast_cpu_ms = CpuMs() - c;
  } else {
    // Lost: the model stays the raycast from the last good pose (for relocalisation); D_v of
    // this view is unknown.
    volume_depth_.Resize(intrinsics.width, intrinsics.height);
    std::fill(volume_depth_.data.begin(), volume_depth_.data.end(), 0.0f);
  }

  if (options_.merge_enabled) {
    t = std::chrono::steady_clock::now();
    c = CpuMs();
    const GreyImage* grey = intensity;
    if (grey == nullptr) {
      no_intensity_.Resize(depth.width, depth.height);
      grey = &no_intensity_;
    }
    MergeDepth(frame_.raw_depth, volume_depth_, *grey, options_.merge, merged_, pool);
    ComputeVertexMap(merged_.denoised, intrinsics, merged_vertices_, pool);
    ComputeNormalMap(merged_vertices_, merged_normals_, pool);
    r.timings.merge_ms = MsSince(t);
    r.timings.merge_cpu_ms = CpuMs() - c;
  }
  r.timings.total_ms = r.timings.preprocess_ms + r.timings.icp_ms + r.timings.integrate_ms +
                       r.timings.raycast_ms + r.timings.merge_ms;
  return r;
}

}  // namespace probeless::recon
