// Linear light from a face: the face model's estimate (Knorr & Kurz 2014 eq. 19, in the model's
// albedo-normalised, possibly compressed I^g units) converted to linear radiance in the units of
// msgs::ShLight (linear RGB; a white Lambertian surface of albedo 1 under uniform radiance 1 reads
// 1), with the current face's albedo compensated (K&K §3.5: "this albedo term leads to a scale of
// the estimated illumination ... especially important when also estimating light colour"), plus
// the lit / backlit cues that lower the confidence (docs/face_light.md, "Linear light").
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "probeless/face_light/estimator.h"
#include "probeless/face_light/model.h"

namespace probeless::face_light {

struct LinearLightOptions {
  // Linear RGB diffuse albedo of the current face's skin; the samples are divided by it before
  // the fit, so the light comes out free of the skin's tint and scale. The default is a mid
  // skin tone (the geometric middle of the simulator's subject range, docs/sim.md); a face with
  // a darker (lighter) skin reads as a proportionally dimmer (brighter) light.
  std::array<double, 3> skin_albedo = {0.47, 0.32, 0.25};
  // kappa: msgs::ShLight units per model unit of directional power. The model's unit light is
  // the training light that makes the median frontal-lit sample read the face's albedo
  // (training.h), i.e. kappa = the median over the samples of (cosine x visibility) / pi for a
  // light at the camera (about 0.27 for cosines ~0.85). Measured 0.223 (median; p10-p90
  // 0.175-0.276) on simulated faces of known albedo and light, lights within 30 deg of the front
  // (linear_light_data_test; docs/face_light.md, "Linear light"); > 0.
  double unit_scale = 0.223;
  // A used sample counts as lit when the fitted direct term exceeds lit_ratio x its ambient term.
  double lit_ratio = 1.0;
  // Refine the estimator's direction by a local search (<= ~8 deg) minimising the linear fit's
  // residual (the compressed fit minimises that of I^g): a light of the model's linear form then
  // comes back within 3 %, but real faces' directions get worse (held-out Yale B mean 9.5 ->
  // 10.1 deg), so false (default) keeps the estimator's direction.
  bool refine_direction = false;
  // A fitted direction with z (face frame: into the head) above this is "behind" the face.
  double behind_z = 0.25;
};

// The linear light of one face estimate, in the light frame (the face frame, model.h).
struct LinearLight {
  bool valid = false;  // false: too few usable samples or no direction
  // Coefficients[n][c] (bands 0..2, probeless::sh convention): power[c] Y(direction) plus
  // ambient[c] sqrt(4 pi) Y_00, in msgs::ShLight units.
  std::array<std::array<float, 3>, kRtfCoefficients> coefficients{};
  std::array<float, 3> direction{};  // unit, towards the light (estimator's, refined)
  std::array<float, 3> power{};      // directional light P per channel (P Y(d)), ShLight units
  std::array<float, 3> ambient{};    // uniform radiance per channel, ShLight units
  float intensity = 0;               // mean of power
  // Share of the direct term in the summed fitted sample values (channel mean), [0, 1]: ~0 when
  // the face sees only the environment (unlit, backlit).
  float direct_fraction = 0;
  float lit_fraction = 0;  // used samples whose direct term exceeds lit_ratio x ambient term
  bool behind = false;     // direction.z > behind_z
  float r2 = 0;            // R^2 of the linear fit (channel mean), may be < 0
  int samples_used = 0;
};

// Converts estimates of one model to linear light. The model's response of sample i to a
// directional light of unit (model) power from d is tau_i(d) = max(0, t_i . Y(d))^(1/g) (the
// direction RTFs t_i of the model when it has them, else its 9-coefficient RTFs; g = the model's
// intensity_exponent), its response to uniform unit radiance alpha_i = integral of tau_i over the
// sphere (precomputed). Per channel c, with x_ic = I_ic / skin_albedo[c] the non-negative least
// squares fit x_ic = unit_scale (P_c tau_i(d) + r_c alpha_i) gives the directional power P_c and
// the ambient radiance r_c along the estimator's direction d (whose accuracy the compressed fit
// keeps), refined locally for the linear residual (refine_direction). Const and thread-safe.
class LinearLightConverter {
 public:
  // Throws FaceLightError if the model is invalid, an albedo is not in (0, 1], unit_scale <= 0,
  // lit_ratio <= 0 or behind_z is not in [-1, 1].
  explicit LinearLightConverter(const FaceLightModel& model, LinearLightOptions options = {});

  const LinearLightOptions& Options() const { return options_; }
  int SampleCount() const { return sample_count_; }

  // rgb[3 i + c]: linear sample values (as given to EstimateRgb, before any exponent); valid_bits
  // as EstimateRgb (empty = all valid); estimate: the estimator's result for these samples (its
  // dominant_direction is used). Returns valid = false when the estimate has no channel or no
  // direction, or fewer than 9 samples are usable. Throws FaceLightError if rgb.size() !=
  // 3 * SampleCount() or valid_bits is neither empty nor covers SampleCount() bits.
  LinearLight Convert(std::span<const float> rgb, std::span<const uint64_t> valid_bits,
                      const LightEstimate& estimate) const;

  // The forward model: linear sample values x_i (before the albedo) of the face under a
  // directional light of power P from d (face frame, unit) and uniform radiance r, per channel,
  // times the skin albedo: rgb[3 i + c] = albedo_c unit_scale (P_c tau_i(d) + r_c alpha_i).
  std::vector<float> Predict(const std::array<double, 3>& direction,
                             const std::array<double, 3>& power,
                             const std::array<double, 3>& ambient) const;

 private:
  double Tau(int i, const double* basis) const;

  LinearLightOptions options_;
  int sample_count_ = 0;
  int bands_ = 3;
  int n_ = 9;
  double inverse_exponent_ = 1;
  std::vector<double> rtf_;    // [i * n_ + a]
  std::vector<double> alpha_;  // per sample
};

// Expected angular error (degrees, RMS) of the face light's dominant direction from the cues of
// one conversion: the score s = min(clamp01(r2), clamp01((direct_fraction - 0.4) / 0.5)) (0 = the
// fit explains the face no better than its mean, or the direct light explains less than 40 % of
// it: unlit, backlit) mapped through a piecewise-linear table fitted on held-out Yale B subjects
// and simulated faces with lights all round (docs/face_light.md, "Confidence"; 120 deg at s = 0,
// 6.5 deg at s = 1). 180 for an invalid light.
double FaceLightExpectedErrorDeg(const LinearLight& light);

// The score above, in [0, 1].
double FaceLightScore(const LinearLight& light);

}  // namespace probeless::face_light
