// Light fusion: confidence weights, staleness, low confidence, band counts, frames.
#include "probeless/light/fusion.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

namespace probeless::light {
namespace {

msgs::ShLight Light(int64_t stamp, float confidence, float dc, float dx, float dy, float dz,
                    uint32_t bands = 3) {
  msgs::ShLight l;
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
  return l;
}

TEST(FuseLightsTest, WeightsByConfidence) {
  const std::vector<msgs::ShLight> in = {Light(100, 0.75f, 1.0f, 1, 0, 0),
                                         Light(90, 0.25f, 3.0f, 0, 1, 0)};
  const auto out = FuseLights(in);
  ASSERT_TRUE(out);
  EXPECT_EQ(out->header.stamp_ns, 100);
  EXPECT_EQ(out->bands, 3u);
  EXPECT_NEAR(out->coefficients[0][0], 1.5f, 1e-6);  // (0.75*1 + 0.25*3) / 1
  EXPECT_NEAR(out->intensity, 1.5f, 1e-6);
  EXPECT_NEAR(out->dominant_direction[0], 0.75 / std::sqrt(0.75 * 0.75 + 0.25 * 0.25), 1e-6);
  EXPECT_NEAR(out->dominant_direction[1], 0.25 / std::sqrt(0.75 * 0.75 + 0.25 * 0.25), 1e-6);
  EXPECT_NEAR(out->confidence, 1 - 0.25 * 0.75, 1e-6);
}

TEST(FuseLightsTest, StaleAndUnsureInputsAreLeftOut) {
  FusionOptions options;
  options.max_age_ns = 50;
  const std::vector<msgs::ShLight> stale = {Light(1000, 0.5f, 1.0f, 1, 0, 0),
                                            Light(900, 0.9f, 5.0f, 0, 1, 0)};
  const auto a = FuseLights(stale, options);
  ASSERT_TRUE(a);
  EXPECT_FLOAT_EQ(a->coefficients[0][0], 1.0f);
  EXPECT_FLOAT_EQ(a->confidence, 0.5f);
  const std::vector<msgs::ShLight> unsure = {Light(1000, 0.01f, 1.0f, 1, 0, 0)};
  EXPECT_FALSE(FuseLights(unsure));
  EXPECT_FALSE(FuseLights({}));
}

TEST(FuseLightsTest, MoreBandsFromTheInputThatHasThem) {
  const std::vector<msgs::ShLight> in = {Light(100, 0.5f, 1.0f, 0, 0, -1, 2),
                                         Light(100, 0.5f, 3.0f, 0, 0, -1, 3)};
  const auto out = FuseLights(in);
  ASSERT_TRUE(out);
  EXPECT_EQ(out->bands, 3u);
  EXPECT_FLOAT_EQ(out->coefficients[0][0], 2.0f);  // both
  EXPECT_FLOAT_EQ(out->coefficients[8][0], 3.0f);  // band 2: only the second
}

TEST(FuseLightsTest, DifferentFramesAreAnError) {
  std::vector<msgs::ShLight> in = {Light(100, 0.5f, 1.0f, 1, 0, 0),
                                   Light(100, 0.5f, 1.0f, 1, 0, 0)};
  in[1].header.SetFrameId("world");
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
