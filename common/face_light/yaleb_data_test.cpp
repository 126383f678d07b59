// face_light on the shared Extended Yale B data: train on a few subjects, evaluate on others
// (never a training subject), bound the mean angular error of the optimal linear direction; also
// loads the shipped default model. Skips with a message when the data is absent.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <numbers>
#include <string>
#include <vector>

#include "probeless/face_light/estimator.h"
#include "probeless/face_light/model.h"
#include "probeless/face_light/training.h"
#include "probeless/face_light/yaleb.h"

namespace probeless::face_light {
namespace {

std::string YaleBDir() {
  const char* env = std::getenv("PROBELESS_DATA");
  return std::string(env ? env : PROBELESS_DATA_DIR) + "/yaleb";
}

std::vector<TrainingImage> Sampled(const std::string& dir, const std::vector<int>& subjects,
                                   const std::vector<Point2>& positions, int radius) {
  std::vector<TrainingImage> out;
  for (int s : subjects) {
    for (const YaleBImage& image : LoadYaleBSubject(dir, s)) {
      TrainingImage t;
      t.subject = s;
      t.azimuth_deg = image.name.azimuth_deg;
      t.elevation_deg = image.name.elevation_deg;
      t.values.resize(positions.size());
      t.valid.resize(positions.size());
      SamplePatches(image.pixels.data(), image.width, image.height, image.width, 1,
                    SimilarityTransform{}, positions, radius, 255, t.values, t.valid);
      out.push_back(std::move(t));
    }
  }
  return out;
}

double MeanAngularErrorDeg(const FaceLightModel& model, const EstimatorOptions& options,
                           const std::vector<TrainingImage>& test) {
  const FaceLightEstimator estimator(model, options);
  double sum = 0;
  for (const TrainingImage& image : test) {
    std::vector<uint64_t> bits(8, 0);
    for (size_t i = 0; i < image.valid.size(); ++i) {
      if (image.valid[i]) bits[i / 64] |= uint64_t{1} << (i % 64);
    }
    const LightEstimate e = estimator.EstimateGray(image.values, bits);
    const std::array<double, 3> t = YaleBLightDirection(image.azimuth_deg, image.elevation_deg);
    const double dot = t[0] * e.dominant_direction[0] + t[1] * e.dominant_direction[1] +
                       t[2] * e.dominant_direction[2];
    sum += std::acos(std::clamp(dot, -1.0, 1.0)) * 180 / std::numbers::pi;
  }
  return sum / test.size();
}

TEST(YaleBDataTest, TrainOnSixSubjectsEvaluateOnTwoUnseen) {
  const std::string dir = YaleBDir();
  if (!std::filesystem::is_directory(dir + "/yaleB01")) {
    GTEST_SKIP() << "Yale B data not found at " << dir << " (set PROBELESS_DATA)";
  }
  const std::vector<Point2> candidates = CandidatePositions();
  const std::vector<TrainingImage> train = Sampled(dir, {1, 2, 3, 4, 5, 6}, candidates, 2);
  // rtf_train's defaults: g = 0.5, every candidate kept, 5-band direction RTFs.
  TrainingOptions options;
  options.intensity_exponent = 0.5;
  options.percentile = 0;
  options.direction_bands = 5;
  const FaceLightModel model = Train(candidates, train, options);
  EXPECT_EQ(model.training.subjects, (std::vector<int>{1, 2, 3, 4, 5, 6}));
  EXPECT_EQ(model.SampleCount(), 512);
  EXPECT_EQ(model.direction_bands, 5);
  const std::vector<TrainingImage> test = Sampled(dir, {7, 8}, model.positions, 2);
  ASSERT_EQ(test.size(), 128u);
  // Default estimator: directional fit with the direction RTFs. Measured 8.3 deg.
  const double error = MeanAngularErrorDeg(model, {}, test);
  RecordProperty("mean_angular_error_deg", std::to_string(error));
  EXPECT_LT(error, 10.5) << "directional fit: mean angular error " << error << " deg";
  // The paper's linear direction with the back prior: measured 12.0 deg.
  EstimatorOptions linear;
  linear.back_prior = 0.1;
  linear.directional_fit = false;
  const double linear_error = MeanAngularErrorDeg(model, linear, test);
  RecordProperty("linear_mean_angular_error_deg", std::to_string(linear_error));
  EXPECT_LT(linear_error, 15.0) << "linear direction: mean angular error " << linear_error;
  EXPECT_LT(error, linear_error);
}

TEST(YaleBDataTest, ShippedDefaultModelLoads) {
  const std::string path = std::string(PROBELESS_SOURCE_DIR) + "/data/face_light/default_model.txt";
  const FaceLightModel model = LoadModel(path);
  EXPECT_EQ(model.training.subjects.size(), 27u);
  EXPECT_EQ(model.intensity_exponent, 0.5);
  EXPECT_EQ(model.SampleCount(), 512);
  EXPECT_EQ(model.direction_bands, 5);
  EXPECT_NO_THROW(FaceLightEstimator(model, {}));
}

}  // namespace
}  // namespace probeless::face_light
