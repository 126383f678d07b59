// Light estimation (Knorr & Kurz 2014, sec. 3.5, eq. 19) with optional prior, robust rejection and
// non-negativity (see probeless/face_light/estimator.h).
#include "probeless/face_light/estimator.h"

#include <algorithm>
#include <cmath>

#include "linalg.h"
#include "probeless/msgs/sh_light.h"
#include "probeless/sh/sh.h"

namespace probeless::face_light {
namespace {

constexpr int kN = kRtfCoefficients;
constexpr int kMaxNnDirections = 1024;
constexpr int kMaxPassive = 32;

bool BitSet(std::span<const uint64_t> bits, int i) {
  return bits.empty() || ((bits[i / 64] >> (i % 64)) & 1u);
}

// sum_i a[i] b[i] for count a multiple of 8, with 8 independent lanes so the compiler vectorises
// it without -ffast-math.
float Dot8(const float* a, const float* b, int count) {
  float lanes[8] = {};
  for (int i = 0; i < count; i += 8) {
    for (int l = 0; l < 8; ++l) lanes[l] += a[i + l] * b[i + l];
  }
  return ((lanes[0] + lanes[4]) + (lanes[1] + lanes[5])) +
         ((lanes[2] + lanes[6]) + (lanes[3] + lanes[7]));
}

}  // namespace

FaceLightEstimator::FaceLightEstimator(const FaceLightModel& model, EstimatorOptions options)
    : options_(options) {
  model.Validate();
  if (!(options.ridge >= 0) || !(options.back_prior >= 0) || !(options.weight_floor >= 0) ||
      options.robust_iterations < 1 || options.robust_iterations > 20 ||
      !(options.robust_threshold > 0) || options.nn_directions < 9 ||
      options.nn_directions > kMaxNnDirections || options.nn_iterations < 1 ||
      options.nn_iterations > 10000) {
    throw FaceLightError(
        "FaceLightEstimator: options out of range (ridge, back_prior, weight_floor >= 0; "
        "robust_iterations 1..20; robust_threshold > 0; nn_directions 9..1024; "
        "nn_iterations 1..10000)");
  }
  sample_count_ = model.SampleCount();
  exponent_ = model.intensity_exponent;
  const int n_samples = sample_count_;
  rtf_.resize(static_cast<size_t>(n_samples) * kN);
  weights_.assign(n_samples, 1.0f);
  for (int i = 0; i < n_samples; ++i) {
    for (int n = 0; n < kN; ++n) rtf_[i * kN + n] = model.rtf[i][n];
    if (options.weight_floor > 0) {
      const double r = model.residual_rms[i];
      weights_[i] = static_cast<float>(1 / (r * r + options.weight_floor * options.weight_floor));
    }
  }
  if (options.weight_floor > 0) {  // mean weight 1, so the prior's scale does not depend on it
    double sum = 0;
    for (float w : weights_) sum += w;
    for (float& w : weights_) w = static_cast<float>(w * n_samples / sum);
  }
  std::array<double, 81> data{};
  for (int i = 0; i < n_samples; ++i) {
    const float* t = &rtf_[i * kN];
    for (int a = 0; a < kN; ++a) {
      for (int b = 0; b < kN; ++b) data[a * kN + b] += weights_[i] * double(t[a]) * t[b];
    }
  }
  double trace = 0;
  for (int a = 0; a < kN; ++a) trace += data[a * kN + a];
  const double scale = trace / kN;
  prior_.fill(0);
  if (options.ridge > 0) {
    for (int a = 0; a < kN; ++a) prior_[a * kN + a] += scale * options.ridge;
  }
  if (options.back_prior > 0) {
    // B_ab = integral over z > 0 (behind the head in the light frame) of Y_a Y_b.
    const sh::QuadratureRule rule = sh::GaussLegendreRule(48);
    for (size_t q = 0; q < rule.directions.size(); ++q) {
      if (rule.directions[q][2] <= 0) continue;
      const std::array<double, 9> y = sh::Basis9(rule.directions[q]);
      for (int a = 0; a < kN; ++a) {
        for (int b = 0; b < kN; ++b) {
          prior_[a * kN + b] += scale * options.back_prior * rule.weights[q] * y[a] * y[b];
        }
      }
    }
  }
  for (int k = 0; k < 81; ++k) normal_[k] = data[k] + prior_[k];
  std::array<double, 81> factor = normal_;
  if (!internal::Cholesky<9>(factor)) {
    throw FaceLightError(
        "FaceLightEstimator: the model's RTFs are rank-deficient (T^T T is singular)");
  }
  stride_ = (n_samples + 7) / 8 * 8;
  pinv_.assign(static_cast<size_t>(kN) * stride_, 0.0f);
  rtf_t_.assign(static_cast<size_t>(kN) * stride_, 0.0f);
  for (int i = 0; i < n_samples; ++i) {
    for (int n = 0; n < kN; ++n) rtf_t_[static_cast<size_t>(n) * stride_ + i] = rtf_[i * kN + n];
  }
  for (int i = 0; i < n_samples; ++i) {
    double column[kN];
    for (int n = 0; n < kN; ++n) column[n] = weights_[i] * double(rtf_[i * kN + n]);
    internal::CholeskySolve<9>(factor, column);
    for (int n = 0; n < kN; ++n) pinv_[static_cast<size_t>(n) * stride_ + i] = float(column[n]);
  }
  if (options.non_negative) {
    const std::vector<sh::Vec3> directions = sh::FibonacciSphere(options.nn_directions);
    nn_basis_.resize(directions.size() * kN);
    for (size_t k = 0; k < directions.size(); ++k) {
      const std::array<double, 9> y = sh::Basis9(directions[k]);
      std::copy(y.begin(), y.end(), nn_basis_.begin() + k * kN);
    }
  }
}

LightEstimate FaceLightEstimator::EstimateGray(std::span<const float> intensities,
                                               std::span<const uint64_t> valid_bits) const {
  if (intensities.size() != static_cast<size_t>(sample_count_)) {
    throw FaceLightError("FaceLightEstimator: " + std::to_string(intensities.size()) +
                         " intensities, the model has " + std::to_string(sample_count_) +
                         " samples");
  }
  return Estimate(intensities.data(), 1, valid_bits);
}

LightEstimate FaceLightEstimator::EstimateRgb(std::span<const float> rgb,
                                              std::span<const uint64_t> valid_bits) const {
  if (rgb.size() != 3 * static_cast<size_t>(sample_count_)) {
    throw FaceLightError("FaceLightEstimator: " + std::to_string(rgb.size()) +
                         " RGB values, expected 3 x " + std::to_string(sample_count_) + " samples");
  }
  return Estimate(rgb.data(), 3, valid_bits);
}

LightEstimate FaceLightEstimator::Estimate(const float* values, int channels,
                                           std::span<const uint64_t> valid_bits) const {
  const int n_samples = sample_count_;
  if (!valid_bits.empty() && valid_bits.size() * 64 < static_cast<size_t>(n_samples)) {
    throw FaceLightError("FaceLightEstimator: " + std::to_string(valid_bits.size()) +
                         " validity words cover fewer than " + std::to_string(n_samples) +
                         " samples");
  }
  // Deinterleave (zero padding up to stride_), apply the response exponent, flag validity.
  const int stride = stride_;
  alignas(32) float v[3][kMaxSamples + 8];
  alignas(32) float mean_value[kMaxSamples + 8];
  uint8_t valid[kMaxSamples];
  uint8_t active[kMaxSamples];
  for (int c = 0; c < channels; ++c) {
    float* row = v[c];
    for (int i = 0; i < n_samples; ++i) row[i] = values[i * channels + c];
    for (int i = n_samples; i < stride; ++i) row[i] = 0;
    if (exponent_ == 0.5) {
      for (int i = 0; i < n_samples; ++i) row[i] = std::sqrt(row[i] > 0 ? row[i] : 0.0f);
    } else if (exponent_ != 1) {
      const float g = static_cast<float>(exponent_);
      for (int i = 0; i < n_samples; ++i) row[i] = std::pow(row[i] > 0 ? row[i] : 0.0f, g);
    }
  }
  int valid_count = 0;
  const float inv_channels = 1.0f / channels;
  for (int i = 0; i < stride; ++i) {
    float sum = 0;
    for (int c = 0; c < channels; ++c) sum += v[c][i];
    mean_value[i] = sum * inv_channels;
  }
  for (int i = 0; i < n_samples; ++i) {
    bool ok = BitSet(valid_bits, i);
    for (int c = 0; c < channels; ++c) ok = ok && std::isfinite(values[i * channels + c]);
    valid[i] = ok;
    active[i] = ok;
    valid_count += ok;
  }
  LightEstimate out;
  out.samples_used = valid_count;
  if (valid_count < kN) return out;
  const float* weights = weights_.data();

  double e[3][kN] = {};
  std::array<double, 81> factor{};
  double rhs[3][kN] = {};
  // Weighted normal equations over the active set: factor = L of (T^T W T + R), rhs = T^T W v.
  const auto build = [&]() -> bool {
    int inactive = 0;
    for (int i = 0; i < n_samples; ++i) inactive += !active[i];
    if (2 * inactive < n_samples) {  // downdate the precomputed full-set matrix
      factor = normal_;
      for (int i = 0; i < n_samples; ++i) {
        if (active[i]) continue;
        const float* t = &rtf_[i * kN];
        const double w = weights_[i];
        for (int a = 0; a < kN; ++a) {
          for (int b = 0; b <= a; ++b) factor[a * kN + b] -= w * t[a] * t[b];
        }
      }
    } else {
      factor = prior_;
      for (int i = 0; i < n_samples; ++i) {
        if (!active[i]) continue;
        const float* t = &rtf_[i * kN];
        const double w = weights[i];
        for (int a = 0; a < kN; ++a) {
          for (int b = 0; b <= a; ++b) factor[a * kN + b] += w * t[a] * t[b];
        }
      }
    }
    for (int c = 0; c < channels; ++c) {
      double* acc = rhs[c];
      std::fill(acc, acc + kN, 0.0);
      for (int i = 0; i < n_samples; ++i) {
        if (!active[i]) continue;
        const double wv = weights[i] * double(v[c][i]);
        const float* t = &rtf_[i * kN];
        for (int n = 0; n < kN; ++n) acc[n] += t[n] * wv;
      }
    }
    return internal::Cholesky<9>(factor);
  };
  const auto solve = [&]() {
    for (int c = 0; c < channels; ++c) {
      std::copy(rhs[c], rhs[c] + kN, e[c]);
      internal::CholeskySolve<9>(factor, e[c]);
    }
  };

  const bool fast = valid_count == n_samples && !options_.robust && !options_.non_negative;
  if (fast) {
    // E = pinv v: precomputed pseudo-inverse of the full valid set (eq. 19).
    for (int c = 0; c < channels; ++c) {
      for (int n = 0; n < kN; ++n)
        e[c][n] = Dot8(&pinv_[static_cast<size_t>(n) * stride], v[c], stride);
    }
  } else {
    if (!build()) return out;
    solve();
  }

  // Residuals (channel mean) of every sample under the current light: the residual is linear, so
  // it is the channel-mean intensity minus the RTF applied to the channel-mean light.
  alignas(32) float residual[kMaxSamples + 8];
  const auto compute_residuals = [&]() {
    float mean_e[kN];
    for (int n = 0; n < kN; ++n) {
      double sum = 0;
      for (int c = 0; c < channels; ++c) sum += e[c][n];
      mean_e[n] = static_cast<float>(sum / channels);
    }
    std::copy(mean_value, mean_value + stride, residual);
    for (int n = 0; n < kN; ++n) {
      const float* t = &rtf_t_[static_cast<size_t>(n) * stride];
      const float en = mean_e[n];
      for (int i = 0; i < stride; ++i) residual[i] -= t[i] * en;
    }
  };

  if (options_.robust) {
    float magnitude[kMaxSamples];
    for (int iteration = 0; iteration < options_.robust_iterations; ++iteration) {
      compute_residuals();
      int m = 0;
      for (int i = 0; i < n_samples; ++i) {
        if (valid[i]) magnitude[m++] = std::abs(residual[i]);
      }
      std::nth_element(magnitude, magnitude + m / 2, magnitude + m);
      const float limit = static_cast<float>(options_.robust_threshold * 1.4826 * magnitude[m / 2]);
      bool changed = false;
      int kept = 0;
      uint8_t next[kMaxSamples];
      for (int i = 0; i < n_samples; ++i) {
        next[i] = valid[i] && std::abs(residual[i]) <= limit;
        kept += next[i];
        changed = changed || next[i] != active[i];
      }
      if (!changed || kept < 2 * kN) break;
      std::copy(next, next + n_samples, active);
      if (!build()) return out;
      solve();
    }
    if (options_.non_negative && !build()) return out;  // factor/rhs of the final active set
  }

  if (options_.non_negative) {
    // Rebuild the (unfactored) normal matrix of the active set: G = L L^T.
    double g[81];
    for (int a = 0; a < kN; ++a) {
      for (int b = 0; b <= a; ++b) {
        double s = 0;
        for (int k = 0; k <= b; ++k) s += factor[a * kN + k] * factor[b * kN + k];
        g[a * kN + b] = g[b * kN + a] = s;
      }
    }
    for (int c = 0; c < channels; ++c) {
      if (!SolveNonNegative(g, rhs[c], e[c])) return out;
    }
  }

  // Outputs.
  compute_residuals();
  double mean_light[kN] = {};
  for (int n = 0; n < kN; ++n) {
    for (int c = 0; c < 3; ++c) {
      const double value = e[channels == 1 ? 0 : c][n];
      out.coefficients[n][c] = static_cast<float>(value);
      mean_light[n] += value / 3;
    }
  }
  const sh::Vec3 direction = sh::OptimalLinearDirection(mean_light);
  for (int k = 0; k < 3; ++k) out.dominant_direction[k] = static_cast<float>(direction[k]);
  out.intensity = direction == sh::Vec3{0, 0, 0}
                      ? 0.0f
                      : static_cast<float>(sh::DirectionalPower(
                            std::span<const double>(mean_light, kN), direction));
  int used = 0;
  double mean = 0;
  for (int i = 0; i < n_samples; ++i) {
    if (active[i]) ++used, mean += mean_value[i];
  }
  mean /= std::max(used, 1);
  double ss_res = 0, ss_tot = 0;
  for (int i = 0; i < n_samples; ++i) {
    if (!active[i]) continue;
    ss_res += double(residual[i]) * residual[i];
    ss_tot += (mean_value[i] - mean) * (mean_value[i] - mean);
  }
  out.channels = channels;
  out.samples_used = used;
  out.samples_rejected = valid_count - used;
  out.rms_residual = static_cast<float>(std::sqrt(ss_res / std::max(used, 1)));
  const double r2 = ss_tot > 0 ? 1 - ss_res / ss_tot : 0;
  out.confidence =
      static_cast<float>(std::clamp(r2, 0.0, 1.0) * static_cast<double>(used) / n_samples);
  return out;
}

bool FaceLightEstimator::SolveNonNegative(const double* g, const double* rhs, double* light) const {
  // Lawson & Hanson (1974) active-set NNLS on min 1/2 (B c)^T G (B c) - rhs^T B c, c >= 0, where
  // column k of B is Y(d_k): the light is a non-negative sum of directional lights.
  const int directions = options_.nn_directions;
  double f[kMaxNnDirections];  // B^T rhs
  double scale = 0;
  for (int k = 0; k < directions; ++k) {
    const double* y = &nn_basis_[k * kN];
    double s = 0;
    for (int n = 0; n < kN; ++n) s += y[n] * rhs[n];
    f[k] = s;
    scale = std::max(scale, std::abs(s));
  }
  const double tolerance = 1e-10 * std::max(scale, 1e-300);
  int passive[kMaxPassive];
  double c[kMaxPassive];  // coefficient of passive[p]
  int count = 0;
  uint8_t in_passive[kMaxNnDirections] = {};
  double e[kN] = {};
  const auto light_of = [&](const double* coefficients, double* out_light) {
    std::fill(out_light, out_light + kN, 0.0);
    for (int p = 0; p < count; ++p) {
      const double* y = &nn_basis_[passive[p] * kN];
      for (int n = 0; n < kN; ++n) out_light[n] += coefficients[p] * y[n];
    }
  };
  // Unconstrained solution on the passive set: (Y_P^T G Y_P) s = f_P.
  const auto solve_passive = [&](double* s) -> bool {
    double gy[kMaxPassive][kN];
    for (int p = 0; p < count; ++p) {
      const double* y = &nn_basis_[passive[p] * kN];
      for (int a = 0; a < kN; ++a) {
        double sum = 0;
        for (int b = 0; b < kN; ++b) sum += g[a * kN + b] * y[b];
        gy[p][a] = sum;
      }
    }
    double h[kMaxPassive * kMaxPassive];
    double trace = 0;
    for (int p = 0; p < count; ++p) {
      for (int q = 0; q <= p; ++q) {
        const double* y = &nn_basis_[passive[q] * kN];
        double sum = 0;
        for (int n = 0; n < kN; ++n) sum += gy[p][n] * y[n];
        h[p * count + q] = sum;
      }
      trace += h[p * count + p];
      s[p] = f[passive[p]];
    }
    for (int p = 0; p < count; ++p) h[p * count + p] += 1e-12 * trace;  // rank <= 9 guard
    if (!internal::CholeskyN(h, count)) return false;
    internal::CholeskySolveN(h, count, s);
    return true;
  };
  for (int iteration = 0; iteration < options_.nn_iterations; ++iteration) {
    // Gradient of the objective's negative: w = f - B^T G B c.
    double ge[kN];
    for (int a = 0; a < kN; ++a) {
      double sum = 0;
      for (int b = 0; b < kN; ++b) sum += g[a * kN + b] * e[b];
      ge[a] = sum;
    }
    int best = -1;
    double best_w = tolerance;
    for (int k = 0; k < directions; ++k) {
      if (in_passive[k]) continue;
      const double* y = &nn_basis_[k * kN];
      double w = f[k];
      for (int n = 0; n < kN; ++n) w -= y[n] * ge[n];
      if (w > best_w) best_w = w, best = k;
    }
    if (best < 0 || count == kMaxPassive) break;
    passive[count] = best;
    c[count] = 0;
    in_passive[best] = 1;
    ++count;
    for (int inner = 0; inner < kMaxPassive + 1; ++inner) {
      double s[kMaxPassive];
      if (!solve_passive(s)) return false;
      bool feasible = true;
      for (int p = 0; p < count; ++p) feasible = feasible && s[p] > 0;
      if (feasible) {
        std::copy(s, s + count, c);
        break;
      }
      double alpha = 1;
      for (int p = 0; p < count; ++p) {
        if (s[p] <= 0) alpha = std::min(alpha, c[p] / (c[p] - s[p]));
      }
      int kept = 0;
      for (int p = 0; p < count; ++p) {
        const double value = c[p] + alpha * (s[p] - c[p]);
        if (value > 1e-14 * std::max(1.0, std::abs(c[p]))) {
          passive[kept] = passive[p];
          c[kept] = value;
          ++kept;
        } else {
          in_passive[passive[p]] = 0;
        }
      }
      count = kept;
      if (count == 0) break;
    }
    light_of(c, e);
  }
  std::copy(e, e + kN, light);
  return true;
}

void FillShLight(const LightEstimate& estimate, msgs::ShLight& out) {
  out.bands = kShBands;
  for (auto& row : out.coefficients) row[0] = row[1] = row[2] = 0;
  for (int n = 0; n < kN; ++n) {
    for (int c = 0; c < 3; ++c) out.coefficients[n][c] = estimate.coefficients[n][c];
  }
  for (int k = 0; k < 3; ++k) out.dominant_direction[k] = estimate.dominant_direction[k];
  out.intensity = estimate.intensity;
  out.confidence = std::clamp(estimate.confidence, 0.0f, 1.0f);
}

}  // namespace probeless::face_light
