#include "probeless/recon/pipeline.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <ctime>

#include "byte_io.h"

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
  if (!(volume_normal_max_gap_m >= 0)) {
    throw ReconError("fusion: volume_normal_max_gap_m must be >= 0");
  }
  if (volume_normal_block < 1 || volume_normal_block > 4) {
    throw ReconError("fusion: volume_normal_block must be 1..4");
  }
  if (!(volume_normal_step_voxels > 0 && volume_normal_step_voxels <= 4)) {
    throw ReconError("fusion: volume_normal_step_voxels must be in (0, 4]");
  }
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
  quality.Validate();
  if (!(relocalise_max_distance_m > 0)) {
    throw ReconError("fusion: relocalise_max_distance_m must be > 0");
  }
  if (!(relocalise_max_extrapolation_s >= 0)) {
    throw ReconError("fusion: relocalise_max_extrapolation_s must be >= 0");
  }
}

FusionPipeline::FusionPipeline(const FusionOptions& options)
    : options_(options), monitor_(options.quality) {
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
  monitor_.Reset();
  uncertain_run_ = 0;
  since_good_s_ = 0;
  last_stamp_ns_ = 0;
  resume_model_ = false;
}

namespace {
constexpr char kCheckpointMagic[8] = {'P', 'L', 'F', 'U', 'S', 'M', 'A', 'P'};
constexpr uint32_t kCheckpointVersion = 1;
constexpr uint32_t kByteOrderMark = 0x01020304;
}  // namespace

std::vector<std::byte> FusionPipeline::Checkpoint() const {
  std::vector<std::byte> out;
  if (state_ == TrackingState::kEmpty) return out;
  detail::ByteWriter w(out);
  w.PutBytes(kCheckpointMagic, sizeof kCheckpointMagic);
  w.Put(kCheckpointVersion);
  w.Put(kByteOrderMark);
  const VolumeOptions& v = volume_->options();
  w.Put(int32_t{v.resolution});
  w.Put(v.size_m);
  w.Put(v.origin);
  w.Put(v.truncation_m);
  w.Put(int32_t{v.max_weight});
  w.Put(model_.camera_to_world);  // the last integrated pose
  w.Put(since_good_s_);
  w.Put(last_stamp_ns_);
  const TrackingQualityMonitor::SavedState m = monitor_.Saved();
  w.Put(int32_t{m.accepted});
  w.Put(m.mean_rms_m);
  w.Put(m.mean_inlier_fraction);
  w.Put(uint8_t{m.have_velocity});
  w.Put(m.velocity);
  volume_->AppendObservedBricks(out);
  w.Put(detail::Checksum(out));
  return out;
}

void FusionPipeline::Resume(std::span<const std::byte> checkpoint, const std::string& name) {
  Reset();
  try {
    if (checkpoint.size() < sizeof kCheckpointMagic ||
        std::memcmp(checkpoint.data(), kCheckpointMagic, sizeof kCheckpointMagic) != 0) {
      throw ReconError(name + ": not a fusion checkpoint (expected it to start with PLFUSMAP)");
    }
    detail::ByteReader r(checkpoint, name);
    char magic[8];
    r.GetBytes(magic, sizeof magic);
    const uint32_t version = r.Get<uint32_t>();
    if (version != kCheckpointVersion) {
      throw ReconError(name + ": checkpoint version " + std::to_string(version) + ", expected " +
                       std::to_string(kCheckpointVersion));
    }
    if (r.Get<uint32_t>() != kByteOrderMark) {
      throw ReconError(name + ": written on a machine of another byte order");
    }
    r.Need(8);  // the checksum
    const auto body = checkpoint.first(checkpoint.size() - 8);
    uint64_t stored;
    std::memcpy(&stored, checkpoint.data() + body.size(), 8);
    if (detail::Checksum(body) != stored) {
      throw ReconError(name + ": checksum mismatch (the file is corrupt or truncated)");
    }
    const VolumeOptions& v = volume_->options();
    auto differs = [&](const char* field, const std::string& theirs, const std::string& ours) {
      throw ReconError(name + ": written for volume " + field + " " + theirs +
                       ", the pipeline has " + ours);
    };
    const int32_t resolution = r.Get<int32_t>();
    if (resolution != v.resolution) {
      differs("resolution", std::to_string(resolution), std::to_string(v.resolution));
    }
    const float size_m = r.Get<float>();
    if (size_m != v.size_m) differs("size_m", std::to_string(size_m), std::to_string(v.size_m));
    const Vec3f origin = r.Get<Vec3f>();
    if (origin.x != v.origin.x || origin.y != v.origin.y || origin.z != v.origin.z) {
      auto text = [](Vec3f o) {
        std::string t = "(";
        t += std::to_string(o.x);
        t += ", ";
        t += std::to_string(o.y);
        t += ", ";
        t += std::to_string(o.z);
        return t + ")";
      };
      differs("origin", text(origin), text(v.origin));
    }
    const float truncation_m = r.Get<float>();
    if (truncation_m != v.truncation_m) {
      differs("truncation_m", std::to_string(truncation_m), std::to_string(v.truncation_m));
    }
    const int32_t max_weight = r.Get<int32_t>();
    if (max_weight != v.max_weight) {
      differs("max_weight", std::to_string(max_weight), std::to_string(v.max_weight));
    }
    const Pose good = r.Get<Pose>();
    for (double x : good.r) {
      if (!std::isfinite(x)) throw ReconError(name + ": the saved pose is not finite");
    }
    for (double x : good.t) {
      if (!std::isfinite(x)) throw ReconError(name + ": the saved pose is not finite");
    }
    const double since_good_s = r.Get<double>();
    if (!(since_good_s >= 0) || !std::isfinite(since_good_s)) {
      throw ReconError(name + ": seconds since the saved pose must be finite and >= 0");
    }
    const int64_t last_stamp_ns = r.Get<int64_t>();
    TrackingQualityMonitor::SavedState m;
    m.accepted = r.Get<int32_t>();
    m.mean_rms_m = r.Get<float>();
    m.mean_inlier_fraction = r.Get<float>();
    m.have_velocity = r.Get<uint8_t>() != 0;
    r.GetBytes(m.velocity, sizeof m.velocity);
    try {
      monitor_.Restore(m);
    } catch (const ReconError& e) {
      throw ReconError(name + ": " + e.what());
    }
    size_t offset = r.offset();
    volume_->ReadObservedBricks(body, &offset, name);
    if (offset != body.size()) {
      throw ReconError(name + ": " + std::to_string(body.size() - offset) +
                       " bytes after the last brick");
    }
    model_.camera_to_world = good;
    pose_ = good;
    since_good_s_ = since_good_s;
    last_stamp_ns_ = last_stamp_ns;
    state_ = TrackingState::kLost;  // relocalise against the restored map
    resume_model_ = true;
  } catch (const ReconError&) {
    Reset();
    throw;
  }
}

void FusionPipeline::Track(double interval_s, FrameResult& r) {
  const double dt = interval_s > 0 ? interval_s : options_.quality.nominal_frame_interval_s;
  if (state_ != TrackingState::kLost) {
    r.icp = TrackIcp(frame_, model_, pose_, options_.icp, pool_.get());
    r.quality = monitor_.Assess(r.icp, pose_, interval_s, false, uncertain_run_);
    if (r.quality.state == TrackingState::kTracking) {
      monitor_.Accept(r.icp, pose_, r.icp.camera_to_world, interval_s);
      pose_ = r.icp.camera_to_world;
      uncertain_run_ = 0;
    } else if (r.quality.state == TrackingState::kUncertain) {
      // Doubtful: keep tracking from the estimate, but it must not enter the map.
      pose_ = r.icp.camera_to_world;
      ++uncertain_run_;
    } else {
      pose_ = model_.camera_to_world;  // the last good pose
      uncertain_run_ = 0;
    }
    state_ = r.quality.state;
    since_good_s_ = state_ == TrackingState::kTracking ? 0.0 : since_good_s_ + dt;
    return;
  }
  // Relocalisation against the model raycast from the last good pose, from that pose and from
  // its constant-velocity extrapolation (a camera that kept moving during the loss): a wide
  // association gate with twice the coarse iterations first, then the normal gate from there.
  since_good_s_ += dt;
  const Pose& good = model_.camera_to_world;
  const double elapsed = std::min(since_good_s_, options_.relocalise_max_extrapolation_s);
  const Pose candidates[2] = {good, monitor_.Predict(good, elapsed)};
  const Pose moved = good.Inverse() * candidates[1];
  const bool distinct = std::sqrt(moved.t[0] * moved.t[0] + moved.t[1] * moved.t[1] +
                                  moved.t[2] * moved.t[2]) > 0.005 ||
                        moved.RotationAngle() > 0.5 * 3.14159265358979 / 180;
  IcpOptions wide = options_.icp;
  wide.max_distance_m = std::max(wide.max_distance_m, options_.relocalise_max_distance_m);
  for (size_t l = 1; l < wide.iterations.size(); ++l) wide.iterations[l] *= 2;
  bool have = false;
  for (int c = 0; c < (distinct ? 2 : 1); ++c) {
    const IcpResult coarse = TrackIcp(frame_, model_, candidates[c], wide, pool_.get());
    IcpResult fine = TrackIcp(frame_, model_, coarse.ok ? coarse.camera_to_world : candidates[c],
                              options_.icp, pool_.get());
    const TrackingQuality q = monitor_.Assess(fine, good, elapsed, true, 0);
    const bool better =
        !have || (q.state == TrackingState::kTracking &&
                  (r.quality.state != TrackingState::kTracking || fine.rms_m < r.icp.rms_m));
    if (better) {
      r.icp = fine;
      r.quality = q;
      have = true;
    }
  }
  if (r.quality.state == TrackingState::kTracking) {
    pose_ = r.icp.camera_to_world;
    state_ = TrackingState::kTracking;
    r.relocalised = true;
    monitor_.ForgetVelocity();  // the motion across the loss is unknown
    since_good_s_ = 0;
  } else {
    pose_ = good;
  }
  uncertain_run_ = 0;
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
                                    const GreyImage* intensity, const Pose* known_pose,
                                    int64_t stamp_ns) {
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
  if (state_ != TrackingState::kEmpty && !resume_model_ &&
      (frame_.raw_depth.width != intrinsics.width ||
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

  const double interval_s = stamp_ns > 0 && last_stamp_ns_ > 0 && stamp_ns > last_stamp_ns_
                                ? (stamp_ns - last_stamp_ns_) * 1e-9
                                : 0.0;
  if (stamp_ns > 0) last_stamp_ns_ = stamp_ns;
  if (resume_model_) {
    // The first frame after Resume: the model to relocalise against, from the restored volume at
    // the saved pose, with this frame's intrinsics.
    const Intrinsics track_k = intrinsics.Level(options_.track_level);
    const Pose good = model_.camera_to_world;
    volume_->Raycast(good, track_k, view_, pool);
    BuildModelPyramid(view_, good, track_k, options_.preprocess.levels, model_);
    resume_model_ = false;
  }
  if (known_pose != nullptr || state_ == TrackingState::kEmpty) {
    pose_ = known_pose != nullptr ? *known_pose : pose_;
    state_ = TrackingState::kTracking;
    r.quality.state = TrackingState::kTracking;
    r.quality.score = 1;
    uncertain_run_ = 0;
    since_good_s_ = 0;
  } else {
    t = std::chrono::steady_clock::now();
    c = CpuMs();
    Track(interval_s, r);
    r.timings.icp_ms = MsSince(t);
    r.timings.icp_cpu_ms = CpuMs() - c;
  }
  const bool integrate = state_ == TrackingState::kTracking;
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
    // Uncertain or lost: the model stays the raycast from the last good pose (for tracking and
    // relocalisation); D_v of this view is not trusted.
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
    if (options_.normal_source == NormalSource::kVolume && integrate) {
      VolumeNormals();
    }
    r.timings.merge_ms = MsSince(t);
    r.timings.merge_cpu_ms = CpuMs() - c;
  }
  r.timings.total_ms = r.timings.preprocess_ms + r.timings.icp_ms + r.timings.integrate_ms +
                       r.timings.raycast_ms + r.timings.merge_ms;
  return r;
}

void FusionPipeline::VolumeNormals() {
  const DepthImage& d = merged_.denoised;
  const float gap = options_.volume_normal_max_gap_m;
  const float step = options_.volume_normal_step_voxels;
  const int block = options_.volume_normal_block;
  const Pose& c2w = pose_;
  const double* r = c2w.r;
  // D''' is on the volume's surface at (x, y) (not a moving object, hole fill or unseen part).
  auto agrees = [&](int x, int y) {
    const float z = d.At(x, y), zv = volume_depth_.At(x, y);
    return z > 0 && zv > 0 && std::fabs(z - zv) <= gap;
  };
  // The camera-frame normal of the volume at pixel (x, y)'s D''' point; false where D''' and D_v
  // disagree or the volume has no gradient there.
  auto normal_at = [&](int x, int y, Vec3f* out) {
    if (!agrees(x, y)) return false;
    const Vec3f p = merged_vertices_.At(x, y);
    Vec3f nw;
    if (!volume_->NormalAt(c2w.Apply(p), step, &nw)) return false;
    // R^T n: world -> camera.
    Vec3f n{static_cast<float>(r[0] * nw.x + r[3] * nw.y + r[6] * nw.z),
            static_cast<float>(r[1] * nw.x + r[4] * nw.y + r[7] * nw.z),
            static_cast<float>(r[2] * nw.x + r[5] * nw.y + r[8] * nw.z)};
    if (Dot(n, p) > 0) n = -1.0f * n;  // towards the camera
    *out = n;
    return true;
  };
  constexpr int kTasks = 16;
  if (block == 1) {
    ParallelFor(pool_.get(), kTasks, [&](int task) {
      for (int y = d.height * task / kTasks; y < d.height * (task + 1) / kTasks; ++y) {
        for (int x = 0; x < d.width; ++x) {
          Vec3f n;
          if (normal_at(x, y, &n)) merged_normals_.At(x, y) = n;
        }
      }
    });
    return;
  }
  // Anchors every `block` pixels in x and y (zero = none); every other agreeing pixel takes the
  // bilinear interpolation of its (up to) four surrounding anchors that lie on its surface (D'''
  // within the gap), renormalised, and is evaluated itself when none does.
  const int aw = (d.width - 1) / block + 2, ah = (d.height - 1) / block + 2;
  anchor_normals_.Resize(aw, ah);
  ParallelFor(pool_.get(), kTasks, [&](int task) {
    for (int ay = ah * task / kTasks; ay < ah * (task + 1) / kTasks; ++ay) {
      for (int ax = 0; ax < aw; ++ax) {
        const int x = ax * block, y = ay * block;
        Vec3f n{};
        if (x < d.width && y < d.height && !normal_at(x, y, &n)) n = {};
        anchor_normals_.At(ax, ay) = n;
      }
    }
  });
  const float inv_block = 1.0f / block;
  ParallelFor(pool_.get(), kTasks, [&](int task) {
    for (int y = d.height * task / kTasks; y < d.height * (task + 1) / kTasks; ++y) {
      const int ay = y / block;
      const float fy = (y - ay * block) * inv_block;
      for (int x = 0; x < d.width; ++x) {
        if (!agrees(x, y)) continue;
        const int ax = x / block;
        const float fx = (x - ax * block) * inv_block;
        const float z = d.At(x, y);
        Vec3f sum{};
        float weight = 0;
        for (int c = 0; c < 4; ++c) {
          const int cx = ax + (c & 1), cy = ay + (c >> 1);
          const float w = ((c & 1) ? fx : 1 - fx) * ((c >> 1) ? fy : 1 - fy);
          if (w <= 0) continue;
          const Vec3f n = anchor_normals_.At(cx, cy);
          if (n.x == 0 && n.y == 0 && n.z == 0) continue;
          if (std::fabs(d.At(cx * block, cy * block) - z) > gap) continue;
          sum = sum + w * n;
          weight += w;
        }
        Vec3f n;
        if (weight > 0 && Norm(sum) > 1e-6f) {
          merged_normals_.At(x, y) = Normalized(sum);
        } else if (normal_at(x, y, &n)) {
          merged_normals_.At(x, y) = n;
        }
      }
    }
  });
}

}  // namespace probeless::recon
