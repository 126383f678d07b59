#include "probeless/face_track/light_output.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <opencv2/core.hpp>
#include <span>
#include <stdexcept>

#include "probeless/error/error.h"
#include "probeless/sh/sh.h"

namespace probeless::face_track {

namespace fl = face_light;

Sh9Rgb RotateSh9(const Sh9Rgb& c, const std::array<double, 9>& r) {
  // c' = pinv(Y) Y_rot c with Y[k][n] = Y_n(d_k), Y_rot[k][m] = Y_m(R^T d_k): exact for bands
  // 0..2 (rotations keep bands) given enough well-spread directions.
  static const std::vector<sh::Vec3> directions = sh::FibonacciSphere(64);
  const int k = static_cast<int>(directions.size());
  cv::Mat y(k, 9, CV_64F), yr(k, 9, CV_64F);
  for (int i = 0; i < k; ++i) {
    const sh::Vec3& d = directions[i];
    const sh::Vec3 back{r[0] * d[0] + r[3] * d[1] + r[6] * d[2],
                        r[1] * d[0] + r[4] * d[1] + r[7] * d[2],
                        r[2] * d[0] + r[5] * d[1] + r[8] * d[2]};
    const auto a = sh::Basis9(d);
    const auto b = sh::Basis9(back);
    for (int n = 0; n < 9; ++n) {
      y.at<double>(i, n) = a[n];
      yr.at<double>(i, n) = b[n];
    }
  }
  cv::Mat m;
  cv::solve(y, yr, m, cv::DECOMP_SVD);  // 9 x 9: c' = m c
  Sh9Rgb out{};
  for (int n = 0; n < 9; ++n) {
    for (int ch = 0; ch < 3; ++ch) {
      double v = 0;
      for (int j = 0; j < 9; ++j) v += m.at<double>(n, j) * c[j][ch];
      out[n][ch] = static_cast<float>(v);
    }
  }
  return out;
}

std::array<float, 3> RotateVector(const std::array<double, 9>& r, const std::array<float, 3>& v) {
  return {static_cast<float>(r[0] * v[0] + r[1] * v[1] + r[2] * v[2]),
          static_cast<float>(r[3] * v[0] + r[4] * v[1] + r[5] * v[2]),
          static_cast<float>(r[6] * v[0] + r[7] * v[1] + r[8] * v[2])};
}

std::array<float, 3> LightColour(const Sh9Rgb& c) {
  const double mean = (c[0][0] + c[0][1] + c[0][2]) / 3.0;
  if (!(mean > 0)) return {1, 1, 1};
  return {static_cast<float>(c[0][0] / mean), static_cast<float>(c[0][1] / mean),
          static_cast<float>(c[0][2] / mean)};
}

namespace {

// Direction and power of the channel-mean light (as FaceLightEstimator computes them).
void Derive(fl::LightEstimate& e) {
  std::array<double, 9> mean{};
  for (int n = 0; n < 9; ++n) {
    mean[n] = (e.coefficients[n][0] + e.coefficients[n][1] + e.coefficients[n][2]) / 3.0;
  }
  const sh::Vec3 d = sh::OptimalLinearDirection(mean.data());
  e.dominant_direction = {static_cast<float>(d[0]), static_cast<float>(d[1]),
                          static_cast<float>(d[2])};
  e.intensity = (d[0] == 0 && d[1] == 0 && d[2] == 0)
                    ? 0.f
                    : static_cast<float>(sh::DirectionalPower(mean, d));
}

std::array<double, 4> MeanBands01(const fl::LightEstimate& e) {
  std::array<double, 4> v{};
  for (int n = 0; n < 4; ++n) {
    v[n] = (e.coefficients[n][0] + e.coefficients[n][1] + e.coefficients[n][2]) / 3.0;
  }
  return v;
}

}  // namespace

fl::LightEstimate LightSmoother::Update(const fl::LightEstimate& estimate) {
  last_jumped_ = false;
  if (estimate.channels == 0) {
    Miss();
    return has_state_ ? state_ : estimate;
  }
  if (!options_.enabled) return estimate;
  bool jump = !has_state_ || gap_ > options_.max_gap;
  if (!jump) {
    // Relative change of the ambient (band 0) and directional (band-1 vector) parts.
    const auto a = MeanBands01(state_);
    const auto b = MeanBands01(estimate);
    const double e0 = std::abs(b[0] - a[0]) / std::max({std::abs(a[0]), std::abs(b[0]), 1e-9});
    const double d1 = std::sqrt((b[1] - a[1]) * (b[1] - a[1]) + (b[2] - a[2]) * (b[2] - a[2]) +
                                (b[3] - a[3]) * (b[3] - a[3]));
    const double na = std::sqrt(a[1] * a[1] + a[2] * a[2] + a[3] * a[3]);
    const double nb = std::sqrt(b[1] * b[1] + b[2] * b[2] + b[3] * b[3]);
    const double e1 = d1 / std::max({na, nb, 1e-9});
    jump = std::max(e0, e1) > options_.change_threshold;
  }
  gap_ = 0;
  if (jump) {
    state_ = estimate;
    has_state_ = true;
    last_jumped_ = true;
    return state_;
  }
  const float alpha = static_cast<float>(options_.alpha);
  for (int n = 0; n < 9; ++n) {
    for (int c = 0; c < 3; ++c) {
      state_.coefficients[n][c] =
          alpha * estimate.coefficients[n][c] + (1 - alpha) * state_.coefficients[n][c];
    }
  }
  state_.confidence = alpha * estimate.confidence + (1 - alpha) * state_.confidence;
  state_.channels = estimate.channels;
  state_.samples_used = estimate.samples_used;
  state_.samples_rejected = estimate.samples_rejected;
  state_.rms_residual = estimate.rms_residual;
  Derive(state_);
  return state_;
}

LightHold::LightHold(const HoldOptions& options) : options_(options) {
  if (!(options_.min_confidence >= 0 && options_.min_confidence <= 1) ||
      !(options_.blend_time_s > 0)) {
    throw InputError("LightHold: min_confidence must be in [0, 1] and blend_time_s > 0");
  }
}

LightHold::Output LightHold::Update(const Sh9Rgb& coefficients,
                                    const std::array<float, 3>& direction, float intensity,
                                    float confidence, int64_t stamp_ns) {
  Output out;
  if (confidence >= options_.min_confidence) {
    has_light_ = true;
    held_ = coefficients;
    direction_ = direction;
    intensity_ = intensity;
    stamp_ns_ = stamp_ns;
    out.coefficients = coefficients;
    out.direction = direction;
    out.intensity = intensity;
    return out;
  }
  out.held = true;
  if (!has_light_) {
    // Nothing trustworthy yet: the environment part only, no direction.
    for (int c = 0; c < 3; ++c) out.coefficients[0][c] = coefficients[0][c];
    out.weight = 0;
    return out;
  }
  const double age_s = std::max<int64_t>(0, stamp_ns - stamp_ns_) * 1e-9;
  out.weight = std::exp(-age_s / options_.blend_time_s);
  const float w = static_cast<float>(out.weight);
  for (int n = 0; n < 9; ++n) {
    for (int c = 0; c < 3; ++c) out.coefficients[n][c] = n == 0 ? held_[0][c] : w * held_[n][c];
  }
  if (w > 0) out.direction = direction_;
  out.intensity = w * intensity_;
  return out;
}

Sh9Rgb ToYUpFrame(const Sh9Rgb& c) {
  // Camera (x right, y down, z forward) -> y up, z towards the viewer: diag(1, -1, -1).
  Sh9Rgb out = RotateSh9(c, {1, 0, 0, 0, -1, 0, 0, 0, -1});
  // Drop the Condon-Shortley phase: odd-m basis functions change sign.
  for (int n : {1, 3, 5, 7}) {
    for (int ch = 0; ch < 3; ++ch) out[n][ch] = -out[n][ch];
  }
  return out;
}

namespace {
void AppendFloat(std::string& s, double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.7g", std::isfinite(v) ? v : 0.0);
  s += buf;
}
void AppendArray(std::string& s, std::span<const float> v) {
  s += '[';
  for (size_t i = 0; i < v.size(); ++i) {
    if (i) s += ',';
    AppendFloat(s, v[i]);
  }
  s += ']';
}
std::string Escape(const std::string& in) {
  std::string out;
  for (char ch : in) {
    if (ch == '"' || ch == '\\') out += '\\';
    if (static_cast<unsigned char>(ch) >= 0x20) out += ch;
  }
  return out;
}
}  // namespace

std::string LightJson(const Sh9Rgb& coefficients_camera, const std::array<float, 3>& direction,
                      float intensity, float confidence, const std::array<float, 3>& colour,
                      int64_t stamp_ns, const std::string& frame_id, msgs::ShLightUnits units) {
  if (units != msgs::ShLightUnits::kLinear) {
    const std::string_view name = msgs::ShLightUnitsName(units);
    throw InputError(
        "LightJson: the ARKit and WebXR exports take linear radiance, got " +
        (name.empty() ? std::to_string(static_cast<uint32_t>(units)) : std::string(name)) +
        " units");
  }
  const Sh9Rgb y_up = ToYUpFrame(coefficients_camera);
  std::string s = "{\"stamp_ns\":" + std::to_string(stamp_ns) + ",\"frame_id\":\"" +
                  Escape(frame_id) + "\",\"units\":\"linear\",\"confidence\":";
  AppendFloat(s, confidence);
  s += ",\"intensity\":";
  AppendFloat(s, intensity);
  s += ",\"dominant_direction\":";
  AppendArray(s, direction);
  s += ",\"colour\":";
  AppendArray(s, colour);
  s += ",\"arkit\":{\"sphericalHarmonicsCoefficients\":[";
  for (int c = 0; c < 3; ++c) {
    std::array<float, 9> plane{};
    for (int n = 0; n < 9; ++n) plane[n] = y_up[n][c];
    if (c) s += ',';
    AppendArray(s, plane);
  }
  s += "]},\"webxr\":{\"sphericalHarmonicsCoefficients\":";
  std::array<float, 27> interleaved{};
  for (int n = 0; n < 9; ++n) {
    for (int c = 0; c < 3; ++c) interleaved[3 * n + c] = y_up[n][c];
  }
  AppendArray(s, interleaved);
  s += "}}";
  return s;
}

}  // namespace probeless::face_track
