// Light fusion: the confidence scale, inverse-variance weights, staleness, low confidence, band
// weighting, disagreeing inputs against ground truth, units and frames refused.
#include "probeless/light/fusion.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <numbers>
#include <random>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "probeless/sh/sh.h"

namespace probeless::light {
namespace {

FusionInput Light(int64_t stamp, float confidence, float dc, float dx, float dy, float dz,
                  uint32_t bands = 3) {
  FusionInput in;
  msgs::ShLight& l = in.light;
  l.header.stamp_ns = stamp;
  l.header.SetFrameId("camera");
  l.bands = bands;
  for (uint32_t i = 0; i < bands * bands; ++i) {
    for (int c = 0; c < 3; ++c) l.coefficients[i][c] = dc;
  }
  l.dominant_direction[0] = dx;
  l.dominant_direction[1] = dy;
  l.dominant_direction[2] = dz;
  l.intensity = dc;
  l.confidence = confidence;
  l.units = msgs::ShLightUnits::kLinear;
  return in;
}

// A directional light of power `power` from unit d plus ambient (ShLight units), with
// confidence.
FusionInput Directional(const sh::Vec3& d, double power, float confidence, const char* name) {
  FusionInput in;
  in.name = name;
  msgs::ShLight& l = in.light;
  l.header.stamp_ns = 100;
  l.header.SetFrameId("camera");
  l.bands = 3;
  const auto y = sh::Basis9(d);
  for (int n = 0; n < 9; ++n) {
    for (int c = 0; c < 3; ++c) l.coefficients[n][c] = static_cast<float>(power * y[n]);
  }
  for (int k = 0; k < 3; ++k) l.dominant_direction[k] = static_cast<float>(d[k]);
  l.intensity = static_cast<float>(power);
  l.confidence = confidence;
  l.units = msgs::ShLightUnits::kLinear;
  return in;
}

sh::Vec3 Rotated(const sh::Vec3& d, const sh::Vec3& axis, double degrees) {
  // Rodrigues: d cos + (a x d) sin + a (a.d)(1 - cos).
  const double t = degrees * std::numbers::pi / 180, c = std::cos(t), s = std::sin(t);
  const sh::Vec3 x{axis[1] * d[2] - axis[2] * d[1], axis[2] * d[0] - axis[0] * d[2],
                   axis[0] * d[1] - axis[1] * d[0]};
  const double dot = axis[0] * d[0] + axis[1] * d[1] + axis[2] * d[2];
  return {d[0] * c + x[0] * s + axis[0] * dot * (1 - c),
          d[1] * c + x[1] * s + axis[1] * dot * (1 - c),
          d[2] * c + x[2] * s + axis[2] * dot * (1 - c)};
}

double AngleDeg(const sh::Vec3& a, const float* b) {
  const double dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  return std::acos(std::clamp(dot, -1.0, 1.0)) * 180 / std::numbers::pi;
}

TEST(FuseLightsTest, ConfidenceScale) {
  EXPECT_DOUBLE_EQ(ConfidenceFromExpectedError(10), 0.5);
  EXPECT_DOUBLE_EQ(ConfidenceFromExpectedError(20), 0.2);
  EXPECT_DOUBLE_EQ(ConfidenceFromExpectedError(0), 1);
  EXPECT_EQ(ConfidenceFromExpectedError(std::numeric_limits<double>::infinity()), 0);
  for (double e : {1.0, 5.0, 30.0, 120.0}) {
    EXPECT_NEAR(ExpectedErrorFromConfidence(ConfidenceFromExpectedError(e)), e, 1e-9 * e);
  }
  EXPECT_TRUE(std::isinf(ExpectedErrorFromConfidence(0)));
}

// The expected light under the direction uncertainty: band l scaled by exp(-l(l+1) sigma^2 / 2),
// sigma = blur e / sqrt(2 ln 2); no known direction (c = 0) keeps band 0 only.
TEST(FuseLightsTest, UncertaintyBandFactorIsTheGaussianBlurOfTheExpectedError) {
  const double sigma = 10.0 * std::numbers::pi / 180 / std::sqrt(2 * std::log(2.0));  // c = 0.5
  EXPECT_NEAR(UncertaintyBandFactor(0.5, 1, 1), std::exp(-sigma * sigma), 1e-12);
  EXPECT_NEAR(UncertaintyBandFactor(0.5, 1, 3), std::exp(-6 * sigma * sigma), 1e-12);
  EXPECT_NEAR(UncertaintyBandFactor(0.5, 2, 1), std::exp(-4 * sigma * sigma), 1e-12);
  EXPECT_EQ(UncertaintyBandFactor(0.5, 1, 0), 1);
  EXPECT_EQ(UncertaintyBandFactor(0.5, 0, 2), 1);
  EXPECT_EQ(UncertaintyBandFactor(1.0, 1, 2), 1);  // certain: nothing blurred
  EXPECT_EQ(UncertaintyBandFactor(0.0, 1, 1), 0);
  EXPECT_EQ(UncertaintyBandFactor(0.0, 1, 0), 1);
  EXPECT_LT(UncertaintyBandFactor(0.05, 1, 2), UncertaintyBandFactor(0.05, 1, 1));
}

// Both layouts scale coefficient k by the factor of its band (0 for k = 0, 1 for 1..3, 2 for 4..8,
// 3 for 9..15, 4 for 16..24), the RGB one with the factor rounded to float.
TEST(FuseLightsTest, BlurByUncertaintyScalesEachCoefficientByItsBand) {
  constexpr int kBandOf[25] = {0, 1, 1, 1, 2, 2, 2, 2, 2, 3, 3, 3, 3,
                               3, 3, 3, 4, 4, 4, 4, 4, 4, 4, 4, 4};
  std::mt19937 rng(21);
  std::uniform_real_distribution<double> value(-1, 1);
  std::vector<double> white(25);
  std::vector<std::array<float, 3>> rgb(25);
  for (size_t k = 0; k < white.size(); ++k) {
    white[k] = value(rng);
    for (float& c : rgb[k]) c = static_cast<float>(value(rng));
  }
  const std::vector<double> white_in = white;
  const std::vector<std::array<float, 3>> rgb_in = rgb;
  BlurByUncertainty(white, 0.3, 1.5);
  BlurByUncertainty(rgb, 0.3, 1.5);
  for (size_t k = 0; k < white.size(); ++k) {
    const double f = UncertaintyBandFactor(0.3, 1.5, kBandOf[k]);
    EXPECT_EQ(white[k], white_in[k] * f) << "coefficient " << k;
    for (int c = 0; c < 3; ++c) {
      EXPECT_EQ(rgb[k][c], rgb_in[k][c] * static_cast<float>(f)) << "coefficient " << k;
    }
  }
  EXPECT_EQ(white[0], white_in[0]);
  EXPECT_LT(std::abs(white[24]), 0.9 * std::abs(white_in[24]));  // the highest band blurred most
  // Blur 0 leaves the light as it is; no known direction (c = 0) keeps band 0 only.
  std::vector<double> unblurred = white_in;
  BlurByUncertainty(unblurred, 0.3, 0);
  EXPECT_EQ(unblurred, white_in);
  std::vector<std::array<float, 3>> ambient = rgb_in;
  BlurByUncertainty(std::span(ambient).first(9), 0, 1);
  EXPECT_EQ(ambient[0], rgb_in[0]);
  for (size_t k = 1; k < 9; ++k) EXPECT_EQ(ambient[k], (std::array<float, 3>{0, 0, 0}));
  EXPECT_EQ(ambient[9], rgb_in[9]);  // beyond the span: untouched
}

TEST(FuseLightsTest, InverseVarianceWeights) {
  // c = 0.75 (weight 3) and 0.25 (weight 1/3), directions 10 deg apart (consistent).
  const double t = 10 * std::numbers::pi / 180;
  const std::vector<FusionInput> in = {Light(100, 0.75f, 1.0f, 1, 0, 0),
                                       Light(90, 0.25f, 3.0f, std::cos(t), std::sin(t), 0)};
  const auto out = FuseLights(in);
  ASSERT_TRUE(out);
  EXPECT_EQ(out->header.stamp_ns, 100);
  EXPECT_EQ(out->bands, 3u);
  EXPECT_NEAR(out->coefficients[0][0], (3 * 1.0 + 3.0 / 3) / (3 + 1.0 / 3), 1e-6);
  EXPECT_NEAR(out->intensity, (3 * 1.0 + 3.0 / 3) / (3 + 1.0 / 3), 1e-6);
  const double x = 3 + std::cos(t) / 3, y = std::sin(t) / 3;
  EXPECT_NEAR(out->dominant_direction[0], x / std::hypot(x, y), 1e-6);
  EXPECT_NEAR(out->dominant_direction[1], y / std::hypot(x, y), 1e-6);
  // Inverse variances add: W = 10/3, c = W / (1 + W).
  EXPECT_NEAR(out->confidence, (10.0 / 3) / (1 + 10.0 / 3), 1e-6);
}

TEST(FuseLightsTest, StaleAndUnsureInputsAreLeftOut) {
  FusionOptions options;
  options.max_age_ns = 50;
  const std::vector<FusionInput> stale = {Light(1000, 0.5f, 1.0f, 1, 0, 0),
                                          Light(900, 0.9f, 5.0f, 0, 1, 0)};
  const auto a = FuseLights(stale, options);
  ASSERT_TRUE(a);
  EXPECT_FLOAT_EQ(a->coefficients[0][0], 1.0f);
  EXPECT_FLOAT_EQ(a->confidence, 0.5f);
  const std::vector<FusionInput> unsure = {Light(1000, 0.01f, 1.0f, 1, 0, 0)};
  EXPECT_FALSE(FuseLights(unsure));
  EXPECT_FALSE(FuseLights({}));
}

TEST(FuseLightsTest, ABandOneInputHasIsWeightedByItsConfidence) {
  // Weights 1 (c 0.5) and 3 (c 0.75).
  const std::vector<FusionInput> in = {Light(100, 0.5f, 1.0f, 0, 0, -1, 2),
                                       Light(100, 0.75f, 3.0f, 0, 0, -1, 3)};
  const auto out = FuseLights(in);
  ASSERT_TRUE(out);
  EXPECT_EQ(out->bands, 3u);
  EXPECT_FLOAT_EQ(out->coefficients[0][0], (1 * 1.0f + 3 * 3.0f) / 4);  // both
  // Band 2 only the second has: its share 3 / 4 of its value, not the value at full weight.
  EXPECT_FLOAT_EQ(out->coefficients[8][0], 3 * 3.0f / 4);
  // One input alone keeps its bands.
  const std::vector<FusionInput> one = {in[1]};
  EXPECT_FLOAT_EQ(FuseLights(one)->coefficients[8][0], 3.0f);
}

// Ground truth d; the face estimate 5 deg off claims 6 deg (c 0.735), the scene estimate 70 deg
// off (a wrong light) claims 10 deg (c 0.5). Averaged by the same weights they give 12.6 deg; the
// fusion keeps the face alone (75 deg apart > 3 sqrt(6^2 + 10^2) = 35 deg).
TEST(FuseLightsTest, DisagreeingInputsAgainstGroundTruth) {
  const sh::Vec3 truth{0.3 / std::sqrt(1.1), -0.1 / std::sqrt(1.1), -1 / std::sqrt(1.1)};
  const sh::Vec3 axis{0, 1, 0};
  const float face_c = static_cast<float>(ConfidenceFromExpectedError(6));
  const float scene_c = static_cast<float>(ConfidenceFromExpectedError(10));
  const std::vector<FusionInput> in = {
      Directional(Rotated(truth, axis, 5), 2.0, face_c, "face"),
      Directional(Rotated(truth, axis, -70), 2.0, scene_c, "scene")};
  const auto out = FuseLights(in);
  ASSERT_TRUE(out);
  EXPECT_LT(AngleDeg(truth, out->dominant_direction), 5.5);
  EXPECT_FLOAT_EQ(out->confidence, face_c);
  FusionOptions average;
  average.consistency_sigma = 0;
  const auto raw = FuseLights(in, average);
  EXPECT_GT(AngleDeg(truth, raw->dominant_direction), 10);
  // Consistent inputs on either side of the truth (8 deg and 12 deg off, claiming 8 and 12 deg):
  // the fused direction is better than either.
  const std::vector<FusionInput> agree = {
      Directional(Rotated(truth, axis, 8), 2.0, static_cast<float>(ConfidenceFromExpectedError(8)),
                  "face"),
      Directional(Rotated(truth, axis, -12), 2.0,
                  static_cast<float>(ConfidenceFromExpectedError(12)), "scene")};
  const auto both = FuseLights(agree);
  ASSERT_TRUE(both);
  EXPECT_LT(AngleDeg(truth, both->dominant_direction), 3);
  EXPECT_GT(both->confidence, agree[0].light.confidence);
}

TEST(FuseLightsTest, ConfidenceCalibrationMapsRawConfidences) {
  const ConfidenceCalibration identity;
  EXPECT_TRUE(identity.identity());
  EXPECT_EQ(identity.Apply(0.3), 0.3);
  const std::vector<double> knots{0.0, 90.0, 0.5, 20.0, 1.0, 5.0};
  const ConfidenceCalibration table(knots);
  EXPECT_NEAR(table.Apply(0.5), ConfidenceFromExpectedError(20), 1e-12);
  EXPECT_NEAR(table.Apply(0.75), ConfidenceFromExpectedError(12.5), 1e-12);
  EXPECT_NEAR(table.Apply(0.0), ConfidenceFromExpectedError(90), 1e-12);
  EXPECT_NEAR(table.Apply(1.0), ConfidenceFromExpectedError(5), 1e-12);
  const std::vector<double> odd{0.0, 90.0, 0.5};
  try {
    ConfidenceCalibration bad(odd);
    FAIL() << "no exception";
  } catch (const FusionError& e) {
    EXPECT_STREQ(e.what(),
                 "confidence calibration: 3 values, expected pairs (raw confidence, expected "
                 "error in degrees)");
  }
  const std::vector<double> descending{0.5, 20.0, 0.2, 30.0};
  try {
    ConfidenceCalibration bad(descending);
    FAIL() << "no exception";
  } catch (const FusionError& e) {
    EXPECT_STREQ(e.what(),
                 "confidence calibration: knot 1 needs a raw confidence in [0, 1] above the "
                 "previous one and an error > 0");
  }
}

TEST(FuseLightsTest, DifferentUnitsAreRefused) {
  std::vector<FusionInput> in = {Light(100, 0.5f, 1.0f, 1, 0, 0), Light(100, 0.5f, 1.0f, 1, 0, 0)};
  in[0].name = "face/light";
  const std::pair<msgs::ShLightUnits, const char*> cases[] = {
      {msgs::ShLightUnits::kFaceModel, "face_model"},
      {msgs::ShLightUnits::kLinearUnscaled, "linear_unscaled"},
      {msgs::ShLightUnits::kUnknown, "unknown"}};
  for (const auto& [units, name] : cases) {
    in[0].light.units = units;
    try {
      FuseLights(in);
      FAIL() << "no exception for " << name;
    } catch (const FusionError& e) {
      EXPECT_EQ(std::string(e.what()), std::string("light fusion: 'face/light' is in ") + name +
                                           " units, expected linear radiance (msgs::ShLight); "
                                           "not averaged");
    }
  }
  in[0].light.units = msgs::ShLightUnits::kLinear;
  const auto fused = FuseLights(in);
  ASSERT_TRUE(fused);
  EXPECT_EQ(fused->units, msgs::ShLightUnits::kLinear);
}

TEST(FuseLightsTest, DifferentFramesAreAnError) {
  std::vector<FusionInput> in = {Light(100, 0.5f, 1.0f, 1, 0, 0), Light(100, 0.5f, 1.0f, 1, 0, 0)};
  in[1].light.header.SetFrameId("world");
  try {
    FuseLights(in);
    FAIL() << "no exception";
  } catch (const FusionError& e) {
    EXPECT_STREQ(e.what(),
                 "light fusion: inputs in different frames ('camera' and 'world'); expected one "
                 "frame");
  }
}

}  // namespace
}  // namespace probeless::light
