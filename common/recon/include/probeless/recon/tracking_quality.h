// The tracking-quality test of frame-to-model ICP (issue #20): per frame, ICP's own checks
// (IcpResult::ok) plus four cues that catch a wrong pose ICP reports as converged:
//   - residual: the level-0 point-to-plane RMS against its running mean over accepted frames;
//   - inliers: the associated fraction against its running mean over accepted frames;
//   - motion: the step against a constant-velocity prediction (hand-held motion is smooth at
//     30 fps; a converged ICP that jumps 12 cm in one frame has slid, not the camera);
//   - observability: the weakest direction of ICP's 6x6 normal equations (KinectFusion eq. 16-18,
//     Newcombe et al. 2011), rotations scaled to metres by the mean depth (Gelfand et al. 2003,
//     "Geometrically stable sampling for the ICP algorithm", 3DIM, §3: the eigenvalues of the
//     point-to-plane covariance matrix); a single plane, or a floor and one wall, leave a slide
//     unobserved and ICP's estimate along it is noise. Taken over the frame and over the part of it
//     ICP matched to the model, whichever is weaker: geometry outside the model pins nothing, and
//     a slow slide along a direction only it pinned keeps the other cues quiet.
// Each cue maps to a score in [0, 1] (1 = clearly fine, 0.5 = at its soft limit, 0 = at its hard
// limit); the frame's score is the smallest. The state follows the score exactly:
//   tracked   <=> score >= 0.5 (every cue within its soft limit),
//   uncertain <=> 0 < score < 0.5 (some cue beyond its soft limit, none at its hard limit),
//   lost      <=> score == 0 (ICP failed, a cue at its hard limit, or more consecutive uncertain
//                 frames than TrackingQualityOptions::max_uncertain_frames).
// Deterministic: no clocks, no randomness; the running statistics depend only on the frames fed.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "probeless/recon/icp.h"
#include "probeless/recon/math.h"

namespace probeless::recon {

enum class TrackingState {
  kEmpty,      // no map yet (the next frame initialises it)
  kTracking,   // tracked: the pose passed the quality test and the frame was integrated
  kUncertain,  // the pose is doubtful: published (flagged), not integrated; tracking continues
               // from it
  kLost,       // failed: not integrated, no pose; the next frames try to relocalise
};
// "empty", "tracked", "uncertain", "lost".
std::string_view TrackingStateName(TrackingState state);

// Why a frame is not tracked: bits of TrackingQuality::reasons.
enum TrackingReason : uint32_t {
  kReasonNone = 0,
  kReasonIcpFailed = 1u << 0,     // ICP's own test failed (IcpResult::failure)
  kReasonResidual = 1u << 1,      // RMS residual high against its running mean
  kReasonInliers = 1u << 2,       // inlier fraction dropped against its running mean
  kReasonMotion = 1u << 3,        // step far from the constant-velocity prediction
  kReasonDegenerate = 1u << 4,    // a direction of the pose is (nearly) unobserved
  kReasonPersistent = 1u << 5,    // too many consecutive uncertain frames
  kReasonRelocalising = 1u << 6,  // lost earlier; no candidate passed this frame
};

// Limits of the cues. For each cue: `good` (score 1), `soft` (score 0.5: beyond it the frame is
// uncertain) and `hard` (score 0: lost); the score is piecewise linear in between. Chosen on the
// shared 7-Scenes RedKitchen frames (must stay tracked) and the crafted sequences of
// tracking_quality_test.cpp (must not); docs/recon.md "Tracking quality" has the measured values.
struct TrackingQualityOptions {
  // rms_m / max(running mean of rms_m, residual_floor_m). The floor keeps a noise-free scene's
  // 0.1 mm residual from flagging a 0.4 mm frame.
  float residual_ratio_good = 1.5f;
  float residual_ratio_soft = 2.0f;
  float residual_ratio_hard = 3.5f;
  float residual_floor_m = 0.002f;
  // inlier_fraction / running mean of inlier_fraction (smaller is worse).
  float inlier_ratio_good = 0.8f;
  float inlier_ratio_soft = 0.6f;
  float inlier_ratio_hard = 0.3f;
  // |step - predicted step| per nominal frame interval: translation (metres) and rotation
  // (degrees); scaled by the frame interval / nominal_frame_interval_s, clamped to
  // [1, max_interval_scale], when the frames are further apart (dropped frames). A relocalisation
  // is held to the unscaled limits around the extrapolated pose: with an allowance growing over
  // the loss, relocalisations on generated rooms accepted the same 12-17 cm slide again and again.
  float motion_translation_good_m = 0.025f;
  float motion_translation_soft_m = 0.05f;
  float motion_translation_hard_m = 0.10f;
  float motion_rotation_good_deg = 1.5f;
  float motion_rotation_soft_deg = 3.0f;
  float motion_rotation_hard_deg = 10.0f;
  // IcpObservability (smaller is worse): the smallest eigenvalue of the per-pair normal matrix.
  float observability_good = 0.01f;
  float observability_soft = 0.005f;
  float observability_hard = 0.001f;
  // The observability cue takes the smaller of the frame's and the model-matched part's
  // (IcpResult::matched_normal_equations); false: the frame's only (for A/B measurements: it
  // misses geometry the frame sees but the model lacks, e.g. outside the volume).
  bool matched_observability = true;
  double nominal_frame_interval_s = 1.0 / 30.0;
  double max_interval_scale = 3.0;
  // Accepted frames before the residual and inlier cues apply (their running means need data).
  int warmup_frames = 5;
  // Weight of a new accepted frame in the running means (exponential, in (0, 1]).
  float statistics_alpha = 0.1f;
  // Consecutive uncertain frames tolerated; the next one is lost (kReasonPersistent).
  int max_uncertain_frames = 1;

  // Throws ReconError naming the first field out of order or range, e.g.
  // "tracking quality: need residual_ratio_good <= residual_ratio_soft < residual_ratio_hard".
  void Validate() const;
};

// The verdict on one frame.
struct TrackingQuality {
  TrackingState state = TrackingState::kEmpty;
  float score = 0;       // in [0, 1]; see the file comment for its relation to `state`
  uint32_t reasons = 0;  // TrackingReason bits of the cues beyond their soft limit
  std::string text;      // one line: the failing cues with values and limits; "" if tracked
  // The cue values (0 when the cue did not apply, e.g. in warm-up or on the first frame).
  float residual_ratio = 0;        // rms_m / max(running mean, floor)
  float inlier_ratio = 0;          // inlier_fraction / running mean
  float motion_translation_m = 0;  // |translation of (predicted^-1 * step)|, metres
  float motion_rotation_deg = 0;   // rotation angle of (predicted^-1 * step), degrees
  // The observability cue: the smaller of the two below (matched only when ICP paired pixels).
  float observability = 0;
  float frame_observability = 0;    // IcpObservability of the frame's geometry
  float matched_observability = 0;  // IcpObservability of the part ICP matched to the model
};

// How well the frame pins each direction of the pose: the smaller of the smallest eigenvalues of
// the translation block sum(n_q n_q^T) / n and of the rotation block
// sum((p x n_q)(p x n_q)^T) / (n L^2) of ICP's normal matrix A (IcpResult::normal_equations:
// upper triangle of J^T J, J = (p x n_q, n_q) per pair), n the pairs, L = `length_m` (the mean
// depth: a turn counts by the displacement it causes at the scene). Gelfand et al. 2003 §3
// analyse the eigenvalues of this matrix; the coupling block is left out on purpose: through a
// narrow field of view a turn about y and a slide along x look alike in every real view (the
// full matrix's smallest eigenvalue is 0.0003-0.006 on 7-Scenes), and ICP separates them by the
// perspective, whereas a direction missing from a block is a true null space of the pose: a
// single plane's slides and its turn about its normal, a floor and one wall's slide along their
// intersection. Dimensionless, in [0, 1] for unit normals: 1/3 for three orthogonal, equally seen
// walls' translations; ~ the normal noise (sigma_n^2) for those null directions. Returns 0 for
// n < 6 or a non-positive L.
float IcpObservability(const double normal_equations[21], int pairs, float length_m);

// Running state of the test over a stream: the means of the residual and the inlier fraction
// and the velocity of the last accepted frames.
class TrackingQualityMonitor {
 public:
  // Throws ReconError for invalid options (TrackingQualityOptions::Validate).
  explicit TrackingQualityMonitor(const TrackingQualityOptions& options);

  // Judges `icp` (estimated from `previous`, the pose of the previous frame, camera -> world)
  // for a frame `interval_s` seconds after it (<= 0: the nominal interval); the motion limits
  // grow with interval_s / nominal_frame_interval_s (1..max_interval_scale). `relocalising`: the
  // frame follows a loss, `previous` is the last good pose and `interval_s` the time since it (the
  // prediction extrapolates over it; the motion limits stay those of one frame); the verdict is
  // then tracked or lost, never uncertain (kReasonRelocalising). `uncertain_run`
  // consecutive uncertain frames precede this one. Does not change the monitor.
  TrackingQuality Assess(const IcpResult& icp, const Pose& previous, double interval_s,
                         bool relocalising, int uncertain_run) const;
  // Records an accepted (integrated) frame: updates the running means and the velocity
  // (previous -> current over interval_s).
  void Accept(const IcpResult& icp, const Pose& previous, const Pose& current, double interval_s);
  // Forgets the velocity (after a loss: the motion across it is unknown); keeps the means.
  void ForgetVelocity() { have_velocity_ = false; }
  // Forgets everything (a new map).
  void Reset();
  // The constant-velocity prediction of the pose `interval_s` after `previous` (`previous`
  // itself without a velocity).
  Pose Predict(const Pose& previous, double interval_s) const;

  // The running state (the means and the velocity), for a checkpoint of the pipeline
  // (FusionPipeline::Checkpoint): Restore(Saved()) continues exactly where this monitor was.
  struct SavedState {
    int accepted = 0;
    float mean_rms_m = 0;
    float mean_inlier_fraction = 0;
    bool have_velocity = false;
    double velocity[6] = {};  // rad/s (wx, wy, wz), m/s (tx, ty, tz), camera frame
  };
  SavedState Saved() const;
  // Throws ReconError for a negative count, non-finite or negative means or a non-finite velocity.
  void Restore(const SavedState& state);

  int accepted_frames() const { return accepted_; }
  float mean_rms_m() const { return mean_rms_; }
  float mean_inlier_fraction() const { return mean_inliers_; }
  const TrackingQualityOptions& options() const { return options_; }

 private:
  double Interval(double interval_s) const;

  TrackingQualityOptions options_;
  int accepted_ = 0;
  float mean_rms_ = 0;
  float mean_inliers_ = 0;
  bool have_velocity_ = false;
  double velocity_[6] = {};  // twist of the last accepted step per second (rad/s, m/s), camera
};

}  // namespace probeless::recon
