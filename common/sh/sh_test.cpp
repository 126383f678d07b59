// SH convention tests against analytic values: basis at the axes, closed forms of bands 0..2,
// orthonormality by quadrature, A_l, directional-light projection, clamped-cosine irradiance,
// optimal linear direction, lat-long mapping and error messages.
#include "probeless/sh/sh.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "probeless/testing/expect.h"

namespace probeless::sh {
namespace {

constexpr double kPi = std::numbers::pi;

Vec3 Normalised(Vec3 d) {
  const double n = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  return {d[0] / n, d[1] / n, d[2] / n};
}

TEST(ShTest, IndexIsLTimesLPlusOnePlusM) {
  EXPECT_EQ(Index(0, 0), 0);
  EXPECT_EQ(Index(1, -1), 1);
  EXPECT_EQ(Index(1, 0), 2);
  EXPECT_EQ(Index(1, 1), 3);
  EXPECT_EQ(Index(2, -2), 4);
  EXPECT_EQ(Index(4, 4), 24);
  EXPECT_EQ(DegreeOf(0), 0);
  EXPECT_EQ(DegreeOf(3), 1);
  EXPECT_EQ(DegreeOf(8), 2);
  EXPECT_EQ(DegreeOf(24), 4);
}

TEST(ShTest, BasisAtAxesMatchesCondonShortleyConvention) {
  const double c1 = std::sqrt(3 / (4 * kPi));
  const std::vector<double> px = Basis(2, {1, 0, 0});
  const std::vector<double> py = Basis(2, {0, 1, 0});
  const std::vector<double> pz = Basis(2, {0, 0, 1});
  EXPECT_NEAR(px[0], 0.5 / std::sqrt(kPi), 1e-15);
  // Y_1,-1 = -c y, Y_10 = c z, Y_11 = -c x (msgs/sh_light.h).
  EXPECT_NEAR(px[3], -c1, 1e-15);
  EXPECT_NEAR(px[1], 0, 1e-15);
  EXPECT_NEAR(py[1], -c1, 1e-15);
  EXPECT_NEAR(py[3], 0, 1e-15);
  EXPECT_NEAR(pz[2], c1, 1e-15);
  // Zonal values at the pole: Y_l0(z = 1) = sqrt((2l + 1)/(4 pi)); every m != 0 vanishes.
  const std::vector<double> pole = Basis(5, {0, 0, 1});
  for (int l = 0; l < 5; ++l) {
    for (int m = -l; m <= l; ++m) {
      const double expected = m == 0 ? std::sqrt((2 * l + 1) / (4 * kPi)) : 0.0;
      EXPECT_NEAR(pole[Index(l, m)], expected, 1e-14) << "l=" << l << " m=" << m;
    }
  }
  // Y_33 at +x: -sqrt(35/(32 pi)) (x^3 - 3xy^2) with the Condon-Shortley phase.
  EXPECT_NEAR(Basis(4, {1, 0, 0})[Index(3, 3)], -std::sqrt(35 / (32 * kPi)), 1e-14);
  // Y_44 at +x: (3/16) sqrt(35/pi) (x^4 - 6x^2y^2 + y^4).
  EXPECT_NEAR(Basis(5, {1, 0, 0})[Index(4, 4)], 3.0 / 16 * std::sqrt(35 / kPi), 1e-14);
}

TEST(ShTest, BandsZeroToTwoMatchClosedForms) {
  const Vec3 d = Normalised({0.3, -0.5, 0.8});
  const double x = d[0], y = d[1], z = d[2];
  const std::array<double, 9> expected = {0.5 * std::sqrt(1 / kPi),
                                          -std::sqrt(3 / (4 * kPi)) * y,
                                          std::sqrt(3 / (4 * kPi)) * z,
                                          -std::sqrt(3 / (4 * kPi)) * x,
                                          0.5 * std::sqrt(15 / kPi) * x * y,
                                          -0.5 * std::sqrt(15 / kPi) * y * z,
                                          0.25 * std::sqrt(5 / kPi) * (3 * z * z - 1),
                                          -0.5 * std::sqrt(15 / kPi) * x * z,
                                          0.25 * std::sqrt(15 / kPi) * (x * x - y * y)};
  const std::array<double, 9> got = Basis9(d);
  for (int n = 0; n < 9; ++n) EXPECT_NEAR(got[n], expected[n], 1e-14) << "n=" << n;
  // The float instantiation agrees.
  float got_float[25];
  EvaluateBasis<float>(5, static_cast<float>(x), static_cast<float>(y), static_cast<float>(z),
                       got_float);
  const std::vector<double> got25 = Basis(5, d);
  for (int n = 0; n < 25; ++n) EXPECT_NEAR(got_float[n], got25[n], 1e-6) << "n=" << n;
}

TEST(ShTest, BasisIsOrthonormalUnderQuadrature) {
  const QuadratureRule rule = GaussLegendreRule(6);  // exact for degree <= 11 >= 4 + 4
  double total_weight = 0;
  for (double w : rule.weights) total_weight += w;
  EXPECT_NEAR(total_weight, 4 * kPi, 1e-12);
  for (int a = 0; a < 25; ++a) {
    for (int b = 0; b < 25; ++b) {
      double sum = 0;
      for (size_t i = 0; i < rule.directions.size(); ++i) {
        const std::vector<double> y = Basis(5, rule.directions[i]);
        sum += rule.weights[i] * y[a] * y[b];
      }
      EXPECT_NEAR(sum, a == b ? 1.0 : 0.0, 1e-12) << "a=" << a << " b=" << b;
    }
  }
}

TEST(ShTest, AdditionTheoremSumsEachBandToTwoLPlusOneOverFourPi) {
  const std::vector<double> y = Basis(5, Normalised({-0.2, 0.7, 0.4}));
  for (int l = 0; l < 5; ++l) {
    double sum = 0;
    for (int m = -l; m <= l; ++m) sum += y[Index(l, m)] * y[Index(l, m)];
    EXPECT_NEAR(sum, (2 * l + 1) / (4 * kPi), 1e-14) << "l=" << l;
  }
}

TEST(ShTest, ClampedCosineConstantsAreRamamoorthiHanrahan) {
  EXPECT_NEAR(ClampedCosineCoefficient(0), kPi, 1e-15);
  EXPECT_NEAR(ClampedCosineCoefficient(1), 2 * kPi / 3, 1e-15);
  EXPECT_NEAR(ClampedCosineCoefficient(2), kPi / 4, 1e-15);
  EXPECT_EQ(ClampedCosineCoefficient(3), 0.0);
  EXPECT_NEAR(ClampedCosineCoefficient(4), -kPi / 24, 1e-15);
  EXPECT_NEAR(ClampedCosineCoefficient(6), kPi / 64, 1e-15);
  // A_l = sqrt(4 pi / (2l + 1)) * (projection of max(0, z) onto Y_l0).
  const std::vector<double> cosine =
      Project([](const Vec3& d) { return std::max(0.0, d[2]); }, 5, GaussLegendreRule(200));
  for (int l = 0; l < 5; ++l) {
    EXPECT_NEAR(std::sqrt(4 * kPi / (2 * l + 1)) * cosine[Index(l, 0)], ClampedCosineCoefficient(l),
                1e-4)  // quadrature across the kink at z = 0
        << "l=" << l;
  }
}

TEST(ShTest, DirectionalLightProjectionIsBasisAtItsDirection) {
  const Vec3 d = Normalised({0.6, -0.3, -0.7});
  const std::vector<double> light = DirectionalLight(d, 2.5, 5);
  const std::vector<double> y = Basis(5, d);
  for (int n = 0; n < 25; ++n) EXPECT_DOUBLE_EQ(light[n], 2.5 * y[n]);
  // A narrow normalised lobe around d (power 1) projects onto nearly Y(d): check with Monte-Carlo
  // and the fixed seed (lobe (k+1)/(2 pi) max(0, w.d)^k integrates to 1).
  const double k = 200;
  const auto lobe = [&](const Vec3& w) {
    const double c = std::max(0.0, w[0] * d[0] + w[1] * d[1] + w[2] * d[2]);
    return (k + 1) / (2 * kPi) * std::pow(c, k);
  };
  const std::vector<double> projected = Project(lobe, 3, GaussLegendreRule(256));
  for (int n = 0; n < 9; ++n) EXPECT_NEAR(projected[n], y[n], 0.02) << "n=" << n;
  const std::vector<double> mc =
      ProjectMonteCarlo([](const Vec3& w) { return 1 + w[2]; }, 3, 200000, 42);
  EXPECT_NEAR(mc[0], 2 * std::sqrt(kPi), 0.01);      // 1 -> sqrt(4 pi)
  EXPECT_NEAR(mc[2], std::sqrt(4 * kPi / 3), 0.02);  // z -> sqrt(4 pi / 3) Y_10
  EXPECT_EQ(mc, ProjectMonteCarlo([](const Vec3& w) { return 1 + w[2]; }, 3, 200000, 42));
}

TEST(ShTest, IrradianceOfDirectionalLightApproximatesClampedCosine) {
  const Vec3 d = Normalised({0.2, -0.4, -0.9});
  std::vector<double> irradiance = DirectionalLight(d, 1, 3);
  ConvolveClampedCosine(irradiance, 3);
  // Ramamoorthi & Hanrahan: 3 bands reproduce max(0, n.d) to within ~0.08 of its peak 1 (worst at
  // grazing angles) and the band-0 term is exactly the mean (1/4).
  double worst = 0;
  for (const Vec3& n : FibonacciSphere(2000)) {
    const double exact = std::max(0.0, n[0] * d[0] + n[1] * d[1] + n[2] * d[2]);
    worst = std::max(worst, std::abs(Evaluate(irradiance, n) - exact));
  }
  EXPECT_LT(worst, 0.1);
  EXPECT_NEAR(Evaluate(irradiance, d), 1.0, 0.08);
  EXPECT_NEAR(irradiance[0] * Basis9(d)[0] * 0 + irradiance[0] / (2 * std::sqrt(kPi)), 0.25, 1e-12);
  // Band 5 halves the error.
  std::vector<double> irradiance5 = DirectionalLight(d, 1, 5);
  ConvolveClampedCosine(irradiance5, 5);
  double worst5 = 0;
  for (const Vec3& n : FibonacciSphere(2000)) {
    const double exact = std::max(0.0, n[0] * d[0] + n[1] * d[1] + n[2] * d[2]);
    worst5 = std::max(worst5, std::abs(Evaluate(irradiance5, n) - exact));
  }
  EXPECT_LT(worst5, worst);
}

TEST(ShTest, OptimalLinearDirectionRecoversDirectionalLights) {
  for (const Vec3& d : FibonacciSphere(50)) {
    std::vector<double> light = DirectionalLight(d, 3.0, 3);
    light[0] += 5;  // ambient does not move it
    const Vec3 got = OptimalLinearDirection(light.data());
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(got[i], d[i], 1e-12);
    EXPECT_NEAR(DirectionalPower(light, d), 3.0, 1e-12);
  }
  const std::vector<double> uniform = {1, 0, 0, 0};
  EXPECT_EQ(OptimalLinearDirection(uniform.data()), (Vec3{0, 0, 0}));
  // Float coefficients, light from the camera's left (-x): L_11 = -c * (-1) > 0.
  const float coefficients[4] = {1, 0, 0, 0.4f};
  const Vec3 left = OptimalLinearDirection(coefficients);
  EXPECT_NEAR(left[0], -1, 1e-12);
}

TEST(ShTest, AzimuthElevationFollowYaleBConvention) {
  // Positive azimuth = light from the subject's right = the camera's left (-x); 0/0 = towards
  // the camera (-z); positive elevation = up (-y).
  const Vec3 right = DirectionFromAzimuthElevation(kPi / 2, 0);
  EXPECT_NEAR(right[0], -1, 1e-15);
  const Vec3 front = DirectionFromAzimuthElevation(0, 0);
  EXPECT_NEAR(front[2], -1, 1e-15);
  const Vec3 up = DirectionFromAzimuthElevation(0, kPi / 2);
  EXPECT_NEAR(up[1], -1, 1e-15);
  const std::array<double, 2> ae = AzimuthElevation(DirectionFromAzimuthElevation(2.2, -0.6));
  EXPECT_NEAR(ae[0], 2.2, 1e-12);
  EXPECT_NEAR(ae[1], -0.6, 1e-12);
  // Lat-long: centre pixel looks at the camera, the left column at azimuth ~ +180.
  const Vec3 centre = LatLongDirection(50, 25, 101, 51);
  EXPECT_NEAR(centre[2], -1, 1e-12);
  const std::array<double, 2> left = AzimuthElevation(LatLongDirection(0, 25, 100, 51));
  EXPECT_NEAR(left[0], kPi - kPi / 100, 1e-12);
}

TEST(ShTest, RenderLatLongEvaluatesEveryPixel) {
  const Vec3 d = DirectionFromAzimuthElevation(0.5, 0.3);
  const std::vector<double> light = DirectionalLight(d, 1, 3);
  std::vector<float> coefficients(9 * 2);
  for (int n = 0; n < 9; ++n) {
    coefficients[n * 2] = static_cast<float>(light[n]);
    coefficients[n * 2 + 1] = static_cast<float>(2 * light[n]);
  }
  std::vector<float> image(32 * 16 * 2);
  RenderLatLong(coefficients, 3, 2, 32, 16, image);
  size_t brightest = 0;
  for (size_t i = 0; i < image.size(); i += 2) {
    EXPECT_NEAR(image[i + 1], 2 * image[i], 1e-5);
    if (image[i] > image[brightest]) brightest = i;
  }
  const int u = static_cast<int>(brightest / 2) % 32, v = static_cast<int>(brightest / 2) / 32;
  const std::array<double, 2> ae = AzimuthElevation(LatLongDirection(u, v, 32, 16));
  EXPECT_NEAR(ae[0], 0.5, 0.2);
  EXPECT_NEAR(ae[1], 0.3, 0.2);
}

TEST(ShTest, WeightedBasisWithTheNormalisationIsTheBasis) {
  const std::array<double, 25> k = BasisNormalisation();
  std::array<float, 25> kf{}, half{};
  for (int i = 0; i < 25; ++i) {
    kf[i] = static_cast<float>(k[i]);
    half[i] = static_cast<float>(0.5 * k[i]);
  }
  std::mt19937 rng(7);
  std::normal_distribution<double> normal;
  for (int trial = 0; trial < 50; ++trial) {
    Vec3 d{normal(rng), normal(rng), normal(rng)};
    const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    for (double& v : d) v /= len;
    const std::vector<double> expected = Basis(5, d);
    double y[25];
    EvaluateWeightedBasis<5, false>(k.data(), d[0], d[1], d[2], y);
    for (int i = 0; i < 25; ++i) ASSERT_NEAR(y[i], expected[i], 1e-12) << i;
    double y3[9];
    EvaluateWeightedBasis<3, false>(k.data(), d[0], d[1], d[2], y3);
    for (int i = 0; i < 9; ++i) ASSERT_NEAR(y3[i], expected[i], 1e-12) << i;
    // Accumulate, in float, with per-entry factors: adds 0.5 Y to what is there.
    float acc[16];
    for (int i = 0; i < 16; ++i) acc[i] = 1.0f;
    const float fx = static_cast<float>(d[0]), fy = static_cast<float>(d[1]),
                fz = static_cast<float>(d[2]);
    EvaluateWeightedBasis<4, true>(half.data(), fx, fy, fz, acc);
    for (int i = 0; i < 16; ++i) ASSERT_NEAR(acc[i], 1.0 + 0.5 * expected[i], 2e-6) << i;
  }
  EXPECT_EQ(k[Index(0, 0)], 0.5 / std::sqrt(std::numbers::pi));
}

TEST(ShTest, BadArgumentsThrowOneLineMessages) {
  PROBELESS_EXPECT_THROWS_MESSAGE(Basis(6, {0, 0, 1}), ShError,
                                  "sh::Basis: bands 6 out of range 1..5");
  PROBELESS_EXPECT_THROWS_MESSAGE(DirectionalLight({0, 0, 1}, 1, 0), ShError,
                                  "sh::DirectionalLight: bands 0 out of range 1..5");
  PROBELESS_EXPECT_THROWS_MESSAGE(Evaluate(std::vector<double>(5), {0, 0, 1}), ShError,
                                  "sh::Evaluate: 5 coefficients is not a square 1..25");
  PROBELESS_EXPECT_THROWS_MESSAGE(DirectionalPower(std::vector<double>(1), {0, 0, 1}), ShError,
                                  "sh::DirectionalPower: 1 coefficients is not a square 4..25");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      {
        std::vector<double> c(4);
        ConvolveClampedCosine(c, 3);
      },
      ShError, "sh::ConvolveClampedCosine: 4 coefficients, expected 9");
  PROBELESS_EXPECT_THROWS_MESSAGE(GaussLegendreRule(0), ShError,
                                  "sh::GaussLegendreRule: n_z 0 out of range 1..512");
  PROBELESS_EXPECT_THROWS_MESSAGE(ProjectMonteCarlo([](const Vec3&) { return 1.0; }, 3, 0, 1),
                                  ShError, "sh::ProjectMonteCarlo: samples 0 must be >= 1");
  std::vector<float> coefficients(9), image(10);
  PROBELESS_EXPECT_THROWS_MESSAGE(RenderLatLong(coefficients, 3, 1, 4, 2, image), ShError,
                                  "sh::RenderLatLong: output holds 10 floats, expected 8");
  PROBELESS_EXPECT_THROWS_MESSAGE(RenderLatLong(coefficients, 3, 5, 4, 2, image), ShError,
                                  "sh::RenderLatLong: channels 5 out of range 1..4");
}

}  // namespace
}  // namespace probeless::sh
