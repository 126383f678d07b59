// Light estimation (Knorr & Kurz 2014, sec. 3.5, eq. 19) with optional prior, robust rejection and
// non-negativity (see probeless/face_light/estimator.h).
#include "probeless/face_light/estimator.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "linalg.h"
#include "probeless/msgs/sh_light.h"
#include "probeless/sh/sh.h"

namespace probeless::face_light {
namespace {

constexpr int kN = kRtfCoefficients;
constexpr int kMaxNnDirections = 1024;
constexpr int kMaxPassive = 32;

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

constexpr int kMaxDirN = 25;       // 5 bands
constexpr size_t kMaxGrid = 1024;  // EstimatorOptions::directional_grid

// Normalisation constants of sh::EvaluateBasis for bands <= 5, index l(l+1)+m for m >= 0:
// sqrt((2l+1)/(4 pi) (l-m)!/(l+m)!), times sqrt(2) for m > 0.
struct BasisConstants {
  double k[kMaxDirN] = {};
  BasisConstants() {
    for (int l = 0; l < 5; ++l) {
      for (int m = 0; m <= l; ++m) {
        double ratio = 1;
        for (int f = l - m + 1; f <= l + m; ++f) ratio /= f;
        const double k_lm = std::sqrt((2 * l + 1) / (4 * std::numbers::pi) * ratio);
        k[l * (l + 1) + m] = m == 0 ? k_lm : std::numbers::sqrt2 * k_lm;
      }
    }
  }
};

const BasisConstants& Constants() {
  static const BasisConstants constants;
  return constants;
}

// sh::EvaluateBasis<double> (same recurrence, same convention) with the normalisation constants
// precomputed: the directional fit evaluates it ~50 times per estimate.
void FastBasis(const BasisConstants& constants, int bands, double x, double y, double z,
               double* out) {
  double c = 1, s = 0;  // Re and Im of (x + i y)^m
  double q_mm = 1;      // (-1)^m (2m-1)!!
  for (int m = 0; m < bands; ++m) {
    if (m > 0) {
      const double c_next = c * x - s * y;
      s = c * y + s * x;
      c = c_next;
      q_mm *= -static_cast<double>(2 * m - 1);
    }
    double q_prev2 = 0, q_prev = 0;
    for (int l = m; l < bands; ++l) {
      double q;
      if (l == m) {
        q = q_mm;
      } else if (l == m + 1) {
        q = z * (2 * m + 1) * q_prev;
      } else {
        q = ((2 * l - 1) * z * q_prev - (l + m - 1) * q_prev2) / (l - m);
      }
      const double scaled = constants.k[l * (l + 1) + m] * q;
      if (m == 0) {
        out[l * (l + 1)] = scaled;
      } else {
        out[l * (l + 1) + m] = scaled * c;
        out[l * (l + 1) - m] = scaled * s;
      }
      q_prev2 = q_prev;
      q_prev = q;
    }
  }
}

// Closed-form a (>= 0) and c of E = a Y + c e_0 for one direction from syy = Y^T M Y,
// s0y = (M Y)_0, ry = b^T Y, s00 = M_00, r0 = b_0; returns the cost -(a ry + c r0).
double ClosedFormCost(double syy, double s0y, double ry, double s00, double r0, bool ambient,
                      double* a_out, double* c_out) {
  double a = 0, c = 0, cost = 0;
  if (ambient) {
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

// Start directions of the directional fit with their basis values ([k * n + a]) and, for the
// full-set cost matrix M, Y_k^T M Y_k and (M Y_k)_0.
struct DirectionGrid {
  std::span<const sh::Vec3> directions;
  const double* basis = nullptr;
  const double* basis_t = nullptr;  // transposed: [a * directions.size() + k]
  const double* syy = nullptr;
  const double* s0y = nullptr;
};

// Directional fit in coefficient space: minimise cost(E) = E^T M E - 2 b^T E (the least-squares
// cost up to a constant) over E = a Y(d) + c e_0, a >= 0 (c = 0 without ambient). For a fixed d,
// a and c are closed form and cost(d) = -(a b.Y(d) + c b_0).
struct DirectionalProblem {
  const double* m;  // n x n
  const double* b;  // n
  int bands;
  int n;
  bool ambient;

  const BasisConstants* constants;
  // True if M is the full-set matrix, so the grids' precomputed Y^T M Y and (M Y)_0 hold.
  bool tables = false;

  double Cost(const double* y, double* a_out = nullptr, double* c_out = nullptr) const {
    // y^T M y from the lower triangle (M symmetric), (M y)_0 and b^T y.
    double syy = 0, ry = 0;
    for (int i = 0; i < n; ++i) {
      const double* row = m + i * n;
      double off = 0;
      for (int j = 0; j < i; ++j) off += row[j] * y[j];
      syy += y[i] * (row[i] * y[i] + 2 * off);
      ry += b[i] * y[i];
    }
    double s0y = 0;
    for (int j = 0; j < n; ++j) s0y += m[j] * y[j];
    return ClosedFormCost(syy, s0y, ry, m[0], b[0], ambient, a_out, c_out);
  }
  // Cost of direction k of a grid: from its tables (b^T Y only) when they hold for M.
  double GridCost(const DirectionGrid& grid, size_t k) const {
    const double* y = grid.basis + k * n;
    if (!tables) return Cost(y);
    double ry = 0;
    for (int i = 0; i < n; ++i) ry += b[i] * y[i];
    return ClosedFormCost(grid.syy[k], grid.s0y[k], ry, m[0], b[0], ambient, nullptr, nullptr);
  }
  double CostAt(const sh::Vec3& d, double* a = nullptr, double* c = nullptr) const {
    double y[kMaxDirN];
    FastBasis(*constants, bands, d[0], d[1], d[2], y);
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
  return Normalised(
      {d[0] + u * t1[0] + v * t2[0], d[1] + u * t1[1] + v * t2[1], d[2] + u * t1[2] + v * t2[2]});
}

// Best start direction (init and the grid), then Newton steps with finite-difference derivatives
// on the tangent plane, backtracking when a step does not lower the cost.
sh::Vec3 FitDirection(const DirectionalProblem& problem, const sh::Vec3& init,
                      const DirectionGrid& grid, int iterations, double* power,
                      double* ambient = nullptr) {
  sh::Vec3 d = init;
  double best = problem.CostAt(d);
  const size_t count = grid.directions.size();
  if (problem.tables && count <= kMaxGrid) {
    // M is the full-set matrix: b^T Y_k of every grid direction as one matrix-vector product,
    // then the closed form with the precomputed Y_k^T M Y_k and (M Y_k)_0.
    double ry[kMaxGrid];
    std::fill(ry, ry + count, 0.0);
    for (int a = 0; a < problem.n; ++a) {
      const double* row = grid.basis_t + a * count;
      const double ba = problem.b[a];
      for (size_t k = 0; k < count; ++k) ry[k] += ba * row[k];
    }
    const double s00 = problem.m[0], r0 = problem.b[0];
    for (size_t k = 0; k < count; ++k) {
      const double cost = ClosedFormCost(grid.syy[k], grid.s0y[k], ry[k], s00, r0, problem.ambient,
                                         nullptr, nullptr);
      if (cost < best) best = cost, d = grid.directions[k];
    }
  } else {
    for (size_t k = 0; k < count; ++k) {
      const double cost = problem.GridCost(grid, k);
      if (cost < best) best = cost, d = grid.directions[k];
    }
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
        "direction_ridge, directional_robust >= 0; robust_iterations 1..20; robust_threshold > 0; "
        "nn_directions "
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
  wrtf_t_.assign(static_cast<size_t>(kN) * stride_, 0.0f);
  for (int i = 0; i < n_samples; ++i) {
    for (int n = 0; n < kN; ++n) {
      rtf_t_[static_cast<size_t>(n) * stride_ + i] = rtf_[i * kN + n];
      wrtf_t_[static_cast<size_t>(n) * stride_ + i] = weights_[i] * rtf_[i * kN + n];
    }
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
          for (int b = 0; b < dir_n_; ++b)
            dir_normal_[a * dir_n_ + b] += weights_[i] * double(t[a]) * t[b];
        }
      }
      double dir_trace = 0;
      for (int a = 0; a < dir_n_; ++a) dir_trace += dir_normal_[a * dir_n_ + a];
      for (int a = 0; a < dir_n_; ++a) {
        dir_normal_[a * dir_n_ + a] += options.direction_ridge * dir_trace / dir_n_;
      }
    }
    const std::vector<double> full_m =
        dir_rtf_.empty() ? std::vector<double>(normal_.begin(), normal_.end()) : dir_normal_;
    // Start directions with their basis values, Y^T M Y and (M Y)_0 for the full-set M.
    const auto tabulate = [&](int count, std::vector<sh::Vec3>& directions,
                              std::vector<double>& basis, std::vector<double>& syy,
                              std::vector<double>& s0y) {
      directions = count > 0 ? sh::FibonacciSphere(count) : std::vector<sh::Vec3>{};
      basis.resize(directions.size() * dir_n_);
      syy.resize(directions.size());
      s0y.resize(directions.size());
      for (size_t k = 0; k < directions.size(); ++k) {
        double* y = &basis[k * dir_n_];
        sh::EvaluateBasis<double>(dir_bands_, directions[k][0], directions[k][1], directions[k][2],
                                  y);
        double quadratic = 0;
        for (int a = 0; a < dir_n_; ++a) {
          double my = 0;
          for (int b = 0; b < dir_n_; ++b) my += full_m[a * dir_n_ + b] * y[b];
          quadratic += y[a] * my;
          if (a == 0) s0y[k] = my;
        }
        syy[k] = quadratic;
      }
    };
    tabulate(options.directional_grid, dir_grid_, dir_grid_basis_, dir_grid_syy_, dir_grid_s0y_);
    dir_grid_basis_t_.resize(dir_grid_basis_.size());
    for (size_t k = 0; k < dir_grid_.size(); ++k) {
      for (int a = 0; a < dir_n_; ++a) {
        dir_grid_basis_t_[a * dir_grid_.size() + k] = dir_grid_basis_[k * dir_n_ + a];
      }
    }
    const float* t_all = dir_rtf_.empty() ? rtf_.data() : dir_rtf_.data();
    dir_wrtf_t_.assign(static_cast<size_t>(dir_n_) * stride_, 0.0f);
    for (int i = 0; i < n_samples; ++i) {
      for (int a = 0; a < dir_n_; ++a) {
        dir_wrtf_t_[static_cast<size_t>(a) * stride_ + i] =
            weights_[i] * t_all[static_cast<size_t>(i) * dir_n_ + a];
      }
    }
  }
  uniform_weights_ = options.weight_floor == 0;
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
  // Valid = the caller's bit and finite values (x - x is 0 for finite x, NaN otherwise); written
  // branch-free so the loops vectorise.
  for (int i = 0; i < n_samples; ++i) {
    float check = 0;
    for (int c = 0; c < channels; ++c) {
      const float x = values[i * channels + c];
      check += x - x;
    }
    valid[i] = check == 0.0f;
  }
  if (!valid_bits.empty()) {
    for (int i = 0; i < n_samples; ++i) {
      valid[i] &= static_cast<uint8_t>((valid_bits[i >> 6] >> (i & 63)) & 1u);
    }
  }
  for (int i = 0; i < n_samples; ++i) {
    active[i] = valid[i];
    valid_count += valid[i];
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
    // rhs = T^T W v over the active samples: 8-lane dot products of the transposed weighted
    // RTFs with the intensities, inactive ones zeroed.
    alignas(32) float masked[kMaxSamples + 8];
    for (int c = 0; c < channels; ++c) {
      for (int i = 0; i < stride; ++i) masked[i] = i < n_samples && active[i] ? v[c][i] : 0.0f;
      for (int n = 0; n < kN; ++n) {
        rhs[c][n] = Dot8(&wrtf_t_[static_cast<size_t>(n) * stride], masked, stride);
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

  // Outputs. With the precomputed pseudo-inverse and unit weights the residual sum of squares
  // has a closed form in coefficient space (below); otherwise the per-sample residuals.
  const bool closed_form = !options_.robust && !options_.non_negative && uniform_weights_ &&
                           !(options_.directional_robust > 0);
  if (!closed_form) compute_residuals();
  double mean_light[kN] = {};
  for (int n = 0; n < kN; ++n) {
    for (int c = 0; c < 3; ++c) {
      const double value = e[channels == 1 ? 0 : c][n];
      out.coefficients[n][c] = static_cast<float>(value);
      mean_light[n] += value / 3;
    }
  }
  sh::Vec3 direction = sh::OptimalLinearDirection(mean_light);
  int active_count = 0;
  for (int i = 0; i < n_samples; ++i) active_count += active[i];
  const bool all_active = active_count == n_samples;
  if (options_.directional_fit) {
    // Cost matrix and vector of the directional fit (channel mean): E^T M E - 2 b^T E.
    const int dn = dir_n_;
    double m[kMaxDirN * kMaxDirN];
    const double* cost_matrix = m;
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
      // b = T^T W v over the active samples (8-lane dot products of the transposed weighted
      // RTFs); M = the full-set matrix downdated by the inactive samples.
      if (all_active && !(options_.directional_robust > 0)) {
        cost_matrix = dir_normal_.data();  // used as it is
      } else {
        std::copy(dir_normal_.begin(), dir_normal_.end(), m);
      }
      const float* source = mean_value;
      alignas(32) float masked[kMaxSamples + 8];
      if (!all_active) {
        for (int i = 0; i < stride; ++i) masked[i] = i < n_samples && active[i] ? mean_value[i] : 0;
        source = masked;
        for (int i = 0; i < n_samples; ++i) {
          if (active[i]) continue;
          const float* t = &dir_rtf_[static_cast<size_t>(i) * dn];
          const double w = weights[i];
          for (int a = 0; a < dn; ++a) {
            const double wt = w * double(t[a]);
            for (int k = 0; k <= a; ++k) m[a * dn + k] -= wt * t[k];
          }
        }
        for (int a = 0; a < dn; ++a) {
          for (int k = 0; k < a; ++k) m[k * dn + a] = m[a * dn + k];
        }
      }
      for (int a = 0; a < dn; ++a) {
        b[a] = Dot8(&dir_wrtf_t_[static_cast<size_t>(a) * stride], source, stride);
      }
    }
    // With every sample active M is the full-set matrix: the grids' quadratic terms are
    // precomputed.
    const DirectionalProblem problem{
        cost_matrix, b, dir_bands_, dn, options_.directional_ambient, &Constants(), all_active};
    const DirectionGrid grid{dir_grid_, dir_grid_basis_.data(), dir_grid_basis_t_.data(),
                             dir_grid_syy_.data(), dir_grid_s0y_.data()};
    const sh::Vec3 init = direction == sh::Vec3{0, 0, 0} ? sh::Vec3{0, 0, -1} : direction;
    double power = 0, ambient = 0;
    sh::Vec3 fitted =
        FitDirection(problem, init, grid, options_.directional_iterations, &power, &ambient);
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
        const DirectionalProblem trimmed{
            m, b, dir_bands_, dn, options_.directional_ambient, &Constants(), false};
        const sh::Vec3 refit =
            FitDirection(trimmed, fitted, {}, options_.directional_iterations, &power2);
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
  const int used = active_count;
  double ss_res = 0, ss_tot = 0;
  if (closed_form) {
    // Unit weights, e = N^-1 r with N = T^T T + R and r = T^T v over the active samples (the
    // full set: r = N e), so |v - T e|^2 = v^T v - 2 e^T r + e^T (N - R) e
    // = v^T v - e^T r - e^T R e (channel mean: the same with the mean intensities, light and r).
    double lane_sum[4] = {}, lane_sq[4] = {};  // independent lanes: the loop vectorises
    const int whole = n_samples / 4 * 4;
    for (int i = 0; i < whole; i += 4) {
      for (int l = 0; l < 4; ++l) {
        const double x = active[i + l] ? double(mean_value[i + l]) : 0.0;
        lane_sum[l] += x;
        lane_sq[l] += x * x;
      }
    }
    for (int i = whole; i < n_samples; ++i) {
      const double x = active[i] ? double(mean_value[i]) : 0.0;
      lane_sum[0] += x;
      lane_sq[0] += x * x;
    }
    const double sum = (lane_sum[0] + lane_sum[1]) + (lane_sum[2] + lane_sum[3]);
    const double sum_sq = (lane_sq[0] + lane_sq[1]) + (lane_sq[2] + lane_sq[3]);
    double quadratic = 0;
    for (int a = 0; a < kN; ++a) {
      double r = 0, re = 0;
      if (fast) {
        for (int k = 0; k < kN; ++k) r += normal_[a * kN + k] * mean_light[k];
      } else {
        for (int c = 0; c < channels; ++c) r += rhs[c][a] / channels;
      }
      for (int k = 0; k < kN; ++k) re += prior_[a * kN + k] * mean_light[k];
      quadratic += mean_light[a] * (r + re);
    }
    ss_res = std::max(0.0, sum_sq - quadratic);
    ss_tot = std::max(0.0, sum_sq - sum * sum / std::max(used, 1));
  } else {
    double mean = 0;
    for (int i = 0; i < n_samples; ++i) {
      if (active[i]) mean += mean_value[i];
    }
    mean /= std::max(used, 1);
    for (int i = 0; i < n_samples; ++i) {
      if (!active[i]) continue;
      ss_res += double(residual[i]) * residual[i];
      ss_tot += (mean_value[i] - mean) * (mean_value[i] - mean);
    }
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
