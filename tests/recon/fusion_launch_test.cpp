// The fusion node runs from launch/fusion_7scenes.yaml, fed by the player in lock-step from the
// shared 7-Scenes frames: it processes every frame without losing tracking, publishes G_r and the
// pose (seen by a subscriber in the test) and writes the mesh at shutdown.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>

#include "probeless/bus/bus.h"
#include "probeless/msgs/msgs.h"

namespace {

namespace fs = std::filesystem;
using namespace probeless;

std::string Slurp(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

TEST(FusionLaunch, RecordedStreamInLockStepThroughTheFusionNode) {
  const char* env = std::getenv("PROBELESS_DATA");
  const fs::path data = fs::path(env != nullptr ? env : PROBELESS_DATA_DIR) / "7scenes-redkitchen";
  if (!fs::exists(data / "camera-intrinsics.txt")) {
    GTEST_SKIP() << "shared 7-Scenes frames not found at " << data
                 << " (set PROBELESS_DATA to the shared data folder)";
  }
  const fs::path dir =
      fs::temp_directory_path() / ("probeless_fusion_launch_" + std::to_string(getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path mesh = dir / "mesh.ply";
  const fs::path log = dir / "launch.log";

  // Count what the node publishes while the graph runs.
  std::atomic<bool> stop{false};
  std::atomic<int> poses{0}, gbuffers{0};
  std::atomic<bool> gbuffer_ok{true};
  std::thread listener([&] {
    bus::Subscriber pose_sub("/scene/pose", msgs::TopicTypeOf<msgs::Pose>());
    bus::Subscriber gbuffer_sub("/scene/gbuffer", msgs::TopicTypeOf<msgs::GeometryBuffer>());
    while (!stop) {
      while (auto s = pose_sub.TryTake()) ++poses;
      while (auto s = gbuffer_sub.TryTake()) {
        const auto m = msgs::ReadMessage<msgs::GeometryBuffer>(s->data());
        if (m->width != 640 || m->height != 480) gbuffer_ok = false;
        int valid = 0;
        for (float d : msgs::DepthPlane(*m, m.payload)) valid += d > 0;
        if (valid < 640 * 480 / 2) gbuffer_ok = false;
        ++gbuffers;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
  });
  const std::string cmd = std::string(PROBELESS_BIN_DIR) + "/probeless launch " +
                          PROBELESS_SOURCE_DIR +
                          "/launch/fusion_7scenes.yaml source:=" + data.string() +
                          " max_frames:=40 mesh_out:=" + mesh.string();
  const int status = std::system((cmd + " < /dev/null > " + log.string() + " 2>&1").c_str());
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  stop = true;
  listener.join();
  const std::string out = Slurp(log);
  ASSERT_TRUE(WIFEXITED(status)) << out;
  EXPECT_EQ(WEXITSTATUS(status), 0) << out;
  EXPECT_NE(out.find("fusion: frames=40 tracked=40 uncertain=0 lost=0 relocalised=0"),
            std::string::npos)
      << out;
  EXPECT_TRUE(fs::exists(mesh)) << out;
  EXPECT_GT(fs::file_size(mesh), 100000u);
  // The subscriber may join after the first messages; most frames must arrive.
  EXPECT_GE(poses.load(), 30) << out;
  EXPECT_GE(gbuffers.load(), 30) << out;
  EXPECT_TRUE(gbuffer_ok.load());
  fs::remove_all(dir);
}

}  // namespace
