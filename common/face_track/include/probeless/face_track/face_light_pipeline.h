// The face light of one observation stream (Knorr & Kurz 2014, eq. 19, and what this project adds
// around it): the face_light estimator on a tracker's samples, the model's compressed units
// converted to linear radiance with the skin albedo compensated, smoothing over frames, the face
// frame rotated into the camera frame by the head pose, and the hold of the last confident light
// for an unlit or backlit face. The node `face_light` runs this object (docs/face_light.md,
// "face_light node").
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "probeless/face_light/estimator.h"
#include "probeless/face_light/linear_light.h"
#include "probeless/face_light/model.h"
#include "probeless/face_track/light_output.h"
#include "probeless/msgs/face_observation.h"
#include "probeless/msgs/sh_light.h"

namespace probeless::face_track {

struct FaceLightPipelineOptions {
  // true: the estimate from each sample's mean of R, G and B (the model's grey fit); false: one
  // fit per channel.
  bool gray = false;
  face_light::EstimatorOptions estimator;
  SmootherOptions smoother;
  // true: lights in linear radiance (msgs::ShLightUnits::kLinear) with the confidence from the
  // calibrated expected error and the hold; false: the model's compressed units (kFaceModel), the
  // fit's own confidence times the tracking quality, no hold.
  bool linear_output = true;
  face_light::LinearLightOptions linear;
  HoldOptions hold;
};

// Stateful over one stream (smoother and hold): feed observations in stamp order.
class FaceLightPipeline {
 public:
  // `model` is copied from as needed (it need not outlive this object). Throws FaceLightError for
  // an invalid model or options (estimator, linear conversion) and InputError for bad hold options.
  FaceLightPipeline(const face_light::FaceLightModel& model,
                    const FaceLightPipelineOptions& options);

  // Samples per observation the model expects (msgs::FaceObservation::sample_count).
  int SampleCount() const { return estimator_.SampleCount(); }

  // The light of one observation in its camera frame (header copied; 3 bands; confidence clamped
  // to [0, 1]), or nothing: no face, too few valid samples, or no valid linear light (each counted
  // as a miss by the smoother). Throws FaceLightError when the observation's sample_count is not
  // SampleCount() (tracker and estimator configured with different models).
  std::optional<msgs::ShLight> Process(const msgs::FaceObservation& observation);

 private:
  FaceLightPipelineOptions options_;
  face_light::FaceLightEstimator estimator_;
  face_light::LinearLightConverter converter_;
  LightHold hold_;
  LightSmoother smoother_;
  std::vector<float> gray_;
};

}  // namespace probeless::face_track
