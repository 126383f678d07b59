// Message -> renderer conversions: the dominant light of a light message (its own, or fitted from
// its band 1 when it has none).
#include "probeless/render/msgs_io.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "probeless/sh/sh.h"

namespace probeless::render {
namespace {

// A light message of `bands` bands whose R, G, B are `white` x (1.2, 1.0, 0.8): its grey (the mean
// of the three) is `white`.
msgs::ShLight Light(const std::vector<double>& white, uint32_t bands) {
  msgs::ShLight m;
  m.bands = bands;
  m.units = msgs::ShLightUnits::kLinear;
  for (uint32_t k = 0; k < bands * bands; ++k) {
    m.coefficients[k][0] = static_cast<float>(1.2 * white[k]);
    m.coefficients[k][1] = static_cast<float>(white[k]);
    m.coefficients[k][2] = static_cast<float>(0.8 * white[k]);
  }
  return m;
}

TEST(MsgsIoTest, DominantLightIsTheMessagesOwnWhenItHasOne) {
  msgs::ShLight m = Light(sh::DirectionalLight({0, 0, 1}, 2, 3), 3);
  m.dominant_direction[0] = 0.6f;
  m.dominant_direction[2] = 0.8f;
  m.intensity = 1.5f;
  const light::DominantLight d = DominantLightFromMsg(m);
  EXPECT_EQ(d.direction, (light::Vec3f{0.6f, 0, 0.8f}));
  EXPECT_EQ(d.intensity, 1.5f);
}

// Without an intensity, or with a direction that is not one (squared length <= 0.5), the
// direction and power of the light's band 1.
TEST(MsgsIoTest, DominantLightIsFittedFromBandOneWithoutOne) {
  std::mt19937 rng(21);
  std::normal_distribution<double> gauss;
  for (int trial = 0; trial < 20; ++trial) {
    sh::Vec3 dir{gauss(rng), gauss(rng), gauss(rng)};
    const double n = std::sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
    for (double& x : dir) x /= n;
    std::vector<double> white = sh::DirectionalLight(dir, 3, 4);
    white[0] += 0.5;  // an ambient part does not change the fit
    msgs::ShLight m = Light(white, 4);
    if (trial % 2 == 1) {
      m.intensity = 9;
      m.dominant_direction[1] = 0.7f;  // squared length 0.49
    }
    const light::DominantLight d = DominantLightFromMsg(m);
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(d.direction[i], dir[i], 1e-5) << "trial " << trial;
    EXPECT_NEAR(d.intensity, 3, 1e-4) << "trial " << trial;
  }
}

TEST(MsgsIoTest, DominantLightIsNoneWithoutBandOne) {
  const msgs::ShLight ambient = Light({1.0}, 1);
  const msgs::ShLight flat = Light({1.0, 0, 0, 0, 0.3, 0, 0, 0, 0}, 3);
  for (const msgs::ShLight& m : {ambient, flat}) {
    const light::DominantLight d = DominantLightFromMsg(m);
    EXPECT_EQ(d.direction, (light::Vec3f{0, 0, 0}));
    EXPECT_EQ(d.intensity, 0);
  }
  // A weak band 1 along +z against a strong negative band 2 there: the power is clamped to 0.
  const light::DominantLight d = DominantLightFromMsg(Light({1.0, 0, 0.1, 0, 0, 0, -5, 0, 0}, 3));
  EXPECT_EQ(d.direction, (light::Vec3f{0, 0, 1}));
  EXPECT_EQ(d.intensity, 0);
}

}  // namespace
}  // namespace probeless::render
