// Light estimation (Knorr & Kurz 2014, sec. 3.5, eq. 19) with optional prior, robust rejection and
// non-negativity (see probeless/face_light/estimator.h).
#include "probeless/face_light/estimator.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstring>
#include <mutex>
#include <numbers>

#include "linalg.h"
#include "probeless/msgs/sh_light.h"
#include "probeless/sh/sh.h"

// Hot kernels are compiled twice, for AVX2 and for the baseline, and the loader picks the version
// for the CPU (GCC / Clang function multi-versioning, x86-64 only). Neither uses FMA (no
// -mfma), so both versions perform the same operations in the same order: the same values.
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define PROBELESS_AVX2_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define PROBELESS_AVX2_CLONES
#endif

namespace probeless::face_light {
namespace {

constexpr int kN = kRtfCoefficients;
constexpr int kMaxNnDirections = 1024;
constexpr int kMaxPassive = 32;

// sum_i a[i] b[i] for count a multiple of 8, with 8 independent lanes so the compiler vectorises
// it without -ffast-math. Cloned for AVX2 (chosen at load time on CPUs that have it): the same
// lanes, operations and order (no FMA), so the same values, one 8-wide register per row.
PROBELESS_AVX2_CLONES float Dot8(const float* a, const float* b, int count) {
  float lanes[8] = {};
  for (int i = 0; i < count; i += 8) {
    for (int l = 0; l < 8; ++l) lanes[l] += a[i + l] * b[i + l];
  }
  return ((lanes[0] + lanes[4]) + (lanes[1] + lanes[5])) +
         ((lanes[2] + lanes[6]) + (lanes[3] + lanes[7]));
}

// out[r] = sum_i rows[r * stride + i] x[i] for r < count (stride a multiple of 8), accumulated
// in double in 8 independent lanes (the products of the float values are exact in double), x
// converted once, three rows at a time (independent accumulator chains). Cloned for AVX2 (same
// operations and order, no FMA: the same values).
using Double4 = double __attribute__((vector_size(32)));
PROBELESS_AVX2_CLONES void DotDRows(const double* rows, int count, const float* x, int stride,
                                    double* out) {
  alignas(64) double xd[kMaxSamples + 8];
  for (int i = 0; i < stride; ++i) xd[i] = x[i];
  const auto finish = [](const Double4& low, const Double4& high) {  // lanes 0-3 and 4-7
    return ((low[0] + high[0]) + (low[1] + high[1])) + ((low[2] + high[2]) + (low[3] + high[3]));
  };
  int r = 0;
  for (; r + 3 <= count; r += 3) {
    const double* a = rows + static_cast<size_t>(r) * stride;
    Double4 low[3] = {}, high[3] = {};
    for (int i = 0; i < stride; i += 8) {
      Double4 x0, x1;
      std::memcpy(&x0, xd + i, sizeof x0);
      std::memcpy(&x1, xd + i + 4, sizeof x1);
      for (int k = 0; k < 3; ++k) {
        Double4 a0, a1;
        std::memcpy(&a0, a + static_cast<size_t>(k) * stride + i, sizeof a0);
        std::memcpy(&a1, a + static_cast<size_t>(k) * stride + i + 4, sizeof a1);
        low[k] += a0 * x0;
        high[k] += a1 * x1;
      }
    }
    for (int k = 0; k < 3; ++k) out[r + k] = finish(low[k], high[k]);
  }
  for (; r < count; ++r) {
    const double* a = rows + static_cast<size_t>(r) * stride;
    double lanes[8] = {};
    for (int i = 0; i < stride; i += 8) {
      for (int l = 0; l < 8; ++l) lanes[l] += a[i + l] * xd[i + l];
    }
    out[r] = ((lanes[0] + lanes[4]) + (lanes[1] + lanes[5])) +
             ((lanes[2] + lanes[6]) + (lanes[3] + lanes[7]));
  }
}

// out[r] = Dot8(rows + r * stride, x, stride) for r < count: several rows at a time, so several
// independent accumulator chains (a single row is bound by the latency of its additions); the same
// lanes, operations and order as Dot8, so the same values. Cloned for AVX2.
using Float8 = float __attribute__((vector_size(32)));
template <int Block, typename T>
inline void Dot8RowsBlocked(const float* rows, int count, const float* x, int stride, T* out) {
  int r = 0;
  for (; r + Block <= count; r += Block) {
    const float* a = rows + static_cast<size_t>(r) * stride;
    Float8 acc[Block] = {};
    for (int i = 0; i < stride; i += 8) {
      Float8 xv;
      std::memcpy(&xv, x + i, sizeof xv);
      for (int k = 0; k < Block; ++k) {
        Float8 av;
        std::memcpy(&av, a + static_cast<size_t>(k) * stride + i, sizeof av);
        acc[k] += av * xv;
      }
    }
    for (int k = 0; k < Block; ++k) {
      out[r + k] = ((acc[k][0] + acc[k][4]) + (acc[k][1] + acc[k][5])) +
                   ((acc[k][2] + acc[k][6]) + (acc[k][3] + acc[k][7]));
    }
  }
  for (; r < count; ++r) out[r] = Dot8(rows + static_cast<size_t>(r) * stride, x, stride);
}
// Blocks of 3 for 9 rows, 5 for 25 (no single-row remainder), else 4.
template <typename T>
PROBELESS_AVX2_CLONES void Dot8Rows(const float* rows, int count, const float* x, int stride,
                                    T* out) {
  if (count % 5 == 0) return Dot8RowsBlocked<5>(rows, count, x, stride, out);
  if (count % 3 == 0) return Dot8RowsBlocked<3>(rows, count, x, stride, out);
  Dot8RowsBlocked<4>(rows, count, x, stride, out);
}

// Solves L L^T x = b in place for `count` (<= 3) right-hand sides b[c] (l from
// internal::Cholesky<9>): the operations of linalg::CholeskySolveFactored per right-hand side (the
// same values), interleaved so their division chains overlap.
void CholeskySolve9Multi(const std::array<double, 81>& l, double (*b)[kRtfCoefficients],
                         int count) {
  constexpr int n = kRtfCoefficients;
  for (int i = 0; i < n; ++i) {
    double s[3];
    for (int c = 0; c < count; ++c) s[c] = b[c][i];
    for (int k = 0; k < i; ++k) {
      for (int c = 0; c < count; ++c) s[c] -= l[i * n + k] * b[c][k];
    }
    for (int c = 0; c < count; ++c) b[c][i] = s[c] / l[i * n + i];
  }
  for (int i = n - 1; i >= 0; --i) {
    double s[3];
    for (int c = 0; c < count; ++c) s[c] = b[c][i];
    for (int k = i + 1; k < n; ++k) {
      for (int c = 0; c < count; ++c) s[c] -= l[k * n + i] * b[c][k];
    }
    for (int c = 0; c < count; ++c) b[c][i] = s[c] / l[i * n + i];
  }
}

constexpr int kMaxDirN = 25;       // 5 bands
constexpr size_t kMaxGrid = 1024;  // EstimatorOptions::directional_grid
constexpr int kMaxMaskCache = 64;  // EstimatorOptions::mask_cache
// Largest infinity norm of the mask correction N_valid^-1 N_full for the pseudo-inverse path
// (EstimatorOptions::exact_masked_solve): it bounds how much the float error grows.
constexpr double kMaxCorrectionNorm = 1e9;
constexpr int kMaskWords = kMaxSamples / 64;

// Symmetric m (N x N, row-major) += sign * sum_j (w t) t^T over the listed samples j (rows
// [index * N] of wt = w t and t), sign = +1 or -1: the lower triangle, mirrored (m stays exactly
// symmetric). Cloned for AVX2 (same operations and order, no FMA: the same values).
template <int N>
inline void RankUpdateBody(double* m, const double* wt_rows, const double* t_rows, const int* index,
                           int count, double sign) {
  // Row a (its lower triangle, b <= a) accumulated in registers, the samples in order; then
  // mirrored.
#pragma GCC unroll 32
  for (int a = 0; a < N; ++a) {
    double acc[N];
    for (int b = 0; b <= a; ++b) acc[b] = m[a * N + b];
    for (int j = 0; j < count; ++j) {
      const double s = sign * wt_rows[static_cast<size_t>(index[j]) * N + a];
      const double* t = t_rows + static_cast<size_t>(index[j]) * N;
#pragma GCC unroll 32
      for (int b = 0; b <= a; ++b) acc[b] += s * t[b];
    }
    for (int b = 0; b <= a; ++b) m[a * N + b] = m[b * N + a] = acc[b];
  }
}
PROBELESS_AVX2_CLONES void RankUpdate9(double* m, const double* wt, const double* t,
                                       const int* index, int count, double sign) {
  RankUpdateBody<9>(m, wt, t, index, count, sign);
}
PROBELESS_AVX2_CLONES void RankUpdate25(double* m, const double* wt, const double* t,
                                        const int* index, int count, double sign) {
  RankUpdateBody<25>(m, wt, t, index, count, sign);
}
PROBELESS_AVX2_CLONES void RankUpdate16(double* m, const double* wt, const double* t,
                                        const int* index, int count, double sign) {
  RankUpdateBody<16>(m, wt, t, index, count, sign);
}
void RankUpdate(double* m, int n, const double* wt, const double* t, const int* index, int count,
                double sign) {
  if (n == 9) return RankUpdate9(m, wt, t, index, count, sign);
  if (n == 16) return RankUpdate16(m, wt, t, index, count, sign);
  if (n == 25) return RankUpdate25(m, wt, t, index, count, sign);
  for (int j = 0; j < count; ++j) {  // other sizes: the same, sample by sample
    const double* wt_j = wt + static_cast<size_t>(index[j]) * n;
    const double* t_j = t + static_cast<size_t>(index[j]) * n;
    for (int a = 0; a < n; ++a) {
      const double s = sign * wt_j[a];
      for (int b = 0; b <= a; ++b) m[a * n + b] += s * t_j[b];
    }
  }
  for (int a = 0; a < n; ++a) {
    for (int b = 0; b < a; ++b) m[b * n + a] = m[a * n + b];
  }
}

// Y_k^T M Y_k and (M Y_k)_0 of every grid direction k for M = M_full - sum_j w_j t_j t_j^T (the
// full-set matrix downdated by the listed samples j): syy_full[k] - sum_j w_j (t_j.Y_k)^2 and
// s0y_full[k] - sum_j w_j t_j0 (t_j.Y_k), from the precomputed projections
// proj[i * count + k] = t_i.Y_k (wt0[i] = w_i t_i0); vectorised over k. Cloned for AVX2 (same
// operations and order, no FMA: the same values).
PROBELESS_AVX2_CLONES void GridDowndate(const double* syy_full, const double* s0y_full,
                                        const double* proj, size_t count, const float* weights,
                                        const double* wt0, int wt0_stride, const int* index,
                                        int listed, double* syy, double* s0y) {
  std::copy(syy_full, syy_full + count, syy);
  std::copy(s0y_full, s0y_full + count, s0y);
  for (int j = 0; j < listed; ++j) {
    const size_t i = static_cast<size_t>(index[j]);
    const double* p = proj + i * count;
    const double w = weights[i];
    const double w0 = wt0[i * wt0_stride];
    for (size_t k = 0; k < count; ++k) {
      syy[k] -= w * (p[k] * p[k]);
      s0y[k] -= w0 * p[k];
    }
  }
}

// What the estimator derives from one validity mask (EstimatorOptions::mask_cache).
struct MaskData {
  std::array<double, 81> factor{};  // Cholesky factor of the downdated T^T W T + R
  bool factor_ok = false;
  // EstimatorOptions::exact_masked_solve off and the correction well conditioned: e = C pinv v.
  bool corrected = false;
  std::array<double, 81> normal;      // the downdated T^T W T + R itself (if corrected)
  std::array<double, 81> correction;  // C = normal^-1 (T^T W T + R)_full, row-major
  bool dir_ready = false;             // the directional fit's data below is filled
  double dir_m[kMaxDirN * kMaxDirN];
  double syy[kMaxGrid], s0y[kMaxGrid];
};

// Normalisation constants of sh::EvaluateBasis for bands <= 5 (sh::BasisNormalisation).
struct BasisConstants {
  std::array<double, 25> k = sh::BasisNormalisation();
};

const BasisConstants& Constants() {
  static const BasisConstants constants;
  return constants;
}

// sh::EvaluateBasis<double> with the normalisation precomputed (sh::EvaluateWeightedBasis): the
// directional fit evaluates it ~50 times per estimate.
void FastBasis(const BasisConstants& constants, int bands, double x, double y, double z,
               double* out) {
  switch (bands) {
    case 1:
      return sh::EvaluateWeightedBasis<1, false>(constants.k.data(), x, y, z, out);
    case 2:
      return sh::EvaluateWeightedBasis<2, false>(constants.k.data(), x, y, z, out);
    case 3:
      return sh::EvaluateWeightedBasis<3, false>(constants.k.data(), x, y, z, out);
    case 4:
      return sh::EvaluateWeightedBasis<4, false>(constants.k.data(), x, y, z, out);
    default:
      return sh::EvaluateWeightedBasis<5, false>(constants.k.data(), x, y, z, out);
  }
}

// For a symmetric 25 x 25 M (row-major) and y, b: y^T M y, (M y)_0 and b^T y. M y as a sum of
// rows (= columns) so the loops vectorise; cloned for AVX2 (same operations and order, no FMA).
PROBELESS_AVX2_CLONES void Forms25(const double* m, const double* y, const double* b, double* syy,
                                   double* s0y, double* ry) {
  constexpr int kSize = 25;
  double my[kSize] = {};
  for (int j = 0; j < kSize; ++j) {
    const double* row = m + j * kSize;
    const double yj = y[j];
    for (int i = 0; i < kSize; ++i) my[i] += row[i] * yj;
  }
  double s[4] = {}, r[4] = {};
  for (int i = 0; i < 24; i += 4) {
    for (int l = 0; l < 4; ++l) {
      s[l] += y[i + l] * my[i + l];
      r[l] += b[i + l] * y[i + l];
    }
  }
  *syy = ((s[0] + s[2]) + (s[1] + s[3])) + y[24] * my[24];
  *ry = ((r[0] + r[2]) + (r[1] + r[3])) + b[24] * y[24];
  *s0y = my[0];
}

// Deinterleaves values[i * channels + c] into v[c][i] (zero padded up to stride), flags the
// samples with a non-finite value (valid[i] = 0, else 1; 0 from n to stride), applies the
// response exponent (x -> max(x, 0)^exponent) and averages the channels into mean. Branch-free so
// the loops vectorise.
void PrepareSamples(const float* values, int channels, int n, int stride, double exponent,
                    float (*v)[kMaxSamples + 8], float* mean, uint8_t* valid) {
  if (channels == 3) {  // one pass (the compiler deinterleaves with shuffles)
    for (int i = 0; i < n; ++i) {
      v[0][i] = values[3 * i];
      v[1][i] = values[3 * i + 1];
      v[2][i] = values[3 * i + 2];
    }
  } else {
    for (int c = 0; c < channels; ++c) {
      for (int i = 0; i < n; ++i) v[c][i] = values[i * channels + c];
    }
  }
  for (int c = 0; c < channels; ++c) {
    for (int i = n; i < stride; ++i) v[c][i] = 0;
  }
  // Finite: x - x is 0 for finite x, NaN otherwise.
  float check[kMaxSamples + 8];
  for (int i = 0; i < n; ++i) check[i] = v[0][i] - v[0][i];
  for (int c = 1; c < channels; ++c) {
    for (int i = 0; i < n; ++i) check[i] += v[c][i] - v[c][i];
  }
  for (int i = 0; i < n; ++i) valid[i] = check[i] == 0.0f;
  for (int i = n; i < stride; ++i) valid[i] = 0;
  for (int c = 0; c < channels; ++c) {
    float* row = v[c];
    if (exponent == 0.5) {
      for (int i = 0; i < n; ++i) row[i] = std::sqrt(row[i] > 0 ? row[i] : 0.0f);
    } else if (exponent != 1) {
      const float g = static_cast<float>(exponent);
      for (int i = 0; i < n; ++i) row[i] = std::pow(row[i] > 0 ? row[i] : 0.0f, g);
    }
  }
  const float inv_channels = 1.0f / channels;
  for (int i = 0; i < stride; ++i) {
    float sum = 0;
    for (int c = 0; c < channels; ++c) sum += v[c][i];
    mean[i] = sum * inv_channels;
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

// ClosedFormCost of every grid direction k from the tables syy[k], s0y[k] and the transposed basis
// values basis_t[a * count + k] (ry = b^T Y_k as one matrix-vector product): the same formulas,
// branch-free so the loops vectorise; cloned for AVX2 (no FMA: the same values).
PROBELESS_AVX2_CLONES void GridCosts(const double* basis_t, const double* b, int n, size_t count,
                                     const double* syy, const double* s0y, double s00, double r0,
                                     bool ambient, double* cost) {
  double ry[kMaxGrid];
  std::fill(ry, ry + count, 0.0);
  for (int a = 0; a < n; ++a) {
    const double* row = basis_t + a * count;
    const double ba = b[a];
    for (size_t k = 0; k < count; ++k) ry[k] += ba * row[k];
  }
  if (ambient) {
    const double c_only = s00 > 0 ? r0 / s00 : 0;  // a = 0
    const double cost_c_only = -(0 * 0.0 + c_only * r0);
    for (size_t k = 0; k < count; ++k) {
      const double det = syy[k] * s00 - s0y[k] * s0y[k];
      const bool solvable = det > 1e-12 * syy[k] * s00;
      const double safe_det = solvable ? det : 1.0;
      const double a = solvable ? (ry[k] * s00 - s0y[k] * r0) / safe_det : 0.0;
      const double c = solvable ? (syy[k] * r0 - s0y[k] * ry[k]) / safe_det : 0.0;
      cost[k] = a > 0 ? -(a * ry[k] + c * r0) : cost_c_only;
    }
  } else {
    for (size_t k = 0; k < count; ++k) {
      const double a = syy[k] > 0 ? std::max(ry[k] / (syy[k] > 0 ? syy[k] : 1.0), 0.0) : 0.0;
      cost[k] = -a * ry[k];
    }
  }
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

  // y^T M y from the lower triangle (M symmetric), (M y)_0 and b^T y; fixed-size loops for the
  // usual sizes (fully unrolled: no branches).
  template <int N>
  double CostFixed(const double* y, double* a_out, double* c_out) const {
    double syy = 0, ry = 0;
    for (int i = 0; i < N; ++i) {
      const double* row = m + i * N;
      double off = 0;
      for (int j = 0; j < i; ++j) off += row[j] * y[j];
      syy += y[i] * (row[i] * y[i] + 2 * off);
      ry += b[i] * y[i];
    }
    double s0y = 0;
    for (int j = 0; j < N; ++j) s0y += m[j] * y[j];
    return ClosedFormCost(syy, s0y, ry, m[0], b[0], ambient, a_out, c_out);
  }
  double Cost(const double* y, double* a_out = nullptr, double* c_out = nullptr) const {
    if (n == 25) {
      double syy, s0y, ry;
      Forms25(m, y, b, &syy, &s0y, &ry);
      return ClosedFormCost(syy, s0y, ry, m[0], b[0], ambient, a_out, c_out);
    }
    if (n == 16) return CostFixed<16>(y, a_out, c_out);
    if (n == 9) return CostFixed<9>(y, a_out, c_out);
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
  double best_a = 0, best_c = 0;  // a and c at d while known (saves re-evaluating it at the end)
  double best = problem.CostAt(d, &best_a, &best_c);
  bool known = true;
  const size_t count = grid.directions.size();
  if (problem.tables && count <= kMaxGrid) {
    // M is the full-set matrix: b^T Y_k of every grid direction as one matrix-vector product,
    // then the closed form with the precomputed Y_k^T M Y_k and (M Y_k)_0.
    double costs[kMaxGrid];
    GridCosts(grid.basis_t, problem.b, problem.n, count, grid.syy, grid.s0y, problem.m[0],
              problem.b[0], problem.ambient, costs);
    for (size_t k = 0; k < count; ++k) {
      if (costs[k] < best) best = costs[k], d = grid.directions[k], known = false;
    }
  } else {
    for (size_t k = 0; k < count; ++k) {
      const double cost = problem.GridCost(grid, k);
      if (cost < best) best = cost, d = grid.directions[k], known = false;
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
      double a = 0, c = 0;
      const double cost = problem.CostAt(candidate, &a, &c);
      if (cost < f0) {
        d = candidate, best = cost, improved = true;
        best_a = a, best_c = c, known = true;
        break;
      }
      su *= 0.5, sv *= 0.5;
    }
    if (!improved || std::sqrt(su * su + sv * sv) < 1e-4) break;
  }
  if (power && known) {
    *power = best_a;
    if (ambient) *ambient = best_c;
  } else if (power) {
    problem.CostAt(d, power, ambient);
  }
  return d;
}

}  // namespace

// Least-recently-used entries, each the key (validity bits) and its MaskData; stamp 0 = empty.
// A hit is read in place (no copy): Acquire counts the reader, Release uncounts it, and Store
// only overwrites an entry without readers (so a reader's entry never changes under it).
struct FaceLightEstimator::MaskCache {
  struct Entry {
    uint64_t key[kMaskWords] = {};
    uint64_t stamp = 0;
    std::atomic<int> readers{0};
    MaskData data;
  };
  std::mutex mutex;
  std::unique_ptr<Entry[]> entries;
  int size = 0;
  uint64_t clock = 0;
  int dir_n = 0;
  size_t grid = 0;

  // The entry of key, counted as read until Release; null if absent or the cache is busy.
  Entry* Acquire(const uint64_t* key) {
    std::unique_lock lock(mutex, std::try_to_lock);
    if (!lock.owns_lock()) return nullptr;
    for (int k = 0; k < size; ++k) {
      Entry& entry = entries[k];
      if (entry.stamp == 0 || std::memcmp(entry.key, key, sizeof entry.key) != 0) continue;
      entry.stamp = ++clock;
      entry.readers.fetch_add(1);
      return &entry;
    }
    return nullptr;
  }
  static void Release(Entry* entry) {
    if (entry) entry->readers.fetch_sub(1);
  }
  // Stores data under key in the least recently used entry without readers (skipped if the cache
  // is busy or every entry is being read).
  void Store(const uint64_t* key, const MaskData& data) {
    std::unique_lock lock(mutex, std::try_to_lock);
    if (!lock.owns_lock()) return;
    Entry* oldest = nullptr;
    for (int k = 0; k < size; ++k) {
      Entry& entry = entries[k];
      if (entry.readers.load() == 0 && (!oldest || entry.stamp < oldest->stamp)) oldest = &entry;
    }
    if (!oldest) return;
    std::memcpy(oldest->key, key, sizeof oldest->key);
    oldest->stamp = ++clock;
    MaskData& out = oldest->data;
    out.factor = data.factor;
    out.factor_ok = data.factor_ok;
    out.corrected = data.corrected;
    out.normal = data.normal;
    out.correction = data.correction;
    out.dir_ready = data.dir_ready;
    if (data.dir_ready) {
      std::copy(data.dir_m, data.dir_m + dir_n * dir_n, out.dir_m);
      std::copy(data.syy, data.syy + grid, out.syy);
      std::copy(data.s0y, data.s0y + grid, out.s0y);
    }
  }
};

FaceLightEstimator::~FaceLightEstimator() = default;
FaceLightEstimator::FaceLightEstimator(FaceLightEstimator&&) noexcept = default;
FaceLightEstimator& FaceLightEstimator::operator=(FaceLightEstimator&&) noexcept = default;

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
      !(options.directional_robust >= 0) || options.mask_cache < 0 ||
      options.mask_cache > kMaxMaskCache) {
    throw FaceLightError(
        "FaceLightEstimator: options out of range (ridge, back_prior, weight_floor, "
        "direction_ridge, directional_robust >= 0; robust_iterations 1..20; robust_threshold > 0; "
        "nn_directions "
        "9..1024; nn_iterations 1..10000; directional_grid 0..1024; directional_iterations "
        "0..100; mask_cache 0..64)");
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
  wrtf_td_.assign(wrtf_t_.begin(), wrtf_t_.end());
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
  rtf_d_.resize(rtf_.size());
  wrtf_d_.resize(rtf_.size());
  for (size_t k = 0; k < rtf_.size(); ++k) {
    rtf_d_[k] = rtf_[k];
    wrtf_d_[k] = double(weights_[k / kN]) * double(rtf_[k]);
  }
  if (!dir_rtf_.empty()) {
    dir_rtf_d_.resize(dir_rtf_.size());
    dir_wrtf_d_.resize(dir_rtf_.size());
    for (size_t k = 0; k < dir_rtf_.size(); ++k) {
      dir_rtf_d_[k] = dir_rtf_[k];
      dir_wrtf_d_[k] = double(weights_[k / dir_n_]) * double(dir_rtf_[k]);
    }
    const size_t grid = dir_grid_.size();
    dir_grid_proj_.assign(static_cast<size_t>(n_samples) * grid, 0.0);
    for (int i = 0; i < n_samples; ++i) {
      const double* t = &dir_rtf_d_[static_cast<size_t>(i) * dir_n_];
      for (size_t k = 0; k < grid; ++k) {
        const double* y = &dir_grid_basis_[k * dir_n_];
        double sum = 0;
        for (int a = 0; a < dir_n_; ++a) sum += t[a] * y[a];
        dir_grid_proj_[i * grid + k] = sum;
      }
    }
  }
  if (options.mask_cache > 0) {
    cache_ = std::make_unique<MaskCache>();
    cache_->entries = std::make_unique<MaskCache::Entry[]>(options.mask_cache);
    cache_->size = options.mask_cache;
    cache_->dir_n = dir_n_;
    cache_->grid = dir_grid_.size();
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
  PrepareSamples(values, channels, n_samples, stride, exponent_, v, mean_value, valid);
  int valid_count = 0;
  if (!valid_bits.empty()) {
    for (int i = 0; i < n_samples; i += 8) {
      // 8 caller bits -> 8 bytes of 0 / 1 (bit k to byte k), ANDed into valid.
      const uint64_t bits8 = (valid_bits[i >> 6] >> (i & 63)) & 0xffu;
      uint64_t spread = (bits8 * 0x0101010101010101ull) & 0x8040201008040201ull;
      spread = ((spread + 0x7f7f7f7f7f7f7f7full) >> 7) & 0x0101010101010101ull;
      uint64_t chunk;
      std::memcpy(&chunk, valid + i, 8);
      chunk &= spread;
      std::memcpy(valid + i, &chunk, 8);
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
  const bool all_valid = valid_count == n_samples;
  // Validity as bits (the cache key) and the list of the inactive samples (valid = active here).
  uint64_t key[kMaskWords] = {};
  int inactive_index[kMaxSamples];
  int inactive = 0;
  if (!all_valid) {
    for (int i = 0; i < stride; i += 8) {  // 8 bytes of 0 / 1 -> 8 bits (byte k to bit k)
      uint64_t chunk;
      std::memcpy(&chunk, valid + i, 8);
      key[i >> 6] |= ((chunk * 0x0102040810204080ull) >> 56) << (i & 63);
    }
    for (int w = 0; w * 64 < n_samples; ++w) {
      const int left = n_samples - w * 64;
      uint64_t bits = ~key[w] & (left >= 64 ? ~uint64_t{0} : (uint64_t{1} << left) - 1);
      for (; bits != 0; bits &= bits - 1)
        inactive_index[inactive++] = w * 64 + std::countr_zero(bits);
    }
    // Zero the invalid values (garbage or NaN): T^T W v over the valid set is then a plain dot
    // product over all samples.
    for (int j = 0; j < inactive; ++j) {
      for (int c = 0; c < channels; ++c) v[c][inactive_index[j]] = 0;
      mean_value[inactive_index[j]] = 0;
    }
  }

  double e[3][kN] = {};
  std::array<double, 81> factor{};
  std::array<double, 81> factored{};  // the matrix build_factor factored
  double rhs[3][kN] = {};
  const auto collect_inactive = [&]() {  // after the active set changed (robust)
    inactive = 0;
    for (int i = 0; i < n_samples; ++i) {  // branch-free compaction
      inactive_index[inactive] = i;
      inactive += !active[i];
    }
  };
  // factor = L of the weighted normal matrix over the active set, T^T W T + R: the precomputed
  // full-set matrix downdated by the inactive samples (rebuilt if more than half are inactive).
  const auto build_factor = [&]() -> bool {
    if (2 * inactive < n_samples) {
      factor = normal_;
      RankUpdate(factor.data(), kN, wrtf_d_.data(), rtf_d_.data(), inactive_index, inactive, -1);
    } else {
      int active_index[kMaxSamples];
      int count = 0;
      for (int i = 0; i < n_samples; ++i) {
        active_index[count] = i;
        count += active[i];
      }
      factor = prior_;
      RankUpdate(factor.data(), kN, wrtf_d_.data(), rtf_d_.data(), active_index, count, 1);
    }
    factored = factor;
    return internal::Cholesky<9>(factor);
  };
  // rhs = T^T W v over the active samples: dot products (double accumulation) of the transposed
  // weighted RTFs with the intensities, inactive ones zeroed (already, unless mask).
  const auto build_rhs = [&](bool mask) {
    alignas(32) float masked[kMaxSamples + 8];
    for (int c = 0; c < channels; ++c) {
      const float* source = v[c];
      if (mask) {
        for (int i = 0; i < stride; ++i) masked[i] = i < n_samples && active[i] ? v[c][i] : 0.0f;
        source = masked;
      }
      DotDRows(wrtf_td_.data(), kN, source, stride, rhs[c]);
    }
  };
  const auto build = [&]() -> bool {
    collect_inactive();
    if (!build_factor()) return false;
    build_rhs(true);
    return true;
  };
  const auto solve = [&]() {
    for (int c = 0; c < channels; ++c) std::copy(rhs[c], rhs[c] + kN, e[c]);
    CholeskySolve9Multi(factor, e, channels);
  };

  const bool plain = !options_.robust && !options_.non_negative;
  const bool fast = all_valid && plain;
  // Plain solve with invalid samples: per-mask data, a cache entry read in place (released on
  // return) or computed here (and stored).
  MaskData computed;
  const MaskData* mask = &computed;
  MaskCache::Entry* hit = nullptr;
  struct ReleaseOnReturn {
    MaskCache::Entry*& entry;
    ~ReleaseOnReturn() { MaskCache::Release(entry); }
  } release{hit};
  if (fast) {
    // E = pinv v: precomputed pseudo-inverse of the full valid set (eq. 19).
    for (int c = 0; c < channels; ++c) Dot8Rows(pinv_.data(), kN, v[c], stride, e[c]);
  } else if (plain) {
    // Everything that depends on the validity mask only: from the cache, or computed (and
    // stored). The values are bit-identical either way.
    hit = cache_ ? cache_->Acquire(key) : nullptr;
    if (hit) {
      mask = &hit->data;
    } else {
      computed.factor_ok = build_factor();
      computed.factor = factor;
      computed.corrected = false;
      if (computed.factor_ok && !options_.exact_masked_solve) {
        // C = N_valid^-1 N_full, column by column: e_valid = N_valid^-1 T^T W v_zeroed
        // = C (N_full^-1 T^T W v_zeroed) = C pinv v_zeroed. Its error is the float error of
        // pinv v times |C|: used while |C|_inf <= kMaxCorrectionNorm.
        for (int k = 0; k < kN; k += 3) {  // three columns at a time
          double columns[3][kN];
          for (int q = 0; q < 3; ++q) {
            for (int a = 0; a < kN; ++a) columns[q][a] = normal_[a * kN + k + q];
          }
          CholeskySolve9Multi(factor, columns, 3);
          for (int q = 0; q < 3; ++q) {
            for (int a = 0; a < kN; ++a) computed.correction[a * kN + k + q] = columns[q][a];
          }
        }
        double norm = 0;
        for (int a = 0; a < kN; ++a) {
          double row = 0;
          for (int k = 0; k < kN; ++k) row += std::abs(computed.correction[a * kN + k]);
          norm = std::max(norm, row);
        }
        computed.corrected = norm <= kMaxCorrectionNorm;
        computed.normal = factored;
      }
      computed.dir_ready = false;
      if (computed.factor_ok && options_.directional_fit && !dir_rtf_.empty()) {
        const int dn = dir_n_;
        std::copy(dir_normal_.begin(), dir_normal_.end(), computed.dir_m);
        RankUpdate(computed.dir_m, dn, dir_wrtf_d_.data(), dir_rtf_d_.data(), inactive_index,
                   inactive, -1);
        GridDowndate(dir_grid_syy_.data(), dir_grid_s0y_.data(), dir_grid_proj_.data(),
                     dir_grid_.size(), weights_.data(), dir_wrtf_d_.data(), dn, inactive_index,
                     inactive, computed.syy, computed.s0y);
        computed.dir_ready = true;
      }
      if (cache_) cache_->Store(key, computed);
    }
    if (!mask->factor_ok) return out;
    factor = mask->factor;
    if (mask->corrected) {
      for (int c = 0; c < channels; ++c) {
        double full[kN];  // invalid values zeroed above
        Dot8Rows(pinv_.data(), kN, v[c], stride, full);
        for (int a = 0; a < kN; ++a) {
          const double* row = &mask->correction[a * kN];
          double sum = 0;
          for (int k = 0; k < kN; ++k) sum += row[k] * full[k];
          e[c][a] = sum;
        }
      }
    } else {
      build_rhs(false);
      solve();
    }
  } else {
    if (!build()) return out;
    solve();
  }

  const MaskData& mask_data = *mask;
  // The light came from a float pseudo-inverse (not from rhs): this is its normal matrix
  // (T^T W T + R over the active samples), else null.
  const double* pinv_normal = fast                  ? normal_.data()
                              : mask_data.corrected ? mask_data.normal.data()
                                                    : nullptr;
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
      if (pinv_normal) {
        std::copy(pinv_normal, pinv_normal + kN * kN, m);
        for (int a = 0; a < kN; ++a) {
          double sum = 0;
          for (int k = 0; k < kN; ++k) {
            double mean_e = 0;
            for (int c = 0; c < channels; ++c) mean_e += e[c][k];
            sum += pinv_normal[a * kN + k] * mean_e / channels;
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
      // RTFs); M = the full-set matrix downdated by the inactive samples (per mask, cached).
      const double* full = all_active            ? dir_normal_.data()
                           : mask_data.dir_ready ? mask_data.dir_m
                                                 : nullptr;
      if (full && !(options_.directional_robust > 0)) {
        cost_matrix = full;  // used as it is
      } else if (full) {
        std::copy(full, full + dn * dn, m);
      } else {
        std::copy(dir_normal_.begin(), dir_normal_.end(), m);
        collect_inactive();
        RankUpdate(m, dn, dir_wrtf_d_.data(), dir_rtf_d_.data(), inactive_index, inactive, -1);
      }
      const float* source = mean_value;  // invalid samples zeroed
      alignas(32) float masked[kMaxSamples + 8];
      if (!all_active && options_.robust) {
        for (int i = 0; i < stride; ++i) masked[i] = i < n_samples && active[i] ? mean_value[i] : 0;
        source = masked;
      }
      Dot8Rows(dir_wrtf_t_.data(), dn, source, stride, b);
    }
    // With every sample active M is the full-set matrix: the grids' quadratic terms are
    // precomputed.
    // With a downdated M of the cached kind, the mask data holds them.
    const bool mask_tables = !all_active && mask_data.dir_ready && !dir_rtf_.empty();
    const DirectionalProblem problem{cost_matrix,
                                     b,
                                     dir_bands_,
                                     dn,
                                     options_.directional_ambient,
                                     &Constants(),
                                     all_active || mask_tables};
    const DirectionGrid grid{dir_grid_, dir_grid_basis_.data(), dir_grid_basis_t_.data(),
                             mask_tables ? mask_data.syy : dir_grid_syy_.data(),
                             mask_tables ? mask_data.s0y : dir_grid_s0y_.data()};
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
        double partial[4] = {};  // independent chains (a single sum is latency bound)
        int a = 0;
        for (; a + 4 <= dn; a += 4) {
          for (int l = 0; l < 4; ++l) partial[l] += t[a + l] * light[a + l];
        }
        double predicted = (partial[0] + partial[1]) + (partial[2] + partial[3]);
        for (; a < dn; ++a) predicted += t[a] * light[a];
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
    // The channel mean in double (the float mean_value would not match the exact r = T^T v to
    // the precision this difference needs; the fast path's pseudo-inverse is float anyway);
    // invalid and padding values are zero.
    double lane_sum[4] = {}, lane_sq[4] = {};  // independent lanes: the loop vectorises
    const double inv_channels = 1.0 / channels;
    for (int i = 0; i < stride; i += 4) {
      for (int l = 0; l < 4; ++l) {
        const double x =
            pinv_normal ? double(mean_value[i + l])
            : channels == 3
                ? (double(v[0][i + l]) + double(v[1][i + l]) + double(v[2][i + l])) * inv_channels
                : double(v[0][i + l]);
        lane_sum[l] += x;
        lane_sq[l] += x * x;
      }
    }
    const double sum = (lane_sum[0] + lane_sum[1]) + (lane_sum[2] + lane_sum[3]);
    const double sum_sq = (lane_sq[0] + lane_sq[1]) + (lane_sq[2] + lane_sq[3]);
    double quadratic = 0;
    for (int a = 0; a < kN; ++a) {
      double r = 0, re = 0;
      if (pinv_normal) {
        for (int k = 0; k < kN; ++k) r += pinv_normal[a * kN + k] * mean_light[k];
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
  out.units = msgs::ShLightUnits::kFaceModel;
}

}  // namespace probeless::face_light
