#include "probeless/light/fusion.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace probeless::light {

std::optional<msgs::ShLight> FuseLights(std::span<const msgs::ShLight> inputs,
                                        const FusionOptions& options) {
  if (inputs.empty()) return std::nullopt;
  int64_t newest = inputs[0].header.stamp_ns;
  for (const auto& in : inputs) {
    in.Validate();
    if (in.header.FrameId() != inputs[0].header.FrameId()) {
      throw FusionError("light fusion: inputs in different frames ('" +
                        std::string(inputs[0].header.FrameId()) + "' and '" +
                        std::string(in.header.FrameId()) + "'); expected one frame");
    }
    newest = std::max(newest, in.header.stamp_ns);
  }
  std::vector<const msgs::ShLight*> used;
  for (const auto& in : inputs) {
    if (newest - in.header.stamp_ns > options.max_age_ns) continue;
    if (!(in.confidence >= options.min_confidence)) continue;
    used.push_back(&in);
  }
  if (used.empty()) return std::nullopt;

  msgs::ShLight out;
  const msgs::ShLight* newest_input = *std::max_element(
      used.begin(), used.end(),
      [](const auto* a, const auto* b) { return a->header.stamp_ns < b->header.stamp_ns; });
  out.header = newest_input->header;
  for (const auto* in : used) out.bands = std::max(out.bands, in->bands);
  double weight_sum[msgs::kMaxShCoefficients] = {};
  double sums[msgs::kMaxShCoefficients][3] = {};
  double direction[3] = {};
  double intensity = 0;
  double total = 0;
  double miss = 1;
  for (const auto* in : used) {
    const double w = in->confidence;
    for (uint32_t i = 0; i < in->CoefficientCount(); ++i) {
      weight_sum[i] += w;
      for (int c = 0; c < 3; ++c) sums[i][c] += w * in->coefficients[i][c];
    }
    const double n = std::sqrt(in->dominant_direction[0] * in->dominant_direction[0] +
                               in->dominant_direction[1] * in->dominant_direction[1] +
                               in->dominant_direction[2] * in->dominant_direction[2]);
    if (n > 1e-6) {
      for (int k = 0; k < 3; ++k) direction[k] += w * in->dominant_direction[k] / n;
    }
    intensity += w * in->intensity;
    total += w;
    miss *= 1.0 - w;
  }
  for (uint32_t i = 0; i < out.CoefficientCount(); ++i) {
    for (int c = 0; c < 3; ++c) {
      out.coefficients[i][c] =
          weight_sum[i] > 0 ? static_cast<float>(sums[i][c] / weight_sum[i]) : 0;
    }
  }
  const double n = std::sqrt(direction[0] * direction[0] + direction[1] * direction[1] +
                             direction[2] * direction[2]);
  for (int k = 0; k < 3; ++k) {
    out.dominant_direction[k] = n > 1e-9 ? static_cast<float>(direction[k] / n) : 0.0f;
  }
  out.intensity = static_cast<float>(intensity / total);
  out.confidence = static_cast<float>(std::clamp(1.0 - miss, 0.0, 1.0));
  return out;
}

}  // namespace probeless::light
