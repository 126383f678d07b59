// Online light estimation from face samples (Knorr & Kurz 2014, sec. 3.5, eq. 19) with optional
// extensions beyond the paper: Tikhonov prior, robust sample rejection, non-negative light.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "probeless/face_light/model.h"
#include "probeless/sh/sh.h"

namespace probeless::msgs {
struct ShLight;
}

namespace probeless::face_light {

struct EstimatorOptions {
  // Tikhonov prior added to the normal equations of eq. 19, each scaled by the mean diagonal of
  // T^T T (so the weights are dimensionless): ridge * I (shrinks all 9 coefficients) plus
  // back_prior * B, B_ab = integral over the back hemisphere (z > 0, behind the head) of Y_a Y_b
  // (penalises light the face cannot see). 0 = the paper's plain least squares.
  double ridge = 0;
  double back_prior = 0;
  // Robust rejection: after each solve, samples whose residual (mean over channels) exceeds
  // robust_threshold * 1.4826 * median |residual| are dropped and the light re-solved, up to
  // robust_iterations times or until the rejected set stops changing.
  bool robust = false;
  int robust_iterations = 4;
  double robust_threshold = 2.5;
  // Non-negative light: the final solve is over lights that are sums of non-negative directional
  // lights from nn_directions Fibonacci directions (E = B c, c >= 0; Lawson-Hanson active-set
  // NNLS, at most nn_iterations outer iterations), instead of unconstrained SH coefficients.
  bool non_negative = false;
  int nn_directions = 96;
  int nn_iterations = 100;
  // Weight sample i by 1 / (residual_rms[i]^2 + weight_floor^2) (its training fit quality)
  // instead of 1; 0 = unweighted (the paper).
  double weight_floor = 0;
  // Dominant direction by fitting ONE directional light plus a uniform ambient term,
  // E = a Y(d) + c e_0 (a >= 0), to the samples instead of Sloan's optimal linear direction of the
  // unconstrained light (which attached shadows bias). The fit minimises the same (prior-weighted)
  // least-squares cost as the linear solve, evaluated in coefficient space from the 9 x 9 normal
  // matrix (or, with a model holding direction RTFs of more bands, their normal matrix): a and c
  // in closed form per direction, d by the best of directional_grid Fibonacci directions and the
  // linear direction, then Newton steps on the tangent plane (directional_iterations). Only
  // dominant_direction and intensity change; the SH coefficients stay the linear estimate.
  bool directional_fit = true;
  int directional_grid = 64;        // 0..1024 start directions (0 = start from the linear one)
  int directional_iterations = 3;   // 0..100 Newton steps (3: as accurate as 10 on Yale B)
  bool directional_ambient = true;  // fit the ambient term c (false: c = 0)
  // > 0: after the fit, drop samples whose residual under the fitted light exceeds this many
  // robust standard deviations (1.4826 MAD) and re-fit once from the fitted direction. 0 = off.
  double directional_robust = 0;
  // Use the model's direction RTFs (higher SH bands, model file version 2) for the directional
  // fit when the model has them; false = the 9-coefficient RTFs.
  bool use_direction_rtfs = true;
  // Tikhonov weight (relative to the mean diagonal) added to the direction RTFs' normal matrix.
  double direction_ridge = 1e-3;
  // With invalid samples (and neither robust nor non_negative): least-recently-used cache of this
  // many validity masks (0..64, 0 = off) holding the downdated 9 x 9 Cholesky factor (and the
  // correction of exact_masked_solve) and, for the directional fit, its downdated cost matrix and
  // the start grid's quadratic terms. A steady face changes its mask rarely; a hit skips the
  // downdates. Results are bit-identical with and without.
  int mask_cache = 4;
  // Plain solve with invalid samples: false (default) = the full-set float pseudo-inverse applied
  // to the intensities with the invalid ones zeroed, then the 9 x 9 correction
  // (T^T W T + R)_valid^-1 (T^T W T + R)_full (per mask, cached): the float precision of the
  // all-valid path (~1e-6 relative). Masks whose correction has an infinity norm above 4 (large
  // regions missing) and true here use the exact right-hand side T^T W v accumulated in double
  // (equal to the double least-squares solve to the float rounding of the output; ~1 us more).
  bool exact_masked_solve = false;
};

// One estimated light in the light frame (model.h). Units: albedo-normalised image intensity per
// unit power, i.e. a directional light of power 1 from the front makes the median frontal sample
// of the face read its albedo factor; divide the input intensities by the face's albedo to get
// albedo-free light (or leave them: the light is then scaled by the face's albedo).
struct LightEstimate {
  int channels = 0;  // 1 (gray) or 3 (RGB); 0 = no estimate (too few valid samples)
  // coefficients[n][c], n = l(l+1)+m (bands 0..2), c = R, G, B; gray copies into all three.
  std::array<std::array<float, 3>, kRtfCoefficients> coefficients{};
  // Sloan's optimal linear direction of the channel-mean light (unit, towards the light), or
  // (0, 0, 0) if band 1 vanishes.
  std::array<float, 3> dominant_direction{};
  // Power of the best-fitting directional light along dominant_direction (bands 1..2, channel
  // mean; sh::DirectionalPower).
  float intensity = 0;
  // [0, 1]: (samples used / samples in the model) * max(0, R^2 of the fit).
  float confidence = 0;
  int samples_used = 0;      // valid and not rejected
  int samples_rejected = 0;  // valid but dropped by the robust rejection
  float rms_residual = 0;    // RMS residual of the used samples (channel mean)
};

// Estimates lights from the samples of one model. Construction precomputes the pseudo-inverse for
// the full valid set and the prior matrices; Estimate* are const, allocation-free and thread-safe
// (the per-mask cache is guarded by a mutex that is never waited for: a busy cache is bypassed).
class FaceLightEstimator {
 public:
  // Throws FaceLightError if the model is invalid or options are out of range (negative weights,
  // robust_iterations outside 1..20, robust_threshold <= 0, nn_directions outside 9..1024,
  // nn_iterations outside 1..10000, mask_cache outside 0..64).
  explicit FaceLightEstimator(const FaceLightModel& model, EstimatorOptions options = {});
  ~FaceLightEstimator();
  FaceLightEstimator(FaceLightEstimator&&) noexcept;
  FaceLightEstimator& operator=(FaceLightEstimator&&) noexcept;

  int SampleCount() const { return sample_count_; }
  const EstimatorOptions& Options() const { return options_; }

  // Gray estimate from intensities[i] of model sample i (linear, same units as training: the
  // patch mean / 255, optionally divided by the face's albedo). valid_bits: bit (i % 64) of word
  // i / 64 set = sample i valid (msgs::FaceObservation::sample_valid layout); empty = all valid.
  // Inputs are raised to the model's intensity_exponent first. Non-finite intensities count as
  // invalid. Returns channels = 0 if fewer than 9 samples are
  // usable. Throws FaceLightError if intensities.size() != SampleCount() or valid_bits is neither
  // empty nor covers SampleCount() bits.
  LightEstimate EstimateGray(std::span<const float> intensities,
                             std::span<const uint64_t> valid_bits = {}) const;
  // RGB estimate, one light per channel from rgb[3 i + c] (interleaved R, G, B, e.g.
  // msgs::FaceObservation::sample_rgb); robust rejection uses the channel-mean residual so all
  // channels share one sample set. Same errors with rgb.size() != 3 * SampleCount().
  LightEstimate EstimateRgb(std::span<const float> rgb,
                            std::span<const uint64_t> valid_bits = {}) const;

 private:
  LightEstimate Estimate(const float* values, int channels,
                         std::span<const uint64_t> valid_bits) const;
  // Non-negative light minimising 1/2 E^T g E - rhs^T E (g: 9 x 9 normal matrix); false if the
  // passive-set system is singular.
  bool SolveNonNegative(const double* g, const double* rhs, double* light) const;

  EstimatorOptions options_;
  int sample_count_ = 0;
  double exponent_ = 1;              // model's intensity_exponent, applied to the inputs
  std::vector<float> rtf_;           // [i * 9 + n]
  int stride_ = 0;                   // sample count rounded up to a multiple of 8
  std::vector<float> rtf_t_;         // [n * stride_ + i] (transposed, zero padded)
  std::vector<float> wrtf_t_;        // the same times the sample weights
  std::vector<double> wrtf_td_;      // wrtf_t_ in double (the exact right-hand sides)
  std::vector<float> pinv_;          // [n * stride_ + i], (T^T W T + R)^-1 T^T W (full set), padded
  std::vector<float> weights_;       // per-sample weight (1 or training-residual based)
  std::array<double, 81> normal_{};  // T^T W T + R (full valid set)
  std::array<double, 81> prior_{};   // R
  std::vector<double> nn_basis_;     // [k * 9 + n] = Y_n(d_k)
  // Directional fit: start directions and their basis values ([k * dir_n_ + n]).
  std::vector<sh::Vec3> dir_grid_;
  std::vector<double> dir_grid_basis_;
  int dir_bands_ = 3;               // bands of the directional fit (3, or the direction RTFs')
  int dir_n_ = 9;                   // dir_bands_^2
  std::vector<float> dir_rtf_;      // [i * dir_n_ + n] direction RTFs (empty: use rtf_)
  std::vector<double> dir_normal_;  // their T^T W T + ridge (full valid set), dir_n_^2
  // Weighted RTFs of the fit, transposed and zero padded: [n * stride_ + i] = w_i t_in.
  std::vector<float> dir_wrtf_t_;
  // Per grid direction k, for the full valid set: Y_k^T M Y_k and (M Y_k)_0 (M = dir_normal_, or
  // normal_ for the 9-coefficient fit).
  std::vector<double> dir_grid_basis_t_;  // [a * grid size + k]
  std::vector<double> dir_grid_syy_;
  std::vector<double> dir_grid_s0y_;
  // Direction RTFs projected on the grid's basis, [i * grid size + k] = t_i.Y_k (downdates the
  // tables above per mask).
  std::vector<double> dir_grid_proj_;
  bool uniform_weights_ = true;  // every weight is 1 (weight_floor = 0)
  // Double copies for the downdates: [i * 9 + n] = t_in and w_i t_in; [i * dir_n_ + a] the same
  // for the RTFs of the directional fit.
  std::vector<double> rtf_d_, wrtf_d_, dir_rtf_d_, dir_wrtf_d_;
  struct MaskCache;
  std::unique_ptr<MaskCache> cache_;  // per validity mask (EstimatorOptions::mask_cache)
};

// Writes an estimate into an msgs::ShLight (bands = 3, coefficients, dominant_direction,
// intensity, confidence) as it is, i.e. in the model's units (compressed I^g for g != 1, scaled
// by the face's albedo), and says so: units = msgs::ShLightUnits::kFaceModel, NOT the message's
// linear units; convert with LinearLightConverter (linear_light.h) for a light others consume.
// The header is left to the caller.
void FillShLight(const LightEstimate& estimate, msgs::ShLight& out);

}  // namespace probeless::face_light
