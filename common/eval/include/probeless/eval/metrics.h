// Image metrics of the composite evaluation (docs/evaluation.md, "composite_eval"): sRGB
// decoding, masked RMSE and scale-invariant RMSE on the object, RMSE of the shading ratio on the
// objects' effect region, whole-image PSNR, and the median / percentile summaries.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <vector>

namespace probeless::eval {

// A linear RGB image, row-major, 3 floats per pixel.
struct LinearImage {
  int width = 0;
  int height = 0;
  std::vector<float> rgb;
};

// The sRGB decoding of one 8-bit value (IEC 61966-2-1), in [0, 1].
float SrgbToLinear(uint8_t value);
// rgb8 bytes (width * height * 3) decoded to linear RGB.
LinearImage DecodeSrgb(std::span<const uint8_t> rgb8, int width, int height);

// Squared-error sums of one frame on a mask (every channel of every masked pixel counts).
struct MaskedSums {
  double sum_sq = 0;     // sum of (estimate - truth)^2
  double si_sum_sq = 0;  // the same after the best single scale s (least squares)
  double scale = 1;      // s = <e, t> / <e, e> (1 when e is all zero)
  uint64_t count = 0;    // channel values summed
};

// Object-mask residuals of `estimate` against `truth` where mask >= 128 (same sizes, else an
// empty result).
MaskedSums ObjectSums(const LinearImage& estimate, const LinearImage& truth,
                      std::span<const uint8_t> mask);

// Shading-ratio residuals where mask >= 128: (estimate / original - truth / original)^2 per
// channel where the original is at least `min_original` (darker pixels carry no ratio); ratios are
// clamped to [0, 4]. si_sum_sq and scale are unused (0, 1).
MaskedSums EffectSums(const LinearImage& estimate, const LinearImage& original,
                      const LinearImage& truth, std::span<const uint8_t> mask,
                      float min_original = 0.005f);

// Accumulates frames: root of the pooled mean of the squared residuals (nullopt when empty).
struct PooledRmse {
  double sum_sq = 0, si_sum_sq = 0;
  uint64_t count = 0;
  void Add(const MaskedSums& s) {
    sum_sq += s.sum_sq;
    si_sum_sq += s.si_sum_sq;
    count += s.count;
  }
  std::optional<double> Rmse() const;
  std::optional<double> SiRmse() const;
};

// Mean squared error of the whole image (every channel), linear RGB.
double MeanSquaredError(const LinearImage& a, const LinearImage& b);
// 10 log10(1 / mse) dB for linear values of peak 1; capped at 100 dB (identical images).
double PsnrDb(double mse);

// Median (mean of the two middle values for an even count) and linear-interpolation percentile
// (numpy's default: p in [0, 1]); nullopt for no values.
std::optional<double> Median(std::vector<double> values);
std::optional<double> Percentile(std::vector<double> values, double p);

// Angle between two directions in degrees (any lengths > 0; nullopt if one is zero).
std::optional<double> AngleDeg(const float a[3], const double b[3]);

}  // namespace probeless::eval
