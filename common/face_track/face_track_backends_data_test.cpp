// The optional detector backends (OpenCV YuNet with the shared ONNX model, a Haar cascade of
// Debian's opencv-data) on real and rendered faces, against dlib's HOG detector + shape predictor
// and the ground truth: Extended Yale B frontal-lit crops of every subject, the 640 x 480 ambient
// frames, and face_orbit renders. A detection counts when the backend's own box contains the
// reference eye centres and mouth centre; the 68 landmarks the shape predictor fits from that box
// are compared with the reference in inter-ocular distances. Each case skips with a message when
// the model, the cascade or the shared data is absent ($PROBELESS_DATA or <source>/../shared/data).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

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
std::string YuNetModel() { return DataDir() + "/models/yunet_120x160.onnx"; }

ImageView View(const cv::Mat& m) {
  return {m.data, m.cols, m.rows, static_cast<size_t>(m.step),
          m.channels() == 1 ? PixelFormat::kGray : PixelFormat::kRgb};
}

// The backend's options, or a skip reason when its model file is absent.
struct Backend {
  std::string name;
  TrackerOptions options;
  std::string missing;  // non-empty: why it cannot run here
};

std::vector<Backend> Backends() {
  Backend yunet{"yunet", {}, ""};
  yunet.options.backend = DetectorBackend::kYuNet;
  yunet.options.yunet_model_path = YuNetModel();
  if (!fs::is_regular_file(YuNetModel())) {
    yunet.missing = "shared YuNet model not found at " + YuNetModel() +
                    " (set PROBELESS_DATA or put it in <source>/../shared/data)";
  }
  Backend haar{"haar", {}, ""};
  haar.options.backend = DetectorBackend::kHaar;
  if (!fs::is_regular_file(kDefaultHaarCascadePath)) {
    haar.missing = std::string("Haar cascade not found at ") + kDefaultHaarCascadePath +
                   " (install the Debian package opencv-data)";
  }
  return {yunet, haar};
}

double Dist(Point2f a, Point2f b) { return std::hypot(a.x - b.x, a.y - b.y); }

// Eye centres and mouth centre of a 68-point set (iBUG order).
std::array<Point2f, 3> EyesMouth(const std::array<Point2f, kLandmarkCount>& p) {
  std::array<Point2f, 3> c{};
  for (int i = 0; i < 6; ++i) {
    c[0].x += p[36 + i].x / 6;
    c[0].y += p[36 + i].y / 6;
    c[1].x += p[42 + i].x / 6;
    c[1].y += p[42 + i].y / 6;
  }
  for (int i = 48; i < 68; ++i) {
    c[2].x += p[i].x / 20;
    c[2].y += p[i].y / 20;
  }
  return c;
}

bool BoxContains(const std::array<float, 4>& box, const std::array<Point2f, 3>& points) {
  for (const Point2f& p : points) {
    if (p.x < box[0] || p.y < box[1] || p.x > box[0] + box[2] || p.y > box[1] + box[3]) {
      return false;
    }
  }
  return box[2] > 0 && box[3] > 0;
}

// Mean distance of the 68 landmarks to the reference, in the reference's inter-ocular distances.
double LandmarkError(const std::array<Point2f, kLandmarkCount>& a,
                     const std::array<Point2f, kLandmarkCount>& ref) {
  const auto c = EyesMouth(ref);
  double sum = 0;
  for (int i = 0; i < kLandmarkCount; ++i) sum += Dist(a[i], ref[i]);
  return sum / kLandmarkCount / Dist(c[0], c[1]);
}

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

struct Tally {
  int images = 0, reference = 0, found = 0, contains = 0;
  std::vector<double> errors;  // landmark error vs the reference, where both found the face
};

void Print(const char* set, const std::string& backend, const Tally& t) {
  std::printf(
      "%s, %s: %d images, reference face in %d; found %d, box contains eyes + mouth %d; "
      "68 landmarks vs reference median %.3f, max %.3f iod (%zu faces)\n",
      set, backend.c_str(), t.images, t.reference, t.found, t.contains, Median(t.errors),
      t.errors.empty() ? 0.0 : *std::max_element(t.errors.begin(), t.errors.end()),
      t.errors.size());
}

// Yale B: frontal-lit crops (A = 0, E = 0) of every subject and the 640 x 480 ambient frames;
// the reference is dlib's HOG detection + shape predictor on the same image.
Tally RunYaleB(FaceTracker& reference, FaceTracker& tracker, bool ambient, const char* backend) {
  Tally tally;
  for (int s = 1; s <= 39; ++s) {
    char name[96];
    if (ambient) {
      std::snprintf(name, sizeof(name), "/yaleB%02d/yaleB%02d_P00_Ambient.pgm", s, s);
    } else {
      std::snprintf(name, sizeof(name), "/yaleB%02d/yaleB%02d_P00A+000E+00.pgm", s, s);
    }
    if (!fs::is_regular_file(YaleB() + name)) continue;
    const cv::Mat img = cv::imread(YaleB() + name, cv::IMREAD_GRAYSCALE);
    if (img.empty() || (ambient && img.cols != 640)) continue;
    ++tally.images;
    const Intrinsics k = ambient ? Intrinsics::Guess(640, 480) : Intrinsics{1050, 1050, 83.5, 95.5};
    const FaceTrack ref = reference.DetectOnce(View(img), k);
    const FaceTrack t = tracker.DetectOnce(View(img), k);
    tally.reference += ref.found;
    tally.found += t.found;
    if (t.found && ref.found) {
      const bool in = BoxContains(t.detection_box, EyesMouth(ref.landmarks));
      tally.contains += in;
      tally.errors.push_back(LandmarkError(t.landmarks, ref.landmarks));
      std::printf(
          "  %s subject %d: box %.0f %.0f %.0f %.0f (dlib %.0f %.0f %.0f %.0f)%s, %.3f iod\n",
          backend, s, t.detection_box[0], t.detection_box[1], t.detection_box[2],
          t.detection_box[3], ref.detection_box[0], ref.detection_box[1], ref.detection_box[2],
          ref.detection_box[3], in ? "" : " MISSES", tally.errors.back());
    } else if (t.found != ref.found) {
      std::printf("  %s subject %d: backend %s (box %.0f %.0f %.0f %.0f), dlib %s\n", backend, s,
                  t.found ? "found" : "none", t.detection_box[0], t.detection_box[1],
                  t.detection_box[2], t.detection_box[3], ref.found ? "found" : "none");
    }
  }
  return tally;
}

TEST(FaceTrackBackendsData, YaleBFrontalLitCrops) {
  if (!fs::is_directory(YaleB())) {
    GTEST_SKIP() << "shared Yale B data not found at " << YaleB()
                 << " (set PROBELESS_DATA or put it in <source>/../shared/data)";
  }
  FaceTracker reference;
  int ran = 0;
  for (const Backend& b : Backends()) {
    if (!b.missing.empty()) {
      std::printf("%s: skipped, %s\n", b.name.c_str(), b.missing.c_str());
      continue;
    }
    ++ran;
    FaceTracker tracker(b.options);
    const Tally t = RunYaleB(reference, tracker, false, b.name.c_str());
    Print("Yale B frontal-lit crops", b.name, t);
    ASSERT_GT(t.images, 0);
    // Measured: YuNet 27 of 27 found, 27 boxes contain dlib's eyes and mouth, landmarks vs dlib
    // median 0.019 iod (max 0.033); Haar 21 found, 16 right (the others: a small false positive
    // where the face, which fills the crop, is missed), median 0.016 iod.
    EXPECT_GE(t.contains, t.images * (b.name == "yunet" ? 0.95 : 0.5)) << b.name;
    EXPECT_LT(Median(t.errors), 0.05) << b.name;
  }
  if (ran == 0) GTEST_SKIP() << "neither the YuNet model nor the Haar cascade is installed";
}

TEST(FaceTrackBackendsData, YaleBAmbientFrames) {
  if (!fs::is_directory(YaleB())) {
    GTEST_SKIP() << "shared Yale B data not found at " << YaleB()
                 << " (set PROBELESS_DATA or put it in <source>/../shared/data)";
  }
  FaceTracker reference;
  int ran = 0;
  for (const Backend& b : Backends()) {
    if (!b.missing.empty()) {
      std::printf("%s: skipped, %s\n", b.name.c_str(), b.missing.c_str());
      continue;
    }
    ++ran;
    FaceTracker tracker(b.options);
    const Tally t = RunYaleB(reference, tracker, true, b.name.c_str());
    Print("Yale B ambient 640x480", b.name, t);
    if (t.images == 0) GTEST_SKIP() << "no 640x480 ambient frames in " << YaleB();
    // Measured: dlib finds 4 of 17 (backlit silhouettes from subject 15 on); YuNet the same 4, all
    // boxes right, landmarks vs dlib median 0.027 iod; Haar 10 (the same 4 right, median 0.024
    // iod; 6 where dlib sees no face, unverified).
    EXPECT_GE(t.contains, t.reference - 1) << b.name;
    EXPECT_LT(Median(t.errors), 0.1) << b.name;
  }
  if (ran == 0) GTEST_SKIP() << "neither the YuNet model nor the Haar cascade is installed";
}

// face_orbit renders (the procedural head; ground-truth landmarks from the simulator).
TEST(FaceTrackBackendsData, FaceOrbitRenders) {
  sim::Scenario scenario =
      sim::LoadScenario(std::string(PROBELESS_SOURCE_DIR) + "/data/scenarios/face_orbit.yaml");
  sim::Simulator simulator(scenario, 2);
  std::vector<sim::SimFrame> frames;
  for (uint64_t i = 0; i < static_cast<uint64_t>(scenario.frames); i += 4) {
    frames.push_back(simulator.Render(i));
  }
  int ran = 0;
  for (const Backend& b : Backends()) {
    if (!b.missing.empty()) {
      std::printf("%s: skipped, %s\n", b.name.c_str(), b.missing.c_str());
      continue;
    }
    ++ran;
    FaceTracker tracker(b.options);
    Tally t;
    for (const sim::SimFrame& f : frames) {
      ASSERT_EQ(f.face.landmarks.size(), 68u);
      const cv::Mat img(f.camera.height, f.camera.width, CV_8UC3,
                        const_cast<uint8_t*>(f.rgb.data()));
      const FaceTrack track = tracker.DetectOnce(
          View(img), Intrinsics{f.camera.fx, f.camera.fy, f.camera.cx, f.camera.cy});
      ++t.images;
      ++t.reference;
      if (!track.found) continue;
      ++t.found;
      std::array<Point2f, kLandmarkCount> truth{};
      for (int j = 0; j < 68; ++j) truth[j] = {f.face.landmarks[j][0], f.face.landmarks[j][1]};
      t.contains += BoxContains(track.detection_box, EyesMouth(truth));
      t.errors.push_back(LandmarkError(track.landmarks, truth));
    }
    Print("face_orbit renders (every 4th frame)", b.name, t);
    // Measured: both 30 of 30, every box contains the true eyes and mouth; landmarks vs the
    // ground truth median 0.094 (YuNet) / 0.097 (Haar) iod.
    EXPECT_GE(t.contains, t.images * 0.9) << b.name;
    EXPECT_LT(Median(t.errors), 0.15) << b.name;
  }
  if (ran == 0) GTEST_SKIP() << "neither the YuNet model nor the Haar cascade is installed";
}

}  // namespace
