#include "albedo_groups.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>

#include "probeless/light/transfer.h"

namespace probeless::light::internal {
namespace {

// Entropy (nats) of `values` in bins of Scott's width over their middle 90 %.
double ProjectedEntropy(std::vector<float>& values) {
  const size_t n = values.size();
  std::sort(values.begin(), values.end());
  const size_t lo = n / 20, hi = n - n / 20;
  if (hi <= lo + 8) return 0;
  double mean = 0, sq = 0;
  for (size_t i = lo; i < hi; ++i) mean += values[i];
  mean /= static_cast<double>(hi - lo);
  for (size_t i = lo; i < hi; ++i) sq += (values[i] - mean) * (values[i] - mean);
  const double sigma = std::sqrt(sq / static_cast<double>(hi - lo));
  const double width = 3.5 * sigma * std::pow(static_cast<double>(hi - lo), -1.0 / 3.0);
  if (!(width > 0)) return 0;
  double entropy = 0;
  size_t i = lo;
  while (i < hi) {
    const double end = values[i] + width;
    size_t j = i;
    while (j < hi && values[j] < end) ++j;
    const double p = static_cast<double>(j - i) / static_cast<double>(hi - lo);
    entropy -= p * std::log(p);
    i = j;
  }
  return entropy;
}

}  // namespace

std::vector<int> AlbedoGroupIds(std::span<const float> rgb, int cells, bool invariant, int* count) {
  const size_t m = rgb.size() / 3;
  std::vector<int> id(m, 0);
  if (!invariant) {
    *count = cells * cells;
    for (size_t i = 0; i < m; ++i) {
      const float r = rgb[3 * i], g = rgb[3 * i + 1], b = rgb[3 * i + 2];
      const float sum = r + g + b;
      if (!(sum > 0)) continue;
      const int rc = std::clamp(static_cast<int>(r / sum * cells), 0, cells - 1);
      const int gc = std::clamp(static_cast<int>(g / sum * cells), 0, cells - 1);
      id[i] = rc * cells + gc;
    }
    return id;
  }
  if (m == 0) {
    *count = 1;
    return id;
  }
  // Log chromaticity; a floor keeps black channels finite.
  constexpr float kFloor = 1e-3f;
  std::vector<float> x(m), y(m);
  for (size_t i = 0; i < m; ++i) {
    const float g = std::max(rgb[3 * i + 1], kFloor);
    x[i] = std::log(std::max(rgb[3 * i], kFloor) / g);
    y[i] = std::log(std::max(rgb[3 * i + 2], kFloor) / g);
  }
  // The projection angle of minimum entropy, 1-degree steps over [0, 180).
  std::vector<float> projected(m);
  double best_entropy = 1e300;
  float best_c = 1, best_s = 0;
  for (int deg = 0; deg < 180; ++deg) {
    const float a = static_cast<float>(deg * std::numbers::pi / 180);
    const float c = std::cos(a), s = std::sin(a);
    for (size_t i = 0; i < m; ++i) projected[i] = x[i] * c + y[i] * s;
    const double e = ProjectedEntropy(projected);
    if (e < best_entropy) best_entropy = e, best_c = c, best_s = s;
  }
  const float bin = 3.0f / std::max(cells, 1);
  float lo = 1e30f, hi = -1e30f;
  for (size_t i = 0; i < m; ++i) {
    projected[i] = x[i] * best_c + y[i] * best_s;
    lo = std::min(lo, projected[i]);
    hi = std::max(hi, projected[i]);
  }
  const int bins = std::max(1, std::min(cells * cells, static_cast<int>((hi - lo) / bin) + 1));
  *count = bins;
  for (size_t i = 0; i < m; ++i) {
    id[i] = std::clamp(static_cast<int>((projected[i] - lo) / bin), 0, bins - 1);
  }
  return id;
}

std::vector<uint8_t> FillClippedChroma(std::span<const uint8_t> colour,
                                       std::span<const float> depth, std::span<const float> normals,
                                       int width, int height, int clip_level, float max_jump_rel,
                                       float max_crease_deg, size_t* filled) {
  const size_t n = static_cast<size_t>(width) * height;
  std::vector<uint8_t> out(colour.begin(), colour.end());
  if (filled) *filled = 0;
  if (colour.size() != 3 * n || (!depth.empty() && depth.size() != n) ||
      (!normals.empty() && normals.size() != 3 * n)) {
    return out;
  }
  const float min_cos = std::cos(max_crease_deg * std::numbers::pi_v<float> / 180);
  constexpr int kFar = std::numeric_limits<int>::max();
  std::vector<int> source(n, -1), distance(n, kFar);
  std::vector<uint8_t> is_clipped(n, 0);
  size_t clipped = 0;
  for (size_t i = 0; i < n; ++i) {
    const uint8_t* c = &colour[3 * i];
    if (std::max({c[0], c[1], c[2]}) >= clip_level) {
      is_clipped[i] = 1, ++clipped;
    } else if (c[0] + c[1] + c[2] > 0) {
      source[i] = static_cast<int>(i), distance[i] = 0;
    }
  }
  if (clipped == 0) return out;
  auto joined = [&](size_t a, size_t b) {
    if (!depth.empty()) {
      const float za = depth[a], zb = depth[b];
      if (!(za > 0 && zb > 0 && std::abs(za - zb) <= max_jump_rel * za)) return false;
    }
    if (!normals.empty()) {
      const float* na = &normals[3 * a];
      const float* nb = &normals[3 * b];
      if (na[0] * nb[0] + na[1] * nb[1] + na[2] * nb[2] < min_cos) return false;
    }
    return true;
  };
  bool moved = false;
  auto relax = [&](size_t i, size_t j) {
    if (distance[j] != kFar && distance[j] + 1 < distance[i] && joined(i, j)) {
      distance[i] = distance[j] + 1, source[i] = source[j], moved = true;
    }
  };
  // Raster sweeps (forward: left and up neighbours; backward: right and down) until nothing
  // changes, at most 4 rounds: enough for the convex patches clipping makes.
  for (int round = 0; round < 4; ++round) {
    moved = false;
    for (int y = 0; y < height; ++y) {
      for (int x = 0; x < width; ++x) {
        const size_t i = static_cast<size_t>(y) * width + x;
        if (!is_clipped[i]) continue;
        if (x > 0) relax(i, i - 1);
        if (y > 0) relax(i, i - width);
      }
    }
    for (int y = height - 1; y >= 0; --y) {
      for (int x = width - 1; x >= 0; --x) {
        const size_t i = static_cast<size_t>(y) * width + x;
        if (!is_clipped[i]) continue;
        if (x + 1 < width) relax(i, i + 1);
        if (y + 1 < height) relax(i, i + width);
      }
    }
    if (!moved) break;
  }
  std::array<float, 256> lut;
  for (int v = 0; v < 256; ++v) lut[v] = SrgbToLinear(static_cast<uint8_t>(v));
  auto encode = [&](float linear) {
    const auto it = std::lower_bound(lut.begin(), lut.end(), linear);
    return static_cast<uint8_t>(std::min<std::ptrdiff_t>(255, it - lut.begin()));
  };
  size_t changed = 0;
  for (size_t i = 0; i < n; ++i) {
    if (!is_clipped[i] || source[i] < 0) continue;
    const uint8_t* c = &colour[3 * static_cast<size_t>(source[i])];
    const float r = lut[c[0]], g = lut[c[1]], b = lut[c[2]];
    const float m = std::max({r, g, b});
    if (!(m > 0)) continue;
    out[3 * i] = encode(r / m), out[3 * i + 1] = encode(g / m), out[3 * i + 2] = encode(b / m);
    ++changed;
  }
  if (filled) *filled = changed;
  return out;
}

}  // namespace probeless::light::internal
