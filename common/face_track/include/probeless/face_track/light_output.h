// Light outputs of the face pipeline (docs/face_light.md, "face_light node"): the estimate rotated
// from the face frame into the camera frame, temporal smoothing that follows switches, and JSON
// export in the ARKit and WebXR layouts.
#pragma once

#include <array>
#include <cstdint>
#include <string>

#include "probeless/face_light/estimator.h"
#include "probeless/msgs/sh_light.h"

namespace probeless::face_track {

// 9 SH coefficients (bands 0..2, probeless::sh convention) per channel: [n][c].
using Sh9Rgb = std::array<std::array<float, 3>, 9>;

// Coefficients of the light L'(d) = L(R^T d), i.e. the light expressed in the frame that R
// (row-major, e.g. face -> camera) maps into. Exact for bands 0..2.
Sh9Rgb RotateSh9(const Sh9Rgb& coefficients, const std::array<double, 9>& rotation);

// Colour of the light: the band-0 (ambient) coefficient per channel divided by their mean (so
// the mean is 1; white = (1, 1, 1)); (1, 1, 1) when the mean is not positive.
std::array<float, 3> LightColour(const Sh9Rgb& coefficients);

// R * v for a row-major rotation.
std::array<float, 3> RotateVector(const std::array<double, 9>& rotation,
                                  const std::array<float, 3>& v);

struct SmootherOptions {
  bool enabled = true;
  // Weight of the new frame in steady state (exponential smoothing, 0 < alpha <= 1).
  double alpha = 0.3;
  // Change detector: when a frame's band-0 (ambient) or band-1 (directional) energy of the
  // channel-mean light differs from the smoothed one by more than this relative amount, the
  // smoother jumps to the new frame (alpha = 1) for that frame, so a light switched on or off is
  // followed within one frame; also after `max_gap` frames without an estimate.
  double change_threshold = 0.35;
  int max_gap = 5;
};

// Adaptive exponential smoothing of successive SH estimates (coefficients, then direction,
// intensity and confidence recomputed from the smoothed light).
class LightSmoother {
 public:
  explicit LightSmoother(const SmootherOptions& options = {}) : options_(options) {}
  // Feeds one estimate (channels > 0) and returns the smoothed one.
  face_light::LightEstimate Update(const face_light::LightEstimate& estimate);
  // A frame without estimate (counts towards max_gap).
  void Miss() { ++gap_; }
  void Reset() { has_state_ = false; }
  // Whether the last Update jumped (change detected).
  bool last_jumped() const { return last_jumped_; }

 private:
  SmootherOptions options_;
  bool has_state_ = false;
  bool last_jumped_ = false;
  int gap_ = 0;
  face_light::LightEstimate state_;
};

struct HoldOptions {
  // A light with confidence below this (msgs::ShLight scale; 0.1 = an expected error of 30 deg:
  // an unlit or backlit face) is not followed.
  double min_confidence = 0.1;
  // Time constant of the held light's blend towards its ambient term, seconds (> 0).
  double blend_time_s = 2.0;
};

// What to publish for an unreliable face light (beyond the paper): while the face is unlit or
// backlit, the fit's direction is wrong (it puts the light in front, ~135 deg off) and would light
// a virtual object from the front. LightHold passes confident lights through and remembers the
// last one, H; for a light below HoldOptions::min_confidence it returns A + w (H - A), A = H's
// ambient term (band 0 only), w = exp(-(t - t_H) / blend_time_s), t_H the stamp of H: the
// object keeps the last trustworthy light and fades to its environment, never brighter than H
// from any direction it had no light from. Without a held light: the unreliable light's own
// ambient term. Coefficients in the camera frame, linear (msgs::ShLight units).
class LightHold {
 public:
  struct Output {
    Sh9Rgb coefficients{};
    std::array<float, 3> direction{};  // H's direction while w > 0, else (0, 0, 0)
    float intensity = 0;               // w x H's intensity
    bool held = false;                 // the input was below min_confidence
    double weight = 1;                 // w (1 for a confident input)
  };
  // Throws InputError unless 0 <= min_confidence <= 1 and blend_time_s > 0.
  explicit LightHold(const HoldOptions& options = {});
  Output Update(const Sh9Rgb& coefficients, const std::array<float, 3>& direction, float intensity,
                float confidence, int64_t stamp_ns);
  bool has_light() const { return has_light_; }

 private:
  HoldOptions options_;
  bool has_light_ = false;
  Sh9Rgb held_{};
  std::array<float, 3> direction_{};
  float intensity_ = 0;
  int64_t stamp_ns_ = 0;
};

// One light as JSON (one line, no trailing newline):
// {"stamp_ns":S,"frame_id":"camera","units":"linear","confidence":c,"intensity":i,
//  "dominant_direction":[x,y,z],"colour":[r,g,b],
//  "arkit":{"sphericalHarmonicsCoefficients":[[9 R],[9 G],[9 B]]},          planar 3 x 9
//  "webxr":{"sphericalHarmonicsCoefficients":[r0,g0,b0,r1,g1,b1,...]}}     interleaved 27
// ARKit and WebXR coefficient order and sign conventions are documented in docs/face_light.md;
// the values are this project's SH convention converted to theirs (y up, z towards the viewer).
// ARKit and WebXR shade with linear radiance, so `units` must be msgs::ShLightUnits::kLinear (the
// light's msgs::ShLight units); anything else throws InputError naming the units.
std::string LightJson(const Sh9Rgb& coefficients_camera, const std::array<float, 3>& direction,
                      float intensity, float confidence, const std::array<float, 3>& colour,
                      int64_t stamp_ns, const std::string& frame_id, msgs::ShLightUnits units);

// The camera-frame coefficients converted to the ARKit / WebXR frame (x right, y up, z towards
// the viewer: a rotation of 180 degrees about x) in this project's basis order l(l+1)+m — the
// same order ARKit's ARDirectionalLightEstimate and WebXR's XRLightProbe use.
Sh9Rgb ToYUpFrame(const Sh9Rgb& coefficients_camera);

}  // namespace probeless::face_track
