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

constexpr int kMaxDirN = 25;  // 5 bands

// Directional fit in coefficient space: minimise cost(E) = E^T M E - 2 b^T E (the least-squares
// cost up to a constant) over E = a Y(d) + c e_0, a >= 0 (c = 0 without ambient). For a fixed d,
// a and c are closed form and cost(d) = -(a b.Y(d) + c b_0).
struct DirectionalProblem {
  const double* m;  // n x n
  const double* b;  // n
  int bands;
  int n;
  bool ambient;

  double Cost(const double* y, double* a_out = nullptr, double* c_out = nullptr) const {
    double my[kMaxDirN];
    double syy = 0, ry = 0;
    for (int i = 0; i < n; ++i) {
      double sum = 0;
      const double* row = m + i * n;
      for (int j = 0; j < n; ++j) sum += row[j] * y[j];
      my[i] = sum;
      syy += y[i] * sum;
      ry += b[i] * y[i];
    }
    double a = 0, c = 0, cost = 0;
    if (ambient) {
      const double s0y = my[0], s00 = m[0], r0 = b[0];
      const double det = syy * s00 - s0y * s0y;
      if (det > 1e-12 * syy * s00) {
        a = (ry * s00 - s0y * r0) / det;
        c = (syy * r0 - s0y * ry) / det;
      }
      if (!(a > 0)) {
        a = 0;
        c = s00 > 0 ? r0 / s00 : 0;
      }
      cost = -(a * ry + c * r0);
    } else {
      a = syy > 0 ? std::max(ry / syy, 0.0) : 0;
      cost = -a * ry;
    }
    if (a_out) *a_out = a;
    if (c_out) *c_out = c;
    return cost;
  }
  double CostAt(const sh::Vec3& d, double* a = nullptr, double* c = nullptr) const {
    double y[kMaxDirN];
    sh::EvaluateBasis<double>(bands, d[0], d[1], d[2], y);
    return Cost(y, a, c);
  }
};

sh::Vec3 Normalised(const sh::Vec3& v) {
  const double len = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  return {v[0] / len, v[1] / len, v[2] / len};
}

// Tangent basis of unit d.
void Tangents(const sh::Vec3& d, sh::Vec3& t1, sh::Vec3& t2) {
  const sh::Vec3 helper = std::abs(d[0]) < 0.9 ? sh::Vec3{1, 0, 0} : sh::Vec3{0, 1, 0};
  t1 = Normalised({helper[1] * d[2] - helper[2] * d[1], helper[2] * d[0] - helper[0] * d[2],
                   helper[0] * d[1] - helper[1] * d[0]});
  t2 = {d[1] * t1[2] - d[2] * t1[1], d[2] * t1[0] - d[0] * t1[2], d[0] * t1[1] - d[1] * t1[0]};
}

sh::Vec3 Moved(const sh::Vec3& d, const sh::Vec3& t1, const sh::Vec3& t2, double u, double v) {
  return Normalised({d[0] + u * t1[0] + v * t2[0], d[1] + u * t1[1] + v * t2[1],
                     d[2] + u * t1[2] + v * t2[2]});
}

// Best start direction (init and the grid), then Newton steps with finite-difference derivatives
// on the tangent plane, backtracking when a step does not lower the cost.
sh::Vec3 FitDirection(const DirectionalProblem& problem, const sh::Vec3& init,
                      std::span<const sh::Vec3> grid, const double* grid_basis, int iterations,
                      double* power, double* ambient = nullptr) {
  sh::Vec3 d = init;
  double best = problem.CostAt(d);
  for (size_t k = 0; k < grid.size(); ++k) {
    const double cost = problem.Cost(grid_basis + k * problem.n);
    if (cost < best) best = cost, d = grid[k];
  }
  constexpr double h = 1e-3;
  for (int it = 0; it < iterations; ++it) {
    sh::Vec3 t1, t2;
    Tangents(d, t1, t2);
    const double f0 = best;
    const double fpu = problem.CostAt(Moved(d, t1, t2, h, 0));
    const double fmu = problem.CostAt(Moved(d, t1, t2, -h, 0));
    const double fpv = problem.CostAt(Moved(d, t1, t2, 0, h));
    const double fmv = problem.CostAt(Moved(d, t1, t2, 0, -h));
    const double fuv = problem.CostAt(Moved(d, t1, t2, h, h));
    const double gu = (fpu - fmu) / (2 * h), gv = (fpv - fmv) / (2 * h);
    const double huu = (fpu - 2 * f0 + fmu) / (h * h), hvv = (fpv - 2 * f0 + fmv) / (h * h);
    const double huv = (fuv - fpu - fpv + f0) / (h * h);
    double su, sv;
    const double det = huu * hvv - huv * huv;
    if (huu > 0 && det > 0) {
      su = -(hvv * gu - huv * gv) / det;
      sv = -(huu * gv - huv * gu) / det;
    } else {  // not convex here: a gradient step of 0.05 rad
      const double g = std::sqrt(gu * gu + gv * gv);
      if (!(g > 0)) break;
      su = -0.05 * gu / g, sv = -0.05 * gv / g;
    }
    const double length = std::sqrt(su * su + sv * sv);
    if (length > 0.3) su *= 0.3 / length, sv *= 0.3 / length;
    bool improved = false;
    for (int back = 0; back < 6; ++back) {
      const sh::Vec3 candidate = Moved(d, t1, t2, su, sv);
      const double cost = problem.CostAt(candidate);
      if (cost < f0) {
        d = candidate, best = cost, improved = true;
        break;
      }
      su *= 0.5, sv *= 0.5;
    }
    if (!improved || std::sqrt(su * su + sv * sv) < 1e-4) break;
  }
  if (power) problem.CostAt(d, power, ambient);
  return d;
}

}  // namespace

FaceLightEstimator::FaceLightEstimator(const FaceLightModel& model, EstimatorOptions options)
    : options_(options) {
  model.Validate();
  if (!(options.ridge >= 0) || !(options.back_prior >= 0) || !(options.weight_floor >= 0) ||
      options.robust_iterations < 1 || options.robust_iterations > 20 ||
      !(options.robust_threshold > 0) || options.nn_directions < 9 ||
      options.nn_directions > kMaxNnDirections || options.nn_iterations < 1 ||
      options.nn_iterations > 10000 || options.directional_grid < 0 ||
      options.directional_grid > 1024 || options.directional_iterations < 0 ||
      options.directional_iterations > 100 || !(options.direction_ridge >= 0) ||
      !(options.directional_robust >= 0)) {
    throw FaceLightError(
        "FaceLightEstimator: options out of range (ridge, back_prior, weight_floor, "
        "direction_ridge, directional_robust >= 0; robust_iterations 1..20; robust_threshold > 0; nn_directions "
        "9..1024; nn_iterations 1..10000; directional_grid 0..1024; directional_iterations "
        "0..100)");
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
  if (options.directional_fit) {
    if (options.use_direction_rtfs && model.direction_bands > 0) {
      dir_bands_ = model.direction_bands;
      dir_n_ = dir_bands_ * dir_bands_;
      dir_rtf_.assign(model.direction_rtf.begin(), model.direction_rtf.end());
      dir_normal_.assign(static_cast<size_t>(dir_n_) * dir_n_, 0.0);
      for (int i = 0; i < n_samples; ++i) {
        const float* t = &dir_rtf_[static_cast<size_t>(i) * dir_n_];
        for (int a = 0; a < dir_n_; ++a) {
          for (int b = 0; b < dir_n_; ++b) dir_normal_[a * dir_n_ + b] += weights_[i] * double(t[a]) * t[b];
        }
      }
      double dir_trace = 0;
      for (int a = 0; a < dir_n_; ++a) dir_trace += dir_normal_[a * dir_n_ + a];
      for (int a = 0; a < dir_n_; ++a) {
        dir_normal_[a * dir_n_ + a] += options.direction_ridge * dir_trace / dir_n_;
      }
    }
    if (options.directional_grid > 0) dir_grid_ = sh::FibonacciSphere(options.directional_grid);
    dir_grid_basis_.resize(dir_grid_.size() * dir_n_);
    for (size_t k = 0; k < dir_grid_.size(); ++k) {
      sh::EvaluateBasis<double>(dir_bands_, dir_grid_[k][0], dir_grid_[k][1], dir_grid_[k][2],
                                &dir_grid_basis_[k * dir_n_]);
    }
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
  sh::Vec3 direction = sh::OptimalLinearDirection(mean_light);
  if (options_.directional_fit) {
    // Cost matrix and vector of the directional fit (channel mean): E^T M E - 2 b^T E.
    const int dn = dir_n_;
    double m[kMaxDirN * kMaxDirN];
    double b[kMaxDirN] = {};
    if (dir_rtf_.empty()) {
      if (fast) {
        std::copy(normal_.begin(), normal_.end(), m);
        for (int a = 0; a < kN; ++a) {
          double sum = 0;
          for (int k = 0; k < kN; ++k) {
            double mean_e = 0;
            for (int c = 0; c < channels; ++c) mean_e += e[c][k];
            sum += normal_[a * kN + k] * mean_e / channels;
          }
          b[a] = sum;
        }
      } else {
        for (int a = 0; a < kN; ++a) {
          for (int k = 0; k <= a; ++k) {
            double sum = 0;
            for (int j = 0; j <= k; ++j) sum += factor[a * kN + j] * factor[k * kN + j];
            m[a * kN + k] = m[k * kN + a] = sum;
          }
          for (int c = 0; c < channels; ++c) b[a] += rhs[c][a] / channels;
        }
      }
    } else {
      std::copy(dir_normal_.begin(), dir_normal_.end(), m);
      for (int i = 0; i < n_samples; ++i) {
        const float* t = &dir_rtf_[static_cast<size_t>(i) * dn];
        const double w = weights[i];
        if (!active[i]) {
          for (int a = 0; a < dn; ++a) {
            for (int k = 0; k < dn; ++k) m[a * dn + k] -= w * double(t[a]) * t[k];
          }
          continue;
        }
        const double wv = w * double(mean_value[i]);
        for (int a = 0; a < dn; ++a) b[a] += wv * t[a];
      }
    }
    const DirectionalProblem problem{m, b, dir_bands_, dn, options_.directional_ambient};
    const sh::Vec3 init =
        direction == sh::Vec3{0, 0, 0} ? sh::Vec3{0, 0, -1} : direction;
    double power = 0, ambient = 0;
    sh::Vec3 fitted = FitDirection(problem, init, dir_grid_, dir_grid_basis_.data(),
                                   options_.directional_iterations, &power, &ambient);
    if (options_.directional_robust > 0 && power > 0) {
      // One round of trimming under the directional model: drop samples whose residual exceeds
      // directional_robust * 1.4826 * MAD (cast shadows the RTFs blur, highlights), re-fit.
      const float* t_all = dir_rtf_.empty() ? rtf_.data() : dir_rtf_.data();
      double y[kMaxDirN];
      sh::EvaluateBasis<double>(dir_bands_, fitted[0], fitted[1], fitted[2], y);
      double light[kMaxDirN];
      for (int a = 0; a < dn; ++a) light[a] = power * y[a];
      light[0] += ambient;
      float magnitude[kMaxSamples];
      float dres[kMaxSamples];
      int count = 0;
      for (int i = 0; i < n_samples; ++i) {
        if (!active[i]) continue;
        const float* t = t_all + static_cast<size_t>(i) * dn;
        double predicted = 0;
        for (int a = 0; a < dn; ++a) predicted += t[a] * light[a];
        dres[i] = static_cast<float>(mean_value[i] - predicted);
        magnitude[count++] = std::abs(dres[i]);
      }
      std::nth_element(magnitude, magnitude + count / 2, magnitude + count);
      const double limit = options_.directional_robust * 1.4826 * magnitude[count / 2];
      int dropped = 0;
      for (int i = 0; i < n_samples; ++i) {
        if (!active[i] || !(std::abs(dres[i]) > limit)) continue;
        const float* t = t_all + static_cast<size_t>(i) * dn;
        const double w = weights[i];
        for (int a = 0; a < dn; ++a) {
          b[a] -= w * double(mean_value[i]) * t[a];
          for (int k = 0; k < dn; ++k) m[a * dn + k] -= w * double(t[a]) * t[k];
        }
        ++dropped;
      }
      if (dropped > 0 && count - dropped >= 2 * kN) {
        double power2 = 0;
        const sh::Vec3 refit = FitDirection(problem, fitted, {}, nullptr,
                                            options_.directional_iterations, &power2);
        if (power2 > 0) fitted = refit, power = power2;
      }
    }
    if (power > 0) direction = fitted;
  }
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
