// The tracker on real and rendered faces: the shared Extended Yale B frontal crops (landmarks vs
// the canonical crop landmarks), the 640 x 480 ambient frames (subjects 11+), and the face_orbit
// stream (landmarks vs the procedural head's 68 ground-truth landmarks). The Yale B
// cases skip with a message when the shared data is absent ($PROBELESS_DATA or
// <source>/../shared/data).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "probeless/face_light/estimator.h"
#include "probeless/face_light/model.h"
#include "probeless/face_light/training.h"
#include "probeless/face_light/yaleb.h"
#include "probeless/face_track/face_tracker.h"
#include "probeless/face_track/sampling.h"
#include "probeless/sim/scenario.h"
#include "probeless/sim/simulator.h"

namespace {

namespace fs = std::filesystem;
using namespace probeless;
using namespace probeless::face_track;

std::string DataDir() {
  if (const char* env = std::getenv("PROBELESS_DATA"); env && *env) return env;
  return PROBELESS_DATA_DIR;
}

std::string YaleB() { return DataDir() + "/yaleb"; }

#define SKIP_WITHOUT_YALEB()                                                      \
  if (!fs::is_directory(YaleB())) {                                               \
    GTEST_SKIP() << "shared Yale B data not found at " << YaleB()                 \
                 << " (set PROBELESS_DATA or put it in <source>/../shared/data)"; \
  }

ImageView View(const cv::Mat& m) {
  return {m.data, m.cols, m.rows, static_cast<size_t>(m.step),
          m.channels() == 1 ? PixelFormat::kGray : PixelFormat::kRgb};
}

double Dist(face_light::Point2 a, face_light::Point2 b) { return std::hypot(a.x - b.x, a.y - b.y); }

TEST(FaceTrackData, YaleBFrontalCropsLandmarksAtTheCanonicalPoints) {
  SKIP_WITHOUT_YALEB();
  FaceTracker tracker;
  int found = 0, total = 0;
  double worst = 0, sum = 0;
  for (int s = 1; s <= 39; ++s) {
    char name[96];
    std::snprintf(name, sizeof(name), "/yaleB%02d/yaleB%02d_P00A+000E+00.pgm", s, s);
    const cv::Mat img = cv::imread(YaleB() + name, cv::IMREAD_GRAYSCALE);
    if (img.empty()) continue;
    ++total;
    const FaceTrack t = tracker.DetectOnce(View(img), Intrinsics{1050, 1050, 83.5, 95.5});
    if (!t.found) {
      std::printf("subject %d: no face\n", s);
      continue;
    }
    ++found;
    const auto c = CanonicalLandmarks(t.landmarks);
    const auto& ref = kTrackerCanonical;
    double e = 0;
    for (int k = 0; k < 4; ++k) e = std::max(e, Dist(c[k], ref[k]));
    std::printf("subject %d: box %.0f %.0f %.0f, worst canonical landmark %.1f px\n", s, t.box[0],
                t.box[1], t.box[2], e);
    worst = std::max(worst, e);
    sum += e;
  }
  ASSERT_GT(total, 0);
  std::printf("found %d / %d, mean worst %.2f px, max %.2f px\n", found, total, sum / found, worst);
  EXPECT_GE(found, total - 1);
  EXPECT_LT(sum / found, 8.0);
}

TEST(FaceTrackData, AmbientFramesFaceFoundAndTracked) {
  SKIP_WITHOUT_YALEB();
  FaceTracker tracker;
  int found = 0, total = 0;
  for (int s = 11; s <= 39; ++s) {
    char name[96];
    std::snprintf(name, sizeof(name), "/yaleB%02d/yaleB%02d_P00_Ambient.pgm", s, s);
    const cv::Mat img = cv::imread(YaleB() + name, cv::IMREAD_GRAYSCALE);
    if (img.empty() || img.cols != 640) continue;
    ++total;
    tracker.Reset();
    const Intrinsics k = Intrinsics::Guess(640, 480);
    FaceTrack first = tracker.Track(View(img), k);
    if (!first.found) {
      std::printf("subject %d ambient: no face\n", s);
      continue;
    }
    ++found;
    // Tracking the same frame keeps the landmarks (steady state without drift).
    FaceTrack t = first;
    for (int i = 0; i < 5; ++i) t = tracker.Track(View(img), k);
    ASSERT_TRUE(t.found);
    double drift = 0;
    for (int i = 0; i < kLandmarkCount; ++i) {
      drift = std::max(drift, double(std::hypot(t.landmarks[i].x - first.landmarks[i].x,
                                                t.landmarks[i].y - first.landmarks[i].y)));
    }
    const auto c = CanonicalLandmarks(t.landmarks);
    const double iod = Dist(c[0], c[1]);
    std::printf(
        "subject %d ambient: box %.0f %.0f %.0f, iod %.1f px, drift %.1f px, pose z %.2f m\n", s,
        t.box[0], t.box[1], t.box[2], iod, drift, t.pose.translation[2]);
    EXPECT_GT(iod, 20);
    EXPECT_LT(drift, 0.6 * iod);  // measured <= 0.08 iod except one dim face (0.57)
    EXPECT_LT(c[0].x, c[1].x);    // subject's right eye is on the image left
    EXPECT_LT(c[0].y, c[2].y);    // eyes above the nose
  }
  if (total == 0) GTEST_SKIP() << "no 640x480 ambient frames in " << YaleB();
  std::printf("ambient: found %d / %d\n", found, total);
  // Measured 4 of 17: from subject 15 on the ambient frames are backlit silhouettes (mean gray
  // ~10 of 255) in which no detector sees a face.
  EXPECT_GE(found, 3);
}

// Landmark-aligned sampling (rtf_train --align tracker, face_light_eval --landmarks tracker): each
// subject's samples through CanonicalToImage of the tracker's landmarks on its frontal-lit image.
// Trained on 14 subjects, evaluated on 6 unseen ones, with and without the alignment.
TEST(FaceTrackData, LandmarkAlignedSamplingBeatsTheCropOnUnseenSubjects) {
  SKIP_WITHOUT_YALEB();
  namespace fl = probeless::face_light;
  TrackerOptions options;
  options.clahe_clip_limit = 0;  // as the tools: evenly lit crops
  FaceTracker tracker(options);
  const std::vector<fl::Point2> candidates = fl::CandidatePositions();
  const auto sample = [&](const std::vector<int>& subjects,
                          const std::vector<fl::Point2>& positions, bool aligned) {
    std::vector<fl::TrainingImage> out;
    for (int s : subjects) {
      const std::vector<fl::YaleBImage> images = fl::LoadYaleBSubject(YaleB(), s);
      fl::SimilarityTransform crop_to_image;
      for (const fl::YaleBImage& image : images) {
        if (!aligned || image.name.azimuth_deg != 0 || image.name.elevation_deg != 0) continue;
        const FaceTrack t =
            tracker.DetectOnce(ImageView{image.pixels.data(), image.width, image.height,
                                         static_cast<size_t>(image.width), PixelFormat::kGray},
                               Intrinsics{1050, 1050, 83.5, 95.5});
        EXPECT_TRUE(t.found) << "subject " << s;
        if (t.found) crop_to_image = CanonicalToImage(t.landmarks);
      }
      for (const fl::YaleBImage& image : images) {
        fl::TrainingImage t;
        t.subject = s;
        t.azimuth_deg = image.name.azimuth_deg;
        t.elevation_deg = image.name.elevation_deg;
        t.values.resize(positions.size());
        t.valid.resize(positions.size());
        fl::SamplePatches(image.pixels.data(), image.width, image.height, image.width, 1,
                          crop_to_image, positions, 2, 255, t.values, t.valid);
        out.push_back(std::move(t));
      }
    }
    return out;
  };
  const auto mean_error = [](const fl::FaceLightModel& model,
                             const std::vector<fl::TrainingImage>& test) {
    const fl::FaceLightEstimator estimator(model);
    double sum = 0;
    for (const fl::TrainingImage& image : test) {
      std::vector<uint64_t> bits(8, 0);
      for (size_t i = 0; i < image.valid.size(); ++i) {
        if (image.valid[i]) bits[i / 64] |= uint64_t{1} << (i % 64);
      }
      const fl::LightEstimate e = estimator.EstimateGray(image.values, bits);
      const auto t = fl::YaleBLightDirection(image.azimuth_deg, image.elevation_deg);
      const double dot = t[0] * e.dominant_direction[0] + t[1] * e.dominant_direction[1] +
                         t[2] * e.dominant_direction[2];
      sum += std::acos(std::clamp(dot, -1.0, 1.0)) * 180 / M_PI;
    }
    return sum / test.size();
  };
  fl::TrainingOptions training;  // rtf_train's defaults
  training.intensity_exponent = 0.5;
  training.percentile = 0;
  training.direction_bands = 5;
  const std::vector<int> train_subjects{1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 15};
  const std::vector<int> test_subjects{22, 23, 24, 25, 26, 27};
  double errors[2];
  for (int aligned = 0; aligned < 2; ++aligned) {
    const fl::FaceLightModel model =
        fl::Train(candidates, sample(train_subjects, candidates, aligned), training);
    errors[aligned] = mean_error(model, sample(test_subjects, model.positions, aligned));
  }
  std::printf("unseen subjects 22-27: crop %.2f deg, landmark-aligned %.2f deg\n", errors[0],
              errors[1]);
  // Measured: crop 10.86 deg, landmark-aligned 9.28 deg.
  EXPECT_LT(errors[1], errors[0] - 0.5);
  EXPECT_LT(errors[1], 10.5);
}

// The whole face_orbit stream (the demo: a point light orbiting the head, to its side and behind)
// through one tracker, with and without flow tracking: error of the eye, nose and mouth
// combinations vs the procedural head's ground-truth landmarks, in true inter-ocular distances.
TEST(FaceTrackData, SyntheticFaceOrbitStreamTrackedWhileLitFromTheSide) {
  sim::Scenario scenario =
      sim::LoadScenario(std::string(PROBELESS_SOURCE_DIR) + "/data/scenarios/face_orbit.yaml");
  sim::Simulator simulator(scenario, 2);
  TrackerOptions no_flow;
  no_flow.flow_tracking = false;
  FaceTracker tracker, legacy(no_flow);
  int frames = 0, found = 0, flow_only = 0, wrong = 0, found_legacy = 0;
  double sum = 0, worst = 0, worst_flow_confidence = 0;
  for (uint64_t i = 0; i < static_cast<uint64_t>(scenario.frames); ++i) {
    const sim::SimFrame f = simulator.Render(i);
    ASSERT_EQ(f.face.landmarks.size(), 68u);
    const cv::Mat img(f.camera.height, f.camera.width, CV_8UC3, const_cast<uint8_t*>(f.rgb.data()));
    const Intrinsics k{f.camera.fx, f.camera.fy, f.camera.cx, f.camera.cy};
    const FaceTrack t = tracker.Track(View(img), k);
    found_legacy += legacy.Track(View(img), k).found;
    ++frames;
    if (!t.found) continue;
    ++found;
    std::vector<Point2f> truth(68);
    for (int j = 0; j < 68; ++j) truth[j] = {f.face.landmarks[j][0], f.face.landmarks[j][1]};
    const auto a = CanonicalLandmarks(t.landmarks);
    const auto b = CanonicalLandmarks(truth);
    const double iod = Dist(b[0], b[1]);
    double e = 0;
    for (int j = 0; j < 4; ++j) e += Dist(a[j], b[j]) / 4;
    e /= iod;
    sum += e;
    worst = std::max(worst, e);
    wrong += e > 0.3;
    if (t.flow) {
      ++flow_only;
      worst_flow_confidence = std::max(worst_flow_confidence, double(t.confidence));
    }
    if (i % 15 == 0) {
      std::printf("frame %d: %s, error %.3f iod, confidence %.2f\n", int(i),
                  t.detected ? "detected"
                  : t.flow   ? "flow"
                             : "landmark-tracked",
                  e, t.confidence);
    }
  }
  ASSERT_GT(found, 0) << "the procedural head was never found";
  std::printf(
      "face_orbit: face in %d / %d frames (%d flow-only), mean error %.3f iod, worst %.3f, "
      "%d > 0.3; without flow tracking %d frames\n",
      found, frames, flow_only, sum / found, worst, wrong, found_legacy);
  // Measured: 120 of 120 (21 flow-only), mean 0.099 iod, none > 0.3; without flow 82. Since the
  // procedural head has human proportions (issue #6): 120 of 120 (3 flow-only), mean 0.061, worst
  // 0.163 iod; without flow 120 too, so flow tracking must not lose frames rather than win them.
  EXPECT_GE(found, frames - 6);
  EXPECT_GE(found, found_legacy);
  EXPECT_EQ(wrong, 0);
  EXPECT_LT(sum / found, 0.15);
  EXPECT_LE(worst_flow_confidence, 0.5);  // a face kept by the flow alone cannot look certain
}

}  // namespace
