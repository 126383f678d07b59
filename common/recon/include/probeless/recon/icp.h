// Frame-to-model camera tracking: projective point-to-plane ICP, coarse to fine (KinectFusion,
// Newcombe et al. 2011, §3.5, eq. 16-18): the current frame's vertices are associated with the
// model's by projecting them into the model view, pairs are rejected by distance and normal
// angle, and each iteration solves the linearised 6x6 normal equations accumulated per task
// (deterministic whatever the thread count).
#pragma once

#include <vector>

#include "probeless/recon/math.h"
#include "probeless/recon/preprocess.h"
#include "probeless/recon/thread_pool.h"
#include "probeless/recon/tsdf_volume.h"

namespace probeless::recon {

struct IcpOptions {
  std::vector<int> iterations = {4, 5, 10};  // per pyramid level, level 0 (finest) first
  float max_distance_m = 0.10f;              // association distance threshold
  float max_angle_deg = 30.0f;               // association normal-angle threshold
  // Tracking quality test: the result is rejected (tracking lost) when fewer than this fraction
  // of the frame's valid level-0 pixels found a pair, when the level-0 RMS point-to-plane
  // residual exceeds max_rms_m, when the system is ill-conditioned, or when the motion from the
  // initial guess exceeds max_translation_m / max_rotation_deg.
  float min_inlier_fraction = 0.10f;
  float max_rms_m = 0.02f;
  float max_translation_m = 0.20f;
  float max_rotation_deg = 20.0f;
  float min_condition = 1e-5f;  // smallest / largest pivot of the Cholesky factorisation
  // Pixels (at the tracking level) per side of the blocks of IcpResult::normal_equations.
  int observability_block = 8;
};

// The model to track against: a raycast view (points and normals in that view's camera frame)
// with its pose and per-level intrinsics (level l is the raycast subsampled by 2^l).
struct ModelPyramid {
  Pose camera_to_world;
  std::vector<Intrinsics> intrinsics;
  std::vector<Vec3Image> points;
  std::vector<Vec3Image> normals;
};

struct IcpResult {
  Pose camera_to_world;       // the estimate (the initial guess when !ok)
  bool ok = false;            // passed the tracking quality test
  float inlier_fraction = 0;  // level 0
  float rms_m = 0;            // level 0, point-to-plane
  int iterations = 0;         // total iterations run
  std::string failure;        // why !ok, e.g. "too few correspondences (0.12 < 0.25)"
  // The point-to-plane normal matrix of the frame's level-0 geometry, one pair per
  // IcpOptions::observability_block^2 pixels (sampled every second pixel each way; the block's mean
  // point p, metres, frame camera, and its renormalised mean normal n; blocks less than half valid
  // are skipped): upper triangle (row-major, 21 values) of J^T J with J = (p x n, n), the block
  // count and the blocks' mean depth (metres). The inputs of IcpObservability (tracking_quality.h);
  // averaging keeps the normals' noise from posing as a constraint.
  double normal_equations[21] = {};
  int pairs = 0;
  float mean_depth_m = 0;
  // The same matrix over the samples that find a model pair at the final estimate (the level-0
  // association gates of the iterations; a block counts when at least half of its samples are
  // valid and paired): the geometry that actually constrains the estimate. Geometry the frame
  // sees but the model lacks (outside the volume, not yet integrated) is in normal_equations but
  // not here. Zero when ICP stopped early (too few pairs, singular).
  double matched_normal_equations[21] = {};
  int matched_pairs = 0;
  float matched_mean_depth_m = 0;
};

// Builds the model pyramid from a raycast view (levels subsample every 2nd pixel).
void BuildModelPyramid(const GeometryView& view, const Pose& camera_to_world,
                       const Intrinsics& intrinsics, int levels, ModelPyramid& out);

// Estimates the pose of `frame` against `model`, starting from `initial` (camera -> world).
// Throws ReconError if the frame and model pyramids have different sizes or level counts, or
// options.observability_block < 1.
IcpResult TrackIcp(const FramePyramid& frame, const ModelPyramid& model, const Pose& initial,
                   const IcpOptions& options, ThreadPool* pool);

}  // namespace probeless::recon
