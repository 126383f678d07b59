// The tracker on real and rendered faces: the shared Extended Yale B frontal crops (landmarks vs
// the canonical crop landmarks), the 640 x 480 ambient frames (subjects 11+), and frames of the
// face_orbit scenario (landmarks vs the procedural head's 68 ground-truth landmarks). The Yale B
// cases skip with a message when the shared data is absent ($PROBELESS_DATA or
// <source>/../shared/data).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "probeless/face_light/model.h"
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

TEST(FaceTrackData, SyntheticFaceOrbitLandmarksMatchTheGroundTruth) {
  sim::Scenario scenario =
      sim::LoadScenario(std::string(PROBELESS_SOURCE_DIR) + "/data/scenarios/face_orbit.yaml");
  sim::Simulator simulator(scenario, 2);
  FaceTracker tracker;
  int found = 0;
  double sum = 0;
  int frames = 0;
  for (uint64_t i : {0u, 15u, 30u, 45u}) {
    const sim::SimFrame f = simulator.Render(i);
    ASSERT_EQ(f.face.landmarks.size(), 68u);
    const cv::Mat img(f.camera.height, f.camera.width, CV_8UC3, const_cast<uint8_t*>(f.rgb.data()));
    const Intrinsics k{f.camera.fx, f.camera.fy, f.camera.cx, f.camera.cy};
    const FaceTrack t = tracker.Track(View(img), k);
    ++frames;
    if (!t.found) {
      std::printf("frame %d: no face\n", int(i));
      continue;
    }
    ++found;
    // Error of the eye, nose and mouth combinations, relative to the true inter-ocular distance.
    std::vector<Point2f> truth(68);
    for (int j = 0; j < 68; ++j) truth[j] = {f.face.landmarks[j][0], f.face.landmarks[j][1]};
    const auto a = CanonicalLandmarks(t.landmarks);
    const auto b = CanonicalLandmarks(truth);
    const double iod = Dist(b[0], b[1]);
    double e = 0;
    for (int j = 0; j < 4; ++j) e += Dist(a[j], b[j]) / 4;
    std::printf(
        "frame %d: mean canonical landmark error %.1f px (iod %.1f), pose t %.3f %.3f %.3f\n",
        int(i), e, iod, t.pose.translation[0], t.pose.translation[1], t.pose.translation[2]);
    sum += e / iod;
  }
  ASSERT_GT(found, 0) << "the procedural head was never found";
  std::printf("synthetic: found %d / %d, mean error %.3f iod\n", found, frames, sum / found);
  EXPECT_GE(found, frames - 1);
  EXPECT_LT(sum / found, 0.15);
}

}  // namespace
