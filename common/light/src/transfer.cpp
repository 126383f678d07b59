#include "probeless/light/transfer.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <string>

#include "occlusion_kernel.h"
#include "parallel.h"
#include "probeless/sh/sh.h"

namespace probeless::light {
namespace {

constexpr float kPi = std::numbers::pi_v<float>;

struct SrgbTable {
  float v[256];
  SrgbTable() {
    for (int i = 0; i < 256; ++i) {
      const double c = i / 255.0;
      v[i] = static_cast<float>(c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4));
    }
  }
};
const SrgbTable& Srgb() {
  static const SrgbTable table;
  return table;
}

bool Finite(double v) { return std::isfinite(v); }

void ValidateAux(const OrthographicView& view, size_t index) {
  const std::string name =
      "light::TransferComputer::Compute: auxiliary view " + std::to_string(index);
  if (view.width < 1 || view.height < 1) throw LightError(name + ": width and height must be >= 1");
  if (view.depth.size() != static_cast<size_t>(view.width) * view.height) {
    throw LightError(name + ": depth has " + std::to_string(view.depth.size()) +
                     " values, expected " + std::to_string(view.width) + "x" +
                     std::to_string(view.height));
  }
  if (!view.normals.empty() && view.normals.size() != 3 * view.depth.size()) {
    throw LightError(name + ": normals must be empty or 3 per pixel");
  }
  if (!(view.pixel_size_m > 0) || !std::isfinite(view.pixel_size_m)) {
    throw LightError(name + ": pixel_size_m must be finite and > 0");
  }
  for (float r : view.rotation) {
    if (!std::isfinite(r)) throw LightError(name + ": non-finite rotation");
  }
  for (float t : view.translation) {
    if (!std::isfinite(t)) throw LightError(name + ": non-finite translation");
  }
}

// Catmull-Rom weights for fractional position t in [0, 1).
inline void CubicWeights(float t, float w[4]) {
  const float t2 = t * t, t3 = t2 * t;
  w[0] = 0.5f * (-t3 + 2 * t2 - t);
  w[1] = 0.5f * (3 * t3 - 5 * t2 + 2);
  w[2] = 0.5f * (-3 * t3 + 4 * t2 + t);
  w[3] = 0.5f * (t3 - t2);
}

}  // namespace

float SrgbToLinear(uint8_t v) { return Srgb().v[v]; }

void SrgbToLinearGrey(std::span<const uint8_t> rgb, std::vector<float>* out) {
  const float* lut = Srgb().v;
  out->resize(rgb.size() / 3);
  for (size_t i = 0; i < out->size(); ++i) {
    (*out)[i] = (lut[rgb[3 * i]] + lut[rgb[3 * i + 1]] + lut[rgb[3 * i + 2]]) * (1.0f / 3);
  }
}

void ValidateGeometryView(const GeometryView& g, const char* where) {
  const std::string name = std::string("light::") + where;
  if (g.width < 1 || g.height < 1) {
    throw LightError(name + ": geometry buffer is empty (" + std::to_string(g.width) + "x" +
                     std::to_string(g.height) + ")");
  }
  const size_t pixels = static_cast<size_t>(g.width) * g.height;
  const std::string size = std::to_string(g.width) + "x" + std::to_string(g.height);
  if (g.depth.size() != pixels) {
    throw LightError(name + ": depth has " + std::to_string(g.depth.size()) + " values, expected " +
                     size);
  }
  if (g.normals.empty()) throw LightError(name + ": missing normals");
  if (g.normals.size() != 3 * pixels) {
    throw LightError(name + ": normals have " + std::to_string(g.normals.size()) +
                     " values, expected 3 x " + size);
  }
  if (!g.colour.empty() && g.colour.size() != 3 * pixels) {
    throw LightError(name + ": colour has " + std::to_string(g.colour.size()) +
                     " bytes, expected 3 x " + size);
  }
  const Intrinsics& k = g.intrinsics;
  if (!Finite(k.fx) || !Finite(k.fy) || !Finite(k.cx) || !Finite(k.cy)) {
    throw LightError(name + ": non-finite intrinsics");
  }
  if (!(k.fx > 0) || !(k.fy > 0)) throw LightError(name + ": fx and fy must be > 0");
}

TransferComputer::TransferComputer(const TransferOptions& options)
    : options_(options), directions_(options.directions, options.bands, options.seed) {
  if (!(options.radius_m > 0) || !std::isfinite(options.radius_m)) {
    throw LightError("light::TransferComputer: radius_m must be finite and > 0");
  }
  if (!(options.max_occluder_distance_m > 0)) {
    throw LightError("light::TransferComputer: max_occluder_distance_m must be > 0");
  }
  if (options.subsample < 1 || options.subsample > 16) {
    throw LightError("light::TransferComputer: subsample must be 1..16, got " +
                     std::to_string(options.subsample));
  }
  if (options.threads < 1) throw LightError("light::TransferComputer: threads must be >= 1");
  // §5.1: random offsets precomputed for an area of 2x2 pixels (one row of N per pixel).
  std::mt19937_64 rng(options.seed ^ 0x9e3779b97f4a7c15ull);
  const int n = directions_.count();
  n_padded_ = (n + 7) / 8 * 8;
  offsets_.assign(4 * static_cast<size_t>(n_padded_), 0.0f);
  for (int row = 0; row < 4; ++row) {
    for (int j = 0; j < n; ++j) {
      offsets_[row * n_padded_ + j] =
          0.1f + 0.9f * static_cast<float>(static_cast<double>(rng() >> 11) / 9007199254740992.0);
    }
  }
  // The directions as padded structure-of-arrays for the occlusion kernel (zero = never lit).
  directions_soa_.assign(3 * static_cast<size_t>(n_padded_), 0.0f);
  for (int j = 0; j < n; ++j) {
    for (int c = 0; c < 3; ++c) directions_soa_[c * n_padded_ + j] = directions_.directions()[j][c];
  }
  // (A_l / pi) times the normalisation of Y_lm (sh::BasisNormalisation), so that
  // AddClampedCosine needs no square roots per pixel.
  const int bands = directions_.bands();
  const std::array<double, 25> k = sh::BasisNormalisation();
  for (int l = 0; l < bands; ++l) {
    const double a = sh::ClampedCosineCoefficient(l) / std::numbers::pi;
    for (int m = 0; m <= l; ++m) {
      clamped_[l * (l + 1) + m] = static_cast<float>(a * k[l * (l + 1) + m]);
    }
  }
}

void TransferComputer::AddClampedCosine(float x, float y, float z, float* out) const {
  // clamped_ holds (A_l / pi) times the Y_lm normalisation at indices l (l + 1) + m, m >= 0.
  switch (directions_.bands()) {
    case 1:
      return sh::EvaluateWeightedBasis<1, true>(clamped_.data(), x, y, z, out);
    case 2:
      return sh::EvaluateWeightedBasis<2, true>(clamped_.data(), x, y, z, out);
    case 3:
      return sh::EvaluateWeightedBasis<3, true>(clamped_.data(), x, y, z, out);
    case 4:
      return sh::EvaluateWeightedBasis<4, true>(clamped_.data(), x, y, z, out);
    default:
      return sh::EvaluateWeightedBasis<5, true>(clamped_.data(), x, y, z, out);
  }
}

TransferComputer::~TransferComputer() = default;

void TransferComputer::ComputeRows(const GeometryView& g, const AuxiliaryBuffers& aux,
                                   const DominantLight* light, int step, int x0_pixel, int y0_pixel,
                                   int out_width, int row_begin, int row_end, float* transfer,
                                   uint8_t* valid, float* indirect, const uint8_t* mask) const {
  const int w = g.width, h = g.height;
  const int n_dir = directions_.count();
  const int cc = directions_.coefficient_count();
  const auto& dirs = directions_.directions();
  const float* weights = directions_.weights().data();
  const float chi = static_cast<float>(directions_.chi());
  const float inv_chi = 1.0f / chi;
  const float fx = static_cast<float>(g.intrinsics.fx), fy = static_cast<float>(g.intrinsics.fy);
  const float cx = static_cast<float>(g.intrinsics.cx), cy = static_cast<float>(g.intrinsics.cy);
  const float ifx = 1 / fx, ify = 1 / fy;
  const float* depth = g.depth.data();
  const float* normals = g.normals.data();
  const float radius = options_.radius_m;
  const float max_occ2 = options_.max_occluder_distance_m * options_.max_occluder_distance_m;
  const float bias = options_.depth_bias_m, bias_rel = options_.depth_bias_rel;
  const bool do_indirect = light != nullptr && indirect != nullptr;
  const bool analytic = options_.analytic_unoccluded;
  const float* lut = Srgb().v;
  // eq. 10-11 patch area: the ~N/2 directions of a hemisphere share the disc pi r^2.
  const float patch = kPi * radius * radius * 2.0f / n_dir;
  const float min_d2 = 0.01f * radius * radius;
  float vis[kMaxDirections];
  int nonzero[kMaxDirections];
  internal::OcclusionParams occ_params;
  occ_params.depth = depth;
  occ_params.width = w;
  occ_params.height = h;
  occ_params.fx = fx, occ_params.fy = fy, occ_params.cx = cx, occ_params.cy = cy;
  occ_params.ifx = ifx, occ_params.ify = ify;
  occ_params.radius = radius;
  occ_params.max_occ2 = max_occ2;
  occ_params.bias = bias, occ_params.bias_rel = bias_rel;
  occ_params.chi = chi, occ_params.inv_chi = inv_chi;
  occ_params.n_padded = n_padded_;
  occ_params.dir_x = directions_soa_.data();
  occ_params.dir_y = directions_soa_.data() + n_padded_;
  occ_params.dir_z = directions_soa_.data() + 2 * n_padded_;
  internal::PixelOcclusion occ;
  const internal::OcclusionFn occlusion = internal::OcclusionKernel();

  for (int r = row_begin; r < row_end; ++r) {
    const int v = std::min(y0_pixel + r * step + step / 2, h - 1);
    for (int c = 0; c < out_width; ++c) {
      const int u = std::min(x0_pixel + c * step + step / 2, w - 1);
      const size_t p = static_cast<size_t>(v) * w + u;
      const size_t o = static_cast<size_t>(r) * out_width + c;
      float* t_out = transfer + o * cc;
      const float d = depth[p];
      const float nx = normals[3 * p], ny = normals[3 * p + 1], nz = normals[3 * p + 2];
      float ind[3] = {0, 0, 0};
      if (!(d > 0) || (nx == 0 && ny == 0 && nz == 0) || (mask != nullptr && mask[o] == 0)) {
        std::fill(t_out, t_out + cc, 0.0f);
        valid[o] = 0;
        if (do_indirect) std::fill(indirect + 3 * o, indirect + 3 * o + 3, 0.0f);
        continue;
      }
      valid[o] = 1;
      const float x0 = d * (u - cx) * ifx, x1 = d * (v - cy) * ify, x2 = d;
      // Random offsets per 2x2 block of image pixels (§5.1), keyed by the full-resolution pixel
      // also in OursFast: a sparse sample gets exactly the full variant's transfer at its pixel.
      const float* off = offsets_.data() + static_cast<size_t>((u & 1) + 2 * (v & 1)) * n_padded_;
      const float xp[3] = {x0, x1, x2}, np[3] = {nx, ny, nz};
      // Main buffer (§5.1, eq. 7-8), 8 directions per step where the CPU has AVX2.
      occlusion(occ_params, off, xp, np, &occ);
      if (!do_indirect && aux.views.empty()) {
        // Branch-free (vectorised): nothing else to test per direction.
        for (int j = 0; j < n_dir; ++j) {
          const float cosn = occ.cosn[j], k_vis = occ.k[j];
          const float s = analytic ? (k_vis - 1) * cosn : k_vis * cosn;
          vis[j] = cosn > 0 ? s : 0.0f;
        }
      }
      for (int j = 0; j < n_dir && (do_indirect || !aux.views.empty()); ++j) {
        const auto& om = dirs[j];
        const float cosn = occ.cosn[j];
        if (!(cosn > 0)) {
          vis[j] = 0;
          continue;
        }
        float k_vis = occ.k[j];
        if (do_indirect && k_vis < 1) {
          // eq. 10-12: light reflected by s_j towards x from the dominant light.
          const int32_t q = occ.occluder[j];
          const int iu = q % w, iv = q / w;
          const float ds = depth[q];
          const float s0 = ds * (iu - cx) * ifx - x0, s1 = ds * (iv - cy) * ify - x1, s2 = ds - x2;
          const float dist2 = s0 * s0 + s1 * s1 + s2 * s2;
          const float inv = 1.0f / std::sqrt(dist2);
          const float t0 = s0 * inv, t1 = s1 * inv, t2 = s2 * inv;  // eq. 7
          const float* ns = normals + 3 * static_cast<size_t>(q);
          const float cos_s = -(ns[0] * t0 + ns[1] * t1 + ns[2] * t2);
          const float cos_x = nx * t0 + ny * t1 + nz * t2;
          const float e = ns[0] * light->direction[0] + ns[1] * light->direction[1] +
                          ns[2] * light->direction[2];
          if (cos_s > 0 && cos_x > 0 && e > 0) {
            const float f = (1 - k_vis) * e * light->intensity * cos_x * cos_s * patch /
                            (kPi * kPi * std::max(dist2, min_d2));
            if (g.colour.empty()) {
              ind[0] += f, ind[1] += f, ind[2] += f;
            } else {
              const uint8_t* a = g.colour.data() + 3 * static_cast<size_t>(q);
              ind[0] += f * lut[a[0]], ind[1] += f * lut[a[1]], ind[2] += f * lut[a[2]];
            }
          }
        }
        const float len = radius * off[j];
        const float y0 = x0 + om[0] * len, y1 = x1 + om[1] * len, y2 = x2 + om[2] * len;
        // Auxiliary orthographic buffers: hidden surfaces occlude too (§5.1, Fig. 5a).
        for (const OrthographicView& av : aux.views) {
          if (k_vis <= 0) break;
          const auto& R = av.rotation;
          const float a0 = y0 - av.translation[0], a1 = y1 - av.translation[1],
                      a2 = y2 - av.translation[2];
          const float q0 = R[0] * a0 + R[3] * a1 + R[6] * a2;  // R^T (y - t)
          const float q1 = R[1] * a0 + R[4] * a1 + R[7] * a2;
          const float q2 = R[2] * a0 + R[5] * a1 + R[8] * a2;
          const float hw = 0.5f * (av.width - 1), hh = 0.5f * (av.height - 1);
          const float pu = q0 / av.pixel_size_m + hw, pv = q1 / av.pixel_size_m + hh;
          if (!(pu > -0.5f && pv > -0.5f && pu < av.width - 0.5f && pv < av.height - 0.5f)) {
            continue;
          }
          const int iu = static_cast<int>(pu + 0.5f), iv = static_cast<int>(pv + 0.5f);
          const float dv = av.depth[static_cast<size_t>(iv) * av.width + iu];
          if (!(dv > 0 && dv < q2 - bias)) continue;
          const float sv0 = (iu - hw) * av.pixel_size_m, sv1 = (iv - hh) * av.pixel_size_m;
          const float s0 = R[0] * sv0 + R[1] * sv1 + R[2] * dv + av.translation[0] - x0;
          const float s1 = R[3] * sv0 + R[4] * sv1 + R[5] * dv + av.translation[1] - x1;
          const float s2 = R[6] * sv0 + R[7] * sv1 + R[8] * dv + av.translation[2] - x2;
          const float dist2 = s0 * s0 + s1 * s1 + s2 * s2;
          if (!(dist2 <= max_occ2 && dist2 > 1e-12f)) continue;
          const float inv = 1.0f / std::sqrt(dist2);
          const float cos_a = (s0 * om[0] + s1 * om[1] + s2 * om[2]) * inv;
          k_vis = std::min(k_vis, std::min(chi, 1.0f - cos_a) * inv_chi);
        }
        // analytic_unoccluded: only the occluded part is sampled (subtracted below).
        vis[j] = analytic ? (k_vis - 1) * cosn : k_vis * cosn;
      }
      // T_n(x) = sum_j K(x, w_j) (w_j . n) Y_n(w_j) 4 pi / (N pi) (eq. 6): contiguous, SIMD.
      // Only the directions with a non-zero term (with analytic_unoccluded: the occluded ones),
      // listed without branches (a data-dependent skip mispredicts about every other direction).
      int terms = 0;
      for (int j = 0; j < n_dir; ++j) {
        nonzero[terms] = j;
        terms += vis[j] != 0;
      }
      std::fill(t_out, t_out + cc, 0.0f);
      if (cc == 16) {
        float acc[16] = {};
        for (int i = 0; i < terms; ++i) {
          const int j = nonzero[i];
          const float s = vis[j];
          const float* wj = weights + j * 16;
          for (int k = 0; k < 16; ++k) acc[k] += s * wj[k];
        }
        std::copy(acc, acc + 16, t_out);
      } else {
        for (int i = 0; i < terms; ++i) {
          const int j = nonzero[i];
          const float s = vis[j];
          const float* wj = weights + static_cast<size_t>(j) * cc;
          for (int k = 0; k < cc; ++k) t_out[k] += s * wj[k];
        }
      }
      // + (A_l / pi) Y_n(n): the exact unoccluded clamped cosine (Ramamoorthi & Hanrahan 2001).
      if (analytic) AddClampedCosine(nx, ny, nz, t_out);
      if (do_indirect) std::copy(ind, ind + 3, indirect + 3 * o);
    }
  }
}

void TransferComputer::Compute(const GeometryView& g, const AuxiliaryBuffers& aux,
                               const DominantLight* light, TransferResult* out) {
  ValidateGeometryView(g, "TransferComputer::Compute");
  for (size_t i = 0; i < aux.views.size(); ++i) ValidateAux(aux.views[i], i);
  if (light != nullptr) {
    for (float v : light->direction) {
      if (!std::isfinite(v)) throw LightError("light::TransferComputer::Compute: bad light");
    }
    if (!(light->intensity > 0)) light = nullptr;
  }
  const int w = g.width, h = g.height, cc = directions_.coefficient_count();
  const size_t pixels = static_cast<size_t>(w) * h;
  out->width = w;
  out->height = h;
  out->coefficient_count = cc;
  out->transfer.resize(pixels * cc);
  out->valid.resize(pixels);
  if (light) {
    out->indirect.resize(3 * pixels);
  } else {
    out->indirect.clear();
  }
  const int step = options_.subsample;
  const int threads = options_.threads;
  out->sample_step = step;
  out->sample_width = step == 1 ? 0 : (w + step - 1) / step;
  out->sample_height = step == 1 ? 0 : (h + step - 1) / step;
  if (step == 1) {
    out->samples.clear();
    out->sample_valid.clear();
    internal::ParallelRows(threads, h, 8, [&](int begin, int end) {
      ComputeRows(g, aux, light, 1, 0, 0, w, begin, end, out->transfer.data(), out->valid.data(),
                  light ? out->indirect.data() : nullptr);
    });
    return;
  }
  // OursFast (§5.1): every step-th pixel, then bicubic (Catmull-Rom) upsampling.
  const int lw = out->sample_width, lh = out->sample_height;
  const size_t low = static_cast<size_t>(lw) * lh;
  std::vector<float>& low_transfer = out->samples;
  std::vector<uint8_t>& low_valid = out->sample_valid;
  low_transfer.resize(low * cc);
  low_valid.resize(low);
  low_indirect_.resize(light ? 3 * low : 0);
  internal::ParallelRows(threads, lh, 2, [&](int begin, int end) {
    ComputeRows(g, aux, light, step, 0, 0, lw, begin, end, low_transfer.data(), low_valid.data(),
                light ? low_indirect_.data() : nullptr);
  });
  // Fill invalid low-resolution samples from valid 8-neighbours (3 passes) so that edges do not
  // pull zeros into the interpolation; pixels without a surface are zeroed afterwards.
  const int channels = cc + (light ? 3 : 0);
  std::vector<float>& merged = low_merged_;
  merged.resize(low * channels);
  for (size_t i = 0; i < low; ++i) {
    std::copy_n(&low_transfer[i * cc], cc, &merged[i * channels]);
    if (light) std::copy_n(&low_indirect_[3 * i], 3, &merged[i * channels + cc]);
  }
  std::vector<uint8_t> ok(low_valid.begin(), low_valid.end());
  std::vector<size_t> holes, still, filled;
  for (size_t i = 0; i < low; ++i) {
    if (!ok[i]) holes.push_back(i);
  }
  for (int pass = 0; pass < 3 && !holes.empty(); ++pass) {
    still.clear();
    filled.clear();
    for (size_t i : holes) {
      const int x = static_cast<int>(i % lw), y = static_cast<int>(i / lw);
      int count = 0;
      float* dst = &merged[i * channels];
      std::fill(dst, dst + channels, 0.0f);
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          const int xx = x + dx, yy = y + dy;
          if (xx < 0 || yy < 0 || xx >= lw || yy >= lh) continue;
          const size_t k = static_cast<size_t>(yy) * lw + xx;
          if (!ok[k]) continue;
          for (int c = 0; c < channels; ++c) dst[c] += merged[k * channels + c];
          ++count;
        }
      }
      if (count) {
        for (int c = 0; c < channels; ++c) dst[c] /= count;
        filled.push_back(i);
      } else {
        still.push_back(i);
      }
    }
    for (size_t i : filled) ok[i] = 1;  // a pass reads only the previous passes' samples
    holes.swap(still);
  }
  // Separable bicubic (Catmull-Rom); low sample i sits at full-resolution coordinate
  // i * step + step / 2. The vertical pass runs first, at the low width (into a per-thread row of
  // lw samples), so the horizontal pass writes each full-resolution pixel exactly once.
  auto taps = [&](int x, int n_low, int idx[4], float wt[4]) {
    const float f = (x - step / 2) / static_cast<float>(step);
    const int i = static_cast<int>(std::floor(f));
    CubicWeights(f - i, wt);
    for (int k = 0; k < 4; ++k) idx[k] = std::clamp(i - 1 + k, 0, n_low - 1);
  };
  std::vector<int> x_idx(4 * static_cast<size_t>(w));
  std::vector<float> x_wt(4 * static_cast<size_t>(w));
  for (int x = 0; x < w; ++x) taps(x, lw, &x_idx[4 * x], &x_wt[4 * x]);
  const size_t row_len = static_cast<size_t>(lw) * channels;
  internal::ParallelRows(threads, h, 16, [&](int begin, int end) {
    std::vector<float> column_mix(row_len);
    float* mix = column_mix.data();
    for (int y = begin; y < end; ++y) {
      int yi[4];
      float wy[4];
      taps(y, lh, yi, wy);
      const float* r0 = &merged[yi[0] * row_len];
      const float* r1 = &merged[yi[1] * row_len];
      const float* r2 = &merged[yi[2] * row_len];
      const float* r3 = &merged[yi[3] * row_len];
      for (size_t j = 0; j < row_len; ++j) {
        mix[j] = wy[0] * r0[j] + wy[1] * r1[j] + wy[2] * r2[j] + wy[3] * r3[j];
      }
      // One horizontal row; kCc > 0: the coefficient count known at compile time (unrolled).
      auto horizontal = [&]<int kCc>() {
        const int n = kCc > 0 ? kCc : cc;
        for (int x = 0; x < w; ++x) {
          const size_t p = static_cast<size_t>(y) * w + x;
          const float nx = g.normals[3 * p], ny = g.normals[3 * p + 1], nz = g.normals[3 * p + 2];
          const bool valid = g.depth[p] > 0 && !(nx == 0 && ny == 0 && nz == 0);
          out->valid[p] = valid;
          float* t = &out->transfer[p * cc];
          if (!valid) {
            std::fill(t, t + n, 0.0f);
            if (light) std::fill(&out->indirect[3 * p], &out->indirect[3 * p] + 3, 0.0f);
            continue;
          }
          const int* xi = &x_idx[4 * x];
          const float* wx = &x_wt[4 * x];
          const float* s0 = mix + static_cast<size_t>(xi[0]) * channels;
          const float* s1 = mix + static_cast<size_t>(xi[1]) * channels;
          const float* s2 = mix + static_cast<size_t>(xi[2]) * channels;
          const float* s3 = mix + static_cast<size_t>(xi[3]) * channels;
          for (int c = 0; c < n; ++c) {
            t[c] = wx[0] * s0[c] + wx[1] * s1[c] + wx[2] * s2[c] + wx[3] * s3[c];
          }
          if (light) {
            for (int c = cc; c < cc + 3; ++c) {
              out->indirect[3 * p + c - cc] =
                  std::max(0.0f, wx[0] * s0[c] + wx[1] * s1[c] + wx[2] * s2[c] + wx[3] * s3[c]);
            }
          }
        }
      };
      if (cc == 16) {
        horizontal.template operator()<16>();
      } else if (cc == 9) {
        horizontal.template operator()<9>();
      } else {
        horizontal.template operator()<0>();
      }
    }
  });
}

void TransferComputer::ComputeRegion(const GeometryView& g, const AuxiliaryBuffers& aux,
                                     const DominantLight* light, const PixelRect& rect, int step,
                                     TransferResult* out, std::span<const uint8_t> mask) {
  ValidateGeometryView(g, "TransferComputer::ComputeRegion");
  for (size_t i = 0; i < aux.views.size(); ++i) ValidateAux(aux.views[i], i);
  if (step < 1) {
    throw LightError("light::TransferComputer::ComputeRegion: step must be >= 1, got " +
                     std::to_string(step));
  }
  if (rect.empty() || rect.x0 < 0 || rect.y0 < 0 || rect.x1 > g.width || rect.y1 > g.height) {
    throw LightError("light::TransferComputer::ComputeRegion: rect [" + std::to_string(rect.x0) +
                     ", " + std::to_string(rect.x1) + ") x [" + std::to_string(rect.y0) + ", " +
                     std::to_string(rect.y1) + ") is empty or not inside " +
                     std::to_string(g.width) + "x" + std::to_string(g.height));
  }
  if (light != nullptr) {
    for (float v : light->direction) {
      if (!std::isfinite(v)) throw LightError("light::TransferComputer::ComputeRegion: bad light");
    }
    if (!(light->intensity > 0)) light = nullptr;
  }
  const int cc = directions_.coefficient_count();
  const int ow = (rect.width() + step - 1) / step, oh = (rect.height() + step - 1) / step;
  const size_t samples = static_cast<size_t>(ow) * oh;
  if (!mask.empty() && mask.size() != samples) {
    throw LightError("light::TransferComputer::ComputeRegion: mask has " +
                     std::to_string(mask.size()) + " bytes, expected " + std::to_string(ow) + "x" +
                     std::to_string(oh));
  }
  out->width = ow;
  out->height = oh;
  out->coefficient_count = cc;
  out->transfer.resize(samples * cc);
  out->valid.resize(samples);
  if (light) {
    out->indirect.resize(3 * samples);
  } else {
    out->indirect.clear();
  }
  out->sample_step = 1;
  out->sample_width = out->sample_height = 0;
  out->samples.clear();
  out->sample_valid.clear();
  internal::ParallelRows(options_.threads, oh, 4, [&](int begin, int end) {
    ComputeRows(g, aux, light, step, rect.x0, rect.y0, ow, begin, end, out->transfer.data(),
                out->valid.data(), light ? out->indirect.data() : nullptr,
                mask.empty() ? nullptr : mask.data());
  });
}

void SmoothDepth(std::span<float> depth, int width, int height, int radius, float max_rel) {
  if (width < 1 || height < 1 || depth.size() != static_cast<size_t>(width) * height) {
    throw LightError("light::SmoothDepth: depth has " + std::to_string(depth.size()) +
                     " values, expected " + std::to_string(width) + "x" + std::to_string(height));
  }
  if (radius < 0) throw LightError("light::SmoothDepth: radius must be >= 0");
  if (radius == 0) return;
  std::vector<float> tmp(depth.begin(), depth.end());
  auto pass = [&](const float* src, float* dst, int n_lines, int length, size_t line_stride,
                  size_t step) {
    for (int line = 0; line < n_lines; ++line) {
      const float* s = src + line * line_stride;
      float* d = dst + line * line_stride;
      for (int i = 0; i < length; ++i) {
        const float z = s[i * step];
        if (!(z > 0)) {
          d[i * step] = 0;
          continue;
        }
        float sum = 0;
        int count = 0;
        const int lo = std::max(0, i - radius), hi = std::min(length - 1, i + radius);
        for (int k = lo; k <= hi; ++k) {
          const float zk = s[k * step];
          if (zk > 0 && std::abs(zk - z) <= max_rel * z) {
            sum += zk;
            ++count;
          }
        }
        d[i * step] = sum / count;
      }
    }
  };
  pass(depth.data(), tmp.data(), height, width, width, 1);  // rows
  pass(tmp.data(), depth.data(), width, height, 1, width);  // columns
}

void NormalsFromDepth(std::span<const float> depth, int width, int height, const Intrinsics& k,
                      std::vector<float>* normals, float max_jump_rel, int step) {
  if (step < 1) throw LightError("light::NormalsFromDepth: step must be >= 1");
  if (width < 1 || height < 1 || depth.size() != static_cast<size_t>(width) * height) {
    throw LightError("light::NormalsFromDepth: depth has " + std::to_string(depth.size()) +
                     " values, expected " + std::to_string(width) + "x" + std::to_string(height));
  }
  if (!Finite(k.fx) || !Finite(k.fy) || !Finite(k.cx) || !Finite(k.cy) || !(k.fx > 0) ||
      !(k.fy > 0)) {
    throw LightError("light::NormalsFromDepth: intrinsics must be finite with fx, fy > 0");
  }
  normals->assign(3 * depth.size(), 0.0f);
  auto point = [&](int u, int v, float out[3]) {
    k.BackProject(u, v, depth[static_cast<size_t>(v) * width + u], out);
  };
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      const size_t p = static_cast<size_t>(v) * width + u;
      const float z = depth[p];
      if (!(z > 0)) continue;
      auto ok = [&](int uu, int vv) {
        if (uu < 0 || vv < 0 || uu >= width || vv >= height) return false;
        const float zz = depth[static_cast<size_t>(vv) * width + uu];
        return zz > 0 && std::abs(zz - z) <= max_jump_rel * step * z;
      };
      const int ul = ok(u - step, v) ? u - step : u, ur = ok(u + step, v) ? u + step : u;
      const int vt = ok(u, v - step) ? v - step : v, vb = ok(u, v + step) ? v + step : v;
      if (ul == ur || vt == vb) continue;
      float a[3], b[3], c[3], d[3];
      point(ur, v, a);
      point(ul, v, b);
      point(u, vb, c);
      point(u, vt, d);
      const float ex[3] = {a[0] - b[0], a[1] - b[1], a[2] - b[2]};
      const float ey[3] = {c[0] - d[0], c[1] - d[1], c[2] - d[2]};
      // ex x ey points away from the camera for x right, y down: negate it.
      float n[3] = {-(ex[1] * ey[2] - ex[2] * ey[1]), -(ex[2] * ey[0] - ex[0] * ey[2]),
                    -(ex[0] * ey[1] - ex[1] * ey[0])};
      const float len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
      if (!(len > 0)) continue;
      float* dst = normals->data() + 3 * p;
      const float view = n[0] * (u - k.cx) / k.fx + n[1] * (v - k.cy) / k.fy + n[2];
      const float sign = view > 0 ? -1.0f : 1.0f;  // face the camera: n . (x - 0) < 0
      for (int i = 0; i < 3; ++i) dst[i] = sign * n[i] / len;
    }
  }
}

void FilterNormals(std::span<const float> depth, int width, int height, const Intrinsics& k,
                   const NormalFilterOptions& options, std::span<float> normals) {
  const size_t pixels = static_cast<size_t>(std::max(width, 0)) * std::max(height, 0);
  if (width < 1 || height < 1 || depth.size() != pixels || normals.size() != 3 * pixels) {
    throw LightError("light::FilterNormals: depth has " + std::to_string(depth.size()) +
                     " values and normals " + std::to_string(normals.size()) + ", expected " +
                     std::to_string(width) + "x" + std::to_string(height) + " (x3)");
  }
  if (!Finite(k.fx) || !Finite(k.fy) || !Finite(k.cx) || !Finite(k.cy) || !(k.fx > 0) ||
      !(k.fy > 0)) {
    throw LightError("light::FilterNormals: intrinsics must be finite with fx, fy > 0");
  }
  const int r = std::max(0, options.radius);
  const float cos_neighbour =
      std::cos(std::clamp(options.max_neighbour_angle_deg, 0.0f, 180.0f) * 3.14159265f / 180);
  const bool view_test = options.max_view_angle_deg < 90;
  const float cos_view =
      std::cos(std::clamp(options.max_view_angle_deg, 0.0f, 90.0f) * 3.14159265f / 180);
  std::vector<uint8_t> drop(pixels, 0);
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      const size_t p = static_cast<size_t>(v) * width + u;
      const float z = depth[p];
      const float* n = &normals[3 * p];
      if (!(z > 0) || (n[0] == 0 && n[1] == 0 && n[2] == 0)) continue;
      if (view_test) {
        const float rx = static_cast<float>((u - k.cx) / k.fx),
                    ry = static_cast<float>((v - k.cy) / k.fy);
        const float c = -(n[0] * rx + n[1] * ry + n[2]) / std::sqrt(rx * rx + ry * ry + 1);
        if (c < cos_view) {
          drop[p] = 1;
          continue;
        }
      }
      if (r == 0) continue;
      const int du[4] = {-r, r, 0, 0}, dv[4] = {0, 0, -r, r};
      for (int j = 0; j < 4; ++j) {
        const int uu = u + du[j], vv = v + dv[j];
        if (uu < 0 || vv < 0 || uu >= width || vv >= height) {
          drop[p] = 1;
          break;
        }
        const size_t q = static_cast<size_t>(vv) * width + uu;
        const float* m = &normals[3 * q];
        const float zq = depth[q];
        // Distance of the neighbour's point from the pixel's tangent plane.
        const float dx =
            zq * static_cast<float>((uu - k.cx) / k.fx) - z * static_cast<float>((u - k.cx) / k.fx);
        const float dy =
            zq * static_cast<float>((vv - k.cy) / k.fy) - z * static_cast<float>((v - k.cy) / k.fy);
        const float off_plane = std::abs(n[0] * dx + n[1] * dy + n[2] * (zq - z));
        if (!(zq > 0) || off_plane > options.max_plane_distance_rel * z ||
            n[0] * m[0] + n[1] * m[1] + n[2] * m[2] < cos_neighbour) {
          drop[p] = 1;
          break;
        }
      }
    }
  }
  for (size_t p = 0; p < pixels; ++p) {
    if (drop[p]) normals[3 * p] = normals[3 * p + 1] = normals[3 * p + 2] = 0;
  }
}

}  // namespace probeless::light
