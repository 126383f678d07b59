// ShLight: incident lighting as RGB spherical-harmonic coefficients.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "probeless/msgs/header.h"
#include "probeless/msgs/layout.h"

namespace probeless::msgs {

inline constexpr uint32_t kMaxShBands = 5;
inline constexpr uint32_t kMaxShCoefficients = kMaxShBands * kMaxShBands;  // 25

// Coefficients of `bands` SH bands (degrees 0..bands-1): bands^2.
constexpr uint32_t ShCoefficientCount(uint32_t bands) { return bands * bands; }

// Index of the basis function of degree l (0..4) and order m (-l..l): l*(l+1)+m.
constexpr uint32_t ShIndex(uint32_t l, int32_t m) {
  return static_cast<uint32_t>(static_cast<int32_t>(l * (l + 1)) + m);
}

// What a light's coefficients and intensity are measured in (ShLight::units).
enum class ShLightUnits : uint32_t {
  // Not stated: a message recorded before the field existed (its reserved zero). Consumers apply
  // their documented default (docs/messages.md, "ShLight").
  kUnknown = 0,
  // Linear RGB radiance in the units of the camera's image intensities at its exposure (the
  // contract below): what scene_light, face_light (linear_output) and light_fusion publish.
  kLinear = 1,
  // A face model's albedo-normalised, compressed I^g units (face_light linear_output false): only
  // the direction is meaningful; never combine or shade with it as radiance.
  kFaceModel = 2,
  // Linear in shape but of arbitrary scale (e.g. a data set's unit-intensity directional light):
  // direction and relative coefficients are meaningful, the magnitude is not.
  kLinearUnscaled = 3,
};
constexpr std::string_view DescribeEnum(ShLightUnits) {
  return "ShLightUnits{unknown=0,linear=1,face_model=2,linear_unscaled=3}";
}

// "unknown", "linear", "face_model", "linear_unscaled"; "" for a value outside the enum.
constexpr std::string_view ShLightUnitsName(ShLightUnits units) {
  switch (units) {
    case ShLightUnits::kUnknown:
      return "unknown";
    case ShLightUnits::kLinear:
      return "linear";
    case ShLightUnits::kFaceModel:
      return "face_model";
    case ShLightUnits::kLinearUnscaled:
      return "linear_unscaled";
  }
  return "";
}

// The units named `name` (ShLightUnitsName); throws MessageError naming the accepted names.
inline ShLightUnits ShLightUnitsFromName(std::string_view name) {
  for (ShLightUnits u : {ShLightUnits::kUnknown, ShLightUnits::kLinear, ShLightUnits::kFaceModel,
                         ShLightUnits::kLinearUnscaled}) {
    if (ShLightUnitsName(u) == name) return u;
  }
  throw MessageError("probeless_msgs/ShLight: units '" + std::string(name) +
                     "' is not unknown, linear, face_model or linear_unscaled");
}

// Distant incident lighting around a point, as seen in frame header.frame_id (camera optical frame
// or a world frame; directions are expressed in it).
//
// Convention (docs/messages.md, "Spherical harmonics"): real, orthonormal SH basis Y_lm over the
// unit sphere, Condon-Shortley phase included (so Y_1,-1 = -sqrt(3/(4 pi)) y and
// Y_1,1 = -sqrt(3/(4 pi)) x for a unit direction (x, y, z)), coefficient index l*(l+1)+m.
// Incident radiance from unit direction w (pointing from the lit point towards the light) is
// L_c(w) = sum_i coefficients[i][c] * Y_i(w), c = 0, 1, 2 for linear R, G, B, in the linear units
// of the camera's image intensities (1 = a white Lambertian surface of albedo 1 facing a uniform
// radiance of 1 reads as full scale) when units is kLinear; `units` says what a producer
// publishes, and consumers check it.
// The one confidence scale of ShLight (docs/messages.md): confidence c <-> expected RMS angular
// error e of the dominant direction, c = 1 / (1 + (e / kShLightReferenceErrorDeg)^2) (c = 0.5 at
// 10 deg, 0.2 at 20 deg, 0.05 at 44 deg); c / (1 - c) = (10 deg / e)^2 is the estimate's
// inverse-variance weight. e in degrees (>= 0; +inf or NaN -> 0) -> c in [0, 1].
inline constexpr double kShLightReferenceErrorDeg = 10;
inline double ShLightConfidenceFromExpectedError(double error_deg) {
  if (!(error_deg >= 0)) return 0;
  const double r = error_deg / kShLightReferenceErrorDeg;
  return 1 / (1 + r * r);
}

struct ShLight {
  Header header;
  uint32_t bands = 0;  // 1..5; coefficient count bands^2 (1, 4, 9, 16, 25)
  // Units of coefficients and intensity; kUnknown (0) in messages recorded before the field.
  ShLightUnits units = ShLightUnits::kUnknown;
  // coefficients[l*(l+1)+m][c]; entries at or beyond bands^2 are zero.
  float coefficients[kMaxShCoefficients][3] = {};
  // Unit direction towards the dominant light (from the scene to the light) in header.frame_id;
  // (0, 0, 0) if there is no dominant direction (e.g. uniform light).
  float dominant_direction[3] = {};
  // Radiance of the dominant light in the same linear units as the coefficients (mean of R, G, B).
  float intensity = 0;
  // Confidence of the estimate in [0, 1] (0 = no information, 1 = certain), on one scale for
  // every producer: ShLightConfidenceFromExpectedError.
  float confidence = 0;

  static constexpr std::string_view kTypeName = "probeless_msgs/ShLight";
  static constexpr bool kHasPayload = false;
  static const uint64_t kLayoutHash;
  static constexpr std::string LayoutDescription() {
    layout::LayoutBuilder b(kTypeName);
    PROBELESS_MSGS_FIELD(b, ShLight, header);
    PROBELESS_MSGS_FIELD(b, ShLight, bands);
    PROBELESS_MSGS_FIELD(b, ShLight, units);
    PROBELESS_MSGS_FIELD(b, ShLight, coefficients);
    PROBELESS_MSGS_FIELD(b, ShLight, dominant_direction);
    PROBELESS_MSGS_FIELD(b, ShLight, intensity);
    PROBELESS_MSGS_FIELD(b, ShLight, confidence);
    return b.Finish<ShLight>();
  }

  // bands^2.
  constexpr uint32_t CoefficientCount() const { return ShCoefficientCount(bands); }

  // Throws MessageError unless 1 <= bands <= 5, units is a ShLightUnits value and confidence
  // is in [0, 1].
  void Validate() const {
    if (bands < 1 || bands > kMaxShBands) {
      throw MessageError(std::string(kTypeName) + ": bands " + std::to_string(bands) +
                         " out of range 1..5");
    }
    if (ShLightUnitsName(units).empty()) {
      throw MessageError(std::string(kTypeName) + ": units " +
                         std::to_string(static_cast<uint32_t>(units)) +
                         " is not unknown (0), linear (1), face_model (2) or linear_unscaled (3)");
    }
    if (!(confidence >= 0 && confidence <= 1)) {
      throw MessageError(std::string(kTypeName) + ": confidence must be in [0, 1]");
    }
  }
};
inline constexpr uint64_t ShLight::kLayoutHash = layout::Fnv1a64(ShLight::LayoutDescription());

static_assert(Message<ShLight>);
static_assert(sizeof(ShLight) == 384 && alignof(ShLight) == 8);
static_assert(offsetof(ShLight, bands) == 56 && offsetof(ShLight, units) == 60 &&
              offsetof(ShLight, coefficients) == 64 &&
              offsetof(ShLight, dominant_direction) == 364 && offsetof(ShLight, intensity) == 376 &&
              offsetof(ShLight, confidence) == 380);
static_assert(ShIndex(0, 0) == 0 && ShIndex(1, -1) == 1 && ShIndex(1, 1) == 3 &&
              ShIndex(2, -2) == 4 && ShIndex(4, 4) == 24);

}  // namespace probeless::msgs
