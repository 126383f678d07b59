#include "probeless/recon/depth_merge.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <utility>
#include <vector>

#ifdef __AVX__
#include <immintrin.h>
#endif

namespace probeless::recon {

namespace {
constexpr int kTasks = 16;

struct Window {
  int half;
  int stride;
};
Window WindowFor(int k) {
  const int half = k / 2;
  if (half <= 2) return {half, 1};
  const int stride = std::max(1, half / 2);
  return {2 * stride, stride};
}

// The floor((n-1)/2)-th smallest of v[0..n).
float LowerMedian(float* v, int n) {
  // Insertion sort: n <= 25 here.
  for (int i = 1; i < n; ++i) {
    const float x = v[i];
    int j = i - 1;
    while (j >= 0 && v[j] > x) {
      v[j + 1] = v[j];
      --j;
    }
    v[j + 1] = x;
  }
  return v[(n - 1) / 2];
}

// Batcher's odd-even merge sort network for `n` (a power of two) elements.
std::vector<std::pair<int, int>> BatcherNetwork(int n) {
  std::vector<std::pair<int, int>> pairs;
  for (int p = 1; p < n; p <<= 1)
    for (int k = p; k >= 1; k >>= 1)
      for (int j = k % p; j + k < n; j += 2 * k)
        for (int i = 0; i < std::min(k, n - j - k); ++i)
          if ((i + j) / (2 * p) == (i + j + k) / (2 * p)) pairs.emplace_back(i + j, i + j + k);
  return pairs;
}

// Lower medians of kLanes pixels at once: each lane's n valid samples are padded with -inf/+inf
// so that the network's fixed middle slot holds the floor((n-1)/2)-th smallest sample; the
// min/max compare-exchanges run over the lanes (vectorised). slots = 16 takes <= 9 samples,
// slots = 32 <= 25.
constexpr int kLanes = 8;
typedef float Lanes __attribute__((vector_size(kLanes * sizeof(float))));
class LaneMedian {
 public:
  // slots: 16 or 32.
  explicit LaneMedian(int slots)
      : slots_(slots), middle_(slots / 2 - 1), pairs_(Network(slots)), v_(slots) {}
  void Set(int lane, int slot, float value) { v_[slot][lane] = value; }
  // Pads lane `lane` holding n >= 1 samples.
  void Pad(int lane, int n) {
    const int lo = middle_ - (n - 1) / 2;
    int s = n;
    for (int i = 0; i < lo; ++i) v_[s++][lane] = -1e30f;
    while (s < slots_) v_[s++][lane] = 1e30f;
  }
  void Sort() {
    Lanes* v = v_.data();
    for (const auto& [a, b] : pairs_) {
      const Lanes x = v[a], y = v[b];
      const auto less = x < y;
      v[a] = less ? x : y;
      v[b] = less ? y : x;
    }
  }
  float Median(int lane) const { return v_[middle_][lane]; }

 private:
  // The compare-exchanges the middle slot depends on (walking the network backwards), built
  // once per slot count.
  static std::vector<std::pair<int, int>> Pruned(int slots) {
    const int middle = slots / 2 - 1;
    const std::vector<std::pair<int, int>> all = BatcherNetwork(slots);
    std::vector<bool> needed(slots, false);
    needed[middle] = true;
    std::vector<std::pair<int, int>> pairs;
    for (auto it = all.rbegin(); it != all.rend(); ++it) {
      if (needed[it->first] || needed[it->second]) {
        needed[it->first] = needed[it->second] = true;
        pairs.push_back(*it);
      }
    }
    std::reverse(pairs.begin(), pairs.end());
    return pairs;
  }
  static const std::vector<std::pair<int, int>>& Network(int slots) {
    static const std::vector<std::pair<int, int>> k16 = Pruned(16), k32 = Pruned(32);
    return slots == 16 ? k16 : k32;
  }

  int slots_;
  int middle_;
  const std::vector<std::pair<int, int>>& pairs_;
  std::vector<Lanes> v_;
};

// 8 pixels of one row at once (GCC vector extensions; AVX2 when enabled): every window sample
// goes to a fixed slot, missing or excluded samples become +inf or -inf so that each lane's lower
// median lands in the middle slot, which a selection network computes (see MedianBatch).
typedef float F8 __attribute__((vector_size(32)));
typedef int I8 __attribute__((vector_size(32)));

inline F8 LoadF8(const float* p) {
  F8 v;
  std::memcpy(&v, p, sizeof(v));
  return v;
}
typedef uint8_t B8 __attribute__((vector_size(8)));
inline I8 LoadU8(const uint8_t* p) {
#ifdef __AVX2__
  // One 8-byte load widened by vpmovzxbd (GCC builds the generic conversion below from scalar
  // byte extractions).
  return reinterpret_cast<I8>(
      _mm256_cvtepu8_epi32(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(p))));
#else
  B8 v;
  std::memcpy(&v, p, sizeof(v));
  return __builtin_convertvector(v, I8);
#endif
}

// A selection network for the middle slot (samples - 1) / 2 of `samples` (odd, <= 32) values,
// built at compile time: Batcher's network for the next power of two without the
// compare-exchanges that touch slots >= samples (those would hold +inf and never move), then
// only the compare-exchanges the middle slot depends on (walking the network backwards).
struct StaticNetwork {
  std::array<std::pair<int, int>, 256> pairs{};
  int size = 0;
};
constexpr StaticNetwork MakeMiddleNetwork(int samples) {
  int n = 1;
  while (n < samples) n <<= 1;
  std::array<std::pair<int, int>, 256> all{};
  int count = 0;
  for (int p = 1; p < n; p <<= 1)
    for (int k = p; k >= 1; k >>= 1)
      for (int j = k % p; j + k < n; j += 2 * k)
        for (int i = 0; i < std::min(k, n - j - k); ++i)
          if ((i + j) / (2 * p) == (i + j + k) / (2 * p) && i + j + k < samples) {
            all[count++] = {i + j, i + j + k};
          }
  bool needed[32] = {};
  needed[(samples - 1) / 2] = true;
  std::array<std::pair<int, int>, 256> backwards{};
  int kept = 0;
  for (int c = count - 1; c >= 0; --c) {
    if (needed[all[c].first] || needed[all[c].second]) {
      needed[all[c].first] = needed[all[c].second] = true;
      backwards[kept++] = all[c];
    }
  }
  StaticNetwork out;
  for (int c = 0; c < kept; ++c) out.pairs[c] = backwards[kept - 1 - c];
  out.size = kept;
  return out;
}
template <int Samples>
inline constexpr StaticNetwork kMiddleNetwork = MakeMiddleNetwork(Samples);

// The network fully unrolled, so the slots stay in registers as far as possible.
template <int Samples, size_t... I>
inline void RunMiddleNetwork([[maybe_unused]] F8* slots, std::index_sequence<I...>) {
  [[maybe_unused]] auto exchange = [](F8& a, F8& b) {
#ifdef __AVX__
    // vminps(a, b) = a < b ? a : b and vmaxps(b, a) = b > a ? b : a exactly (no NaNs here).
    const F8 lo = _mm256_min_ps(a, b);
    const F8 hi = _mm256_max_ps(b, a);
#else
    const F8 lo = a < b ? a : b;
    const F8 hi = b > a ? b : a;
#endif
    a = lo;
    b = hi;
  };
  (exchange(slots[kMiddleNetwork<Samples>.pairs[I].first],
            slots[kMiddleNetwork<Samples>.pairs[I].second]),
   ...);
}

// Every slot is written by the window loops (Samples = the window's sample count), which GCC
// cannot see through the runtime window size.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
// Medians over the window `win` (Samples = its sample count, odd) of `depth` at pixels
// x0..x0+7 of row y, with the joint intensity test |I(p) - I(q)| < lambda_i when `intensity` is
// not null, restricted to the samples of the centre's depth cluster when `depth_gate` (see
// GateSamples). Needs x0 - win.half >= 0 and x0 + 7 + win.half < width. The lower median of a
// lane's n valid samples is moved to the fixed middle slot m = (Samples - 1) / 2 by turning the
// first m - floor((n - 1) / 2) missing samples into -inf and the rest into +inf (n + that <=
// Samples for an odd count), so one selection network serves every n and the result is read without
// a per-lane index.
template <int Samples, bool Gate>
void MedianBatch(const DepthImage& depth, const GreyImage* intensity, float lambda_i,
                 const DepthImage* depth_gate, float lambda_d, const Window& win, int x0, int y,
                 float* out) {
  F8 slots[Samples];
  I8 count = {};
  const F8 centre = LoadF8(&depth.At(x0, y));
  F8 lowest = centre, highest = centre;  // span of the valid samples and the centre
  const F8 ld = F8{} + lambda_d;
  const F8 inf = F8{} + 1e30f;
  const F8 zero = {};
  const F8 li = F8{} + lambda_i;
  I8 ip = {};
  if (intensity) ip = LoadU8(&intensity->At(x0, y));
  int s = 0;
  for (int dy = -win.half; dy <= win.half; dy += win.stride) {
    const int yy = y + dy;
    if (yy < 0 || yy >= depth.height) {
      for (int dx = -win.half; dx <= win.half; dx += win.stride) slots[s++] = inf;
      continue;
    }
    const float* drow = &depth.At(0, yy);
    const uint8_t* irow = intensity ? &intensity->At(0, yy) : nullptr;
    for (int dx = -win.half; dx <= win.half; dx += win.stride) {
      const F8 d = LoadF8(drow + x0 + dx);
      I8 valid = d > zero;
      if (intensity) {
        I8 diff = ip - LoadU8(irow + x0 + dx);
        diff = diff < 0 ? -diff : diff;
        valid &= __builtin_convertvector(diff, F8) < li;
      }
      slots[s] = valid ? d : inf;
      if constexpr (Gate) {
        lowest = slots[s] < lowest ? slots[s] : lowest;
        highest = (valid & (d > highest)) ? d : highest;
      }
      ++s;
      count -= valid;
    }
  }
  if constexpr (Gate) {
    // Only lanes with a measured depth (depth_gate > 0) whose samples span about lambda_d or more
    // can lose samples to the gate (a narrower span is one cluster; 0.99 keeps rounding out of
    // it); skip the gate when there are none.
    const F8 measured = LoadF8(&depth_gate->At(x0, y));
    const I8 may_split =
        (measured > zero) & (centre > zero) & (highest - lowest >= F8{} + 0.99f * lambda_d);
    bool any_split = false;
    for (int l = 0; l < kLanes; ++l) any_split |= may_split[l] != 0;
    if (any_split) {
      // The centre's cluster [lo, hi], grown by every sample closer than lambda_d to it until none
      // is (as GateSamples; missing samples are +inf and never join).
      F8 lo = centre, hi = centre;
      for (int iteration = 0; iteration <= Samples; ++iteration) {
        // One growth step for every sample at once (Jacobi): the lowest sample above lo - ld and
        // the highest below hi + ld, over 4 independent accumulators (min / max are exact).
        const F8 reach_lo = lo - ld, reach_hi = hi + ld, minus_inf = F8{} - 1e30f;
        F8 new_lo[4] = {lo, lo, lo, lo}, new_hi[4] = {hi, hi, hi, hi};
        for (int i = 0; i < Samples; ++i) {
          const F8 v = slots[i];
          const F8 above = v > reach_lo ? v : inf, below = v < reach_hi ? v : minus_inf;
          new_lo[i & 3] = above < new_lo[i & 3] ? above : new_lo[i & 3];
          new_hi[i & 3] = below > new_hi[i & 3] ? below : new_hi[i & 3];
        }
        F8 grown_lo = new_lo[0], grown_hi = new_hi[0];
        for (int a = 1; a < 4; ++a) {
          grown_lo = new_lo[a] < grown_lo ? new_lo[a] : grown_lo;
          grown_hi = new_hi[a] > grown_hi ? new_hi[a] : grown_hi;
        }
        const I8 changed = (grown_lo != lo) | (grown_hi != hi);
        lo = grown_lo;
        hi = grown_hi;
        bool any = false;
        for (int l = 0; l < kLanes; ++l) any |= changed[l] != 0;
        if (!any) break;
      }
      I8 in_cluster[Samples];
      I8 count_cluster = {};
      for (int i = 0; i < Samples; ++i) {
        in_cluster[i] = (slots[i] >= lo) & (slots[i] <= hi);
        count_cluster -= in_cluster[i];
      }
      // Lanes with a valid centre whose cluster holds >= 1/4 of the samples drop the rest.
      const I8 gate = may_split & (4 * count_cluster >= count);
      for (int i = 0; i < Samples; ++i) slots[i] = (gate & ~in_cluster[i]) ? inf : slots[i];
      count = gate ? count_cluster : count;
    }
  }
  constexpr int kMiddle = (Samples - 1) / 2;
  I8 low = kMiddle - ((count - 1) >> 1);  // missing samples still to turn into -inf
  const F8 minus_inf = F8{} - 1e30f;
  for (int i = 0; i < Samples; ++i) {
    const I8 take = (slots[i] == inf) & (low > 0);
    slots[i] = take ? minus_inf : slots[i];
    low += take;  // take is -1 where taken
  }
  RunMiddleNetwork<Samples>(slots, std::make_index_sequence<kMiddleNetwork<Samples>.size>{});
  const F8 result = count > 0 ? slots[kMiddle] : zero;
  std::memcpy(out, &result, sizeof(result));
}

// MedianBatch for the window's sample count (1, 9 or 25: windows are 1x1, 3x3 or 5x5 samples).
void MedianBatchFor(const DepthImage& depth, const GreyImage* intensity, float lambda_i,
                    const DepthImage* depth_gate, float lambda_d, const Window& win, int x0, int y,
                    float* out) {
  const int per_side = (2 * win.half) / win.stride + 1;
  switch (per_side) {
    case 1:
      if (depth_gate) {
        MedianBatch<1, true>(depth, intensity, lambda_i, depth_gate, lambda_d, win, x0, y, out);
      } else {
        MedianBatch<1, false>(depth, intensity, lambda_i, nullptr, lambda_d, win, x0, y, out);
      }
      break;
    case 3:
      if (depth_gate) {
        MedianBatch<9, true>(depth, intensity, lambda_i, depth_gate, lambda_d, win, x0, y, out);
      } else {
        MedianBatch<9, false>(depth, intensity, lambda_i, nullptr, lambda_d, win, x0, y, out);
      }
      break;
    default:
      if (depth_gate) {
        MedianBatch<25, true>(depth, intensity, lambda_i, depth_gate, lambda_d, win, x0, y, out);
      } else {
        MedianBatch<25, false>(depth, intensity, lambda_i, nullptr, lambda_d, win, x0, y, out);
      }
      break;
  }
}

// The depth gate of the D'' / D''' medians for one pixel (the scalar form, for border pixels):
// `samples` holds the n window samples that passed the intensity test, `centre` is D(p). The
// centre's depth cluster is the interval [lo, hi] grown from the centre by every sample closer
// than lambda_d to it, i.e. the samples linked to the centre by depth steps < lambda_d (a depth
// discontinuity is a gap >= lambda_d; noise, however large, leaves no such gap in a dense
// window). When the centre is valid and its cluster holds at least a quarter of the samples,
// only those are kept; otherwise all n (an isolated outlier is voted out as in the paper's
// eq. 4 / 5). Returns the new count.
int GateSamples(float* samples, int n, float centre, float lambda_d) {
  if (!(centre > 0)) return n;
  float lo = centre, hi = centre;
  for (bool grown = true; grown;) {
    grown = false;
    for (int i = 0; i < n; ++i) {
      const float v = samples[i];
      if (v > lo - lambda_d && v < hi + lambda_d && (v < lo || v > hi)) {
        lo = std::min(lo, v);
        hi = std::max(hi, v);
        grown = true;
      }
    }
  }
  int in_cluster = 0;
  for (int i = 0; i < n; ++i) in_cluster += samples[i] >= lo && samples[i] <= hi;
  if (4 * in_cluster < n) return n;
  int m = 0;
  for (int i = 0; i < n; ++i) {
    if (samples[i] >= lo && samples[i] <= hi) samples[m++] = samples[i];
  }
  return m;
}

// AgreementThreshold (eq. 2 / 3 deviation) of 8 depths at once: the same float operations in
// the same order as the scalar function, so the results are bit-identical.
struct NoiseLanes {
  F8 a, b, z0, q, k, ld;
  bool quantisation;
  explicit NoiseLanes(const MergeOptions& o)
      : a(F8{} + o.noise_a_m),
        b(F8{} + o.noise_b_per_m),
        z0(F8{} + o.noise_z0_m),
        q(F8{} + o.noise_quantisation_per_m),
        k(F8{} + o.lambda_d_sigmas),
        ld(F8{} + o.lambda_d_m),
        quantisation(o.noise_quantisation_per_m > 0) {}
  F8 Threshold(F8 z) const {
    const F8 dz = z - z0;
    F8 sigma = a + b * dz * dz;
    if (quantisation) {
      const F8 step = q * z * z;
      const F8 variance = sigma * sigma + step * step * (F8{} + 1.0f / 12.0f);
#ifdef __AVX__
      sigma = _mm256_sqrt_ps(variance);
#else
      for (int l = 0; l < kLanes; ++l) sigma[l] = std::sqrt(variance[l]);
#endif
    }
    const F8 scaled = k * sigma;
    const F8 capped = scaled < ld ? scaled : ld;  // std::min(ld, scaled)
    return z > F8{} ? capped : ld;
  }
};

// D' (eq. 1-3) at pixels x0..x0+7 of row y (same conditions on x0 as MedianBatch; Samples = the
// window's sample count). The window's medians are only computed when a lane is a hole (its
// Omega counts also when volume_majority and a lane's D_c agrees with D_v). Noise: the agreement
// threshold of eq. 2 / 3 is `agreement`(p) = AgreementThreshold(D_c(p)) per pixel
// (lambda_d_sigmas > 0) instead of lambda_d.
template <int Samples, bool Noise>
F8 MergeBatch(const DepthImage& raw, const DepthImage& volume, const GreyImage& intensity,
              const DepthImage* agreement, float lambda_i, float lambda_d, bool volume_majority,
              const Window& win, int x0, int y) {
  const F8 zero = {};
  const F8 ld_fixed = F8{} + lambda_d;
  const F8 dc = LoadF8(&raw.At(x0, y)), dv = LoadF8(&volume.At(x0, y));
  F8 ld = ld_fixed;
  if constexpr (Noise) ld = LoadF8(&agreement->At(x0, y));
  const I8 dc_valid = dc > zero, dv_valid = dv > zero;
  const F8 diff = dc - dv;
  const I8 agrees = dv_valid & (diff <= ld) & (-diff <= ld);
  F8 valid_result = agrees ? dv : dc;
  bool any_hole = false, any_agrees = false;
  for (int l = 0; l < 8; ++l) {
    any_hole |= dc_valid[l] == 0;
    any_agrees |= (dc_valid & agrees)[l] != 0;
  }
  if (!any_hole && !(volume_majority && any_agrees)) return valid_result;
  F8 slots[Samples];
  I8 n_i = {}, n_d = {};
  const F8 inf = F8{} + 1e30f;
  const F8 li = F8{} + lambda_i;
  const I8 ip = LoadU8(&intensity.At(x0, y));
  int s = 0;
  for (int dy = -win.half; dy <= win.half; dy += win.stride) {
    const int yy = y + dy;
    if (yy < 0 || yy >= raw.height) {
      for (int dx = -win.half; dx <= win.half; dx += win.stride) slots[s++] = inf;
      continue;
    }
    const float* drow = &raw.At(0, yy);
    const float* vrow = &volume.At(0, yy);
    const uint8_t* irow = &intensity.At(0, yy);
    [[maybe_unused]] const float* arow = Noise ? &agreement->At(0, yy) : nullptr;
    for (int dx = -win.half; dx <= win.half; dx += win.stride) {
      const F8 d = LoadF8(drow + x0 + dx), v = LoadF8(vrow + x0 + dx);
      I8 idiff = ip - LoadU8(irow + x0 + dx);
      idiff = idiff < 0 ? -idiff : idiff;
      const I8 in_i = (d > zero) & (__builtin_convertvector(idiff, F8) < li);  // eq. 1
      const F8 dd = d - v;
      F8 lq = ld_fixed;
      if constexpr (Noise) lq = LoadF8(arow + x0 + dx);
      n_d -= in_i & (v > zero) & (dd < lq) & (-dd < lq);  // eq. 2
      slots[s++] = in_i ? d : inf;
      n_i -= in_i;
    }
  }
  // With volume_majority, D_v replaces a valid D_c only where Omega_D is a majority of Omega_I.
  if (volume_majority) valid_result = (agrees & (2 * n_d >= n_i)) ? dv : dc;
  if (!any_hole) return valid_result;
  constexpr int kMiddle = (Samples - 1) / 2;
  I8 low = kMiddle - ((n_i - 1) >> 1);  // as in MedianBatch
  const F8 minus_inf = F8{} - 1e30f;
  for (int i = 0; i < Samples; ++i) {
    const I8 take = (slots[i] == inf) & (low > 0);
    slots[i] = take ? minus_inf : slots[i];
    low += take;
  }
  RunMiddleNetwork<Samples>(slots, std::make_index_sequence<kMiddleNetwork<Samples>.size>{});
  const F8 hole_result = n_i == 0 ? zero : ((dv_valid & (2 * n_d >= n_i)) ? dv : slots[kMiddle]);
  return dc_valid ? valid_result : hole_result;
}

#pragma GCC diagnostic pop

template <class Fn>
void ForRows(ThreadPool* pool, int height, Fn fn) {
  ParallelFor(pool, kTasks, [&](int task) {
    for (int y = height * task / kTasks; y < height * (task + 1) / kTasks; ++y) fn(y);
  });
}
}  // namespace

void MergeOptions::Validate() const {
  if (merge_k < 1 || smooth_k < 1 || denoise_k < 1) {
    throw ReconError("merge: window sizes k must be >= 1");
  }
  if (!(merge_lambda_i >= 0) || !(smooth_lambda_i >= 0) || !(lambda_d_m >= 0) ||
      !(lambda_d_sigmas >= 0)) {
    throw ReconError("merge: thresholds must be >= 0");
  }
  if (!(noise_a_m >= 0) || !(noise_b_per_m >= 0) || !std::isfinite(noise_z0_m) ||
      !(noise_quantisation_per_m >= 0) || !(noise_a_m + noise_quantisation_per_m > 0)) {
    throw ReconError(
        "merge: noise model needs noise_a_m, noise_b_per_m, noise_quantisation_per_m >= 0 and "
        "noise_a_m or noise_quantisation_per_m > 0");
  }
}

float DepthNoiseSigma(float z, const MergeOptions& options) {
  const float dz = z - options.noise_z0_m;
  const float axial = options.noise_a_m + options.noise_b_per_m * dz * dz;  // Nguyen et al. 2012
  if (!(options.noise_quantisation_per_m > 0)) return axial;
  const float step = options.noise_quantisation_per_m * z * z;
  return std::sqrt(axial * axial + step * step * (1.0f / 12.0f));
}

float AgreementThreshold(float z, const MergeOptions& options) {
  if (!(options.lambda_d_sigmas > 0) || !(z > 0)) return options.lambda_d_m;
  return std::min(options.lambda_d_m, options.lambda_d_sigmas * DepthNoiseSigma(z, options));
}

void GreyFromRgb(const uint8_t* rgb, int width, int height, size_t stride, GreyImage& out) {
  out.Resize(width, height);
  for (int y = 0; y < height; ++y) {
    const uint8_t* row = rgb + y * stride;
    for (int x = 0; x < width; ++x) {
      out.At(x, y) =
          static_cast<uint8_t>((77 * row[3 * x] + 150 * row[3 * x + 1] + 29 * row[3 * x + 2]) >> 8);
    }
  }
}

void MergeDepth(const DepthImage& raw, const DepthImage& volume, const GreyImage& intensity,
                const MergeOptions& options, MergedDepth& out, ThreadPool* pool) {
  options.Validate();
  if (raw.Empty()) throw ReconError("merge: empty raw depth");
  if (volume.width != raw.width || volume.height != raw.height || intensity.width != raw.width ||
      intensity.height != raw.height) {
    throw ReconError("merge: raw depth " + std::to_string(raw.width) + "x" +
                     std::to_string(raw.height) + ", volume depth " + std::to_string(volume.width) +
                     "x" + std::to_string(volume.height) + " and intensity " +
                     std::to_string(intensity.width) + "x" + std::to_string(intensity.height) +
                     " must have the same size");
  }
  const int w = raw.width, h = raw.height;
  out.merged.Resize(w, h);
  out.smoothed.Resize(w, h);
  out.denoised.Resize(w, h);
  const float ld = options.lambda_d_m;

  // The noise-scaled agreement threshold of eq. 2 / 3 per pixel (deviation, lambda_d_sigmas > 0),
  // 8 pixels at a time.
  const bool noise_scaled = options.lambda_d_sigmas > 0;
  const DepthImage* agreement = nullptr;
  if (noise_scaled) {
    const NoiseLanes noise(options);
    out.agreement.Resize(w, h);
    ForRows(pool, h, [&](int y) {
      const float* z = &raw.At(0, y);
      float* a = &out.agreement.At(0, y);
      int x = 0;
      for (; x + kLanes <= w; x += kLanes) {
        const F8 t = noise.Threshold(LoadF8(z + x));
        std::memcpy(a + x, &t, sizeof(t));
      }
      for (; x < w; ++x) a[x] = AgreementThreshold(z[x], options);
    });
    agreement = &out.agreement;
  } else {
    out.agreement.Resize(0, 0);
  }

  // D' (eq. 1-3).
  {
    const Window win = WindowFor(options.merge_k);
    const float li = options.merge_lambda_i;
    const bool majority = options.volume_needs_majority;
    const int per_side = (2 * win.half) / win.stride + 1;
    ForRows(pool, h, [&](int y) {
      float samples[121];
      for (int x = 0; x < w; ++x) {
        if (x % kLanes == 0 && x - win.half >= 0 && x + kLanes - 1 + win.half < w) {
          // 8 interior pixels at once (bit-identical to the scalar equations below).
          F8 r;
          const auto batch = [&]<int Samples>() {
            return noise_scaled ? MergeBatch<Samples, true>(raw, volume, intensity, agreement, li,
                                                            ld, majority, win, x, y)
                                : MergeBatch<Samples, false>(raw, volume, intensity, nullptr, li,
                                                             ld, majority, win, x, y);
          };
          if (per_side == 5) {
            r = batch.template operator()<25>();
          } else if (per_side == 3) {
            r = batch.template operator()<9>();
          } else {
            r = batch.template operator()<1>();
          }
          std::memcpy(&out.merged.At(x, y), &r, sizeof(r));
          x += kLanes - 1;
          continue;
        }
        const float dc = raw.At(x, y), dv = volume.At(x, y);
        float result;
        const float ldp = noise_scaled ? agreement->At(x, y) : ld;
        const bool agrees = dv > 0 && std::fabs(dc - dv) <= ldp;
        if (dc > 0 && !(agrees && majority)) {
          result = agrees ? dv : dc;
        } else {
          const int ip = intensity.At(x, y);
          int n_i = 0, n_d = 0;
          for (int dy = -win.half; dy <= win.half; dy += win.stride) {
            const int yy = y + dy;
            if (yy < 0 || yy >= h) continue;
            for (int dx = -win.half; dx <= win.half; dx += win.stride) {
              const int xx = x + dx;
              if (xx < 0 || xx >= w) continue;
              const float dq = raw.At(xx, yy);
              if (dq <= 0) continue;                                      // Omega_k
              if (!(std::abs(ip - intensity.At(xx, yy)) < li)) continue;  // eq. 1
              samples[n_i++] = dq;
              const float vq = volume.At(xx, yy);
              const float lq = noise_scaled ? agreement->At(xx, yy) : ld;
              if (vq > 0 && std::fabs(dq - vq) < lq) ++n_d;  // eq. 2
            }
          }
          if (dc > 0) {
            result = 2 * n_d >= n_i ? dv : dc;  // volume_majority: D_v needs the majority
          } else if (n_i == 0) {
            result = 0;
          } else if (dv > 0 && 2 * n_d >= n_i) {
            result = dv;
          } else {
            result = LowerMedian(samples, n_i);
          }
        }
        out.merged.At(x, y) = result;
      }
    });
  }
  // D'' (eq. 4): joint bilateral median over Omega_I on D', subsampled to 5 x 5 (<= 25 samples);
  // with depth_gated_medians only over the depth-consistent part of Omega_I (GateSamples).
  {
    const Window win = WindowFor(options.smooth_k);
    const float li = options.smooth_lambda_i;
    const DepthImage* gate = options.depth_gated_medians ? &raw : nullptr;
    ForRows(pool, h, [&](int y) {
      LaneMedian median(32);
      int counts[kLanes];
      float samples[25];
      for (int x0 = 0; x0 < w; x0 += kLanes) {
        const int lanes = std::min(kLanes, w - x0);
        if (x0 - win.half >= 0 && x0 + kLanes - 1 + win.half < w) {
          MedianBatchFor(out.merged, &intensity, li, gate, ld, win, x0, y, &out.smoothed.At(x0, y));
          continue;
        }
        for (int lane = 0; lane < kLanes; ++lane) {
          int n = 0;
          if (lane < lanes) {
            const int x = x0 + lane;
            const int ip = intensity.At(x, y);
            for (int dy = -win.half; dy <= win.half; dy += win.stride) {
              const int yy = y + dy;
              if (yy < 0 || yy >= h) continue;
              const float* drow = &out.merged.At(0, yy);
              const uint8_t* irow = &intensity.At(0, yy);
              for (int dx = -win.half; dx <= win.half; dx += win.stride) {
                const int xx = x + dx;
                if (xx < 0 || xx >= w) continue;
                const float d = drow[xx];
                if (d > 0 && std::abs(ip - irow[xx]) < li) samples[n++] = d;
              }
            }
            if (gate && raw.At(x, y) > 0) n = GateSamples(samples, n, out.merged.At(x, y), ld);
            for (int i = 0; i < n; ++i) median.Set(lane, i, samples[i]);
          }
          counts[lane] = n;
          if (n == 0) median.Set(lane, n++, 0.0f);
          median.Pad(lane, n);
        }
        median.Sort();
        for (int lane = 0; lane < lanes; ++lane) {
          out.smoothed.At(x0 + lane, y) = counts[lane] > 0 ? median.Median(lane) : 0.0f;
        }
      }
    });
  }
  // D''' (eq. 5): median over the valid pixels of a small window, no intensity test (depth-gated
  // like D'').
  {
    const Window win = WindowFor(options.denoise_k);
    const int per_side = (2 * win.half) / win.stride + 1;
    const int slots = per_side * per_side <= 9 ? 16 : 32;
    const DepthImage* gate = options.depth_gated_medians ? &raw : nullptr;
    ForRows(pool, h, [&](int y) {
      LaneMedian median(slots);
      int counts[kLanes];
      float samples[25];
      for (int x0 = 0; x0 < w; x0 += kLanes) {
        const int lanes = std::min(kLanes, w - x0);
        if (x0 - win.half >= 0 && x0 + kLanes - 1 + win.half < w) {
          MedianBatchFor(out.smoothed, nullptr, 0, gate, ld, win, x0, y, &out.denoised.At(x0, y));
          continue;
        }
        for (int lane = 0; lane < kLanes; ++lane) {
          int n = 0;
          if (lane < lanes) {
            const int x = x0 + lane;
            for (int dy = -win.half; dy <= win.half; dy += win.stride) {
              const int yy = y + dy;
              if (yy < 0 || yy >= h) continue;
              const float* drow = &out.smoothed.At(0, yy);
              for (int dx = -win.half; dx <= win.half; dx += win.stride) {
                const int xx = x + dx;
                if (xx < 0 || xx >= w) continue;
                if (drow[xx] > 0) samples[n++] = drow[xx];
              }
            }
            if (gate && raw.At(x, y) > 0) n = GateSamples(samples, n, out.smoothed.At(x, y), ld);
            for (int i = 0; i < n; ++i) median.Set(lane, i, samples[i]);
          }
          counts[lane] = n;
          if (n == 0) median.Set(lane, n++, 0.0f);
          median.Pad(lane, n);
        }
        median.Sort();
        for (int lane = 0; lane < lanes; ++lane) {
          out.denoised.At(x0 + lane, y) = counts[lane] > 0 ? median.Median(lane) : 0.0f;
        }
      }
    });
  }
}

}  // namespace probeless::recon
