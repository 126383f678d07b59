#include "probeless/light/fusion.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <vector>

namespace probeless::light {

namespace {

constexpr double kMaxConfidence = 0.999;  // keeps the weight c / (1 - c) finite

std::string Name(const FusionInput& input, size_t index) {
  return input.name.empty() ? "input " + std::to_string(index) : "'" + input.name + "'";
}

double AngleDeg(const float* a, const float* b) {
  const double na = std::sqrt(double(a[0]) * a[0] + double(a[1]) * a[1] + double(a[2]) * a[2]);
  const double nb = std::sqrt(double(b[0]) * b[0] + double(b[1]) * b[1] + double(b[2]) * b[2]);
  if (!(na > 1e-6) || !(nb > 1e-6)) return 0;  // no direction: nothing to disagree about
  const double dot = (double(a[0]) * b[0] + double(a[1]) * b[1] + double(a[2]) * b[2]) / (na * nb);
  return std::acos(std::clamp(dot, -1.0, 1.0)) * 180 / std::numbers::pi;
}

}  // namespace

double ConfidenceFromExpectedError(double error_deg) {
  return msgs::ShLightConfidenceFromExpectedError(error_deg);
}

double ExpectedErrorFromConfidence(double confidence) {
  if (!(confidence > 0)) return std::numeric_limits<double>::infinity();
  const double c = std::min(confidence, 1.0);
  return kConfidenceReferenceErrorDeg * std::sqrt((1 - c) / c);
}

double UncertaintyBandFactor(double confidence, double blur, int band) {
  if (band <= 0 || !(blur > 0)) return 1;
  const double e = ExpectedErrorFromConfidence(confidence) * std::numbers::pi / 180;
  if (std::isinf(e)) return 0;
  const double sigma = blur * e / std::sqrt(2 * std::log(2.0));
  return std::exp(-0.5 * band * (band + 1) * sigma * sigma);
}

namespace {

// The band loop of both layouts: scale(coefficient, factor) for every coefficient of band >= 1.
template <class Coefficient, class Scale>
void ScaleBands(std::span<Coefficient> coefficients, double confidence, double blur, Scale scale) {
  for (size_t k = 1; k < coefficients.size(); ++k) {
    const int band = static_cast<int>(std::sqrt(static_cast<double>(k)));
    scale(coefficients[k], UncertaintyBandFactor(confidence, blur, band));
  }
}

}  // namespace

void BlurByUncertainty(std::span<double> coefficients, double confidence, double blur) {
  ScaleBands(coefficients, confidence, blur, [](double& c, double f) { c *= f; });
}

void BlurByUncertainty(std::span<std::array<float, 3>> coefficients, double confidence,
                       double blur) {
  ScaleBands(coefficients, confidence, blur, [](std::array<float, 3>& c, double f) {
    for (float& channel : c) channel *= static_cast<float>(f);
  });
}

ConfidenceCalibration::ConfidenceCalibration(std::span<const double> knots) {
  if (knots.size() % 2 != 0) {
    throw FusionError("confidence calibration: " + std::to_string(knots.size()) +
                      " values, expected pairs (raw confidence, expected error in degrees)");
  }
  for (size_t k = 0; k < knots.size(); k += 2) {
    const double raw = knots[k], error = knots[k + 1];
    if (!(raw >= 0 && raw <= 1) || (!raw_.empty() && !(raw > raw_.back())) || !(error > 0)) {
      throw FusionError(
          "confidence calibration: knot " + std::to_string(k / 2) +
          " needs a raw confidence in [0, 1] above the previous one and an error > 0");
    }
    raw_.push_back(raw);
    error_deg_.push_back(error);
  }
}

double ConfidenceCalibration::Apply(double raw_confidence) const {
  if (raw_.empty()) return raw_confidence;
  if (!(raw_confidence > raw_.front())) return ConfidenceFromExpectedError(error_deg_.front());
  for (size_t k = 1; k < raw_.size(); ++k) {
    if (raw_confidence <= raw_[k]) {
      const double t = (raw_confidence - raw_[k - 1]) / (raw_[k] - raw_[k - 1]);
      return ConfidenceFromExpectedError(error_deg_[k - 1] +
                                         t * (error_deg_[k] - error_deg_[k - 1]));
    }
  }
  return ConfidenceFromExpectedError(error_deg_.back());
}

std::optional<msgs::ShLight> FuseLights(std::span<const FusionInput> inputs,
                                        const FusionOptions& options) {
  if (inputs.empty()) return std::nullopt;
  int64_t newest = inputs[0].light.header.stamp_ns;
  for (size_t i = 0; i < inputs.size(); ++i) {
    const msgs::ShLight& in = inputs[i].light;
    in.Validate();
    if (in.units != msgs::ShLightUnits::kLinear) {
      throw FusionError("light fusion: " + Name(inputs[i], i) + " is in " +
                        std::string(msgs::ShLightUnitsName(in.units)) +
                        " units, expected linear radiance (msgs::ShLight); not averaged");
    }
    if (in.header.FrameId() != inputs[0].light.header.FrameId()) {
      throw FusionError("light fusion: inputs in different frames ('" +
                        std::string(inputs[0].light.header.FrameId()) + "' and '" +
                        std::string(in.header.FrameId()) + "'); expected one frame");
    }
    newest = std::max(newest, in.header.stamp_ns);
  }
  std::vector<const msgs::ShLight*> candidates;
  for (const auto& input : inputs) {
    const msgs::ShLight& in = input.light;
    if (newest - in.header.stamp_ns > options.max_age_ns) continue;
    if (!(in.confidence >= options.min_confidence)) continue;
    candidates.push_back(&in);
  }
  // Most confident first (stable: ties keep the input order), each kept only if it agrees with
  // every input kept before it.
  std::stable_sort(candidates.begin(), candidates.end(),
                   [](const auto* a, const auto* b) { return a->confidence > b->confidence; });
  std::vector<const msgs::ShLight*> used;
  for (const auto* in : candidates) {
    bool consistent = true;
    for (const auto* kept : used) {
      if (!(options.consistency_sigma > 0)) break;
      const double ea = ExpectedErrorFromConfidence(in->confidence);
      const double eb = ExpectedErrorFromConfidence(kept->confidence);
      if (AngleDeg(in->dominant_direction, kept->dominant_direction) >
          options.consistency_sigma * std::sqrt(ea * ea + eb * eb)) {
        consistent = false;
      }
    }
    if (consistent) used.push_back(in);
  }
  if (used.empty()) return std::nullopt;

  msgs::ShLight out;
  const msgs::ShLight* newest_input = *std::max_element(
      used.begin(), used.end(),
      [](const auto* a, const auto* b) { return a->header.stamp_ns < b->header.stamp_ns; });
  out.header = newest_input->header;
  out.units = msgs::ShLightUnits::kLinear;
  for (const auto* in : used) out.bands = std::max(out.bands, in->bands);
  double sums[msgs::kMaxShCoefficients][3] = {};
  double direction[3] = {};
  double intensity = 0;
  double total = 0;
  for (const auto* in : used) {
    const double c = std::min<double>(in->confidence, kMaxConfidence);
    const double w = c / (1 - c);
    for (uint32_t i = 0; i < in->CoefficientCount(); ++i) {
      for (int ch = 0; ch < 3; ++ch) sums[i][ch] += w * in->coefficients[i][ch];
    }
    const double n = std::sqrt(in->dominant_direction[0] * in->dominant_direction[0] +
                               in->dominant_direction[1] * in->dominant_direction[1] +
                               in->dominant_direction[2] * in->dominant_direction[2]);
    if (n > 1e-6) {
      for (int k = 0; k < 3; ++k) direction[k] += w * in->dominant_direction[k] / n;
    }
    intensity += w * in->intensity;
    total += w;
  }
  for (uint32_t i = 0; i < out.CoefficientCount(); ++i) {
    for (int ch = 0; ch < 3; ++ch)
      out.coefficients[i][ch] = static_cast<float>(sums[i][ch] / total);
  }
  const double n = std::sqrt(direction[0] * direction[0] + direction[1] * direction[1] +
                             direction[2] * direction[2]);
  for (int k = 0; k < 3; ++k) {
    out.dominant_direction[k] = n > 1e-9 ? static_cast<float>(direction[k] / n) : 0.0f;
  }
  out.intensity = static_cast<float>(intensity / total);
  out.confidence = static_cast<float>(std::clamp(total / (1 + total), 0.0, 1.0));
  return out;
}

}  // namespace probeless::light
