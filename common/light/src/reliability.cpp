#include "probeless/light/reliability.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>

namespace probeless::light {

void NormalReliability(std::span<const float> depth, int width, int height, const Intrinsics& k,
                       std::span<const float> normals, const NormalReliabilityOptions& options,
                       std::vector<float>* out) {
  const size_t pixels = static_cast<size_t>(std::max(width, 0)) * std::max(height, 0);
  if (width < 1 || height < 1 || depth.size() != pixels || normals.size() != 3 * pixels) {
    throw LightError("light::NormalReliability: depth has " + std::to_string(depth.size()) +
                     " values and normals " + std::to_string(normals.size()) + ", expected " +
                     std::to_string(width) + "x" + std::to_string(height) + " (x3)");
  }
  if (!std::isfinite(k.fx) || !std::isfinite(k.fy) || !std::isfinite(k.cx) ||
      !std::isfinite(k.cy) || !(k.fx > 0) || !(k.fy > 0)) {
    throw LightError("light::NormalReliability: intrinsics must be finite with fx, fy > 0");
  }
  if (options.spacing < 1 || options.window < 0 || !(options.threshold_sigma > 0) ||
      !(options.min_radius_m > 0) || !(options.noise_m >= 0) || !(options.noise_quadratic >= 0)) {
    throw LightError(
        "light::NormalReliability: spacing must be >= 1, window >= 0, threshold_sigma and "
        "min_radius_m > 0, noise >= 0");
  }
  // Discontinuity ratio per pixel: the largest departure of its depth from the plane through
  // two neighbours `spacing` pixels away (x, y, both diagonals), relative to what noise and a
  // sphere of min_radius_m allow. Under perspective 1/z is affine in (u, v) on a plane, so the
  // plane's depth between the neighbours is the harmonic mean of theirs.
  const int h = options.spacing;
  const float f = static_cast<float>(0.5 * (k.fx + k.fy));
  const float noise_scale = options.threshold_sigma * std::sqrt(1.5f);
  const float inv_2r = 0.5f / options.min_radius_m;
  std::vector<float> ratio(pixels, 0.0f);
  const int du[4] = {1, 0, 1, 1}, dv[4] = {0, 1, 1, -1};
  const float len[4] = {1.0f, 1.0f, std::numbers::sqrt2_v<float>, std::numbers::sqrt2_v<float>};
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      const size_t p = static_cast<size_t>(v) * width + u;
      const float z = depth[p];
      if (!(z > 0)) continue;
      const float sigma = options.noise_m + options.noise_quadratic * z * z;
      float worst = 0;
      for (int j = 0; j < 4; ++j) {
        const int ua = u - h * du[j], va = v - h * dv[j], ub = u + h * du[j], vb = v + h * dv[j];
        if (ua < 0 || ub < 0 || va < 0 || vb < 0 || ua >= width || ub >= width || va >= height ||
            vb >= height) {
          continue;
        }
        const float za = depth[static_cast<size_t>(va) * width + ua];
        const float zb = depth[static_cast<size_t>(vb) * width + ub];
        if (!(za > 0) || !(zb > 0)) continue;  // holes: no evidence either way
        const float plane = 2.0f / (1.0f / za + 1.0f / zb);
        const float lateral = h * len[j] * z / f;
        const float allowed = noise_scale * sigma + lateral * lateral * inv_2r;
        worst = std::max(worst, std::abs(z - plane) / allowed);
      }
      ratio[p] = worst;
    }
  }
  // Largest ratio within the window (separable max filter: rows, then columns).
  const int w = options.window;
  if (w > 0) {
    std::vector<float> tmp(pixels);
    for (int v = 0; v < height; ++v) {
      const float* in = &ratio[static_cast<size_t>(v) * width];
      float* o = &tmp[static_cast<size_t>(v) * width];
      for (int u = 0; u < width; ++u) {
        float m = 0;
        for (int x = std::max(0, u - w); x <= std::min(width - 1, u + w); ++x)
          m = std::max(m, in[x]);
        o[u] = m;
      }
    }
    for (int v = 0; v < height; ++v) {
      for (int u = 0; u < width; ++u) {
        float m = 0;
        for (int y = std::max(0, v - w); y <= std::min(height - 1, v + w); ++y) {
          m = std::max(m, tmp[static_cast<size_t>(y) * width + u]);
        }
        ratio[static_cast<size_t>(v) * width + u] = m;
      }
    }
  }
  const bool view_test = options.max_view_angle_deg < 90;
  const float cos_view = std::cos(std::clamp(options.max_view_angle_deg, 0.0f, 90.0f) *
                                  std::numbers::pi_v<float> / 180);
  out->assign(pixels, 0.0f);
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      const size_t p = static_cast<size_t>(v) * width + u;
      const float* n = &normals[3 * p];
      if (!(depth[p] > 0) || (n[0] == 0 && n[1] == 0 && n[2] == 0)) continue;
      if (view_test) {
        const float rx = static_cast<float>((u - k.cx) / k.fx),
                    ry = static_cast<float>((v - k.cy) / k.fy);
        const float c = -(n[0] * rx + n[1] * ry + n[2]) / std::sqrt(rx * rx + ry * ry + 1);
        if (c < cos_view) continue;
      }
      const float r2 = ratio[p] * ratio[p];
      (*out)[p] = 1.0f / (1.0f + r2 * r2);
    }
  }
}

}  // namespace probeless::light

namespace probeless::light {

void NormalsWithReliability(std::span<const float> depth, int width, int height,
                            const Intrinsics& k, const DepthNormalOptions& options,
                            std::vector<float>* normals, std::vector<float>* reliability) {
  const size_t pixels = static_cast<size_t>(std::max(width, 0)) * std::max(height, 0);
  if (width < 1 || height < 1 || depth.size() != pixels) {
    throw LightError("light::NormalsWithReliability: depth has " + std::to_string(depth.size()) +
                     " values, expected " + std::to_string(width) + "x" + std::to_string(height));
  }
  if (!std::isfinite(k.fx) || !std::isfinite(k.fy) || !std::isfinite(k.cx) ||
      !std::isfinite(k.cy) || !(k.fx > 0) || !(k.fy > 0)) {
    throw LightError("light::NormalsWithReliability: intrinsics must be finite with fx, fy > 0");
  }
  if (options.step < 1 || !(options.threshold_sigma > 0) || !(options.min_radius_m > 0) ||
      !(options.noise_m >= 0) || !(options.noise_quadratic >= 0)) {
    throw LightError(
        "light::NormalsWithReliability: step must be >= 1, threshold_sigma and min_radius_m > 0, "
        "noise >= 0");
  }
  normals->assign(3 * pixels, 0.0f);
  reliability->assign(pixels, 0.0f);
  const int s = options.step;
  const float f = static_cast<float>(0.5 * (k.fx + k.fy));
  const float noise_scale = options.threshold_sigma * std::sqrt(6.0f);
  const float inv_r = 1.0f / options.min_radius_m;
  const bool view_test = options.max_view_angle_deg < 90;
  const float cos_view = std::cos(std::clamp(options.max_view_angle_deg, 0.0f, 90.0f) *
                                  std::numbers::pi_v<float> / 180);
  // Inverse depth (0 = none).
  std::vector<float> inv(pixels, 0.0f);
  for (size_t p = 0; p < pixels; ++p) inv[p] = depth[p] > 0 ? 1.0f / depth[p] : 0.0f;
  auto point = [&](int u, int v, float out[3]) {
    k.BackProject(u, v, depth[static_cast<size_t>(v) * width + u], out);
  };
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      const size_t p = static_cast<size_t>(v) * width + u;
      const float z = depth[p];
      if (!(z > 0)) continue;
      const float sigma = options.noise_m + options.noise_quadratic * z * z;
      const float lateral = s * z / f;
      // Allowed second difference of 1/z (the depth allowance / z^2).
      const float allowed = (noise_scale * sigma + lateral * lateral * inv_r) / (z * z);
      float tangent[2][3];
      float worst = 0;
      bool ok = true;
      for (int axis = 0; axis < 2 && ok; ++axis) {
        const int du = axis == 0 ? 1 : 0, dv = axis == 0 ? 0 : 1;
        // Inverse depth at offsets -2s .. 2s along the axis (0 = none or off the image).
        float d[5];
        for (int j = -2; j <= 2; ++j) {
          const int uu = u + j * s * du, vv = v + j * s * dv;
          d[j + 2] = uu < 0 || vv < 0 || uu >= width || vv >= height
                         ? 0.0f
                         : inv[static_cast<size_t>(vv) * width + uu];
        }
        constexpr float kNone = 1e30f;
        const float c = d[1] > 0 && d[3] > 0 ? std::abs(d[1] - 2 * d[2] + d[3]) : kNone;
        // A one-sided difference without its third sample (a hole or the border beyond) has no
        // continuity evidence: it counts as at the allowance (reliability 0.5 at most), not as
        // exact.
        const float l = d[1] > 0 ? (d[0] > 0 ? std::abs(d[0] - 2 * d[1] + d[2]) : allowed) : kNone;
        const float r = d[3] > 0 ? (d[4] > 0 ? std::abs(d[2] - 2 * d[3] + d[4]) : allowed) : kNone;
        int a, b;  // the two samples (offsets in steps) of the chosen difference
        float residual;
        if (c <= allowed) {
          a = -1, b = 1, residual = c;
        } else if (l < kNone && l <= r) {
          a = -1, b = 0, residual = l;
        } else if (r < kNone) {
          a = 0, b = 1, residual = r;
        } else {
          ok = false;
          break;
        }
        worst = std::max(worst, residual / allowed);
        float pa[3], pb[3];
        point(u + a * s * du, v + a * s * dv, pa);
        point(u + b * s * du, v + b * s * dv, pb);
        for (int i = 0; i < 3; ++i) tangent[axis][i] = pb[i] - pa[i];
      }
      if (!ok) continue;
      const float* ex = tangent[0];
      const float* ey = tangent[1];
      float n[3] = {-(ex[1] * ey[2] - ex[2] * ey[1]), -(ex[2] * ey[0] - ex[0] * ey[2]),
                    -(ex[0] * ey[1] - ex[1] * ey[0])};
      const float len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
      if (!(len > 0)) continue;
      const float rx = static_cast<float>((u - k.cx) / k.fx),
                  ry = static_cast<float>((v - k.cy) / k.fy);
      const float towards = n[0] * rx + n[1] * ry + n[2];
      const float sign = towards > 0 ? -1.0f : 1.0f;  // face the camera
      float* dst = normals->data() + 3 * p;
      for (int i = 0; i < 3; ++i) dst[i] = sign * n[i] / len;
      const float cos_angle = std::abs(towards) / len / std::sqrt(rx * rx + ry * ry + 1);
      if (view_test && cos_angle < cos_view) continue;
      const float w2 = worst * worst;
      (*reliability)[p] = 1.0f / (1.0f + w2 * w2);
    }
  }
}

}  // namespace probeless::light

namespace probeless::light {

float DepthNoiseQuadratic(std::span<const float> depth, int width, int height) {
  if (width < 1 || height < 1 || depth.size() != static_cast<size_t>(width) * height) {
    throw LightError("light::DepthNoiseQuadratic: depth has " + std::to_string(depth.size()) +
                     " values, expected " + std::to_string(width) + "x" + std::to_string(height));
  }
  double sum = 0;
  size_t count = 0, candidates = 0;
  for (int v = 0; v < height; v += 2) {
    const float* row = depth.data() + static_cast<size_t>(v) * width;
    for (int u = 1; u + 1 < width; ++u) {
      const float z = row[u], za = row[u - 1], zb = row[u + 1];
      if (!(z > 1.5f) || !(za > 0) || !(zb > 0)) continue;
      const float e = (1.0f / za - 2.0f / z + 1.0f / zb) * z * z;
      if (!(std::abs(e) < 0.02f * z)) continue;  // a depth edge
      ++candidates;
      // Zero second differences (a quantised plateau, or a plane) are left out, so that
      // quantisation counts with its step size however rarely the steps occur.
      if (!(std::abs(e) > 1e-5f * z)) continue;
      const double q = e / (double(z) * z);
      sum += q * q;
      ++count;
    }
  }
  if (candidates < 1000) return std::numeric_limits<float>::quiet_NaN();  // too little far depth
  // Mostly plateaus and planes: a clean image (the few departures are curvature, not noise).
  if (count < 1000) return 0.0f;
  return static_cast<float>(std::sqrt(sum / count / 6.0));
}

float DepthGeometry(std::span<float> depth, int width, int height, const Intrinsics& k,
                    const DepthGeometryOptions& options, std::vector<float>* normals,
                    std::vector<float>* reliability) {
  const std::string what = "light::DepthGeometry: ";
  if (normals == nullptr) throw LightError(what + "normals must not be null");
  if (options.smooth_radius < -1) {
    throw LightError(what + "smooth_radius must be -1 (by the noise) or >= 0, got " +
                     std::to_string(options.smooth_radius));
  }
  if (options.step == 0 || options.step < -1) {
    throw LightError(what + "step must be -1 (by the noise) or >= 1, got " +
                     std::to_string(options.step));
  }
  if (!(options.fine_noise_quadratic >= 0) || !(options.smoothed_noise_quadratic > 0)) {
    throw LightError(what + "fine_noise_quadratic must be >= 0 and smoothed_noise_quadratic > 0");
  }
  const bool automatic =
      options.normals_from == DepthNormals::kAuto || options.smooth_radius < 0 ||
      options.step < 0 ||
      (options.normals_from == DepthNormals::kEdge && options.normals.noise_quadratic < 0);
  const float noise = automatic ? DepthNoiseQuadratic(depth, width, height)
                                : std::numeric_limits<float>::quiet_NaN();
  // Unmeasured noise (too little depth beyond 1.5 m) counts as noisy: the conservative choice.
  const bool fine = std::isfinite(noise) && noise < options.fine_noise_quadratic;
  const bool edge = options.normals_from == DepthNormals::kEdge ||
                    (options.normals_from == DepthNormals::kAuto && fine);
  if (!edge) {
    const int radius = options.smooth_radius >= 0 ? options.smooth_radius : std::max(1, width / 80);
    const int step = options.step >= 1 ? options.step : std::max(2, width / 160);
    if (radius > 0) SmoothDepth(depth, width, height, radius);
    NormalsFromDepth(depth, width, height, k, normals, 0.05f, step);
    if (reliability != nullptr) {
      reliability->assign(depth.size(), 0.0f);
      for (size_t p = 0; p < depth.size(); ++p) {
        const float* n = &(*normals)[3 * p];
        if (n[0] != 0 || n[1] != 0 || n[2] != 0) (*reliability)[p] = 1.0f;
      }
    }
    return noise;
  }
  const int radius =
      options.smooth_radius >= 0 ? options.smooth_radius : (fine ? 0 : std::max(1, width / 160));
  DepthNormalOptions no = options.normals;
  no.step = options.step >= 1 ? options.step
                              : (fine ? std::max(1, width / 320) : std::max(2, width / 160));
  if (no.noise_quadratic < 0) {
    no.noise_quadratic =
        radius > 0 || !std::isfinite(noise) ? options.smoothed_noise_quadratic : noise;
  }
  if (radius > 0) SmoothDepth(depth, width, height, radius);
  std::vector<float> scratch;
  NormalsWithReliability(depth, width, height, k, no, normals,
                         reliability != nullptr ? reliability : &scratch);
  return noise;
}

}  // namespace probeless::light
