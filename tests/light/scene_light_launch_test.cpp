// launch/scene_light_sim.yaml with 3 frames of data/scenarios/courtyard_sun.yaml: the sim
// in lock-step with scene_light (depth mode, normals from the sensor depth); one /scene/light and
// one /scene/transfer per frame, paired with /groundtruth/light by header.sequence, plausible
// (valid bands, unit direction, confidence in [0, 1], transfer 640x480x16); with indirect:=true
// one /scene/indirect (rgb32f 640x480, finite, non-negative, lit somewhere) for every frame after
// the first (it needs the previous frame's light); plus the node's one-line error for a bad mode.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <string>
#include <thread>
#include <utility>

#include "probeless/bus/bus.h"
#include "probeless/msgs/msgs.h"

namespace {

using namespace probeless;
using namespace std::chrono_literals;

TEST(SceneLightLaunch, SimInLockStepWithSceneLight) {
  bus::Subscriber lights("/scene/light", msgs::TopicTypeOf<msgs::ShLight>(), {.queue_depth = 64});
  bus::Subscriber truths("/groundtruth/light", msgs::TopicTypeOf<msgs::ShLight>(),
                         {.queue_depth = 64});
  bus::Subscriber transfers("/scene/transfer", msgs::TopicTypeOf<msgs::TransferBuffer>(),
                            {.queue_depth = 8});
  bus::Subscriber indirects("/scene/indirect", msgs::TopicTypeOf<msgs::Image>(),
                            {.queue_depth = 8});
  struct IndirectStats {
    uint32_t width = 0, height = 0;
    msgs::Encoding encoding = msgs::Encoding::kInvalid;
    size_t non_finite = 0, negative = 0, lit = 0;
  };
  std::map<uint64_t, IndirectStats> indirect;
  std::map<uint64_t, msgs::ShLight> estimated, truth;
  std::map<uint64_t, std::array<uint32_t, 3>> transfer_shape;
  std::atomic<bool> stop{false};
  std::thread drain([&] {
    while (!stop) {
      bool any = false;
      while (auto s = lights.TryTake()) {
        const auto m = msgs::ReadMessage<msgs::ShLight>(s->data());
        estimated[m->header.sequence] = *m;
        any = true;
      }
      while (auto s = truths.TryTake()) {
        const auto m = msgs::ReadMessage<msgs::ShLight>(s->data());
        truth[m->header.sequence] = *m;
        any = true;
      }
      while (auto s = transfers.TryTake()) {
        const auto m = msgs::ReadMessage<msgs::TransferBuffer>(s->data());
        m->Validate(m.payload.size());
        transfer_shape[m->header.sequence] = {m->width, m->height, m->coefficient_count};
        any = true;
      }
      while (auto s = indirects.TryTake()) {
        const auto m = msgs::ReadMessage<msgs::Image>(s->data());
        IndirectStats st{m->width, m->height, m->encoding};
        if (m->encoding == msgs::Encoding::kRgb32f) {
          for (float v : msgs::ImageChannels<float>(*m, m.payload)) {
            st.non_finite += !std::isfinite(v);
            st.negative += v < 0;
            st.lit += v > 1e-6f;
          }
        }
        indirect[m->header.sequence] = st;
        any = true;
      }
      if (!any) std::this_thread::sleep_for(1ms);
    }
  });
  const std::string err = "/tmp/scene_light_launch_test_" + std::to_string(getpid()) + ".txt";
  const std::string command =
      std::string(PROBELESS_BIN_DIR) + "/probeless launch " + PROBELESS_SOURCE_DIR +
      "/launch/scene_light_sim.yaml frames:=3 " + "scenario:=" + PROBELESS_SOURCE_DIR +
      "/data/scenarios/courtyard_sun.yaml indirect:=true < /dev/null > /dev/null 2> " + err;
  const int status = std::system(command.c_str());
  std::this_thread::sleep_for(300ms);
  stop = true;
  drain.join();
  std::string log;
  if (FILE* f = std::fopen(err.c_str(), "r")) {
    char buf[4096];
    size_t n;
    while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) log.append(buf, n);
    std::fclose(f);
  }
  std::remove(err.c_str());
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << log;
  EXPECT_EQ(truth.size(), 3u) << log;
  ASSERT_EQ(estimated.size(), 3u) << log;
  EXPECT_EQ(transfer_shape.size(), 3u);
  ASSERT_EQ(indirect.size(), 2u) << log;  // frames 2 and 3: frame 1 has no previous light
  EXPECT_FALSE(indirect.count(estimated.begin()->first));
  for (const auto& [seq, st] : indirect) {
    EXPECT_EQ(st.encoding, msgs::Encoding::kRgb32f) << "frame " << seq;
    EXPECT_EQ(st.width, 640u);
    EXPECT_EQ(st.height, 480u);
    EXPECT_EQ(st.non_finite, 0u) << "frame " << seq;
    EXPECT_EQ(st.negative, 0u) << "frame " << seq;
    // Courtyard: the sunlit ground and walls bounce light into the corners and under the table.
    EXPECT_GT(st.lit, 640u * 480u * 3 / 100) << "frame " << seq;
  }
  for (const auto& [seq, e] : estimated) {
    ASSERT_TRUE(truth.count(seq)) << "no ground truth for frame " << seq;
    EXPECT_EQ(e.bands, 4u);
    EXPECT_GE(e.confidence, 0.0f);
    EXPECT_LE(e.confidence, 1.0f);
    const float* d = e.dominant_direction;
    EXPECT_NEAR(std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]), 1.0, 1e-4);
    const float* t = truth[seq].dominant_direction;
    const double angle =
        std::acos(std::clamp(d[0] * t[0] + d[1] * t[1] + d[2] * t[2], -1.0f, 1.0f)) * 180 / M_PI;
    std::printf("frame %llu: dominant direction error %.1f deg (sensor depth)\n",
                static_cast<unsigned long long>(seq), angle);
    EXPECT_LT(angle, 60.0) << "frame " << seq;  // with sensor noise; docs/light.md
    const auto shape = transfer_shape[seq];
    EXPECT_EQ(shape[0], 640u);
    EXPECT_EQ(shape[1], 480u);
    EXPECT_EQ(shape[2], 16u);
  }
}

// Runs scene_light with `params` (ros-args) and returns its exit status and stderr.
std::pair<int, std::string> RunSceneLight(const std::string& params) {
  const std::string err = "/tmp/scene_light_params_" + std::to_string(getpid()) + ".txt";
  const std::string command = std::string(PROBELESS_BIN_DIR) + "/scene_light --ros-args " + params +
                              " < /dev/null 2> " + err;
  const int status = std::system(command.c_str());
  std::string log;
  if (FILE* f = std::fopen(err.c_str(), "r")) {
    char buf[1024];
    size_t n;
    while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) log.append(buf, n);
    std::fclose(f);
  }
  std::remove(err.c_str());
  return {status, log};
}

TEST(SceneLightLaunch, BadModeIsAOneLineError) {
  const auto [status, log] = RunSceneLight("-p mode:=lidar");
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 2);
  EXPECT_EQ(log, "[error] [scene_light] scene_light: mode must be gbuffer or depth, got 'lidar'\n");
  const auto [status2, log2] = RunSceneLight("-p gbuffer_normals:=volume");
  EXPECT_TRUE(WIFEXITED(status2) && WEXITSTATUS(status2) == 2);
  EXPECT_EQ(log2,
            "[error] [scene_light] scene_light: gbuffer_normals must be fusion or depth, got "
            "'volume'\n");
}

}  // namespace
