// face_light on synthetic data: frame helpers, patch sampling, training recovers known RTFs,
// point selection, the estimator (gray, RGB, invalid samples, outliers, prior, non-negative),
// ShLight filling, the model file round trip and its error messages.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numbers>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "probeless/face_light/estimator.h"
#include "probeless/face_light/model.h"
#include "probeless/face_light/training.h"
#include "probeless/face_light/yaleb.h"
#include "probeless/msgs/sh_light.h"
#include "probeless/sh/sh.h"
#include "probeless/testing/expect.h"

namespace probeless::face_light {
namespace {

using Rtf = std::array<double, kRtfCoefficients>;

double Uniform(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

// Plausible RTFs: a clamped-cosine lobe around a random normal facing the camera (-z), i.e. the
// band-0..2 irradiance transfer of a Lambertian point with albedo ~0.6..1 (Ramamoorthi-Hanrahan).
std::vector<Rtf> SyntheticRtfs(int count, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<Rtf> rtfs(count);
  for (Rtf& t : rtfs) {
    const double x = 3.0 * (Uniform(rng) - 0.5), y = 3.0 * (Uniform(rng) - 0.5);
    const double norm = std::sqrt(x * x + y * y + 1);
    const sh::Vec3 normal{x / norm, y / norm, -1 / norm};
    const std::array<double, 9> basis = sh::Basis9(normal);
    const double albedo = 0.6 + 0.4 * Uniform(rng);
    for (int n = 0; n < 9; ++n) {
      t[n] = albedo / std::numbers::pi * sh::ClampedCosineCoefficient(sh::DegreeOf(n)) * basis[n];
    }
  }
  return rtfs;
}

FaceLightModel ModelFrom(const std::vector<Rtf>& rtfs) {
  FaceLightModel model;
  for (size_t i = 0; i < rtfs.size(); ++i) {
    model.positions.push_back({(i % 20 + 0.5) / 20, (i / 20 + 0.5) / 30});
    std::array<float, 9> t{};
    for (int n = 0; n < 9; ++n) t[n] = static_cast<float>(rtfs[i][n]);
    model.rtf.push_back(t);
    model.residual_rms.push_back(0.01f);
  }
  model.training.subjects = {1, 2};
  model.training.images = 128;
  model.training.candidates = static_cast<int>(rtfs.size());
  return model;
}

// Synthetic intensities of a model under light E (9 coefficients): rtf . E (eq. 17).
std::vector<float> Render(const FaceLightModel& model, const std::vector<double>& light) {
  std::vector<float> out(model.SampleCount());
  for (int i = 0; i < model.SampleCount(); ++i) {
    double sum = 0;
    for (int n = 0; n < 9; ++n) sum += model.rtf[i][n] * light[n];
    out[i] = static_cast<float>(sum);
  }
  return out;
}

// A band-2 light: directional light of power 2 plus ambient.
std::vector<double> TestLight(double azimuth_deg, double elevation_deg) {
  std::vector<double> light =
      sh::DirectionalLight(YaleBLightDirection(azimuth_deg, elevation_deg), 2.0, 3);
  light[0] += 0.5;
  return light;
}

double AngleDeg(const std::array<float, 3>& a, const std::array<double, 3>& b) {
  const double dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  return std::acos(std::clamp(dot, -1.0, 1.0)) * 180 / std::numbers::pi;
}

TEST(FaceFrameTest, NormalisedCoordinatesAndSimilarity) {
  const Point2 uv = NormalisedFromCropPixel(kCanonicalMouth);
  EXPECT_NEAR(uv.x, 83.5 / 168, 1e-12);
  const Point2 back = CropPixelFromNormalised(uv);
  EXPECT_NEAR(back.x, kCanonicalMouth.x, 1e-12);
  EXPECT_NEAR(back.y, kCanonicalMouth.y, 1e-12);
  // A live face: scaled by 1.5, rotated by 10 degrees, shifted.
  SimilarityTransform truth;
  truth.a = 1.5 * std::cos(0.1745), truth.b = 1.5 * std::sin(0.1745), truth.tx = 200, truth.ty = 80;
  const std::vector<Point2> canonical = {kCanonicalRightEye, kCanonicalLeftEye, kCanonicalNoseTip,
                                         kCanonicalMouth};
  std::vector<Point2> live;
  for (const Point2& p : canonical) live.push_back(truth.Apply(p));
  const SimilarityTransform fitted = FitSimilarity(canonical, live);
  EXPECT_NEAR(fitted.a, truth.a, 1e-9);
  EXPECT_NEAR(fitted.b, truth.b, 1e-9);
  EXPECT_NEAR(fitted.tx, truth.tx, 1e-7);
  EXPECT_NEAR(fitted.ty, truth.ty, 1e-7);
  EXPECT_NEAR(fitted.Scale(), 1.5, 1e-9);
  PROBELESS_EXPECT_THROWS_MESSAGE(
      FitSimilarity(std::span(canonical).first(1), std::span(live).first(1)), FaceLightError,
      "FitSimilarity: need the same number (>= 2) of points, got 1 and 1");
  const std::vector<Point2> same = {{1, 1}, {1, 1}};
  PROBELESS_EXPECT_THROWS_MESSAGE(FitSimilarity(same, same), FaceLightError,
                                  "FitSimilarity: source points are all equal");
}

TEST(FaceFrameTest, SamplePatchesAveragesBoxesAndFlagsInvalid) {
  // 168 x 192 gray image with value = x (so a centred box averages to its centre column).
  std::vector<uint8_t> image(kCropWidth * kCropHeight);
  for (int y = 0; y < kCropHeight; ++y) {
    for (int x = 0; x < kCropWidth; ++x) image[y * kCropWidth + x] = static_cast<uint8_t>(x);
  }
  image[100 * kCropWidth + 60] = 255;  // one saturated pixel
  const std::vector<Point2> positions = {NormalisedFromCropPixel({40, 50}),
                                         NormalisedFromCropPixel({1, 50}),
                                         NormalisedFromCropPixel({60, 101})};
  std::vector<float> values(3);
  std::vector<uint8_t> valid(3);
  SamplePatches(image.data(), kCropWidth, kCropHeight, kCropWidth, 1, SimilarityTransform{},
                positions, 2, 255, values, valid);
  EXPECT_NEAR(values[0], 40 / 255.0, 1e-6);
  EXPECT_EQ(valid[0], 1);
  EXPECT_EQ(valid[1], 0);  // leaves the image
  EXPECT_EQ(valid[2], 0);  // saturated
  // A transform scaling by 2 doubles the patch radius and moves the samples.
  std::vector<uint8_t> big(400 * 400);
  for (int y = 0; y < 400; ++y) {
    for (int x = 0; x < 400; ++x) big[y * 400 + x] = static_cast<uint8_t>(x / 2);
  }
  SimilarityTransform twice;
  twice.a = 2;
  SamplePatches(big.data(), 400, 400, 400, 1, twice, std::span(positions).first(1), 2, 256,
                std::span(values).first(1), std::span(valid).first(1));
  EXPECT_NEAR(values[0], 40 / 255.0, 0.5 / 255);
  PROBELESS_EXPECT_THROWS_MESSAGE(
      SamplePatches(image.data(), kCropWidth, kCropHeight, kCropWidth, 1, SimilarityTransform{},
                    positions, 2, 255, std::span(values).first(2), valid),
      FaceLightError, "SamplePatches: 3 positions need 3 values and 3 flags, got 2 and 3");
}

TEST(TrainingTest, CandidateGridHas512PointsInsideTheMask) {
  const std::vector<Point2> candidates = CandidatePositions();
  EXPECT_EQ(candidates.size(), 512u);
  for (const Point2& p : candidates) {
    const Point2 px = CropPixelFromNormalised(p);
    EXPECT_GE(px.x, 2);
    EXPECT_LE(px.x, kCropWidth - 3);
    EXPECT_GE(px.y, 8);
    EXPECT_LE(px.y, 183);
    const double ex = (px.x - kCanonicalRightEye.x) / 24,
                 ey = (px.y - kCanonicalRightEye.y + 4) / 17;
    EXPECT_GT(ex * ex + ey * ey, 1);
  }
  PROBELESS_EXPECT_THROWS_MESSAGE(CandidatePositions(1), FaceLightError,
                                  "CandidatePositions: step_px 1.000000 out of range 2..40");
}

// Synthetic training set: every person sees every one of 40 light directions; intensity =
// albedo_f * (T_j . Y(w_k)) for known T_j.
std::vector<TrainingImage> SyntheticTraining(const std::vector<Rtf>& rtfs, int persons,
                                             double noise, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<TrainingImage> images;
  for (int f = 1; f <= persons; ++f) {
    const double albedo = 0.5 + 0.2 * f;
    for (int k = 0; k < 40; ++k) {
      TrainingImage image;
      image.subject = f;
      image.azimuth_deg = k == 0 ? 0 : -117 + 6 * k;
      image.elevation_deg = k == 0 ? 0 : -40 + (k * 37) % 100;
      const std::array<double, 9> y =
          sh::Basis9(YaleBLightDirection(image.azimuth_deg, image.elevation_deg));
      for (const Rtf& t : rtfs) {
        double sum = 0;
        for (int n = 0; n < 9; ++n) sum += t[n] * y[n];
        image.values.push_back(static_cast<float>(albedo * sum + noise * (Uniform(rng) - 0.5)));
        image.valid.push_back(1);
      }
      images.push_back(std::move(image));
    }
  }
  return images;
}

TEST(TrainingTest, FitRecoversKnownRtfsUpToTheAlbedoNormalisation) {
  const std::vector<Rtf> rtfs = SyntheticRtfs(101, 7);
  std::vector<TrainingImage> images = SyntheticTraining(rtfs, 3, 0.0, 1);
  // Per-person albedo (sec. 3.4.2) = albedo_f * median_j(T_j . Y(front)); after dividing, every
  // person's data is T_j / m with m = median_j(T_j . Y(front)).
  const std::array<double, 9> front = sh::Basis9(YaleBLightDirection(0, 0));
  std::vector<double> frontal;
  for (const Rtf& t : rtfs) {
    double sum = 0;
    for (int n = 0; n < 9; ++n) sum += t[n] * front[n];
    frontal.push_back(sum);
  }
  std::sort(frontal.begin(), frontal.end());
  const double m = frontal[50];
  EXPECT_NEAR(PersonAlbedo(images, 2), 0.9 * m, 1e-6);
  // An invalid value is simply left out of its candidate's system.
  images[5].valid[3] = 0;
  images[5].values[3] = 1e6f;
  std::vector<float> residuals;
  const std::vector<Rtf> fitted = FitRtfs(images, &residuals);
  ASSERT_EQ(fitted.size(), rtfs.size());
  for (size_t j = 0; j < rtfs.size(); ++j) {
    for (int n = 0; n < 9; ++n) EXPECT_NEAR(fitted[j][n], rtfs[j][n] / m, 2e-5) << j << "," << n;
    EXPECT_LT(residuals[j], 1e-5);
  }
}

TEST(TrainingTest, SelectionKeepsCandidatesAboveThePercentile) {
  std::vector<Rtf> rtfs(100);
  for (int j = 0; j < 100; ++j) rtfs[j].fill(0), rtfs[j][j % 9] = j;  // coefficient j % 9 grows
  double applied = 0;
  TrainingOptions options;
  options.percentile = 90;
  const std::vector<int> selected = SelectSamples(rtfs, options, &applied);
  // Per coefficient, only the top 10% of the 100 ranks (>= 90) pass: the 10 largest j overall
  // that are largest in their coefficient n (the other coefficients are 0 and rank low but tie).
  EXPECT_EQ(applied, 90);
  EXPECT_FALSE(selected.empty());
  EXPECT_TRUE(std::is_sorted(selected.begin(), selected.end()));
  EXPECT_TRUE(std::find(selected.begin(), selected.end(), 99) != selected.end());
  options.points = 7;
  const std::vector<int> seven = SelectSamples(rtfs, options, &applied);
  // Ties (91..99 each rank first in their coefficient) keep the lower index first.
  EXPECT_EQ(seven, (std::vector<int>{91, 92, 93, 94, 95, 96, 97}));
  EXPECT_EQ(applied, 99);
}

TEST(TrainingTest, TrainPacksTheModelAndRejectsBadInput) {
  const std::vector<Rtf> rtfs = SyntheticRtfs(60, 3);
  const std::vector<TrainingImage> images = SyntheticTraining(rtfs, 2, 0.001, 2);
  std::vector<Point2> candidates;
  for (int j = 0; j < 60; ++j) candidates.push_back({(j + 0.5) / 60, 0.5});
  TrainingOptions options;
  options.points = 30;
  std::vector<double> progress;
  const FaceLightModel model =
      Train(candidates, images, options, [&](double f) { progress.push_back(f); });
  EXPECT_EQ(model.SampleCount(), 30);
  EXPECT_EQ(model.training.subjects, (std::vector<int>{1, 2}));
  EXPECT_EQ(model.training.images, 80);
  EXPECT_EQ(model.training.candidates, 60);
  EXPECT_EQ(progress.back(), 1.0);
  std::vector<TrainingImage> no_front(images.begin() + 1, images.begin() + 40);
  PROBELESS_EXPECT_THROWS_MESSAGE(
      FitRtfs(no_front, nullptr), FaceLightError,
      "face_light training: subject 1 has no frontal-lit image (azimuth 0, elevation 0)");
  std::vector<TrainingImage> few(images.begin(), images.begin() + 5);
  PROBELESS_EXPECT_THROWS_MESSAGE(
      FitRtfs(few, nullptr), FaceLightError,
      "face_light training: candidate 0 has 5 valid equations and no unique RTF (need 9 "
      "independent lights)");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      Train(std::span(candidates).first(10), images, options), FaceLightError,
      "face_light training: images have 60 values but there are 10 candidates");
}

TEST(EstimatorTest, GrayRecoversAKnownLightExactly) {
  const FaceLightModel model = ModelFrom(SyntheticRtfs(294, 11));
  const FaceLightEstimator estimator(model);
  for (const auto& [azimuth, elevation] :
       std::vector<std::pair<double, double>>{{0, 0}, {50, -20}, {-95, 10}, {130, 20}, {-35, 65}}) {
    const std::vector<double> light = TestLight(azimuth, elevation);
    const LightEstimate estimate = estimator.EstimateGray(Render(model, light));
    ASSERT_EQ(estimate.channels, 1);
    for (int n = 0; n < 9; ++n) {
      EXPECT_NEAR(estimate.coefficients[n][0], light[n], 2e-3 * (1 + std::abs(light[n])));
      EXPECT_EQ(estimate.coefficients[n][1], estimate.coefficients[n][0]);
    }
    EXPECT_LT(AngleDeg(estimate.dominant_direction, YaleBLightDirection(azimuth, elevation)), 0.1);
    EXPECT_NEAR(estimate.intensity, 2.0, 0.01);
    EXPECT_EQ(estimate.samples_used, 294);
    EXPECT_GT(estimate.confidence, 0.99);
  }
}

TEST(EstimatorTest, RgbWithInvalidSamplesUsesTheFastDowndate) {
  const FaceLightModel model = ModelFrom(SyntheticRtfs(294, 12));
  const FaceLightEstimator estimator(model);
  std::vector<std::vector<double>> lights = {TestLight(20, 10), TestLight(-60, -20),
                                             TestLight(85, 20)};
  lights[1][0] *= 0.5;
  std::vector<float> rgb(3 * 294);
  for (int c = 0; c < 3; ++c) {
    const std::vector<float> channel = Render(model, lights[c]);
    for (int i = 0; i < 294; ++i) rgb[3 * i + c] = channel[i];
  }
  std::vector<uint64_t> valid(8, ~uint64_t{0});
  for (int i = 0; i < 294; i += 7) {  // 42 invalid samples, their values garbage
    valid[i / 64] &= ~(uint64_t{1} << (i % 64));
    rgb[3 * i] = 1e9f;
  }
  const LightEstimate estimate = estimator.EstimateRgb(rgb, valid);
  ASSERT_EQ(estimate.channels, 3);
  EXPECT_EQ(estimate.samples_used, 252);
  for (int c = 0; c < 3; ++c) {
    for (int n = 0; n < 9; ++n) {
      EXPECT_NEAR(estimate.coefficients[n][c], lights[c][n], 3e-3 * (1 + std::abs(lights[c][n])))
          << "c=" << c << " n=" << n;
    }
  }
  EXPECT_NEAR(estimate.confidence, 252.0 / 294, 0.01);
  // NaN counts as invalid too; fewer than 9 usable samples give no estimate.
  std::vector<float> gray = Render(model, lights[0]);
  gray[0] = std::nanf("");
  EXPECT_EQ(estimator.EstimateGray(gray).samples_used, 293);
  std::vector<uint64_t> few(8, 0);
  few[0] = 0xff;
  EXPECT_EQ(estimator.EstimateGray(gray, few).channels, 0);
  PROBELESS_EXPECT_THROWS_MESSAGE(estimator.EstimateGray(std::span(gray).first(10)), FaceLightError,
                                  "FaceLightEstimator: 10 intensities, the model has 294 samples");
  PROBELESS_EXPECT_THROWS_MESSAGE(estimator.EstimateRgb(gray), FaceLightError,
                                  "FaceLightEstimator: 294 RGB values, expected 3 x 294 samples");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      estimator.EstimateGray(gray, std::span(valid).first(2)), FaceLightError,
      "FaceLightEstimator: 2 validity words cover fewer than 294 samples");
}

// The residual statistics come from coefficient space on the fast paths (closed form with the
// prior); they must equal the per-sample residuals of the returned light, with and without invalid
// samples, RGB (channel means) and gray, and match the per-sample path of the robust mode.
TEST(EstimatorTest, ResidualAndConfidenceMatchThePerSampleResiduals) {
  const FaceLightModel model = ModelFrom(SyntheticRtfs(294, 21));
  EstimatorOptions prior;
  prior.back_prior = 0.1;
  const FaceLightEstimator estimator(model, prior);
  std::vector<float> rgb(3 * 294);
  const std::vector<double> lights[3] = {TestLight(30, 10), TestLight(-70, 20), TestLight(0, -35)};
  for (int c = 0; c < 3; ++c) {
    const std::vector<float> channel = Render(model, lights[c]);
    for (int i = 0; i < 294; ++i) {
      rgb[3 * i + c] = channel[i] + 0.02f * static_cast<float>(std::sin(1.7 * i + c));
    }
  }
  std::vector<uint64_t> some_invalid(8, ~uint64_t{0});
  for (int i = 3; i < 294; i += 9) {
    some_invalid[i / 64] &= ~(uint64_t{1} << (i % 64));
    rgb[3 * i + 1] = std::numeric_limits<float>::infinity();
  }
  std::vector<float> finite = rgb;
  for (int i = 3; i < 294; i += 9) finite[3 * i + 1] = 0.3f;
  const auto check = [&](const LightEstimate& e, const std::vector<float>& values, int channels,
                         std::span<const uint64_t> bits) {
    ASSERT_EQ(e.channels, channels);
    double ss_res = 0, sum = 0, sum_sq = 0;
    int used = 0;
    for (int i = 0; i < 294; ++i) {
      if (!bits.empty() && !((bits[i / 64] >> (i % 64)) & 1u)) continue;
      double mean = 0, predicted = 0;
      for (int c = 0; c < channels; ++c) mean += values[channels * i + c] / channels;
      for (int n = 0; n < 9; ++n) {
        double light = 0;
        for (int c = 0; c < channels; ++c) light += e.coefficients[n][c] / channels;
        predicted += model.rtf[i][n] * light;
      }
      ss_res += (mean - predicted) * (mean - predicted);
      sum += mean;
      sum_sq += mean * mean;
      ++used;
    }
    ASSERT_EQ(e.samples_used, used);
    const double rms = std::sqrt(ss_res / used);
    const double r2 = 1 - ss_res / (sum_sq - sum * sum / used);
    EXPECT_NEAR(e.rms_residual, rms, 1e-3 * rms + 1e-6);
    EXPECT_NEAR(e.confidence, r2 * used / 294, 1e-4);
  };
  check(estimator.EstimateRgb(finite), finite, 3, {});
  check(estimator.EstimateRgb(rgb, some_invalid), rgb, 3, some_invalid);
  std::vector<float> gray(294);
  for (int i = 0; i < 294; ++i) gray[i] = finite[3 * i];
  check(estimator.EstimateGray(gray), gray, 1, {});
  check(estimator.EstimateGray(gray, some_invalid), gray, 1, some_invalid);
  // The robust mode computes them per sample: with nothing to reject it agrees.
  EstimatorOptions robust = prior;
  robust.robust = true;
  robust.robust_threshold = 100;
  const LightEstimate a = FaceLightEstimator(model, robust).EstimateRgb(finite);
  const LightEstimate b = estimator.EstimateRgb(finite);
  EXPECT_NEAR(a.rms_residual, b.rms_residual, 1e-3 * b.rms_residual);
  EXPECT_NEAR(a.confidence, b.confidence, 1e-4);
}

TEST(EstimatorTest, RobustModeRejectsOutliers) {
  const FaceLightModel model = ModelFrom(SyntheticRtfs(294, 13));
  const std::vector<double> light = TestLight(-50, 15);
  std::vector<float> values = Render(model, light);
  std::mt19937_64 rng(5);
  for (float& v : values) v += static_cast<float>(0.002 * (Uniform(rng) - 0.5));
  for (int i = 3; i < 294; i += 10) values[i] += 0.8f;  // 30 specular highlights
  for (int i = 6; i < 294; i += 25) values[i] = 0;      // 12 cast shadows
  EstimatorOptions linear;
  linear.directional_fit = false;  // the paper's optimal linear direction
  const LightEstimate plain = FaceLightEstimator(model, linear).EstimateGray(values);
  EstimatorOptions options = linear;
  options.robust = true;
  const LightEstimate robust = FaceLightEstimator(model, options).EstimateGray(values);
  const std::array<double, 3> truth = YaleBLightDirection(-50, 15);
  EXPECT_GT(AngleDeg(plain.dominant_direction, truth), 2.0);
  EXPECT_LT(AngleDeg(robust.dominant_direction, truth), 0.5);
  EXPECT_GE(robust.samples_rejected, 42);
  EXPECT_LE(robust.samples_rejected, 50);
  for (int n = 0; n < 9; ++n) EXPECT_NEAR(robust.coefficients[n][0], light[n], 0.02);
}

TEST(EstimatorTest, PriorAndNonNegativeModes) {
  const FaceLightModel model = ModelFrom(SyntheticRtfs(294, 14));
  const std::vector<double> light = sh::DirectionalLight(YaleBLightDirection(30, 20), 2.0, 3);
  const std::vector<float> values = Render(model, light);
  // A small ridge barely moves the direction.
  EstimatorOptions ridge;
  ridge.ridge = 0.001;
  ridge.back_prior = 0.001;
  const LightEstimate with_prior = FaceLightEstimator(model, ridge).EstimateGray(values);
  EXPECT_LT(AngleDeg(with_prior.dominant_direction, YaleBLightDirection(30, 20)), 3.0);
  // Non-negative: the light is a non-negative sum of directional lights, so its band-2 radiance
  // is a non-negative combination; a directional light is reproduced closely.
  EstimatorOptions nn;
  nn.non_negative = true;
  nn.nn_directions = 256;

  const LightEstimate positive = FaceLightEstimator(model, nn).EstimateGray(values);
  EXPECT_LT(AngleDeg(positive.dominant_direction, YaleBLightDirection(30, 20)), 3.0);
  EXPECT_LT(positive.rms_residual, 1e-3);
  EXPECT_NEAR(positive.coefficients[0][0], light[0], 0.1 * light[0]);
  PROBELESS_EXPECT_THROWS_MESSAGE(
      {
        EstimatorOptions bad;
        bad.ridge = -1;
        FaceLightEstimator(model, bad);
      },
      FaceLightError,
      "FaceLightEstimator: options out of range (ridge, back_prior, weight_floor, "
      "direction_ridge, directional_robust >= 0; robust_iterations 1..20; "
      "robust_threshold > 0; nn_directions 9..1024; nn_iterations 1..10000; "
      "directional_grid 0..1024; directional_iterations 0..100; mask_cache 0..64)");
  EXPECT_THROW(
      {
        EstimatorOptions bad;
        bad.mask_cache = 65;
        FaceLightEstimator(model, bad);
      },
      FaceLightError);
}

// Direction RTFs of `bands` bands for the synthetic normals of SyntheticRtfs(count, seed): the
// clamped-cosine transfer, so a directional light renders the sharp attached shadow (up to band
// `bands` - 1) that the 9-coefficient RTFs blur.
std::vector<float> SyntheticDirectionRtfs(int count, uint64_t seed, int bands) {
  const std::vector<Rtf> rtfs = SyntheticRtfs(count, seed);
  const int n = bands * bands;
  std::vector<float> out(static_cast<size_t>(count) * n);
  for (int i = 0; i < count; ++i) {
    // Recover albedo and normal from band 0 and band 1 of the 9-coefficient RTF.
    const double a0 = sh::ClampedCosineCoefficient(0);
    const double y0 = sh::Basis9({0, 0, 1})[0];
    const double albedo = rtfs[i][0] * std::numbers::pi / (a0 * y0);
    sh::Vec3 normal{-rtfs[i][3], -rtfs[i][1], rtfs[i][2]};  // Y_1 = (-y, z, -x) * 0.4886
    const double len =
        std::sqrt(normal[0] * normal[0] + normal[1] * normal[1] + normal[2] * normal[2]);
    for (double& v : normal) v /= len;
    const std::vector<double> basis = sh::Basis(bands, normal);
    for (int k = 0; k < n; ++k) {
      out[static_cast<size_t>(i) * n + k] = static_cast<float>(
          albedo / std::numbers::pi * sh::ClampedCosineCoefficient(sh::DegreeOf(k)) * basis[k]);
    }
  }
  return out;
}

TEST(EstimatorTest, DirectionalFitRecoversTheDirection) {
  // Samples rendered with 5-band direction RTFs under a directional light of power 2 plus
  // ambient 0.3: the directional fit recovers the direction (the linear band-1 direction of the
  // 9-coefficient fit is biased), with and without the direction RTFs, with invalid samples.
  const int count = 300;
  FaceLightModel model = ModelFrom(SyntheticRtfs(count, 21));
  model.direction_bands = 5;
  model.direction_rtf = SyntheticDirectionRtfs(count, 21, 5);
  EstimatorOptions linear;
  linear.directional_fit = false;
  EstimatorOptions exact;  // no Tikhonov weight on the direction RTFs: exact recovery
  exact.direction_ridge = 0;
  const FaceLightEstimator directional(model, exact);
  const FaceLightEstimator paper(model, linear);
  for (const auto& [azimuth, elevation] :
       std::vector<std::pair<double, double>>{{0, 0}, {50, -20}, {-95, 10}, {35, 65}}) {
    const std::array<double, 3> d = YaleBLightDirection(azimuth, elevation);
    const std::vector<double> y = sh::Basis(5, d);
    std::vector<float> values(count);
    for (int i = 0; i < count; ++i) {
      double v = 0.3 * model.direction_rtf[static_cast<size_t>(i) * 25];
      for (int k = 0; k < 25; ++k)
        v += 2.0 * y[k] * model.direction_rtf[static_cast<size_t>(i) * 25 + k];
      values[i] = static_cast<float>(v);  // ModelFrom's intensity_exponent is 1
    }
    const LightEstimate fit = directional.EstimateGray(values);
    ASSERT_EQ(fit.channels, 1);
    EXPECT_LT(AngleDeg(fit.dominant_direction, d), 0.2) << azimuth << " " << elevation;
    std::vector<uint64_t> valid(8, ~uint64_t{0});
    for (int i = 0; i < count; i += 9) valid[i / 64] &= ~(uint64_t{1} << (i % 64));
    EXPECT_LT(AngleDeg(directional.EstimateGray(values, valid).dominant_direction, d), 0.2);
    const double linear_error = AngleDeg(paper.EstimateGray(values).dominant_direction, d);
    EXPECT_GT(linear_error, AngleDeg(fit.dominant_direction, d));
  }
  // Without direction RTFs the fit uses the 9-coefficient RTFs: exact for a band-2 light.
  EstimatorOptions nine;
  nine.use_direction_rtfs = false;
  const std::vector<float> band2 = Render(model, TestLight(-60, 25));
  EXPECT_LT(AngleDeg(FaceLightEstimator(model, nine).EstimateGray(band2).dominant_direction,
                     YaleBLightDirection(-60, 25)),
            0.1);
  // Robust re-fit: 20 highlights (+0.5) on exact 5-band samples are dropped.
  EstimatorOptions robust = exact;
  robust.directional_robust = 3;
  const std::array<double, 3> d = YaleBLightDirection(40, 10);
  const std::vector<double> y = sh::Basis(5, d);
  std::vector<float> values(count);
  std::mt19937_64 rng(3);
  for (int i = 0; i < count; ++i) {
    double v = 0;
    for (int k = 0; k < 25; ++k)
      v += 2.0 * y[k] * model.direction_rtf[static_cast<size_t>(i) * 25 + k];
    values[i] = static_cast<float>(v + 0.002 * (Uniform(rng) - 0.5) + (i % 15 == 4 ? 0.5 : 0));
  }
  const double plain_error = AngleDeg(directional.EstimateGray(values).dominant_direction, d);
  const double robust_error =
      AngleDeg(FaceLightEstimator(model, robust).EstimateGray(values).dominant_direction, d);
  EXPECT_LT(robust_error, 0.3);
  EXPECT_LT(robust_error, plain_error);
}

// With invalid samples the estimator downdates the full-set matrices (the 9 x 9 normal matrix and
// the directional fit's 25 x 25 cost matrix with its start-grid tables) and caches them per
// validity mask (EstimatorOptions::mask_cache). Results must be bit-identical with and without the
// cache (miss, hit, after eviction, gray sharing RGB's entry), equal the plain least-squares solve
// in double on the valid samples up to the float rounding of the output, and agree with a model
// made of the valid samples alone (every sample valid: the float pseudo-inverse) to float
// precision.
TEST(EstimatorTest, InvalidSamplesMatchThePlainSolveWithAndWithoutTheMaskCache) {
  const int count = 300;
  FaceLightModel model = ModelFrom(SyntheticRtfs(count, 41));
  model.direction_bands = 5;
  model.direction_rtf = SyntheticDirectionRtfs(count, 41, 5);
  EstimatorOptions options;
  options.direction_ridge = 0;  // the ridge scales with the trace, which the sub-models change
  EstimatorOptions uncached_options = options;
  uncached_options.mask_cache = 0;
  const FaceLightEstimator cached(model, options);
  EstimatorOptions exact_options = options;
  exact_options.exact_masked_solve = true;
  const FaceLightEstimator exact_solver(model, exact_options);
  const FaceLightEstimator uncached(model, uncached_options);
  std::mt19937_64 rng(5);
  const std::vector<double> lights[3] = {TestLight(30, 10), TestLight(-50, -15), TestLight(70, 30)};
  std::vector<float> rgb(3 * count);
  for (int c = 0; c < 3; ++c) {
    const std::vector<float> channel = Render(model, lights[c]);
    for (int i = 0; i < count; ++i) {
      rgb[3 * i + c] = channel[i] + 0.01f * static_cast<float>(Uniform(rng) - 0.5);
    }
  }
  std::vector<float> gray(count);
  for (int i = 0; i < count; ++i) gray[i] = rgb[3 * i + 1];
  // Sample i invalid with probability invalid_percent / 100 (fixed seed).
  const auto random_mask = [&](uint64_t seed, int invalid_percent) {
    std::vector<uint64_t> bits(8, ~uint64_t{0});
    std::mt19937_64 mask_rng(seed);
    for (int i = 0; i < count; ++i) {
      if (static_cast<int>(mask_rng() % 100) < invalid_percent) {
        bits[i / 64] &= ~(uint64_t{1} << (i % 64));
      }
    }
    return bits;
  };
  const auto expect_identical = [](const LightEstimate& a, const LightEstimate& b) {
    ASSERT_EQ(a.channels, b.channels);
    for (int n = 0; n < 9; ++n) {
      for (int c = 0; c < 3; ++c) EXPECT_EQ(a.coefficients[n][c], b.coefficients[n][c]);
    }
    for (int k = 0; k < 3; ++k) EXPECT_EQ(a.dominant_direction[k], b.dominant_direction[k]);
    EXPECT_EQ(a.intensity, b.intensity);
    EXPECT_EQ(a.confidence, b.confidence);
    EXPECT_EQ(a.rms_residual, b.rms_residual);
    EXPECT_EQ(a.samples_used, b.samples_used);
  };
  const std::vector<uint64_t> steady = random_mask(1, 10);
  const LightEstimate reference = uncached.EstimateRgb(rgb, steady);
  expect_identical(cached.EstimateRgb(rgb, steady), reference);  // miss
  expect_identical(cached.EstimateRgb(rgb, steady), reference);  // hit
  expect_identical(cached.EstimateGray(gray, steady), uncached.EstimateGray(gray, steady));
  for (uint64_t seed = 2; seed < 8; ++seed) {  // six other masks evict it (4 entries)
    const std::vector<uint64_t> other = random_mask(seed, 10);
    expect_identical(cached.EstimateRgb(rgb, other), uncached.EstimateRgb(rgb, other));
  }
  expect_identical(cached.EstimateRgb(rgb, steady), reference);  // miss again

  // The plain solve on the valid samples only; 10 % and 60 % invalid (the latter rebuilds the
  // normal matrix from the valid samples instead of downdating).
  for (const int invalid_percent : {10, 60}) {
    const std::vector<uint64_t> mask = random_mask(11, invalid_percent);
    FaceLightModel sub = model;
    sub.positions.clear(), sub.rtf.clear(), sub.residual_rms.clear(), sub.direction_rtf.clear();
    std::vector<float> sub_rgb;
    for (int i = 0; i < count; ++i) {
      if (!((mask[i / 64] >> (i % 64)) & 1u)) continue;
      sub.positions.push_back(model.positions[i]);
      sub.rtf.push_back(model.rtf[i]);
      sub.residual_rms.push_back(model.residual_rms[i]);
      sub.direction_rtf.insert(sub.direction_rtf.end(), model.direction_rtf.begin() + i * 25,
                               model.direction_rtf.begin() + (i + 1) * 25);
      sub_rgb.insert(sub_rgb.end(), rgb.begin() + 3 * i, rgb.begin() + 3 * i + 3);
    }
    const int used = sub.SampleCount();
    // Plain solve in double, per channel: (T^T T) e = T^T v over the valid samples (Gaussian
    // elimination; no prior).
    double reference[3][9];
    for (int c = 0; c < 3; ++c) {
      double system[9][10] = {};
      for (int i = 0; i < used; ++i) {
        for (int a = 0; a < 9; ++a) {
          for (int b = 0; b < 9; ++b) system[a][b] += double(sub.rtf[i][a]) * sub.rtf[i][b];
          system[a][9] += double(sub.rtf[i][a]) * sub_rgb[3 * i + c];
        }
      }
      for (int k = 0; k < 9; ++k) {
        for (int r = k + 1; r < 9; ++r) {
          const double f = system[r][k] / system[k][k];
          for (int col = k; col < 10; ++col) system[r][col] -= f * system[k][col];
        }
      }
      for (int k = 8; k >= 0; --k) {
        double sum = system[k][9];
        for (int col = k + 1; col < 9; ++col) sum -= system[k][col] * reference[c][col];
        reference[c][k] = sum / system[k][k];
      }
    }
    const LightEstimate plain = FaceLightEstimator(sub, options).EstimateRgb(sub_rgb);
    const LightEstimate masked = cached.EstimateRgb(rgb, mask);
    const LightEstimate exact = exact_solver.EstimateRgb(rgb, mask);
    ASSERT_EQ(masked.samples_used, used);
    ASSERT_EQ(exact.samples_used, used);
    // exact_masked_solve: equal to the double solve up to the float rounding of the output
    // (2^-24 relative). Default (the full-set float pseudo-inverse and the mask's 9 x 9
    // correction): float precision, like the all-valid path.
    double worst_reference = 0;
    for (int n = 0; n < 9; ++n) {
      for (int c = 0; c < 3; ++c) {
        const double ref = reference[c][n];
        const double error = std::abs(exact.coefficients[n][c] - ref);
        EXPECT_LE(error, 0x1.0p-24 * std::abs(ref) + 1e-12) << "n=" << n << " c=" << c;
        const double float_error = std::abs(masked.coefficients[n][c] - ref) / (1 + std::abs(ref));
        EXPECT_LT(float_error, 1e-5) << "n=" << n << " c=" << c;
        worst_reference = std::max(worst_reference, float_error);
      }
    }
    // The all-valid model of the valid samples (float pseudo-inverse): float precision.
    double worst = 0;
    for (int n = 0; n < 9; ++n) {
      for (int c = 0; c < 3; ++c) {
        const double p = plain.coefficients[n][c];
        worst = std::max(worst, std::abs(masked.coefficients[n][c] - p) / (1 + std::abs(p)));
      }
    }
    EXPECT_LT(worst, 1e-5) << invalid_percent << " % invalid";
    const std::array<double, 3> plain_direction{
        plain.dominant_direction[0], plain.dominant_direction[1], plain.dominant_direction[2]};
    EXPECT_LT(AngleDeg(masked.dominant_direction, plain_direction), 1e-2);
    EXPECT_NEAR(masked.intensity, plain.intensity, 1e-5 * (1 + plain.intensity));
    // The residual (closed form from coefficient space) matches the per-sample residuals of the
    // returned light: to 1e-3 with the exact solve; with the float pseudo-inverse the closed form
    // inherits its first-order error (like the all-valid path, printed): here the noise is small
    // (rms 0.0017 on values ~0.5), the bound 1e-2.
    const auto per_sample_rms = [&](const LightEstimate& estimate) {
      double ss_res = 0;
      for (int i = 0; i < used; ++i) {
        double predicted = 0, mean = 0;
        for (int c = 0; c < 3; ++c) mean += sub_rgb[3 * i + c] / 3.0;
        for (int n = 0; n < 9; ++n) {
          double light = 0;
          for (int c = 0; c < 3; ++c) light += estimate.coefficients[n][c] / 3.0;
          predicted += sub.rtf[i][n] * light;
        }
        ss_res += (mean - predicted) * (mean - predicted);
      }
      return std::sqrt(ss_res / used);
    };
    EXPECT_NEAR(exact.rms_residual, per_sample_rms(exact), 1e-3 * exact.rms_residual);
    EXPECT_NEAR(masked.rms_residual, per_sample_rms(masked), 1e-2 * masked.rms_residual);
    const double rms_error = std::abs(masked.rms_residual / per_sample_rms(masked) - 1);
    const double plain_rms_error = std::abs(plain.rms_residual / per_sample_rms(plain) - 1);
    std::printf(
        "%d %% invalid: vs the double solve %.3g, vs the valid-samples model %.3g (relative to "
        "1 + |value|), direction %.3g deg; rms residual relative error %.3g (all-valid path "
        "%.3g)\n",
        invalid_percent, worst_reference, worst,
        AngleDeg(masked.dominant_direction, plain_direction), rms_error, plain_rms_error);
  }
}

// Two threads share one estimator (and its mask cache) with changing masks: every estimate equals
// the single-threaded one of an estimator without a cache.
TEST(EstimatorTest, MaskCacheIsThreadSafe) {
  const int count = 300;
  FaceLightModel model = ModelFrom(SyntheticRtfs(count, 43));
  model.direction_bands = 5;
  model.direction_rtf = SyntheticDirectionRtfs(count, 43, 5);
  EstimatorOptions uncached_options;
  uncached_options.mask_cache = 0;
  const FaceLightEstimator shared(model);
  const FaceLightEstimator uncached(model, uncached_options);
  std::vector<float> rgb(3 * count);
  for (int c = 0; c < 3; ++c) {
    const std::vector<float> channel = Render(model, TestLight(20 - 40 * c, 10));
    for (int i = 0; i < count; ++i) rgb[3 * i + c] = channel[i];
  }
  std::vector<std::vector<uint64_t>> masks(6, std::vector<uint64_t>(8, ~uint64_t{0}));
  std::vector<LightEstimate> expected;
  for (size_t k = 0; k < masks.size(); ++k) {
    for (int i = static_cast<int>(k); i < count; i += 7 + static_cast<int>(k)) {
      masks[k][i / 64] &= ~(uint64_t{1} << (i % 64));
    }
    expected.push_back(uncached.EstimateRgb(rgb, masks[k]));
  }
  std::atomic<int> mismatches{0};
  const auto run = [&](int offset) {
    for (int iteration = 0; iteration < 300; ++iteration) {
      const size_t k = (iteration * (offset + 1) + offset) % masks.size();
      const LightEstimate e = shared.EstimateRgb(rgb, masks[k]);
      bool same = e.samples_used == expected[k].samples_used &&
                  e.dominant_direction == expected[k].dominant_direction &&
                  e.confidence == expected[k].confidence;
      for (int n = 0; n < 9; ++n) same = same && e.coefficients[n] == expected[k].coefficients[n];
      if (!same) ++mismatches;
    }
  };
  std::thread first(run, 0), second(run, 1);
  first.join();
  second.join();
  EXPECT_EQ(mismatches.load(), 0);
}

TEST(EstimatorTest, FillShLightCopiesTheEstimate) {
  const FaceLightModel model = ModelFrom(SyntheticRtfs(100, 15));
  const LightEstimate estimate =
      FaceLightEstimator(model).EstimateGray(Render(model, TestLight(10, 10)));
  msgs::ShLight light;
  FillShLight(estimate, light);
  EXPECT_EQ(light.bands, 3u);
  EXPECT_EQ(light.coefficients[4][2], estimate.coefficients[4][2]);
  EXPECT_EQ(light.coefficients[9][0], 0.0f);
  EXPECT_EQ(light.dominant_direction[1], estimate.dominant_direction[1]);
  EXPECT_EQ(light.confidence, estimate.confidence);
  EXPECT_EQ(light.units, msgs::ShLightUnits::kFaceModel);  // the model's units, not linear
  EXPECT_NO_THROW(light.Validate());
}

class ModelFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ =
        std::filesystem::temp_directory_path() / ("face_light_test_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::filesystem::path dir_;
};

TEST_F(ModelFileTest, RoundTripIsExact) {
  FaceLightModel model = ModelFrom(SyntheticRtfs(50, 16));
  model.training.percentile = 87.5;
  model.patch_radius_px = 3;
  model.intensity_exponent = 0.5;
  const std::string path = (dir_ / "m.model").string();
  SaveModel(model, path);
  const FaceLightModel loaded = LoadModel(path);
  EXPECT_EQ(SerializeModel(loaded), SerializeModel(model));
  ASSERT_EQ(loaded.SampleCount(), 50);
  for (int i = 0; i < 50; ++i) {
    EXPECT_EQ(loaded.rtf[i], model.rtf[i]);
    EXPECT_EQ(loaded.positions[i].x, model.positions[i].x);
  }
  EXPECT_EQ(loaded.patch_radius_px, 3);
  EXPECT_EQ(loaded.intensity_exponent, 0.5);
  EXPECT_EQ(loaded.training.subjects, model.training.subjects);
  EXPECT_EQ(loaded.training.percentile, 87.5);
  // Version 2 with direction RTFs.
  model.direction_bands = 4;
  model.direction_rtf = SyntheticDirectionRtfs(50, 16, 4);
  SaveModel(model, path);
  const FaceLightModel with_directions = LoadModel(path);
  EXPECT_EQ(SerializeModel(with_directions), SerializeModel(model));
  EXPECT_EQ(with_directions.direction_bands, 4);
  EXPECT_EQ(with_directions.direction_rtf, model.direction_rtf);
}

TEST_F(ModelFileTest, Version1FilesStillLoad) {
  std::string text = SerializeModel(ModelFrom(SyntheticRtfs(30, 18)));
  text.replace(text.find("probeless_face_light_model 2"), 28, "probeless_face_light_model 1");
  text.erase(text.find("direction_bands 0\n"), 18);
  const FaceLightModel model = ParseModel(text, "v1.model");
  EXPECT_EQ(model.SampleCount(), 30);
  EXPECT_EQ(model.direction_bands, 0);
  EXPECT_NO_THROW(FaceLightEstimator(model, {}));
}

TEST_F(ModelFileTest, CorruptFilesGiveOneLineErrors) {
  const std::string good = SerializeModel(ModelFrom(SyntheticRtfs(3, 17)));
  const auto replace = [&](const std::string& from, const std::string& to) {
    std::string text = good;
    text.replace(text.find(from), from.size(), to);
    return text;
  };
  const auto error = [](const std::string& text) {
    return probeless::testing::ThrownMessage<FaceLightError>([&] { ParseModel(text, "m.model"); });
  };
  EXPECT_EQ(error("hello\n"),
            "m.model: line 1: not a face_light model (expected magic "
            "'probeless_face_light_model')");
  EXPECT_EQ(error(""),
            "m.model: line 1: unexpected end of file, expected the magic line "
            "(truncated?)");
  EXPECT_EQ(error(replace("probeless_face_light_model 2", "probeless_face_light_model 3")),
            "m.model: line 1: unsupported version 3 (expected 1 or 2)");
  EXPECT_EQ(error(replace("direction_bands 0", "direction_bands 3")),
            "m.model: line 5: direction_bands 3 must be 0, 4 or 5");
  EXPECT_EQ(error(replace("direction_bands 0", "frame x")),
            "m.model: line 5: expected 'direction_bands', found 'frame'");
  EXPECT_EQ(error(replace("condon-shortley", "no-phase")),
            "m.model: line 3: SH convention 'real-orthonormal;no-phase;index=l(l+1)+m' differs "
            "from 'real-orthonormal;condon-shortley;index=l(l+1)+m'");
  EXPECT_EQ(error(replace("samples 3", "samples 4")),
            "m.model: line 20: expected 'sample', found 'end'");
  EXPECT_EQ(error(good.substr(0, good.rfind("sample "))),
            "m.model: line 19: unexpected end of file, expected 'sample' (truncated?)");
  EXPECT_EQ(error(replace("samples 3", "samples 600")),
            "m.model: line 15: samples 600 out of range 1..512");
  EXPECT_EQ(error(replace("sample 0.025", "sample nan")),
            "m.model: line 17: bad u 'nan' (expected a finite number)");
  EXPECT_EQ(error(replace("intensity_exponent 1", "intensity_exponent 3")),
            "m.model: line 9: intensity_exponent must be in (0, 2]");
  EXPECT_EQ(error(replace("training_images 128", "training_images many")),
            "m.model: line 12: bad training_images 'many' (expected an integer)");
  EXPECT_EQ(error(replace("end\n", "")),
            "m.model: line 20: unexpected end of file, expected 'end' (truncated?)");
  PROBELESS_EXPECT_THROWS_MESSAGE(LoadModel((dir_ / "missing.model").string()), FaceLightError,
                                  (dir_ / "missing.model").string() + ": cannot open model file");
}

TEST(YaleBNameTest, ParsesFileNamesAndSubjectLists) {
  const auto name = ParseYaleBName("yaleB07_P00A-035E+65.pgm");
  ASSERT_TRUE(name.has_value());
  EXPECT_EQ(name->subject, 7);
  EXPECT_EQ(name->azimuth_deg, -35);
  EXPECT_EQ(name->elevation_deg, 65);
  EXPECT_FALSE(ParseYaleBName("yaleB07_P00_Ambient.pgm").has_value());
  EXPECT_FALSE(ParseYaleBName("yaleB07_P00A-035E+65.pgm.bad").has_value());
  // Positive azimuth: light from the subject's right = image left = -x.
  EXPECT_NEAR(YaleBLightDirection(90, 0)[0], -1, 1e-12);
  EXPECT_EQ(ParseSubjectList("1-3,7,2"), (std::vector<int>{1, 2, 3, 7}));
  PROBELESS_EXPECT_THROWS_MESSAGE(
      ParseSubjectList("1-x"), FaceLightError,
      "bad subject list '1-x' (expected e.g. 1-28 or 1,3,5-7 with numbers 1..99)");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      ListYaleBSubjects("/nonexistent/yaleb"), FaceLightError,
      "/nonexistent/yaleb: not a directory (expected the Yale B folder with yaleBxx/)");
}

}  // namespace
}  // namespace probeless::face_light
