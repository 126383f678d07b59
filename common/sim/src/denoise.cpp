#include "denoise.h"

#include <algorithm>
#include <cmath>

namespace probeless::sim::internal {
namespace {

float Luma(const float* c) { return 0.2126f * c[0] + 0.7152f * c[1] + 0.0722f * c[2]; }

}  // namespace

void DenoiseAtrous(const DenoiseGuides& g, std::vector<float>& rgb, parallel::ThreadPool* pool,
                   int iterations) {
  const int w = g.width;
  const int h = g.height;
  const size_t n = static_cast<size_t>(w) * h;
  constexpr float kAlbedoFloor = 0.02f;
  // Demodulated irradiance-like signal: texture detail is kept out of the filter.
  std::vector<float> e(3 * n), next(3 * n);
  for (size_t p = 0; p < n; ++p) {
    for (int c = 0; c < 3; ++c) {
      e[3 * p + c] = rgb[3 * p + c] / std::max(g.albedo[3 * p + c], kAlbedoFloor);
    }
  }
  // Initial luminance variance: 3x3 spatial variance over pixels of similar geometry.
  std::vector<float> var(n, 0), var_next(n);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const size_t p = static_cast<size_t>(y) * w + x;
      if (g.depth[p] <= 0 || g.keep[p]) continue;
      double s = 0, s2 = 0;
      int count = 0;
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          const int qx = x + dx, qy = y + dy;
          if (qx < 0 || qy < 0 || qx >= w || qy >= h) continue;
          const size_t q = static_cast<size_t>(qy) * w + qx;
          if (g.depth[q] <= 0 || g.keep[q]) continue;
          const double l = Luma(&e[3 * q]);
          s += l;
          s2 += l * l;
          ++count;
        }
      }
      var[p] = count > 1 ? static_cast<float>(std::max(0.0, s2 / count - (s / count) * (s / count)))
                         : 0.f;
    }
  }
  const float kernel[3] = {3.f / 8, 1.f / 4, 1.f / 16};
  for (int it = 0; it < iterations; ++it) {
    const int step = 1 << it;
    auto row = [&](size_t row_index) {
      const int y = static_cast<int>(row_index);
      for (int x = 0; x < w; ++x) {
        const size_t p = static_cast<size_t>(y) * w + x;
        if (g.depth[p] <= 0 || g.keep[p]) {
          for (int c = 0; c < 3; ++c) next[3 * p + c] = e[3 * p + c];
          var_next[p] = var[p];
          continue;
        }
        const float* np = &g.normal[3 * p];
        const float zp = g.depth[p];
        const float lp = Luma(&e[3 * p]);
        const float sigma_l = 4.0f * std::sqrt(var[p]) + 1e-4f;
        float sum[3] = {0, 0, 0};
        float weight = 0, var_sum = 0;
        for (int ky = -2; ky <= 2; ++ky) {
          const int qy = y + ky * step;
          if (qy < 0 || qy >= h) continue;
          for (int kx = -2; kx <= 2; ++kx) {
            const int qx = x + kx * step;
            if (qx < 0 || qx >= w) continue;
            const size_t q = static_cast<size_t>(qy) * w + qx;
            if (g.depth[q] <= 0 || g.keep[q]) continue;
            const float* nq = &g.normal[3 * q];
            const float dn = std::max(0.f, np[0] * nq[0] + np[1] * nq[1] + np[2] * nq[2]);
            float wn = dn * dn;  // dn^64 by squaring
            for (int k = 0; k < 5; ++k) wn *= wn;
            const float wz = std::exp(-std::abs(g.depth[q] - zp) / (0.01f * zp * step + 1e-6f));
            const float wl = std::exp(-std::abs(Luma(&e[3 * q]) - lp) / sigma_l);
            const float wk = kernel[std::abs(kx)] * kernel[std::abs(ky)];
            const float wq = wk * wn * wz * wl;
            for (int c = 0; c < 3; ++c) sum[c] += wq * e[3 * q + c];
            weight += wq;
            var_sum += wq * wq * var[q];
          }
        }
        // The centre pixel always contributes (wn = wz = wl = 1), so weight > 0.
        for (int c = 0; c < 3; ++c) next[3 * p + c] = sum[c] / weight;
        var_next[p] = var_sum / (weight * weight);
      }
    };
    if (pool) {
      pool->ParallelFor(static_cast<size_t>(h), row);
    } else {
      for (int y = 0; y < h; ++y) row(static_cast<size_t>(y));
    }
    e.swap(next);
    var.swap(var_next);
  }
  for (size_t p = 0; p < n; ++p) {
    if (g.depth[p] <= 0 || g.keep[p]) continue;
    for (int c = 0; c < 3; ++c) {
      rgb[3 * p + c] = e[3 * p + c] * std::max(g.albedo[3 * p + c], kAlbedoFloor);
    }
  }
}

}  // namespace probeless::sim::internal
