// Yale B source -> face_tracker -> face_light in launch/face_yaleb.yaml (player in lock-step with
// both nodes): one /face/light per frame with a detected face, each paired with the frame's
// /groundtruth/light by header.sequence, and the mean angle between the estimated and the true
// dominant direction within the bound measured on these subjects (plus margin). Skips with a
// message when the shared data is absent.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <thread>

#include "probeless/bus/bus.h"
#include "probeless/msgs/msgs.h"

namespace {

namespace fs = std::filesystem;
using namespace probeless;
using namespace std::chrono_literals;

std::string DataDir() {
  if (const char* env = std::getenv("PROBELESS_DATA"); env && *env) return env;
  return PROBELESS_DATA_DIR;
}

struct Direction {
  float d[3];
};

TEST(FacePipeline, YaleBThroughTrackerAndLightInLockStep) {
  const std::string subject = DataDir() + "/yaleb/yaleB11";
  if (!fs::is_directory(subject)) {
    GTEST_SKIP() << "shared Yale B data not found at " << subject
                 << " (set PROBELESS_DATA or put it in <source>/../shared/data)";
  }
  const fs::path dir =
      fs::temp_directory_path() / ("probeless_face_it_" + std::to_string(getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);

  bus::Subscriber lights("/face/light", msgs::TopicTypeOf<msgs::ShLight>(), {.queue_depth = 64});
  bus::Subscriber truths("/groundtruth/light", msgs::TopicTypeOf<msgs::ShLight>(),
                         {.queue_depth = 64});
  bus::Subscriber observations("/face/observation", msgs::TopicTypeOf<msgs::FaceObservation>(),
                               {.queue_depth = 64});
  std::map<uint64_t, Direction> estimated, truth;
  std::map<uint64_t, bool> detected;
  std::atomic<bool> stop{false};
  std::thread drain([&] {
    while (!stop) {
      bool any = false;
      while (auto s = lights.TryTake()) {
        const auto m = msgs::ReadMessage<msgs::ShLight>(s->data());
        estimated[m->header.sequence] = {
            {m->dominant_direction[0], m->dominant_direction[1], m->dominant_direction[2]}};
        any = true;
      }
      while (auto s = truths.TryTake()) {
        const auto m = msgs::ReadMessage<msgs::ShLight>(s->data());
        truth[m->header.sequence] = {
            {m->dominant_direction[0], m->dominant_direction[1], m->dominant_direction[2]}};
        any = true;
      }
      while (auto s = observations.TryTake()) {
        const auto m = msgs::ReadMessage<msgs::FaceObservation>(s->data());
        detected[m->header.sequence] = m->face_detected == 1;
        any = true;
      }
      if (!any) std::this_thread::sleep_for(1ms);
    }
  });
  const std::string command = std::string(PROBELESS_BIN_DIR) + "/probeless launch " +
                              PROBELESS_SOURCE_DIR + "/launch/face_yaleb.yaml yaleb:=" + subject +
                              " smoothing:=false json:=" + (dir / "lights.jsonl").string() +
                              " < /dev/null > " + (dir / "out.txt").string() + " 2> " +
                              (dir / "err.txt").string();
  const int status = std::system(command.c_str());
  std::this_thread::sleep_for(200ms);
  stop = true;
  drain.join();
  std::ifstream err_file(dir / "err.txt");
  std::stringstream err;
  err << err_file.rdbuf();
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << err.str();

  EXPECT_EQ(truth.size(), 60u);  // yaleB11: 60 light images (ambient excluded)
  EXPECT_EQ(detected.size(), truth.size()) << "an observation for every frame";
  int faces = 0;
  for (const auto& [sequence, found] : detected) faces += found;
  EXPECT_GE(faces, 56) << "measured 60 of 60 (54 before flow tracking and CLAHE)";
  // An estimate for each detected frame (all have enough valid samples here).
  EXPECT_EQ(static_cast<int>(estimated.size()), faces);
  double sum = 0;
  int n = 0;
  for (const auto& [sequence, e] : estimated) {
    ASSERT_TRUE(detected[sequence]) << "estimate without a face, frame " << sequence;
    ASSERT_TRUE(truth.count(sequence)) << "no ground truth for frame " << sequence;
    const auto& t = truth[sequence];
    const double dot = e.d[0] * t.d[0] + e.d[1] * t.d[1] + e.d[2] * t.d[2];
    sum += std::acos(std::clamp(dot, -1.0, 1.0)) * 180 / M_PI;
    ++n;
  }
  ASSERT_GT(n, 0);
  const double mean = sum / n;
  std::printf("face pipeline: %d frames, %d faces, %d estimates, mean angular error %.1f deg\n",
              static_cast<int>(truth.size()), faces, n, mean);
  // Measured 8.4 deg (yaleB11, default model, back prior 0.1; subject 11 is one of the model's
  // training subjects, so this checks the pipeline, not generalisation: docs/face_light.md).
  EXPECT_LT(mean, 12.0);
  // The JSON lines export: one line per estimate.
  std::ifstream jsonl(dir / "lights.jsonl");
  int lines = 0;
  for (std::string line; std::getline(jsonl, line);) {
    EXPECT_NE(line.find("\"webxr\""), std::string::npos);
    ++lines;
  }
  EXPECT_EQ(lines, n);
  fs::remove_all(dir);
}

}  // namespace
