// The reconstruction pipeline of one camera stream (Gruber et al. 2015 §4 on KinectFusion):
// preprocess the depth, track the camera against the volume (ICP), integrate the depth into the
// TSDF volume, raycast G_v in the current view, and merge raw and volume depth into G_r
// (eq. 1-5). Every tracked frame passes the tracking-quality test (tracking_quality.h): an
// uncertain frame keeps its pose but is not integrated; a lost one is not integrated, reports the
// last good pose, and every following frame tries to relocalise against the model raycast from
// that pose (the last good pose and its constant-velocity extrapolation, a wide then a normal
// association gate) until a candidate passes the test as tracked; Reset() starts a new map.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "probeless/recon/depth_merge.h"
#include "probeless/recon/icp.h"
#include "probeless/recon/math.h"
#include "probeless/recon/preprocess.h"
#include "probeless/recon/thread_pool.h"
#include "probeless/recon/tracking_quality.h"
#include "probeless/recon/tsdf_volume.h"

namespace probeless::recon {

// Where G_r's normals come from (see FusionOptions::normal_source).
enum class NormalSource {
  kDepth,   // central differences of D''' (its vertex map), the paper's G_r
  kVolume,  // the TSDF gradient at D''''s points where D''' agrees with D_v, kDepth elsewhere
};

struct FusionOptions {
  VolumeOptions volume;  // in the world frame, see initial_pose
  PreprocessOptions preprocess;
  IcpOptions icp;
  TrackingQualityOptions quality;  // the tracking-quality test after ICP
  // Relocalisation: association gate of the first (wide) ICP pass from each candidate, metres
  // (the second pass uses icp.max_distance_m), and the longest extrapolation of the last
  // velocity across a loss, seconds.
  float relocalise_max_distance_m = 0.20f;
  double relocalise_max_extrapolation_s = 0.5;
  MergeOptions merge;
  bool merge_enabled = true;  // false: skip eq. 1-5 (G_r = nothing)
  // Pyramid level of tracking and of the model raycast: 0 = full resolution, 1 = half (default:
  // ICP on 320 x 240 / 160 x 120 / 80 x 60 for 640 x 480 input, G_v raycast at 320 x 240 and
  // upsampled (nearest) to the input size for the merge). The integration always uses the
  // full-resolution raw depth.
  int track_level = 1;
  int threads = 2;  // worker threads in all (>= 1)
  // G_r's normals. kVolume: at each pixel whose D''' is within volume_normal_max_gap_m (metres)
  // of D_v, the normal of the TSDF gradient (central differences at +-volume_normal_step_voxels
  // voxels, TsdfVolume::NormalAt) at D''''s back-projected point, rotated into the camera frame;
  // elsewhere (moving objects, unobserved or lost) the normals of D'''. The volume averages many
  // frames, so its gradient is far less affected by depth quantisation than D''''s differences.
  NormalSource normal_source = NormalSource::kDepth;
  float volume_normal_max_gap_m = 0.03f;
  float volume_normal_step_voxels = 1.0f;
  // The volume normal is evaluated every volume_normal_block pixels in x and y (anchors) and
  // interpolated bilinearly between the anchors on the same surface (D''' within
  // volume_normal_max_gap_m) in between; 1 = every pixel (about 3x the cost of 2).
  int volume_normal_block = 2;
  // Pose of the first frame (and after Reset), camera -> world. The default volume (origin
  // (-1, -1.2, 0.5), 2 m) then spans x in [-1, 1], y in [-1.2, 0.8] and z in [0.5, 2.5] m of the
  // first camera.
  Pose initial_pose;

  // Throws ReconError naming the first invalid field.
  void Validate() const;
};

// Milliseconds spent in each stage of one frame: wall clock, and process CPU time.
struct FrameTimings {
  double preprocess_ms = 0;  // mm -> m, bilateral filter, pyramid, vertex/normal maps
  double icp_ms = 0;
  double integrate_ms = 0;
  double raycast_ms = 0;
  double merge_ms = 0;  // eq. 1-5 and G_r normals
  double total_ms = 0;  // all of the above
  // Process CPU time (all threads of the process, so other work in the process counts too) of
  // the same stages: on a loaded machine this, not the wall time, shows the cost of a stage.
  double preprocess_cpu_ms = 0;
  double icp_cpu_ms = 0;
  double integrate_cpu_ms = 0;
  double raycast_cpu_ms = 0;
  double merge_cpu_ms = 0;
};

struct FrameResult {
  // The tracked pose; the doubtful estimate when uncertain; the last good (integrated) pose when
  // lost.
  Pose camera_to_world;
  TrackingState state = TrackingState::kEmpty;  // = quality.state
  bool integrated = false;   // the depth was fused into the volume (tracked frames only)
  bool relocalised = false;  // tracking resumed after a loss on this frame
  IcpResult icp;             // empty on the first frame and with a known pose; when lost, the
                             // best relocalisation attempt
  // The verdict of the tracking-quality test: kTracking with score 1 on the first frame and with
  // a known pose.
  TrackingQuality quality;
  FrameTimings timings;
};

class FusionPipeline {
 public:
  // Throws ReconError for invalid options.
  explicit FusionPipeline(const FusionOptions& options);
  ~FusionPipeline();

  // Processes one frame: `depth` in metres (0 = invalid) with `intrinsics` (same size), and an
  // optional grey intensity image of the same size registered to the depth (nullptr: no colour
  // guidance, every lambda_I test passes). `known_pose` (camera -> world), when given, replaces
  // tracking (external tracking or ground truth). Throws ReconError for empty or mismatched
  // inputs or invalid intrinsics (the pipeline state is unchanged then). `stamp_ns`, when > 0
  // (nanoseconds, any clock, increasing), gives the motion test the interval since the previous
  // frame; 0 = frames are nominal_frame_interval_s apart (TrackingQualityOptions).
  FrameResult Process(const DepthImage& depth, const Intrinsics& intrinsics,
                      const GreyImage* intensity, const Pose* known_pose = nullptr,
                      int64_t stamp_ns = 0);
  // Same from depth16 millimetres (`stride_elements` per row, `metres_per_unit` 0.001).
  FrameResult ProcessDepth16(const uint16_t* depth_mm, int width, int height,
                             size_t stride_elements, double metres_per_unit,
                             const Intrinsics& intrinsics, const GreyImage* intensity);
  // Forgets the map and the pose (the next frame starts at options.initial_pose).
  void Reset();

  // The map and what tracking needs to resume against it, as one self-contained checkpoint (the
  // fusion node writes it to a file, checkpoint.h): the volume's options and observed bricks, the
  // last integrated pose (camera -> world), the seconds since it and the last frame's stamp, and
  // the tracking monitor's running state, with a checksum. Empty before the first frame (nothing
  // to save). The volume is not changed by lost or uncertain frames, so a checkpoint taken at
  // any time is consistent.
  std::vector<std::byte> Checkpoint() const;
  // Replaces the map and the tracking state by a Checkpoint() of a pipeline with the same volume
  // options. The next frame relocalises against the restored map (as after a loss: from the
  // saved pose and its constant-velocity extrapolation over the time since the saved stamp, at
  // most relocalise_max_extrapolation_s) at whatever size it has; until a frame is tracked, the
  // frames are lost. Throws ReconError "<name>: ..." (the pipeline then is Reset) for a file that
  // is not a checkpoint, of another version or byte order, truncated, with a wrong checksum,
  // written for other volume options (naming the first that differs) or with invalid contents.
  void Resume(std::span<const std::byte> checkpoint, const std::string& name);

  TrackingState state() const { return state_; }
  const Pose& pose() const { return pose_; }
  const TsdfVolume& volume() const { return *volume_; }
  TsdfVolume& volume() { return *volume_; }
  // G_v of the last frame: the volume raycast at its pose (after integration), camera frame, at
  // the tracking level's resolution (intrinsics.Level(track_level)).
  const GeometryView& volume_view() const { return view_; }
  // D_v at the input resolution (G_v's depth upsampled; 0 = no surface or tracking lost).
  const DepthImage& volume_depth() const { return volume_depth_; }
  // D', D'', D''' of the last frame (D''' = depth of G_r).
  const MergedDepth& merged() const { return merged_; }
  // Normals of G_r (camera frame, towards the camera; (0, 0, 0) = none): from D''' or the volume,
  // see FusionOptions::normal_source.
  const Vec3Image& merged_normals() const { return merged_normals_; }
  // The last frame's preprocessed pyramid (raw_depth = D_c).
  const FramePyramid& frame() const { return frame_; }
  ThreadPool* pool() { return pool_.get(); }
  const FusionOptions& options() const { return options_; }

 private:
  // Replaces merged_normals_ by the volume's where D''' agrees with D_v (NormalSource::kVolume).
  void VolumeNormals();
  // Tracks the frame from pose_ (state_ kTracking or kUncertain) or relocalises it (kLost);
  // fills r.icp, r.quality, r.relocalised and updates pose_, state_, the monitor.
  void Track(double interval_s, FrameResult& r);

  FusionOptions options_;
  std::unique_ptr<ThreadPool> pool_;
  std::unique_ptr<TsdfVolume> volume_;
  TrackingState state_ = TrackingState::kEmpty;
  Pose pose_;
  TrackingQualityMonitor monitor_;
  int uncertain_run_ = 0;      // consecutive uncertain frames before this one
  double since_good_s_ = 0;    // seconds since the last integrated frame (lost: extrapolation)
  int64_t last_stamp_ns_ = 0;  // of the previous frame, 0 = none
  // Resumed from a checkpoint: model_ is to be raycast at model_.camera_to_world with the next
  // frame's intrinsics before it relocalises.
  bool resume_model_ = false;
  FramePyramid frame_;
  ModelPyramid model_;
  GeometryView view_;
  DepthImage volume_depth_;
  MergedDepth merged_;
  Vec3Image merged_vertices_;
  Vec3Image merged_normals_;
  Vec3Image anchor_normals_;  // VolumeNormals scratch
  DepthImage depth_scratch_;
  GreyImage no_intensity_;
};

}  // namespace probeless::recon
