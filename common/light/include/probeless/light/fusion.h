// Light fusion: one light from several estimates of the same lighting (beyond both papers): the
// face-based estimate (Knorr & Kurz 2014) and the scene-based one (Gruber et al. 2015) combined by
// their confidences, so the renderer can follow whichever is better at the moment
// (docs/light.md, "Fusion").
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "probeless/error/error.h"
#include "probeless/msgs/sh_light.h"

namespace probeless::light {

class FusionError : public InputError {
 public:
  using InputError::InputError;
};

// The one confidence scale of msgs::ShLight (docs/messages.md): confidence c <-> expected RMS
// angular error e of the dominant direction, c = 1 / (1 + (e / kConfidenceReferenceErrorDeg)^2)
// (c = 0.5 at 10 deg, 0.2 at 20 deg, 0.05 at 44 deg). Then c / (1 - c) = (10 deg / e)^2 is the
// inverse-variance weight of the estimate.
inline constexpr double kConfidenceReferenceErrorDeg = msgs::kShLightReferenceErrorDeg;
// e in degrees (>= 0; +inf -> 0) -> c in [0, 1] (msgs::ShLightConfidenceFromExpectedError).
double ConfidenceFromExpectedError(double error_deg);
// c in [0, 1] -> e in degrees (c = 0 -> +inf).
double ExpectedErrorFromConfidence(double confidence);
// The factor of SH band `band` (>= 0) in the expected light of an estimate of confidence c under
// its own direction uncertainty: the SH convolution with a spherical Gaussian (Ramamoorthi &
// Hanrahan 2001), exp(-l(l+1) sigma^2 / 2) with sigma = blur x e / sqrt(2 ln 2), e =
// ExpectedErrorFromConfidence(c) in radians (a Rayleigh-distributed angle whose median is e).
// Band 0 is 1; blur 0 gives 1; c = 0 (no known direction) gives 0 for every band >= 1.
double UncertaintyBandFactor(double confidence, double blur, int band);
// A light of confidence c as its expected value under its own direction uncertainty: coefficient k
// (SH order l (l + 1) + m, band l = floor(sqrt(k))) multiplied by UncertaintyBandFactor(c, blur,
// l), so band 0 and blur 0 leave it unchanged. Two layouts, one band loop: a white light's
// coefficients (LightEstimate), and RGB triples (msgs::ShLight, render::ShLightRgb), whose channels
// are multiplied by the factor rounded to float.
void BlurByUncertainty(std::span<double> coefficients, double confidence, double blur);
void BlurByUncertainty(std::span<std::array<float, 3>> coefficients, double confidence,
                       double blur);

// A producer's raw confidence mapped onto the scale above: knots (raw confidence, expected error
// in degrees), raw ascending in [0, 1], errors > 0; piecewise linear in the error between knots,
// constant beyond the ends. scene_light applies its own (ScenePipelineOptions::confidence_knots);
// light_fusion has one per input for producers that publish a raw confidence (docs/light.md
// "Confidence").
class ConfidenceCalibration {
 public:
  // Empty knots = identity (the producer already publishes on the scale). Throws FusionError
  // unless the list has an even number of values (pairs), raw values are strictly ascending in
  // [0, 1] and errors are > 0.
  explicit ConfidenceCalibration(std::span<const double> knots = {});
  bool identity() const { return raw_.empty(); }
  // Raw confidence -> confidence on the ShLight scale.
  double Apply(double raw_confidence) const;

 private:
  std::vector<double> raw_, error_deg_;
};

// One input: a light (its units in light.units, msgs::ShLightUnits) and a name for messages
// (e.g. the topic).
struct FusionInput {
  msgs::ShLight light;
  std::string name;
};

struct FusionOptions {
  // An input whose header.stamp_ns is more than this older than the newest input is ignored, ns.
  int64_t max_age_ns = 500'000'000;
  // Inputs with confidence below this are ignored (0.05 = an expected error of 44 deg).
  float min_confidence = 0.05f;
  // Two inputs whose dominant directions are more than this many combined expected errors
  // (sqrt(e_a^2 + e_b^2)) apart do not see the same light (or one is wrong): the less confident
  // is left out instead of averaging the two into a direction neither supports. 0 = off.
  double consistency_sigma = 3;
};

// Fuses `inputs` (linear lights of one frame_id, e.g. the camera frame):
// - inputs are used when fresh (FusionOptions::max_age_ns), confident enough and consistent
//   (consistency_sigma, most confident first);
// - weights w_i = c_i / (1 - c_i) (inverse variance on the confidence scale above; c clamped to
//   0.999);
// - coefficients: sum over the inputs that have coefficient k of w_i c_ik, divided by the sum of
//   ALL used inputs' weights: a band only one input has is weighted by that input's share (a
//   missing band counts as no light there), never copied at full weight; the result has the
//   largest band count;
// - dominant direction: the normalised w-weighted sum of the unit directions (inputs without one
//   are left out); intensity: the w-weighted mean;
// - confidence: from the summed weights, W / (1 + W) (inverse variances add);
// - header: the newest used input's.
// - units: the output is msgs::ShLightUnits::kLinear.
// Returns nullopt when no input qualifies. Throws FusionError naming the input and its units when
// one is not msgs::ShLightUnits::kLinear (face-model, unscaled and unknown units are never averaged
// raw, and none converts to linear without the face's samples), when the frames differ (naming
// both), or when an input fails ShLight::Validate (msgs::MessageError).
std::optional<msgs::ShLight> FuseLights(std::span<const FusionInput> inputs,
                                        const FusionOptions& options = {});

}  // namespace probeless::light
