#include "probeless/eval/metrics.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace probeless::eval {

namespace {

const std::array<float, 256>& SrgbTable() {
  static const std::array<float, 256> table = [] {
    std::array<float, 256> t{};
    for (int i = 0; i < 256; ++i) {
      const double c = i / 255.0;
      t[i] = static_cast<float>(c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4));
    }
    return t;
  }();
  return table;
}

bool SameSize(const LinearImage& a, const LinearImage& b) {
  return a.width == b.width && a.height == b.height && a.rgb.size() == b.rgb.size();
}

}  // namespace

float SrgbToLinear(uint8_t value) { return SrgbTable()[value]; }

LinearImage DecodeSrgb(std::span<const uint8_t> rgb8, int width, int height) {
  LinearImage image;
  image.width = width;
  image.height = height;
  image.rgb.resize(static_cast<size_t>(width) * height * 3);
  const auto& table = SrgbTable();
  for (size_t i = 0; i < image.rgb.size() && i < rgb8.size(); ++i) image.rgb[i] = table[rgb8[i]];
  return image;
}

MaskedSums ObjectSums(const LinearImage& estimate, const LinearImage& truth,
                      std::span<const uint8_t> mask) {
  MaskedSums s;
  if (!SameSize(estimate, truth) || mask.size() * 3 != truth.rgb.size()) return s;
  double ee = 0, et = 0;
  for (size_t p = 0; p < mask.size(); ++p) {
    if (mask[p] < 128) continue;
    for (size_t c = 0; c < 3; ++c) {
      const double e = estimate.rgb[p * 3 + c], t = truth.rgb[p * 3 + c];
      s.sum_sq += (e - t) * (e - t);
      ee += e * e;
      et += e * t;
      ++s.count;
    }
  }
  s.scale = ee > 0 ? et / ee : 1.0;
  for (size_t p = 0; p < mask.size(); ++p) {
    if (mask[p] < 128) continue;
    for (size_t c = 0; c < 3; ++c) {
      const double d = s.scale * estimate.rgb[p * 3 + c] - truth.rgb[p * 3 + c];
      s.si_sum_sq += d * d;
    }
  }
  return s;
}

MaskedSums EffectSums(const LinearImage& estimate, const LinearImage& original,
                      const LinearImage& truth, std::span<const uint8_t> mask, float min_original) {
  MaskedSums s;
  s.scale = 1;
  if (!SameSize(estimate, truth) || !SameSize(original, truth) ||
      mask.size() * 3 != truth.rgb.size()) {
    return s;
  }
  for (size_t p = 0; p < mask.size(); ++p) {
    if (mask[p] < 128) continue;
    for (size_t c = 0; c < 3; ++c) {
      const double o = original.rgb[p * 3 + c];
      if (o < min_original) continue;
      const double re = std::clamp(estimate.rgb[p * 3 + c] / o, 0.0, 4.0);
      const double rt = std::clamp(truth.rgb[p * 3 + c] / o, 0.0, 4.0);
      s.sum_sq += (re - rt) * (re - rt);
      ++s.count;
    }
  }
  return s;
}

std::optional<double> PooledRmse::Rmse() const {
  if (count == 0) return std::nullopt;
  return std::sqrt(sum_sq / static_cast<double>(count));
}

std::optional<double> PooledRmse::SiRmse() const {
  if (count == 0) return std::nullopt;
  return std::sqrt(si_sum_sq / static_cast<double>(count));
}

double MeanSquaredError(const LinearImage& a, const LinearImage& b) {
  if (!SameSize(a, b) || a.rgb.empty()) return 0;
  double sum = 0;
  for (size_t i = 0; i < a.rgb.size(); ++i) {
    const double d = static_cast<double>(a.rgb[i]) - b.rgb[i];
    sum += d * d;
  }
  return sum / static_cast<double>(a.rgb.size());
}

double PsnrDb(double mse) {
  if (!(mse > 1e-10)) return 100.0;
  return std::min(100.0, 10.0 * std::log10(1.0 / mse));
}

std::optional<double> Median(std::vector<double> values) { return Percentile(values, 0.5); }

std::optional<double> Percentile(std::vector<double> values, double p) {
  if (values.empty()) return std::nullopt;
  std::sort(values.begin(), values.end());
  const double position = std::clamp(p, 0.0, 1.0) * static_cast<double>(values.size() - 1);
  const size_t below = static_cast<size_t>(std::floor(position));
  const size_t above = std::min(values.size() - 1, below + 1);
  const double f = position - static_cast<double>(below);
  return values[below] + f * (values[above] - values[below]);
}

std::optional<double> AngleDeg(const float a[3], const double b[3]) {
  const double na = std::sqrt(double(a[0]) * a[0] + double(a[1]) * a[1] + double(a[2]) * a[2]);
  const double nb = std::sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2]);
  if (!(na > 0) || !(nb > 0)) return std::nullopt;
  const double c = (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) / (na * nb);
  return std::acos(std::clamp(c, -1.0, 1.0)) * 180.0 / 3.14159265358979323846;
}

}  // namespace probeless::eval
