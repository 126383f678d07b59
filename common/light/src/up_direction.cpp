#include "probeless/light/up_direction.h"

#include <cmath>
#include <numbers>
#include <string>
#include <vector>

namespace probeless::light {

UpDirection EstimateUpDirection(const GeometryView& geometry, const UpDirectionOptions& options) {
  if (options.stride < 1) {
    throw LightError("light::EstimateUpDirection: stride must be >= 1, got " +
                     std::to_string(options.stride));
  }
  if (!(options.kernel_deg > 0 && options.kernel_deg <= options.search_deg &&
        options.search_deg < 90)) {
    throw LightError(
        "light::EstimateUpDirection: need 0 < kernel_deg <= search_deg < 90 (degrees)");
  }
  if (!(options.min_support >= 0 && options.min_support <= 1)) {
    throw LightError("light::EstimateUpDirection: min_support must be in [0, 1]");
  }
  ValidateGeometryView(geometry, "EstimateUpDirection");
  constexpr double kDeg = std::numbers::pi / 180;
  std::vector<Vec3f> normals;
  size_t valid = 0;
  const double cos_search = std::cos(options.search_deg * kDeg);
  for (int v = 0; v < geometry.height; v += options.stride) {
    for (int u = 0; u < geometry.width; u += options.stride) {
      const size_t i = static_cast<size_t>(v) * geometry.width + u;
      if (!(geometry.depth[i] > 0)) continue;
      const float* n = &geometry.normals[3 * i];
      const float len2 = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
      if (!(len2 > 0.25f)) continue;
      ++valid;
      if (-n[1] / std::sqrt(len2) >= cos_search) normals.push_back({n[0], n[1], n[2]});
    }
  }
  UpDirection out;
  if (valid == 0 || normals.empty()) return out;
  double u[3] = {0, -1, 0};
  // The window narrows in steps so that a wide start finds the cluster and the end is its mode.
  for (int it = 0; it < 12; ++it) {
    const double t = std::min(1.0, it / 6.0);
    const double window = options.search_deg * (1 - t) + options.kernel_deg * t;
    const double cos_w = std::cos(window * kDeg);
    double s[3] = {0, 0, 0};
    for (const Vec3f& n : normals) {
      const double c = n[0] * u[0] + n[1] * u[1] + n[2] * u[2];
      if (c < cos_w) continue;
      s[0] += n[0], s[1] += n[1], s[2] += n[2];
    }
    const double len = std::sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2]);
    if (!(len > 0)) return out;
    for (int k = 0; k < 3; ++k) u[k] = s[k] / len;
  }
  const double cos_k = std::cos(options.kernel_deg * kDeg);
  size_t support = 0;
  for (const Vec3f& n : normals) support += n[0] * u[0] + n[1] * u[1] + n[2] * u[2] >= cos_k;
  out.support = static_cast<float>(static_cast<double>(support) / static_cast<double>(valid));
  if (out.support < options.min_support) return out;
  out.valid = true;
  out.up = {static_cast<float>(u[0]), static_cast<float>(u[1]), static_cast<float>(u[2])};
  return out;
}

}  // namespace probeless::light
