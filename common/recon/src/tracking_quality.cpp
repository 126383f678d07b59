#include "probeless/recon/tracking_quality.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace probeless::recon {

namespace {

constexpr double kPi = 3.14159265358979323846;

// Rotation vector (axis * angle, radians) of a pose's rotation; steps between frames are far
// from pi, where the axis would be ill-defined.
void RotationVector(const Pose& p, double w[3]) {
  const double angle = p.RotationAngle();
  const double v[3] = {p.r[7] - p.r[5], p.r[2] - p.r[6], p.r[3] - p.r[1]};
  const double s = std::sin(angle);
  const double f = s > 1e-9 ? angle / (2 * s) : 0.5;  // angle / (2 sin angle) -> 1/2 at 0
  for (int i = 0; i < 3; ++i) w[i] = v[i] * f;
}

// Piecewise linear: 1 at `good`, 0.5 at `soft`, 0 at `hard`, clamped outside; works for larger-
// is-worse (good < soft < hard) and smaller-is-worse (good > soft > hard) cues alike.
float CueScore(float value, float good, float soft, float hard) {
  const float sign = hard > good ? 1.0f : -1.0f;
  const float v = sign * value, g = sign * good, s = sign * soft, h = sign * hard;
  if (v <= g) return 1.0f;
  if (v <= s) return s > g ? 1.0f - 0.5f * (v - g) / (s - g) : 0.5f;
  if (v < h) return 0.5f - 0.5f * (v - s) / (h - s);
  return 0.0f;
}

// Smallest eigenvalue of a symmetric 3x3 matrix (cyclic Jacobi rotations; deterministic).
double SmallestEigenvalue3(double a[3][3]) {
  for (int sweep = 0; sweep < 50; ++sweep) {
    double off = 0, diag = 0;
    for (int p = 0; p < 3; ++p) {
      diag += a[p][p] * a[p][p];
      for (int q = p + 1; q < 3; ++q) off += a[p][q] * a[p][q];
    }
    if (off <= 1e-24 * diag) break;
    for (int p = 0; p < 3; ++p) {
      for (int q = p + 1; q < 3; ++q) {
        if (std::fabs(a[p][q]) < 1e-300) continue;
        const double theta = (a[q][q] - a[p][p]) / (2 * a[p][q]);
        const double t = (theta >= 0 ? 1 : -1) / (std::fabs(theta) + std::sqrt(theta * theta + 1));
        const double c = 1 / std::sqrt(t * t + 1), s = t * c;
        for (int k = 0; k < 3; ++k) {  // A <- A J (columns p, q)
          const double akp = a[k][p], akq = a[k][q];
          a[k][p] = c * akp - s * akq;
          a[k][q] = s * akp + c * akq;
        }
        for (int k = 0; k < 3; ++k) {  // A <- J^T A (rows p, q)
          const double apk = a[p][k], aqk = a[q][k];
          a[p][k] = c * apk - s * aqk;
          a[q][k] = s * apk + c * aqk;
        }
      }
    }
  }
  return std::min({a[0][0], a[1][1], a[2][2]});
}

std::string Format(const char* format, double a, double b) {
  char buffer[160];
  std::snprintf(buffer, sizeof buffer, format, a, b);
  return buffer;
}

void Append(std::string& text, const std::string& part) {
  if (!text.empty()) text += "; ";
  text += part;
}

}  // namespace

std::string_view TrackingStateName(TrackingState state) {
  switch (state) {
    case TrackingState::kEmpty:
      return "empty";
    case TrackingState::kTracking:
      return "tracked";
    case TrackingState::kUncertain:
      return "uncertain";
    case TrackingState::kLost:
      return "lost";
  }
  return "invalid";
}

void TrackingQualityOptions::Validate() const {
  auto ordered = [](float good, float soft, float hard, bool larger_worse, const char* name) {
    const bool ok = larger_worse ? (good <= soft && soft < hard) : (good >= soft && soft > hard);
    if (!ok || !std::isfinite(good) || !std::isfinite(hard)) {
      const std::string n(name);
      throw ReconError("tracking quality: need " + n + "_good " + (larger_worse ? "<=" : ">=") +
                       " " + n + "_soft " + (larger_worse ? "<" : ">") + " " + n + "_hard");
    }
  };
  ordered(residual_ratio_good, residual_ratio_soft, residual_ratio_hard, true, "residual_ratio");
  ordered(inlier_ratio_good, inlier_ratio_soft, inlier_ratio_hard, false, "inlier_ratio");
  ordered(motion_translation_good_m, motion_translation_soft_m, motion_translation_hard_m, true,
          "motion_translation");
  ordered(motion_rotation_good_deg, motion_rotation_soft_deg, motion_rotation_hard_deg, true,
          "motion_rotation");
  ordered(observability_good, observability_soft, observability_hard, false, "observability");
  if (!(residual_floor_m >= 0)) throw ReconError("tracking quality: residual_floor_m must be >= 0");
  if (!(nominal_frame_interval_s > 0)) {
    throw ReconError("tracking quality: nominal_frame_interval_s must be > 0");
  }
  if (!(max_interval_scale >= 1)) {
    throw ReconError("tracking quality: max_interval_scale must be >= 1");
  }
  if (warmup_frames < 1) throw ReconError("tracking quality: warmup_frames must be >= 1");
  if (!(statistics_alpha > 0 && statistics_alpha <= 1)) {
    throw ReconError("tracking quality: statistics_alpha must be in (0, 1]");
  }
  if (max_uncertain_frames < 0) {
    throw ReconError("tracking quality: max_uncertain_frames must be >= 0");
  }
}

float IcpObservability(const double normal_equations[21], int pairs, float length_m) {
  if (pairs < 6 || !(length_m > 0)) return 0.0f;
  double a[6][6];
  int idx = 0;
  for (int i = 0; i < 6; ++i)
    for (int j = i; j < 6; ++j) a[i][j] = a[j][i] = normal_equations[idx++];
  // The rotation block (turns, scaled to displacements at the mean depth) and the translation
  // block, each per pair; their coupling is left out (see the header).
  double rotation[3][3], translation[3][3];
  const double rs = 1.0 / (static_cast<double>(length_m) * length_m * pairs), ts = 1.0 / pairs;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      rotation[i][j] = a[i][j] * rs;
      translation[i][j] = a[3 + i][3 + j] * ts;
    }
  const double weakest = std::min(SmallestEigenvalue3(rotation), SmallestEigenvalue3(translation));
  return static_cast<float>(std::clamp(weakest, 0.0, 1.0));
}

TrackingQualityMonitor::TrackingQualityMonitor(const TrackingQualityOptions& options)
    : options_(options) {
  options_.Validate();
}

void TrackingQualityMonitor::Reset() {
  accepted_ = 0;
  mean_rms_ = 0;
  mean_inliers_ = 0;
  have_velocity_ = false;
}

TrackingQualityMonitor::SavedState TrackingQualityMonitor::Saved() const {
  SavedState s;
  s.accepted = accepted_;
  s.mean_rms_m = mean_rms_;
  s.mean_inlier_fraction = mean_inliers_;
  s.have_velocity = have_velocity_;
  std::copy(velocity_, velocity_ + 6, s.velocity);
  return s;
}

void TrackingQualityMonitor::Restore(const SavedState& s) {
  if (s.accepted < 0) throw ReconError("tracking quality: accepted frames must be >= 0");
  if (!(std::isfinite(s.mean_rms_m) && s.mean_rms_m >= 0) ||
      !(std::isfinite(s.mean_inlier_fraction) && s.mean_inlier_fraction >= 0)) {
    throw ReconError("tracking quality: running means must be finite and >= 0");
  }
  for (double v : s.velocity) {
    if (!std::isfinite(v)) throw ReconError("tracking quality: velocity must be finite");
  }
  accepted_ = s.accepted;
  mean_rms_ = s.mean_rms_m;
  mean_inliers_ = s.mean_inlier_fraction;
  have_velocity_ = s.have_velocity;
  std::copy(s.velocity, s.velocity + 6, velocity_);
}

double TrackingQualityMonitor::Interval(double interval_s) const {
  return interval_s > 0 ? interval_s : options_.nominal_frame_interval_s;
}

Pose TrackingQualityMonitor::Predict(const Pose& previous, double interval_s) const {
  if (!have_velocity_) return previous;
  const double dt = Interval(interval_s);
  double xi[6];
  for (int i = 0; i < 6; ++i) xi[i] = velocity_[i] * dt;
  return previous * Pose::FromTwist(xi);
}

TrackingQuality TrackingQualityMonitor::Assess(const IcpResult& icp, const Pose& previous,
                                               double interval_s, bool relocalising,
                                               int uncertain_run) const {
  const TrackingQualityOptions& o = options_;
  TrackingQuality q;
  float score = 1.0f;
  auto cue = [&](float value, float good, float soft, float hard, uint32_t reason,
                 const std::string& what) {
    const float s = CueScore(value, good, soft, hard);
    score = std::min(score, s);
    if (s < 0.5f) {
      q.reasons |= reason;
      Append(q.text, what);
    }
  };
  if (!icp.ok) {
    q.reasons |= kReasonIcpFailed;
    Append(q.text, "icp: " + icp.failure);
    score = 0;
  }
  q.frame_observability = IcpObservability(icp.normal_equations, icp.pairs, icp.mean_depth_m);
  q.matched_observability =
      IcpObservability(icp.matched_normal_equations, icp.matched_pairs, icp.matched_mean_depth_m);
  // Without pairs (ICP stopped early, already failed) only the frame's geometry is known.
  const bool matched = o.matched_observability && (icp.ok || icp.matched_pairs > 0);
  const bool by_match = matched && q.matched_observability < q.frame_observability;
  q.observability = by_match ? q.matched_observability : q.frame_observability;
  cue(q.observability, o.observability_good, o.observability_soft, o.observability_hard,
      kReasonDegenerate,
      Format(by_match ? "degenerate geometry: observability %.4f of the part matched to the model "
                        "(soft %.4f)"
                      : "degenerate geometry: observability %.4f (soft %.4f)",
             q.observability, o.observability_soft));
  if (accepted_ >= o.warmup_frames) {
    q.residual_ratio = icp.rms_m / std::max(mean_rms_, o.residual_floor_m);
    cue(q.residual_ratio, o.residual_ratio_good, o.residual_ratio_soft, o.residual_ratio_hard,
        kReasonResidual,
        Format("residual %.2f x its running mean (soft %.2f)", q.residual_ratio,
               o.residual_ratio_soft));
    q.inlier_ratio = mean_inliers_ > 0 ? icp.inlier_fraction / mean_inliers_ : 1.0f;
    cue(q.inlier_ratio, o.inlier_ratio_good, o.inlier_ratio_soft, o.inlier_ratio_hard,
        kReasonInliers,
        Format("inliers %.2f x their running mean (soft %.2f)", q.inlier_ratio,
               o.inlier_ratio_soft));
  }
  {
    // The step against the constant-velocity prediction, in the previous camera's frame.
    const Pose predicted = Predict(previous, interval_s);
    const Pose deviation = predicted.Inverse() * icp.camera_to_world;
    // A relocalisation gets the one-frame allowance around the extrapolated pose however long the
    // loss: a slide repeated from the last good pose must not be accepted at the next try.
    const double scale = relocalising
                             ? 1.0
                             : std::clamp(Interval(interval_s) / o.nominal_frame_interval_s, 1.0,
                                          o.max_interval_scale);
    const double* t = deviation.t;
    q.motion_translation_m = static_cast<float>(std::sqrt(t[0] * t[0] + t[1] * t[1] + t[2] * t[2]));
    q.motion_rotation_deg = static_cast<float>(deviation.RotationAngle() * 180.0 / kPi);
    const float f = static_cast<float>(scale);
    cue(q.motion_translation_m, f * o.motion_translation_good_m, f * o.motion_translation_soft_m,
        f * o.motion_translation_hard_m, kReasonMotion,
        Format("step %.1f cm off the constant-velocity prediction (soft %.1f cm)",
               100.0 * q.motion_translation_m, 100.0 * f * o.motion_translation_soft_m));
    cue(q.motion_rotation_deg, f * o.motion_rotation_good_deg, f * o.motion_rotation_soft_deg,
        f * o.motion_rotation_hard_deg, kReasonMotion,
        Format("turn %.1f deg off the constant-velocity prediction (soft %.1f deg)",
               q.motion_rotation_deg, f * o.motion_rotation_soft_deg));
  }
  if (score < 0.5f && score > 0 && uncertain_run >= o.max_uncertain_frames) {
    q.reasons |= kReasonPersistent;
    Append(q.text, Format("uncertain for %.0f frames in a row (at most %.0f)", uncertain_run + 1.0,
                          static_cast<double>(o.max_uncertain_frames)));
    score = 0;
  }
  // A relocalisation is accepted only as fully tracked (an uncertain relocalisation stays lost).
  if (relocalising && score < 0.5f) {
    q.reasons |= kReasonRelocalising;
    Append(q.text, "relocalisation not accepted");
    score = 0;
  }
  q.score = std::clamp(score, 0.0f, 1.0f);
  q.state = q.score >= 0.5f  ? TrackingState::kTracking
            : q.score > 0.0f ? TrackingState::kUncertain
                             : TrackingState::kLost;
  if (q.state == TrackingState::kTracking) q.text.clear();
  return q;
}

void TrackingQualityMonitor::Accept(const IcpResult& icp, const Pose& previous, const Pose& current,
                                    double interval_s) {
  const float a = accepted_ == 0 ? 1.0f : options_.statistics_alpha;
  mean_rms_ += a * (icp.rms_m - mean_rms_);
  mean_inliers_ += a * (icp.inlier_fraction - mean_inliers_);
  ++accepted_;
  const Pose step = previous.Inverse() * current;
  const double dt = Interval(interval_s);
  double w[3];
  RotationVector(step, w);
  for (int i = 0; i < 3; ++i) {
    velocity_[i] = w[i] / dt;
    velocity_[3 + i] = step.t[i] / dt;
  }
  have_velocity_ = true;
}

}  // namespace probeless::recon
