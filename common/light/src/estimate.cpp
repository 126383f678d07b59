#include "probeless/light/estimate.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>

#include "probeless/linalg/cholesky.h"
#include "probeless/sh/sh.h"

namespace probeless::light {
namespace {

// Solves the symmetric positive definite system A x = b (n x n, row-major) by Cholesky; returns
// false if A is not positive definite.
bool CholeskySolve(std::vector<double> a, std::vector<double> b, int n, std::vector<double>* x) {
  if (!linalg::CholeskyFactor(a.data(), n)) return false;
  linalg::CholeskySolveFactored(a.data(), n, b.data());
  *x = std::move(b);
  return true;
}

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  const size_t m = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + m, v.end());
  return v[m];
}

}  // namespace

LightEstimate SolveLight(std::span<const float> rows, std::span<const float> targets,
                         int coefficient_count, const EstimateOptions& options) {
  const int cc = coefficient_count;
  if (cc != 4 && cc != 9 && cc != 16 && cc != 25) {
    throw LightError("light::SolveLight: coefficient_count must be 4, 9, 16 or 25, got " +
                     std::to_string(cc));
  }
  const size_t m = targets.size();
  if (rows.size() != m * cc) {
    throw LightError("light::SolveLight: " + std::to_string(rows.size()) + " row values for " +
                     std::to_string(m) + " targets x " + std::to_string(cc) + " coefficients");
  }
  if (!(options.ridge >= 0) || !(options.smoothness >= 0)) {
    throw LightError("light::SolveLight: ridge and smoothness must be >= 0");
  }
  LightEstimate e;
  e.bands = static_cast<int>(std::lround(std::sqrt(cc)));
  e.pixels = static_cast<int>(m);
  if (static_cast<int>(m) < std::max(options.min_pixels, cc)) return e;

  // Prior weights: normal-orientation balancing (see EstimateOptions::balance_normals).
  std::vector<double> prior(m, 1.0);
  if (options.balance_normals) {
    // Cube-map bins of the orientation: 6 faces x 4 x 4 cells (no trigonometry per row).
    constexpr int kCells = 4, kBins = 6 * kCells * kCells;
    std::vector<int> bin(m), count(kBins, 0);
    for (size_t i = 0; i < m; ++i) {
      const float* t = rows.data() + i * cc;
      const float d[3] = {-t[3], -t[1], t[2]};  // band-1 direction (OptimalLinearDirection)
      const float ax = std::abs(d[0]), ay = std::abs(d[1]), az = std::abs(d[2]);
      int face, a, b;
      float u, v, major;
      if (ax >= ay && ax >= az) {
        face = d[0] > 0 ? 0 : 1, u = d[1], v = d[2], major = ax;
      } else if (ay >= az) {
        face = d[1] > 0 ? 2 : 3, u = d[0], v = d[2], major = ay;
      } else {
        face = d[2] > 0 ? 4 : 5, u = d[0], v = d[1], major = az;
      }
      if (!(major > 0)) major = 1, u = v = 0;
      a = std::clamp(static_cast<int>((u / major + 1) * 0.5f * kCells), 0, kCells - 1);
      b = std::clamp(static_cast<int>((v / major + 1) * 0.5f * kCells), 0, kCells - 1);
      bin[i] = (face * kCells + a) * kCells + b;
      ++count[bin[i]];
    }
    int used = 0;
    for (int c : count) used += c > 0;
    for (size_t i = 0; i < m; ++i) prior[i] = static_cast<double>(m) / (used * count[bin[i]]);
  }
  std::vector<double> weight = prior, residual(m, 0.0), l(cc, 0.0);
  std::vector<double> ata(static_cast<size_t>(cc) * cc), atb(cc);
  std::vector<std::array<double, sh::kMaxCoefficients>> penalty;  // non-negativity rows
  const auto constraint_dirs = sh::FibonacciSphere(64);
  double base_trace = 0;

  auto solve = [&]() -> bool {
    std::fill(ata.begin(), ata.end(), 0.0);
    std::fill(atb.begin(), atb.end(), 0.0);
    // Rank-1 updates into a float block (contiguous, vectorised), flushed into double every 256
    // rows so that long sums keep double precision.
    float block[sh::kMaxCoefficients * sh::kMaxCoefficients];
    float block_b[sh::kMaxCoefficients];
    std::fill(block, block + cc * cc, 0.0f);
    std::fill(block_b, block_b + cc, 0.0f);
    int in_block = 0;
    auto flush = [&] {
      for (int k = 0; k < cc * cc; ++k) ata[k] += block[k];
      for (int k = 0; k < cc; ++k) atb[k] += block_b[k];
      std::fill(block, block + cc * cc, 0.0f);
      std::fill(block_b, block_b + cc, 0.0f);
      in_block = 0;
    };
    for (size_t i = 0; i < m; ++i) {
      const float wi = static_cast<float>(weight[i]);
      if (wi <= 0) continue;
      const float* a = rows.data() + i * cc;
      for (int r = 0; r < cc; ++r) {
        const float war = wi * a[r];
        block_b[r] += war * targets[i];
        float* row = &block[r * cc];
        for (int c = 0; c < cc; ++c) row[c] += war * a[c];
      }
      if (++in_block == 256) flush();
    }
    flush();
    double trace = 0;
    for (int r = 0; r < cc; ++r) trace += ata[r * cc + r];
    if (base_trace == 0) base_trace = trace;
    // Non-negativity penalties: rows mu * Y(w_k) with target 0 where the light was negative.
    const double mu2 = 10.0 * base_trace / cc;
    for (const auto& y : penalty) {
      for (int r = 0; r < cc; ++r) {
        for (int c = 0; c <= r; ++c) ata[r * cc + c] += mu2 * y[r] * y[c];
      }
    }
    const double ridge = options.ridge * (trace > 0 ? trace / cc : 1.0);
    const double smooth = options.smoothness * (trace > 0 ? trace / cc : 1.0);
    for (int r = 0; r < cc; ++r) {
      const int l = sh::DegreeOf(r);
      ata[r * cc + r] += ridge + smooth * double(l * (l + 1)) * double(l * (l + 1));
      for (int c = r + 1; c < cc; ++c) ata[r * cc + c] = ata[c * cc + r];
    }
    return CholeskySolve(ata, atb, cc, &l);
  };
  auto residuals = [&] {
    for (size_t i = 0; i < m; ++i) {
      const float* a = rows.data() + i * cc;
      double p = 0;
      for (int k = 0; k < cc; ++k) p += a[k] * l[k];
      residual[i] = targets[i] - p;
    }
  };
  if (!solve()) return e;
  if (options.robust) {
    double rms_t = 0;
    for (float t : targets) rms_t += double(t) * t;
    rms_t = std::sqrt(rms_t / m);
    for (int it = 0; it < 5; ++it) {
      residuals();
      std::vector<double> abs_r(m);
      for (size_t i = 0; i < m; ++i) abs_r[i] = std::abs(residual[i]);
      const double sigma = std::max(1.4826 * Median(abs_r), 1e-7 * rms_t + 1e-12);
      const bool tukey = it >= 2;  // Huber first (convex, reliable start), then redescending
      for (size_t i = 0; i < m; ++i) {
        const double u = abs_r[i] / sigma;
        if (tukey) {
          const double c = 4.685;
          weight[i] = prior[i] * (u < c ? (1 - (u / c) * (u / c)) * (1 - (u / c) * (u / c)) : 0.0);
        } else {
          const double k = 1.345;
          weight[i] = prior[i] * (u <= k ? 1.0 : k / u);
        }
      }
      if (!solve()) return e;
    }
  }
  if (options.non_negative && cc >= 4) {
    for (int it = 0; it < 4; ++it) {
      bool added = false;
      for (const auto& d : constraint_dirs) {
        std::array<double, sh::kMaxCoefficients> y{};
        sh::EvaluateBasis<double>(e.bands, d[0], d[1], d[2], y.data());
        double value = 0;
        for (int k = 0; k < cc; ++k) value += y[k] * l[k];
        if (value < 0) {
          penalty.push_back(y);
          added = true;
        }
      }
      if (!added || !solve()) break;
    }
  }
  residuals();
  double sw = 0, swr2 = 0, swt = 0, swt2 = 0;
  for (size_t i = 0; i < m; ++i) {
    sw += weight[i];
    swr2 += weight[i] * residual[i] * residual[i];
    swt += weight[i] * targets[i];
  }
  const double mean_t = sw > 0 ? swt / sw : 0;
  for (size_t i = 0; i < m; ++i) swt2 += weight[i] * (targets[i] - mean_t) * (targets[i] - mean_t);
  e.rms_residual = sw > 0 ? std::sqrt(swr2 / sw) : 0;
  const double r2 = swt2 > 0 ? std::clamp(1.0 - swr2 / swt2, 0.0, 1.0) : 0.0;
  e.confidence = static_cast<float>(r2 * std::min(1.0, sw / (20.0 * cc)));
  e.coefficients = l;
  e.valid = true;
  const int dc = options.direction_bands * options.direction_bands;
  if (options.direction_bands >= 2 && dc < cc) {
    std::vector<float> linear_rows(m * dc);
    for (size_t i = 0; i < m; ++i) std::copy_n(rows.data() + i * cc, dc, &linear_rows[i * dc]);
    LightEstimate linear = SolveLight(linear_rows, targets, dc, options);
    // A low-band model of max(0, n.d) is biased by the pixels facing away from the light (only
    // ambient reaches them): refit on the pixels facing the current estimate (n.d > 0.05, n from
    // T's band 1), where the shading is exactly linear in n.
    for (int it = 0; it < 2 && linear.valid && options.lit_refits; ++it) {
      std::vector<float> lit_rows, lit_targets;
      const auto& d = linear.dominant_direction;
      for (size_t i = 0; i < m; ++i) {
        const sh::Vec3 n = sh::OptimalLinearDirection(rows.data() + i * cc);
        if (n[0] * d[0] + n[1] * d[1] + n[2] * d[2] <= 0.05) continue;
        lit_rows.insert(lit_rows.end(), &linear_rows[i * dc], &linear_rows[i * dc] + dc);
        lit_targets.push_back(targets[i]);
      }
      const LightEstimate refit = SolveLight(lit_rows, lit_targets, dc, options);
      if (!refit.valid) break;
      linear = refit;
    }
    if (linear.valid) {
      e.dominant_direction = linear.dominant_direction;
      e.intensity = linear.intensity;
      return e;
    }
  }
  if (cc >= 4) {
    const sh::Vec3 d = sh::OptimalLinearDirection(l.data());
    e.dominant_direction = {static_cast<float>(d[0]), static_cast<float>(d[1]),
                            static_cast<float>(d[2])};
    if (d[0] != 0 || d[1] != 0 || d[2] != 0) {
      e.intensity = static_cast<float>(std::max(0.0, sh::DirectionalPower(l, d)));
    }
  }
  return e;
}

LightEstimate EstimateLight(const TransferResult& transfer, std::span<const float> intensity,
                            const EstimateOptions& options) {
  const size_t pixels = static_cast<size_t>(transfer.width) * transfer.height;
  if (intensity.size() != pixels) {
    throw LightError("light::EstimateLight: intensity has " + std::to_string(intensity.size()) +
                     " values, transfer is " + std::to_string(transfer.width) + "x" +
                     std::to_string(transfer.height));
  }
  const int cc = transfer.coefficient_count;
  if (transfer.transfer.size() != pixels * cc || transfer.valid.size() != pixels) {
    throw LightError("light::EstimateLight: transfer buffer sizes do not match " +
                     std::to_string(transfer.width) + "x" + std::to_string(transfer.height));
  }
  if (options.stride < 1) throw LightError("light::EstimateLight: stride must be >= 1");
  const int cc_out = options.bands == 0 ? cc : options.bands * options.bands;
  if (options.bands != 0 && (options.bands < 2 || cc_out > cc)) {
    throw LightError("light::EstimateLight: bands must be 0 or 2.." +
                     std::to_string(static_cast<int>(std::lround(std::sqrt(cc)))) + ", got " +
                     std::to_string(options.bands));
  }
  if (!(options.albedo > 0)) throw LightError("light::EstimateLight: albedo must be > 0");
  std::vector<float> rows, targets;
  const int s = options.stride;
  rows.reserve(pixels / (s * s) * cc_out + cc_out);
  targets.reserve(pixels / (s * s) + 1);
  const float inv_albedo = 1.0f / options.albedo;
  for (int y = s / 2; y < transfer.height; y += s) {
    for (int x = s / 2; x < transfer.width; x += s) {
      const size_t p = static_cast<size_t>(y) * transfer.width + x;
      const float i = intensity[p];
      if (!transfer.valid[p] || !(i >= options.min_intensity) || !(i <= options.max_intensity)) {
        continue;
      }
      const float* t = &transfer.transfer[p * cc];
      rows.insert(rows.end(), t, t + cc_out);
      targets.push_back(i * inv_albedo);
    }
  }
  return SolveLight(rows, targets, cc_out, options);
}

}  // namespace probeless::light
