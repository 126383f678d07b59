#include "albedo_groups.h"

#include <algorithm>
#include <cmath>
#include <numbers>

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

}  // namespace probeless::light::internal
