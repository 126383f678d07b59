#include "probeless/light/estimate.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numbers>
#include <string>

#include "albedo_groups.h"
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

float Median(std::vector<float> v) {
  if (v.empty()) return 0;
  const size_t m = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + m, v.end());
  return v[m];
}

// A^T W A and A^T W b (added to ata, atb; cc x cc row-major, full) for a compile-time row length:
// rank-1 updates of a float block held in 4-wide vectors (GCC vector extension: SSE, or AVX
// pairs with -mavx2), flushed into double every 256 rows so that long sums keep double
// precision. Rows are padded with zeros to a multiple of 4.
using Float4 = float __attribute__((vector_size(16)));

template <int CC>
void AccumulateFixed(const float* rows, const float* targets, const float* weight, size_t m,
                     double* ata, double* atb) {
  constexpr int kVectors = (CC + 3) / 4;
  Float4 block[CC][kVectors] = {};
  Float4 block_b[kVectors] = {};
  int in_block = 0;
  auto flush = [&] {
    for (int r = 0; r < CC; ++r) {
      for (int c = 0; c < CC; ++c) ata[r * CC + c] += block[r][c / 4][c % 4];
      for (int k = 0; k < kVectors; ++k) block[r][k] = Float4{};
    }
    for (int c = 0; c < CC; ++c) atb[c] += block_b[c / 4][c % 4];
    for (int k = 0; k < kVectors; ++k) block_b[k] = Float4{};
    in_block = 0;
  };
  for (size_t i = 0; i < m; ++i) {
    const float wi = weight[i];
    if (!(wi > 0)) continue;
    float padded[kVectors * 4] = {};
    std::memcpy(padded, rows + i * CC, sizeof(float) * CC);
    Float4 a[kVectors];
    std::memcpy(a, padded, sizeof(a));
    const float wt = wi * targets[i];
    for (int k = 0; k < kVectors; ++k) block_b[k] += a[k] * wt;
    for (int r = 0; r < CC; ++r) {
      const float war = wi * padded[r];
      for (int k = 0; k < kVectors; ++k) block[r][k] += a[k] * war;
    }
    if (++in_block == 256) flush();
  }
  flush();
}

void Accumulate(int cc, const float* rows, const float* targets, const float* weight, size_t m,
                double* ata, double* atb) {
  switch (cc) {
    case 4:
      return AccumulateFixed<4>(rows, targets, weight, m, ata, atb);
    case 9:
      return AccumulateFixed<9>(rows, targets, weight, m, ata, atb);
    case 16:
      return AccumulateFixed<16>(rows, targets, weight, m, ata, atb);
    default:
      return AccumulateFixed<25>(rows, targets, weight, m, ata, atb);
  }
}

// targets - rows * l for a compile-time row length (float: the rows are float anyway).
template <int CC>
void ResidualsFixed(const float* rows, const float* targets, const double* l, size_t m,
                    float* residual) {
  float lf[CC];
  for (int k = 0; k < CC; ++k) lf[k] = static_cast<float>(l[k]);
  for (size_t i = 0; i < m; ++i) {
    const float* a = rows + i * CC;
    float p = 0;
    for (int k = 0; k < CC; ++k) p += a[k] * lf[k];
    residual[i] = targets[i] - p;
  }
}

void Residuals(int cc, const float* rows, const float* targets, const double* l, size_t m,
               float* residual) {
  switch (cc) {
    case 4:
      return ResidualsFixed<4>(rows, targets, l, m, residual);
    case 9:
      return ResidualsFixed<9>(rows, targets, l, m, residual);
    case 16:
      return ResidualsFixed<16>(rows, targets, l, m, residual);
    default:
      return ResidualsFixed<25>(rows, targets, l, m, residual);
  }
}

// Orientation cell of a transfer row for balance_normals: the direction of T's band-1 part
// (OptimalLinearDirection's, proportional to the normal where nothing occludes) on a cube map of
// 6 faces x 4 x 4 cells (no trigonometry per row).
constexpr int kOrientationCells = 4;
constexpr int kOrientationBins = 6 * kOrientationCells * kOrientationCells;
int OrientationBin(const float* t) {
  constexpr int kCells = kOrientationCells;
  const float d[3] = {-t[3], -t[1], t[2]};
  const float ax = std::abs(d[0]), ay = std::abs(d[1]), az = std::abs(d[2]);
  int face;
  float u, v, major;
  if (ax >= ay && ax >= az) {
    face = d[0] > 0 ? 0 : 1, u = d[1], v = d[2], major = ax;
  } else if (ay >= az) {
    face = d[1] > 0 ? 2 : 3, u = d[0], v = d[2], major = ay;
  } else {
    face = d[2] > 0 ? 4 : 5, u = d[0], v = d[1], major = az;
  }
  if (!(major > 0)) major = 1, u = v = 0;
  const int a = std::clamp(static_cast<int>((u / major + 1) * 0.5f * kCells), 0, kCells - 1);
  const int b = std::clamp(static_cast<int>((v / major + 1) * 0.5f * kCells), 0, kCells - 1);
  return (face * kCells + a) * kCells + b;
}

// Orientation-bin thinning (EstimateOptions::max_rows_per_bin): with bin[i] the orientation bin of
// row i and count[b] the rows per bin, a bin with more than `cap` rows keeps every k-th of them
// (k = ceil(count / cap)); the rare orientations that pin the light down keep all their rows, the
// big planes lose most of theirs. Compacts rows (cc values each), targets and rgb (3 values each,
// if not null), weights (if not null), bin and count in place to the kept rows and returns how many
// there are.
size_t ThinByOrientation(float* rows, float* targets, float* rgb, float* weights, size_t m, int cc,
                         int cap, std::vector<int>& bin, std::vector<int>& count) {
  std::vector<int> seen(kOrientationBins, 0), kept(kOrientationBins, 0);
  size_t n = 0;
  for (size_t i = 0; i < m; ++i) {
    const int b = bin[i];
    const int k = (count[b] + cap - 1) / cap;
    if (seen[b]++ % k != 0) continue;
    std::copy_n(rows + i * cc, cc, rows + n * cc);
    if (rgb != nullptr) std::copy_n(rgb + 3 * i, 3, rgb + 3 * n);
    if (weights != nullptr) weights[n] = weights[i];
    targets[n] = targets[i];
    bin[n++] = b;
    ++kept[b];
  }
  count = kept;
  return n;
}

}  // namespace

namespace {

// Weighted residual sums of a fit and its R^2 (clamped to [0, 1]; 0 without target variance).
struct WeightedFit {
  double sw = 0, swr2 = 0, r2 = 0;
};

WeightedFit WeightedFitOf(const std::vector<float>& weight, const std::vector<float>& residual,
                          std::span<const float> targets, size_t m) {
  WeightedFit f;
  double swt = 0, swt2 = 0;
  for (size_t i = 0; i < m; ++i) {
    f.sw += weight[i];
    f.swr2 += double(weight[i]) * residual[i] * residual[i];
    swt += double(weight[i]) * targets[i];
  }
  const double mean_t = f.sw > 0 ? swt / f.sw : 0;
  for (size_t i = 0; i < m; ++i) {
    swt2 += double(weight[i]) * (targets[i] - mean_t) * (targets[i] - mean_t);
  }
  f.r2 = swt2 > 0 ? std::clamp(1.0 - f.swr2 / swt2, 0.0, 1.0) : 0.0;
  return f;
}

}  // namespace

LightEstimate SolveLight(std::span<const float> rows, std::span<const float> targets,
                         int coefficient_count, const EstimateOptions& options,
                         std::span<const float> row_weights) {
  const int cc = coefficient_count;
  if (cc != 4 && cc != 9 && cc != 16 && cc != 25) {
    throw LightError("light::SolveLight: coefficient_count must be 4, 9, 16 or 25, got " +
                     std::to_string(cc));
  }
  size_t m = targets.size();
  if (rows.size() != m * cc) {
    throw LightError("light::SolveLight: " + std::to_string(rows.size()) + " row values for " +
                     std::to_string(m) + " targets x " + std::to_string(cc) + " coefficients");
  }
  if (!(options.ridge >= 0) || !(options.smoothness >= 0)) {
    throw LightError("light::SolveLight: ridge and smoothness must be >= 0");
  }
  if (!(options.prior.weight >= 0) || !std::isfinite(options.prior.weight)) {
    throw LightError("light::SolveLight: prior.weight must be finite and >= 0");
  }
  if (options.huber_iterations < 0 || options.tukey_iterations < 0) {
    throw LightError("light::SolveLight: huber_iterations and tukey_iterations must be >= 0");
  }
  if (!row_weights.empty() && row_weights.size() != m) {
    throw LightError("light::SolveLight: " + std::to_string(row_weights.size()) +
                     " row weights for " + std::to_string(m) + " targets");
  }
  for (const float w : row_weights) {
    if (!(w >= 0) || !std::isfinite(w)) {
      throw LightError("light::SolveLight: row weights must be finite and >= 0, got " +
                       std::to_string(w));
    }
  }
  LightEstimate e;
  e.bands = static_cast<int>(std::lround(std::sqrt(cc)));
  e.pixels = static_cast<int>(m);
  if (static_cast<int>(m) < std::max(options.min_pixels, cc)) return e;

  // Prior weights: the rows' reliability (row_weights) times the normal-orientation balancing
  // (see EstimateOptions::balance_normals).
  std::vector<float> prior(m, 1.0f);
  if (!row_weights.empty()) std::copy(row_weights.begin(), row_weights.end(), prior.begin());
  std::vector<float> thin_rows, thin_targets;
  std::vector<float> row_reliability;  // row_weights of the rows kept (the direction refits)
  if (!row_weights.empty()) row_reliability = prior;
  if (options.balance_normals) {
    std::vector<int> bin(m), count(kOrientationBins, 0);
    for (size_t i = 0; i < m; ++i) {
      bin[i] = OrientationBin(rows.data() + i * cc);
      ++count[bin[i]];
    }
    // Thinning (ThinByOrientation; each bin's total weight is the same after balancing), only
    // when some bin is over the cap.
    const int kCap = options.max_rows_per_bin;
    if (kCap > 0 && std::any_of(count.begin(), count.end(), [&](int c) { return c > kCap; })) {
      thin_rows.assign(rows.begin(), rows.end());
      thin_targets.assign(targets.begin(), targets.end());
      m = ThinByOrientation(thin_rows.data(), thin_targets.data(), nullptr, prior.data(), m, cc,
                            kCap, bin, count);
      thin_rows.resize(m * cc);
      thin_targets.resize(m);
      rows = thin_rows;
      targets = thin_targets;
      prior.resize(m);
    }
    if (!row_weights.empty()) row_reliability.assign(prior.begin(), prior.begin() + m);
    // Each bin's total weight is the mean reliability of its rows (1 without row_weights): an
    // orientation seen only by unreliable pixels is not balanced up to a full bin's weight.
    int used = 0;
    for (int c : count) used += c > 0;
    for (size_t i = 0; i < m; ++i) {
      prior[i] *= static_cast<float>(static_cast<double>(m) / (used * count[bin[i]]));
    }
  }
  std::vector<float> weight = prior, residual(m, 0.0f), abs_r(m);
  std::vector<double> l(cc, 0.0), ata(static_cast<size_t>(cc) * cc), atb(cc);
  std::vector<std::array<double, sh::kMaxCoefficients>> penalty;  // non-negativity rows
  double base_trace = 0;
  // LightPrior's ratios rho_k (rho_0 unused; empty: no prior) and its current weight.
  std::vector<double> rho;
  double prior_scale = 0;
  {
    const Vec3f& u = options.prior.up;
    const double un = std::sqrt(double(u[0]) * u[0] + double(u[1]) * u[1] + double(u[2]) * u[2]);
    if (options.prior.weight > 0 && un > 0.5) {
      std::array<double, sh::kMaxCoefficients> y{};
      sh::EvaluateBasis<double>(e.bands, u[0] / un, u[1] / un, u[2] / un, y.data());
      rho.assign(cc, 0.0);
      for (int k = 1; k < cc; ++k) {
        const int deg = sh::DegreeOf(k);
        const double z = deg < 4 ? options.prior.zonal[deg] : 0.0;
        rho[k] = z / (2 * deg + 1) * y[k] / y[0];
      }
    }
  }

  auto solve = [&]() -> bool {
    std::fill(ata.begin(), ata.end(), 0.0);
    std::fill(atb.begin(), atb.end(), 0.0);
    Accumulate(cc, rows.data(), targets.data(), weight.data(), m, ata.data(), atb.data());
    double trace = 0;
    for (int r = 0; r < cc; ++r) trace += ata[r * cc + r];
    if (base_trace == 0) base_trace = trace;
    // Non-negativity penalties: rows mu * Y(w_k) with target 0 where the light was negative.
    const double mu2 = 10.0 * base_trace / cc;
    for (const auto& y : penalty) {
      for (int r = 0; r < cc; ++r) {
        for (int c = 0; c < cc; ++c) ata[r * cc + c] += mu2 * y[r] * y[c];
      }
    }
    if (!rho.empty() && prior_scale > 0) {  // rows sqrt(w) (e_k - rho_k e_0), target 0
      const double w = prior_scale * (trace > 0 ? trace / cc : 1.0);
      for (int k = 1; k < cc; ++k) {
        ata[k * cc + k] += w;
        ata[k * cc + 0] -= w * rho[k];
        ata[0 * cc + k] -= w * rho[k];
        ata[0] += w * rho[k] * rho[k];
      }
    }
    const double ridge = options.ridge * (trace > 0 ? trace / cc : 1.0);
    const double smooth = options.smoothness * (trace > 0 ? trace / cc : 1.0);
    for (int r = 0; r < cc; ++r) {
      const int deg = sh::DegreeOf(r);
      ata[r * cc + r] += ridge + smooth * double(deg * (deg + 1)) * double(deg * (deg + 1));
    }
    return CholeskySolve(ata, atb, cc, &l);
  };
  auto residuals = [&] {
    Residuals(cc, rows.data(), targets.data(), l.data(), m, residual.data());
  };
  if (!solve()) return e;
  // The prior weighs as much as the data leaves unexplained: options.prior.weight times
  // (1 - R^2) / R^2 of the current fit (a MAP weight sigma^2 / tau^2 with the signal's variance
  // as the unit), so clean data that pins the light down is left alone and texture, bounce light
  // and albedo ambiguity give way to the prior.
  // Needs the current residuals.
  auto update_prior = [&]() {
    const double r2 = WeightedFitOf(weight, residual, targets, m).r2;
    prior_scale = options.prior.weight * (1 - r2) / std::max(r2, 0.05);
  };
  if (!rho.empty()) {
    residuals();
    update_prior();
    if (!solve()) return e;
  }
  if (options.robust) {
    double rms_t = 0;
    for (float t : targets) rms_t += double(t) * t;
    rms_t = std::sqrt(rms_t / m);
    const int iterations = options.huber_iterations + options.tukey_iterations;
    for (int it = 0; it < iterations; ++it) {
      residuals();
      if (!rho.empty()) update_prior();  // under the previous weights
      for (size_t i = 0; i < m; ++i) abs_r[i] = std::abs(residual[i]);
      // MAD scale from every k-th residual (at most ~4096 of them: the median's cost otherwise
      // dominates the estimate; the scale only sets the reweighting thresholds).
      const size_t k = std::max<size_t>(1, m / 4096);
      std::vector<float> sample;
      sample.reserve(m / k + 1);
      for (size_t i = 0; i < m; i += k) sample.push_back(abs_r[i]);
      const float sigma =
          static_cast<float>(std::max(1.4826 * Median(std::move(sample)), 1e-7 * rms_t + 1e-12));
      const float inv_sigma = 1.0f / sigma;
      // Huber first (convex, a reliable start), then Tukey's biweight (redescending).
      if (it >= options.huber_iterations) {
        constexpr float c = 4.685f, inv_c = 1.0f / c;
        for (size_t i = 0; i < m; ++i) {
          const float u = abs_r[i] * inv_sigma * inv_c;
          const float q = 1 - u * u;
          weight[i] = u < 1 ? prior[i] * q * q : 0.0f;
        }
      } else {
        constexpr float k = 1.345f;
        for (size_t i = 0; i < m; ++i) {
          const float u = abs_r[i] * inv_sigma;
          weight[i] = u <= k ? prior[i] : prior[i] * k / u;
        }
      }
      if (!solve()) return e;
    }
  }
  if (options.non_negative && cc >= 4) {
    const auto constraint_dirs = sh::FibonacciSphere(64);
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
  const WeightedFit fit = WeightedFitOf(weight, residual, targets, m);
  e.rms_residual = fit.sw > 0 ? std::sqrt(fit.swr2 / fit.sw) : 0;
  e.confidence = static_cast<float>(fit.r2 * std::min(1.0, fit.sw / (20.0 * cc)));
  e.coefficients = l;
  e.valid = true;
  const int dc = options.direction_bands * options.direction_bands;
  if (options.direction_bands >= 2 && dc < cc) {
    std::vector<float> linear_rows(m * dc);
    for (size_t i = 0; i < m; ++i) std::copy_n(rows.data() + i * cc, dc, &linear_rows[i * dc]);
    // The reliability of the (possibly thinned) rows, before balancing (empty: none given).
    const std::span<const float> reliability = row_reliability;
    std::vector<float> lit_weights;
    LightEstimate linear = SolveLight(linear_rows, targets, dc, options, reliability);
    // A low-band model of max(0, n.d) is biased by the pixels facing away from the light (only
    // ambient reaches them): refit on the pixels facing the current estimate (n.d > 0.05, n from
    // T's band 1), where the shading is exactly linear in n.
    if (linear.valid && options.lit_refits) {
      std::vector<sh::Vec3> normal(m);
      for (size_t i = 0; i < m; ++i) normal[i] = sh::OptimalLinearDirection(rows.data() + i * cc);
      std::vector<float> lit_rows, lit_targets;
      lit_rows.reserve(m * dc);
      lit_weights.reserve(m);
      lit_targets.reserve(m);
      for (int it = 0; it < 2; ++it) {
        lit_rows.clear();
        lit_targets.clear();
        lit_weights.clear();
        const auto& d = linear.dominant_direction;
        for (size_t i = 0; i < m; ++i) {
          const sh::Vec3& n = normal[i];
          if (n[0] * d[0] + n[1] * d[1] + n[2] * d[2] <= 0.05) continue;
          lit_rows.insert(lit_rows.end(), &linear_rows[i * dc], &linear_rows[i * dc] + dc);
          lit_targets.push_back(targets[i]);
          if (!reliability.empty()) lit_weights.push_back(reliability[i]);
        }
        const LightEstimate refit = SolveLight(lit_rows, lit_targets, dc, options, lit_weights);
        if (!refit.valid) break;
        linear = refit;
      }
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

namespace {

// EstimateLight's rows: every stride-th valid pixel (or sparse sample) with a usable intensity,
// targets I / albedo, and the linear colour per row when grouped. `what` prefixes the errors.
struct LightRows {
  int coefficient_count = 0;
  std::vector<float> rows, targets, rgb;
  std::vector<float> weights;  // the pixels' reliability (empty: none given)
};

LightRows SelectRows(const TransferResult& transfer, std::span<const float> intensity,
                     const EstimateOptions& options, std::span<const uint8_t> colour,
                     std::span<const float> reliability, const std::string& what) {
  const size_t pixels = static_cast<size_t>(transfer.width) * transfer.height;
  if (intensity.size() != pixels) {
    throw LightError(what + ": intensity has " + std::to_string(intensity.size()) +
                     " values, transfer is " + std::to_string(transfer.width) + "x" +
                     std::to_string(transfer.height));
  }
  const int cc = transfer.coefficient_count;
  if (transfer.transfer.size() != pixels * cc || transfer.valid.size() != pixels) {
    throw LightError(what + ": transfer buffer sizes do not match " +
                     std::to_string(transfer.width) + "x" + std::to_string(transfer.height));
  }
  if (options.stride < 1) throw LightError(what + ": stride must be >= 1");
  const int cc_out = options.bands == 0 ? cc : options.bands * options.bands;
  if (options.bands != 0 && (options.bands < 2 || cc_out > cc)) {
    throw LightError(what + ": bands must be 0 or 2.." +
                     std::to_string(static_cast<int>(std::lround(std::sqrt(cc)))) + ", got " +
                     std::to_string(options.bands));
  }
  if (!(options.albedo > 0)) throw LightError(what + ": albedo must be > 0");
  if (!colour.empty() && colour.size() != 3 * pixels) {
    throw LightError(what + ": colour has " + std::to_string(colour.size()) +
                     " bytes, expected 3 x " + std::to_string(transfer.width) + "x" +
                     std::to_string(transfer.height));
  }
  if (!reliability.empty() && reliability.size() != pixels) {
    throw LightError(what + ": reliability has " + std::to_string(reliability.size()) +
                     " values, transfer is " + std::to_string(transfer.width) + "x" +
                     std::to_string(transfer.height));
  }
  if (options.albedo_groups < 0 || options.albedo_groups > 255 || options.albedo_iterations < 1) {
    throw LightError(what + ": albedo_groups must be 0..255 and albedo_iterations >= 1");
  }
  const bool grouped = !colour.empty() && options.albedo_groups > 0;
  // OursFast: fit to the exact sparse samples (every stride / sample_step-th of them), not to the
  // interpolated pixels; the full variant: every stride-th pixel.
  const int step = transfer.sample_step;
  const bool sparse = step > 1 && transfer.sample_width > 0 && transfer.sample_height > 0;
  if (sparse && (transfer.samples.size() !=
                     static_cast<size_t>(transfer.sample_width) * transfer.sample_height * cc ||
                 transfer.sample_valid.size() !=
                     static_cast<size_t>(transfer.sample_width) * transfer.sample_height)) {
    throw LightError(what + ": sample buffer sizes do not match " +
                     std::to_string(transfer.sample_width) + "x" +
                     std::to_string(transfer.sample_height));
  }
  const int s = sparse ? std::max(1, (options.stride + step / 2) / step) : options.stride;
  const int grid_w = sparse ? transfer.sample_width : transfer.width;
  const int grid_h = sparse ? transfer.sample_height : transfer.height;
  const float* t_data = sparse ? transfer.samples.data() : transfer.transfer.data();
  const uint8_t* v_data = sparse ? transfer.sample_valid.data() : transfer.valid.data();
  std::vector<float> rows, targets;
  const size_t max_rows = static_cast<size_t>((grid_w + s - 1) / s) * ((grid_h + s - 1) / s);
  rows.resize(max_rows * cc_out);
  targets.resize(max_rows);
  std::vector<float> rgb;  // linear colour per row (grouped)
  if (grouped) rgb.resize(3 * max_rows);
  std::vector<float> weights;
  if (!reliability.empty()) weights.resize(max_rows);
  size_t m = 0;
  const float inv_albedo = 1.0f / options.albedo;
  for (int y = s / 2; y < grid_h; y += s) {
    const int py = sparse ? std::min(y * step + step / 2, transfer.height - 1) : y;
    for (int x = s / 2; x < grid_w; x += s) {
      const size_t g = static_cast<size_t>(y) * grid_w + x;
      const int px = sparse ? std::min(x * step + step / 2, transfer.width - 1) : x;
      const size_t p = static_cast<size_t>(py) * transfer.width + px;
      const float i = intensity[p];
      if (!v_data[g] || !(i >= options.min_intensity) || !(i <= options.max_intensity)) continue;
      // A pixel of reliability <= 0 (or NaN) is no row; otherwise its weight.
      if (!reliability.empty() && !(reliability[p] > 0)) continue;
      if (grouped) {
        const float r = SrgbToLinear(colour[3 * p]), gr = SrgbToLinear(colour[3 * p + 1]),
                    b = SrgbToLinear(colour[3 * p + 2]);
        if (!(r + gr + b > 0)) continue;
        rgb[3 * m] = r, rgb[3 * m + 1] = gr, rgb[3 * m + 2] = b;
      }
      std::copy_n(t_data + g * cc, cc_out, &rows[m * cc_out]);
      if (!reliability.empty()) weights[m] = std::min(1.0f, reliability[p]);
      targets[m++] = i * inv_albedo;
    }
  }
  rows.resize(m * cc_out);
  targets.resize(m);
  if (grouped) rgb.resize(3 * m);
  if (!reliability.empty()) weights.resize(m);
  LightRows out;
  out.coefficient_count = cc_out;
  out.rows = std::move(rows);
  out.targets = std::move(targets);
  out.rgb = std::move(rgb);
  out.weights = std::move(weights);
  return out;
}

// The fit of EstimateLight to selected rows (SolveLight, with the albedo alternation when rgb is
// given and options.albedo_groups > 0).
LightEstimate EstimateFromRows(std::vector<float> rows, std::vector<float> targets,
                               std::vector<float> rgb, std::vector<float> weights, int cc_out,
                               const EstimateOptions& options) {
  const bool grouped = !rgb.empty() && options.albedo_groups > 0;
  const bool weighted = !weights.empty();
  const int cells = options.albedo_groups;
  size_t m = targets.size();
  if (!grouped) return SolveLight(rows, targets, cc_out, options, weights);
  const size_t usable = m;  // LightEstimate::pixels: before thinning, as SolveLight reports it
  // Thin the big orientation bins here already (SolveLight would do it in every alternation), so
  // that the albedo updates run over the same few thousand rows.
  if (options.balance_normals && options.max_rows_per_bin > 0) {
    std::vector<int> bin(m), count(kOrientationBins, 0);
    for (size_t i = 0; i < m; ++i) ++count[bin[i] = OrientationBin(&rows[i * cc_out])];
    m = ThinByOrientation(rows.data(), targets.data(), rgb.data(),
                          weighted ? weights.data() : nullptr, m, cc_out, options.max_rows_per_bin,
                          bin, count);
    rows.resize(m * cc_out);
    targets.resize(m);
    if (weighted) weights.resize(m);
  }
  // Albedo groups: chromaticity cells of the linear colour (the albedo's under white light), or
  // the illuminant-invariant coordinate (options.albedo_invariant).
  int ids = 0;
  const std::vector<int> group =
      internal::AlbedoGroupIds({rgb.data(), 3 * m}, cells, options.albedo_invariant, &ids);
  // Per-group albedo (relative to options.albedo), alternating with the light.
  std::vector<float> scaled(targets);
  const size_t group_count = static_cast<size_t>(ids);
  std::vector<double> sum_ip(group_count), sum_pp(group_count);
  std::vector<int> count(group_count, 0);
  std::vector<float> scale(group_count, 1.0f);
  for (size_t i = 0; i < m; ++i) ++count[group[i]];
  LightEstimate e;
  EstimateOptions inner = options;
  inner.direction_bands = 0;  // the direction fits only matter for the final light
  for (int it = 0; it < options.albedo_iterations; ++it) {
    const bool last = it + 1 == options.albedo_iterations;
    e = SolveLight(rows, scaled, cc_out, last ? options : inner, weights);
    if (!e.valid || last) break;
    std::fill(sum_ip.begin(), sum_ip.end(), 0.0);
    std::fill(sum_pp.begin(), sum_pp.end(), 0.0);
    for (size_t i = 0; i < m; ++i) {
      double p = 0;
      for (int k = 0; k < cc_out; ++k) p += rows[i * cc_out + k] * e.coefficients[k];
      if (!(p > 0)) continue;
      const double w = weighted ? weights[i] : 1.0;
      sum_ip[group[i]] += w * targets[i] * p;
      sum_pp[group[i]] += w * p * p;
    }
    // Normalise so that the row-weighted mean albedo stays options.albedo (the light's scale).
    double total = 0;
    size_t rows_scaled = 0;
    for (size_t g = 0; g < scale.size(); ++g) {
      if (count[g] >= 16 && sum_pp[g] > 0 && sum_ip[g] > 0) {
        scale[g] = static_cast<float>(sum_ip[g] / sum_pp[g]);
        total += double(scale[g]) * count[g];
        rows_scaled += count[g];
      }
    }
    const float mean = rows_scaled > 0 ? static_cast<float>(total / rows_scaled) : 1.0f;
    for (size_t g = 0; g < scale.size(); ++g) {
      scale[g] = count[g] >= 16 && sum_pp[g] > 0 && sum_ip[g] > 0 ? scale[g] / mean : 1.0f;
    }
    for (size_t i = 0; i < m; ++i) scaled[i] = targets[i] / scale[group[i]];
  }
  e.pixels = static_cast<int>(usable);
  return e;
}

}  // namespace

LightEstimate EstimateLight(const TransferResult& transfer, std::span<const float> intensity,
                            const EstimateOptions& options, std::span<const uint8_t> colour,
                            std::span<const float> reliability) {
  LightRows r =
      SelectRows(transfer, intensity, options, colour, reliability, "light::EstimateLight");
  return EstimateFromRows(std::move(r.rows), std::move(r.targets), std::move(r.rgb),
                          std::move(r.weights), r.coefficient_count, options);
}

void ShRotationMatrix(const float rotation[9], int bands, std::vector<double>* out) {
  // A[k][n] = integral Y_k(d) Y_n(R d) dw, exact for bands <= 5 with a Gauss-Legendre rule of
  // 5 x 10 nodes (products of two degree-4 polynomials have degree 8 <= 2 * 5 - 1).
  if (bands < 1 || bands > 5) {
    throw LightError("light::ShRotationMatrix: bands must be 1..5, got " + std::to_string(bands));
  }
  static const sh::QuadratureRule rule = sh::GaussLegendreRule(5);
  const int cc = bands * bands;
  out->assign(static_cast<size_t>(cc) * cc, 0.0);
  for (size_t j = 0; j < rule.directions.size(); ++j) {
    const sh::Vec3& d = rule.directions[j];
    const sh::Vec3 rd{rotation[0] * d[0] + rotation[1] * d[1] + rotation[2] * d[2],
                      rotation[3] * d[0] + rotation[4] * d[1] + rotation[5] * d[2],
                      rotation[6] * d[0] + rotation[7] * d[1] + rotation[8] * d[2]};
    const std::vector<double> a = sh::Basis(bands, d), b = sh::Basis(bands, rd);
    for (int k = 0; k < cc; ++k) {
      for (int n = 0; n < cc; ++n) (*out)[k * cc + n] += rule.weights[j] * a[k] * b[n];
    }
  }
}

TemporalLightEstimator::TemporalLightEstimator(const TemporalOptions& options) : options_(options) {
  if (options.frames < 1 || !(options.forgetting >= 0) || !(options.forgetting <= 1)) {
    throw LightError("light::TemporalLightEstimator: frames must be >= 1 and forgetting in [0, 1]");
  }
}

void TemporalLightEstimator::Reset() {
  history_.clear();
  last_light_.clear();
}

LightEstimate TemporalLightEstimator::Estimate(const TransferResult& transfer,
                                               std::span<const float> intensity,
                                               const EstimateOptions& options,
                                               std::span<const uint8_t> colour,
                                               const float* rotation,
                                               std::span<const float> reliability) {
  LightRows r = SelectRows(transfer, intensity, options, colour, reliability,
                           "light::TemporalLightEstimator::Estimate");
  const int cc = r.coefficient_count;
  const bool grouped = !r.rgb.empty();
  // Older frames: drop what no longer fits (coefficient count or grouping changed, or too old),
  // bring the rest into the current camera frame and age them.
  while (!history_.empty() && static_cast<int>(history_.size()) >= options_.frames) {
    history_.pop_back();
  }
  for (auto it = history_.begin(); it != history_.end();) {
    if (it->coefficient_count != cc || it->rgb.empty() != !grouped ||
        it->weights.empty() != r.weights.empty()) {
      it = history_.erase(it);
    } else {
      ++it;
    }
  }
  if (static_cast<int>(last_light_.size()) != cc) history_.clear();
  if (rotation != nullptr && !history_.empty()) {
    const int bands = static_cast<int>(std::lround(std::sqrt(cc)));
    ShRotationMatrix(rotation, bands, &rotation_sh_);
    // The last light into the current frame: l_now = A^T l_prev (A is orthogonal).
    std::vector<double> l(cc, 0.0);
    for (int n = 0; n < cc; ++n) {
      for (int k = 0; k < cc; ++k) l[n] += rotation_sh_[k * cc + n] * last_light_[k];
    }
    last_light_ = l;
    std::vector<float> row(cc);
    for (Frame& f : history_) {
      const size_t m = f.targets.size();
      for (size_t i = 0; i < m; ++i) {
        float* t = &f.rows[i * cc];
        // T' = A^T T: T . l_previous = T . (A l_current) (ShRotationMatrix).
        for (int n = 0; n < cc; ++n) {
          double v = 0;
          for (int k = 0; k < cc; ++k) v += rotation_sh_[k * cc + n] * t[k];
          row[n] = static_cast<float>(v);
        }
        std::copy(row.begin(), row.end(), t);
      }
    }
  }
  // Change detection: the current rows' RMS residual under the last light, against the last
  // frame's own under its light; a jump by more than reset_ratio (the light switched or moved)
  // drops the history, so the estimate follows at once instead of blending for frames.
  auto rms_under = [cc](const std::vector<float>& rows, const std::vector<float>& targets,
                        const std::vector<double>& light) {
    double sum = 0;
    const size_t m = targets.size();
    for (size_t i = 0; i < m; ++i) {
      double p = 0;
      for (int k = 0; k < cc; ++k) p += rows[i * cc + k] * light[k];
      sum += (p - targets[i]) * (p - targets[i]);
    }
    return m > 0 ? std::sqrt(sum / m) : 0.0;
  };
  if (!history_.empty() && options_.reset_ratio > 0 &&
      rms_under(r.rows, r.targets, last_light_) > options_.reset_ratio * last_rms_) {
    history_.clear();
  }
  // Weight forgetting^age by scaling rows and targets by its square root (least squares).
  const float s = std::sqrt(options_.forgetting);
  for (Frame& f : history_) {
    for (float& v : f.rows) v *= s;
    for (float& v : f.targets) v *= s;
  }
  Frame current{cc, r.rows, r.targets, r.rgb, r.weights};
  std::vector<float> rows = std::move(r.rows), targets = std::move(r.targets),
                     rgb = std::move(r.rgb), weights = std::move(r.weights);
  for (const Frame& f : history_) {
    rows.insert(rows.end(), f.rows.begin(), f.rows.end());
    targets.insert(targets.end(), f.targets.begin(), f.targets.end());
    rgb.insert(rgb.end(), f.rgb.begin(), f.rgb.end());
    weights.insert(weights.end(), f.weights.begin(), f.weights.end());
  }
  LightEstimate e = EstimateFromRows(std::move(rows), std::move(targets), std::move(rgb),
                                     std::move(weights), cc, options);
  if (e.valid) {
    last_light_ = e.coefficients;
    last_rms_ = rms_under(current.rows, current.targets, last_light_);
  } else {
    last_light_.clear();
  }
  history_.push_front(std::move(current));
  if (options_.frames == 1) history_.clear();
  return e;
}

}  // namespace probeless::light
