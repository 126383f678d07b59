// Fusion's map survives a restart (issue #22): the fusion node runs under the launch supervisor
// with respawn on (tests/recon/fusion_restart.launch.yaml) and its map checkpointed every 10
// integrated frames; the test plays the corner scene of the recon tests (40 frames, 5 mm and
// 0.2 deg a frame, Kinect-like noise, fixed seeds) in lock-step by hand and SIGKILLs fusion after
// frame 14, i.e. 5 frames after the last checkpoint. The respawned fusion resumes the map, its
// first frame relocalises against it, and its trajectory and final map match the uninterrupted
// run's: ATE against the truth within 10 % of the uninterrupted run's (+ 0.5 mm), every pose
// within 5 mm of it, the maps' TSDF the same to 0.05 truncation distances on average. Without a
// checkpoint the respawn starts a new map at the initial pose: the same check fails there.
#include <gtest/gtest.h>
#include <signal.h>
#include <stdlib.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <map>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "probeless/bus/bus.h"
#include "probeless/msgs/msgs.h"
#include "probeless/recon/checkpoint.h"
#include "probeless/recon/pipeline.h"
#include "probeless/testing/testing.h"
#include "test_scene.h"

namespace probeless {
namespace {

using namespace std::chrono_literals;
using recon::testing::PoseFrom;

constexpr int kFrames = 40;
constexpr int kKillAfter = 14;  // checkpoints after frames 9, 19, 29, 39 (every 10 integrated)
constexpr int64_t kStart = 1'000'000'000LL, kStep = 33'333'333LL;

recon::Pose Truth(int i) { return PoseFrom(0, 0.0035 * i, 0, 0.005 * i, 0, 0); }

recon::DepthImage Frame(int i) {
  static const recon::testing::Scene scene = recon::testing::CornerScene();
  recon::DepthImage depth = scene.Render(Truth(i), recon::testing::TestIntrinsics());
  std::mt19937 rng(100 + i);
  std::normal_distribution<float> unit(0.0f, 1.0f);
  for (float& z : depth.data) {
    if (z > 0) z += (0.0012f + 0.0019f * (z - 0.4f) * (z - 0.4f)) * unit(rng);
  }
  return depth;
}

// The live fusion's pid: the publisher of /scene/tracking that is alive (0 = none).
int FusionPid() {
  for (const bus::TopicSnapshot& t : bus::ListTopics()) {
    if (t.topic != "/scene/tracking") continue;
    for (const bus::PublisherSnapshot& p : t.publishers) {
      if (p.alive) return p.pid;
    }
  }
  return 0;
}

// Whether a live process other than `not_pid` subscribes /camera/depth.
bool DepthSubscriberOtherThan(int not_pid) {
  for (const bus::TopicSnapshot& t : bus::ListTopics()) {
    if (t.topic != "/camera/depth") continue;
    for (const bus::SubscriberSnapshot& s : t.subscribers) {
      if (s.alive && s.pid != not_pid) return true;
    }
  }
  return false;
}

struct PlayedRun {
  std::map<int, recon::Pose> poses;  // by frame
  std::vector<msgs::TrackingStatus> statuses;
  std::string out, err;
  int code = -1;
};

// Plays the sequence through fusion under `probeless launch`; kill: SIGKILL fusion after frame
// kKillAfter and go on with its respawn.
PlayedRun Play(const std::string& checkpoint, bool kill, const std::string& label) {
  static int counter = 0;
  setenv("PROBELESS_DOMAIN",
         ("fusion_restart_" + std::to_string(getpid()) + "_" + std::to_string(counter++)).c_str(),
         1);
  PlayedRun run;
  const recon::Intrinsics k = recon::testing::TestIntrinsics();
  const uint32_t w = static_cast<uint32_t>(k.width), h = static_cast<uint32_t>(k.height);
  bus::Subscriber status_sub("/scene/tracking", msgs::TopicTypeOf<msgs::TrackingStatus>(),
                             {.queue_depth = 64});
  bus::Subscriber pose_sub("/scene/pose", msgs::TopicTypeOf<msgs::Pose>(), {.queue_depth = 64});
  bus::Publisher info_pub("/camera/camera_info", msgs::TopicTypeOf<msgs::CameraInfo>(),
                          {.max_message_bytes = sizeof(msgs::CameraInfo), .history = 1});
  bus::Publisher depth_pub(
      "/camera/depth", msgs::TopicTypeOf<msgs::Image>(),
      {.max_message_bytes = msgs::Image::MessageBytesFor(w, h, msgs::Encoding::kFloat32)});
  bus::Publisher image_pub(
      "/camera/image", msgs::TopicTypeOf<msgs::Image>(),
      {.max_message_bytes = msgs::Image::MessageBytesFor(w, h, msgs::Encoding::kMono8)});
  std::vector<std::string> args = {
      "launch", std::string(PROBELESS_SOURCE_DIR) + "/tests/recon/fusion_restart.launch.yaml"};
  if (!checkpoint.empty()) args.push_back("checkpoint:=" + checkpoint);
  testing::Process launch("probeless", args);
  auto wait_for_fusion = [&] {
    for (int i = 0; i < 1000 && (depth_pub.SubscriberCount() == 0 ||
                                 image_pub.SubscriberCount() == 0 || FusionPid() == 0);
         ++i) {
      std::this_thread::sleep_for(10ms);
    }
  };
  wait_for_fusion();
  if (FusionPid() == 0) {
    ADD_FAILURE() << label << ": fusion did not start\n" << launch.Err();
    return run;
  }
  msgs::CameraInfo info;
  info.header.SetFrameId("camera_depth");
  info.width = w;
  info.height = h;
  info.fx = k.fx;
  info.fy = k.fy;
  info.cx = k.cx;
  info.cy = k.cy;
  info.depth_scale = 1.0;
  info_pub.PublishCopy(std::as_bytes(std::span(&info, 1)));
  std::this_thread::sleep_for(200ms);

  for (int i = 0; i < kFrames; ++i) {
    const int64_t stamp = kStart + i * kStep;
    const recon::DepthImage depth = Frame(i);
    {
      bus::Loan loan =
          depth_pub.Borrow(msgs::Image::MessageBytesFor(w, h, msgs::Encoding::kFloat32));
      auto image = msgs::WriteMessage<msgs::Image>(loan.data());
      image->Init(w, h, msgs::Encoding::kFloat32);
      image->header.SetFrameId("camera_depth");
      image->header.stamp_ns = stamp;
      std::memcpy(image.payload.data(), depth.data.data(), depth.data.size() * sizeof(float));
      depth_pub.Publish(std::move(loan));
    }
    {
      // The image with the depth's stamp: the frame is processed at once (grey is unused
      // without the merge).
      bus::Loan loan = image_pub.Borrow(msgs::Image::MessageBytesFor(w, h, msgs::Encoding::kMono8));
      auto image = msgs::WriteMessage<msgs::Image>(loan.data());
      image->Init(w, h, msgs::Encoding::kMono8);
      image->header.SetFrameId("camera_depth");
      image->header.stamp_ns = stamp;
      std::memset(image.payload.data(), 128, image->PayloadBytes());
      image_pub.Publish(std::move(loan));
    }
    auto s = status_sub.Take(20s);
    if (!s) {
      ADD_FAILURE() << label << ": no status for frame " << i << "\n" << launch.Err();
      return run;
    }
    run.statuses.push_back(*msgs::ReadMessage<msgs::TrackingStatus>(s->data()));
    EXPECT_EQ(run.statuses.back().header.stamp_ns, stamp) << label;
    if (run.statuses.back().state != msgs::TrackingStatusState::kLost) {
      // Published right after the status (the subscriber's pool holds few samples: taken now).
      if (auto p = pose_sub.Take(5s)) {
        const auto pose = msgs::ReadMessage<msgs::Pose>(p->data());
        EXPECT_EQ(pose->header.stamp_ns, stamp) << label;
        run.poses[i] = recon::Pose::FromMsg(pose->transform);
      } else {
        ADD_FAILURE() << label << ": no pose for frame " << i;
      }
    }
    if (kill && i == kKillAfter) {
      if (!checkpoint.empty()) {
        // The checkpoint of frame 9 is written by fusion's writer thread.
        for (int n = 0; n < 500 && !std::filesystem::exists(checkpoint); ++n) {
          std::this_thread::sleep_for(10ms);
        }
        EXPECT_TRUE(std::filesystem::exists(checkpoint)) << label;
      }
      const int pid = FusionPid();
      EXPECT_GT(pid, 0) << label;
      ::kill(pid, SIGKILL);
      for (int n = 0;
           n < 1000 && (!DepthSubscriberOtherThan(pid) || FusionPid() == pid || FusionPid() == 0);
           ++n) {
        std::this_thread::sleep_for(10ms);
      }
      EXPECT_TRUE(DepthSubscriberOtherThan(pid)) << label << ": no respawn\n" << launch.Err();
      wait_for_fusion();
      info_pub.PublishCopy(std::as_bytes(std::span(&info, 1)));
      std::this_thread::sleep_for(200ms);
    }
  }
  launch.Signal(SIGINT);
  run.code = launch.Wait(30s);
  run.out = launch.Out();
  run.err = launch.Err();
  return run;
}

double Distance(const recon::Pose& a, const recon::Pose& b) {
  return std::sqrt((a.t[0] - b.t[0]) * (a.t[0] - b.t[0]) + (a.t[1] - b.t[1]) * (a.t[1] - b.t[1]) +
                   (a.t[2] - b.t[2]) * (a.t[2] - b.t[2]));
}

// RMS position error against the truth over every frame (the first camera is the world frame of
// both, so no alignment).
double Ate(const PlayedRun& run) {
  double sum = 0;
  for (const auto& [frame, pose] : run.poses) sum += std::pow(Distance(pose, Truth(frame)), 2);
  return run.poses.empty() ? 1e9 : std::sqrt(sum / run.poses.size());
}

recon::FusionOptions NodeOptions() {
  recon::FusionOptions o;  // the node's defaults with the launch file's params
  o.merge_enabled = false;
  o.volume.origin = {-1.0f, -1.0f, 0.2f};
  return o;
}

TEST(FusionRestart, KilledAndRespawnedFusionResumesItsMapAndTrajectory) {
  testing::TempDir dir("fusion_restart");
  const std::string uninterrupted_ckpt = dir.File("uninterrupted.ckpt");
  const std::string restarted_ckpt = dir.File("restarted.ckpt");
  const PlayedRun a = Play(uninterrupted_ckpt, false, "uninterrupted");
  const PlayedRun b = Play(restarted_ckpt, true, "killed after frame 14");
  ASSERT_EQ(a.statuses.size(), static_cast<size_t>(kFrames)) << a.err;
  ASSERT_EQ(b.statuses.size(), static_cast<size_t>(kFrames)) << b.err;
  EXPECT_EQ(a.code, 0) << a.err;
  EXPECT_EQ(b.code, 0) << b.err;
  EXPECT_NE(a.out.find("fusion: frames=40 tracked=40 uncertain=0 lost=0 relocalised=0"),
            std::string::npos)
      << a.out;
  // The killed instance prints no summary; its respawn resumed the map and relocalised once.
  EXPECT_NE(b.err.find("resumed the map from " + restarted_ckpt), std::string::npos) << b.err;
  EXPECT_NE(b.out.find("fusion: frames=25 tracked=25 uncertain=0 lost=0 relocalised=1"),
            std::string::npos)
      << b.out << b.err;
  const msgs::TrackingStatus& first = b.statuses[kKillAfter + 1];
  EXPECT_EQ(first.state, msgs::TrackingStatusState::kTracked) << first.ReasonText();
  EXPECT_EQ(first.relocalised, 1);
  EXPECT_EQ(first.frames, 1u);  // the respawned process' count

  ASSERT_EQ(a.poses.size(), static_cast<size_t>(kFrames));
  ASSERT_EQ(b.poses.size(), static_cast<size_t>(kFrames));
  const double ate_a = Ate(a), ate_b = Ate(b);
  std::printf("ATE uninterrupted %.2f mm, killed and resumed %.2f mm\n", 1e3 * ate_a, 1e3 * ate_b);
  EXPECT_LE(ate_b, 1.1 * ate_a + 0.0005);
  double worst = 0;
  for (int i = 0; i < kFrames; ++i) worst = std::max(worst, Distance(a.poses.at(i), b.poses.at(i)));
  std::printf("largest pose difference %.2f mm\n", 1e3 * worst);
  EXPECT_LT(worst, 0.005);

  // The final maps (the checkpoints at shutdown) agree.
  recon::FusionPipeline map_a(NodeOptions()), map_b(NodeOptions());
  map_a.Resume(*recon::ReadFileIfExists(uninterrupted_ckpt), uninterrupted_ckpt);
  map_b.Resume(*recon::ReadFileIfExists(restarted_ckpt), restarted_ckpt);
  const int bricks_a = map_a.volume().ObservedBricks(), bricks_b = map_b.volume().ObservedBricks();
  EXPECT_NEAR(bricks_b, bricks_a, 0.05 * bricks_a);
  const recon::VolumeOptions& v = map_a.volume().options();
  const float voxel = v.size_m / v.resolution;
  double diff = 0;
  int both = 0, one = 0;
  for (int z = 0; z < v.resolution; z += 2) {
    for (int y = 0; y < v.resolution; y += 2) {
      for (int x = 0; x < v.resolution; x += 2) {
        const recon::Vec3f p{v.origin.x + (x + 0.5f) * voxel, v.origin.y + (y + 0.5f) * voxel,
                             v.origin.z + (z + 0.5f) * voxel};
        const float ta = map_a.volume().TsdfAt(p), tb = map_b.volume().TsdfAt(p);
        if (std::isnan(ta) != std::isnan(tb)) ++one;
        if (std::isnan(ta) || std::isnan(tb)) continue;
        diff += std::fabs(ta - tb);
        ++both;
      }
    }
  }
  ASSERT_GT(both, 1000);
  std::printf("maps: %d / %d bricks, %d samples in both, %d in one, mean |tsdf diff| %.4f\n",
              bricks_a, bricks_b, both, one, diff / both);
  EXPECT_LT(diff / both, 0.05);
  EXPECT_LT(one, 0.05 * both);
}

TEST(FusionRestart, WithoutACheckpointTheRespawnStartsANewMap) {
  const PlayedRun c = Play("", true, "killed, no checkpoint");
  ASSERT_EQ(c.statuses.size(), static_cast<size_t>(kFrames)) << c.err;
  EXPECT_EQ(c.code, 0) << c.err;
  EXPECT_EQ(c.err.find("resumed the map"), std::string::npos) << c.err;
  EXPECT_EQ(c.statuses[kKillAfter + 1].relocalised, 0);
  // The new map's first pose is the initial one (identity), 7.5 cm and 3 deg from the truth.
  ASSERT_EQ(c.poses.size(), static_cast<size_t>(kFrames));
  EXPECT_GT(Distance(c.poses.at(kKillAfter + 1), Truth(kKillAfter + 1)), 0.07);
  std::printf("ATE killed, no checkpoint %.1f mm\n", 1e3 * Ate(c));
  EXPECT_GT(Ate(c), 0.05);
}

TEST(FusionRestart, ABadCheckpointIsABadParam) {
  testing::TempDir dir("fusion_restart_bad");
  const std::string path = dir.File("map.ckpt");
  testing::WriteText(path, "not a checkpoint, but long enough to have a checksum");
  setenv("PROBELESS_DOMAIN", ("fusion_restart_bad_" + std::to_string(getpid())).c_str(), 1);
  testing::Process node("fusion", {"--ros-args", "-p", "checkpoint:=" + path});
  EXPECT_EQ(node.Wait(20s), 2);
  EXPECT_EQ(node.Err(), "[error] [fusion] checkpoint '" + path +
                            "': not a fusion checkpoint (expected it to start with PLFUSMAP)\n");
  testing::Process frames("fusion", {"--ros-args", "-p", "checkpoint_frames:=0"});
  EXPECT_EQ(frames.Wait(20s), 2);
  EXPECT_EQ(
      frames.Err(),
      "[error] [fusion] node '/fusion': parameter 'checkpoint_frames' = 0 (from -p) is out of "
      "range: expected a value in [1, inf)\n");
}

}  // namespace
}  // namespace probeless
