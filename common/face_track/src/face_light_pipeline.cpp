#include "probeless/face_track/face_light_pipeline.h"

#include <algorithm>
#include <array>
#include <span>

#include "probeless/face_track/head_model.h"

namespace probeless::face_track {

namespace fl = face_light;

FaceLightPipeline::FaceLightPipeline(const fl::FaceLightModel& model,
                                     const FaceLightPipelineOptions& options)
    : options_(options),
      estimator_(model, options.estimator),
      converter_(model, options.linear),
      hold_(options.hold),
      smoother_(options.smoother),
      gray_(static_cast<size_t>(estimator_.SampleCount())) {}

std::optional<msgs::ShLight> FaceLightPipeline::Process(const msgs::FaceObservation& obs) {
  if (!obs.face_detected) {
    smoother_.Miss();
    return std::nullopt;
  }
  if (static_cast<int>(obs.sample_count) != SampleCount()) {
    throw fl::FaceLightError("observation has " + std::to_string(obs.sample_count) +
                             " samples, the model " + std::to_string(SampleCount()));
  }
  const std::span<const uint64_t> valid(obs.sample_valid);
  const std::span<const float> rgb(&obs.sample_rgb[0][0], gray_.size() * 3);
  fl::LightEstimate e;
  if (options_.gray) {
    for (size_t i = 0; i < gray_.size(); ++i) {
      gray_[i] = (obs.sample_rgb[i][0] + obs.sample_rgb[i][1] + obs.sample_rgb[i][2]) / 3;
    }
    e = estimator_.EstimateGray(gray_, valid);
  } else {
    e = estimator_.EstimateRgb(rgb, valid);
  }
  if (e.channels == 0) {
    smoother_.Miss();
    return std::nullopt;
  }
  float confidence = e.confidence * obs.quality;
  if (options_.linear_output) {
    // The confidence from the cues' calibrated expected error (docs/face_light.md, "Confidence");
    // the tracking quality is left out: it is not calibrated against the light's error.
    const fl::LinearLight linear = converter_.Convert(rgb, valid, e);
    if (!linear.valid) {
      smoother_.Miss();
      return std::nullopt;
    }
    confidence = static_cast<float>(
        msgs::ShLightConfidenceFromExpectedError(fl::FaceLightExpectedErrorDeg(linear)));
    e.channels = 3;
    e.coefficients = linear.coefficients;
    e.dominant_direction = linear.direction;
    e.intensity = linear.intensity;
  }
  e.confidence = confidence;
  e = smoother_.Update(e);
  confidence = e.confidence;
  // Face frame -> camera frame (an unset rotation is the identity).
  const auto& q = obs.head_pose.rotation;
  std::array<double, 9> r{1, 0, 0, 0, 1, 0, 0, 0, 1};
  if (q.w != 0 || q.x != 0 || q.y != 0 || q.z != 0) r = MatrixFromQuaternion({q.w, q.x, q.y, q.z});
  Sh9Rgb camera = RotateSh9(e.coefficients, r);
  std::array<float, 3> direction = RotateVector(r, e.dominant_direction);
  float intensity = e.intensity;
  if (options_.linear_output) {
    const LightHold::Output held =
        hold_.Update(camera, direction, intensity, confidence, obs.header.stamp_ns);
    camera = held.coefficients;
    direction = held.direction;
    intensity = held.intensity;
  }
  msgs::ShLight out{};
  out.header = obs.header;
  out.bands = 3;
  for (int n = 0; n < 9; ++n) {
    for (int c = 0; c < 3; ++c) out.coefficients[n][c] = camera[n][c];
  }
  for (int k = 0; k < 3; ++k) out.dominant_direction[k] = direction[k];
  out.intensity = intensity;
  out.confidence = std::clamp(confidence, 0.f, 1.f);
  out.units = options_.linear_output ? msgs::ShLightUnits::kLinear : msgs::ShLightUnits::kFaceModel;
  return out;
}

}  // namespace probeless::face_track
