// The fusion node as a process on a crafted sequence (the corner scene of the recon tests, a
// smooth 5 mm / 0.2 deg per frame motion, with frames 8 and 9 of another take 12.6 cm to the side
// spliced in, Kinect-like noise): scene/tracking reports every frame (tracked, lost, lost,
// relocalised), scene/pose skips the lost ones, the log says "lost" and "resumed" once each
// (a change of state, not every frame), the shutdown summary line has the counts, and
// fail_on_lost_ratio turns the lost share into exit code 3.
#include <gtest/gtest.h>
#include <signal.h>
#include <stdlib.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "probeless/bus/bus.h"
#include "probeless/msgs/msgs.h"
#include "probeless/testing/testing.h"
#include "test_scene.h"

namespace probeless {
namespace {

using namespace std::chrono_literals;
using recon::testing::PoseFrom;

int Count(const std::string& text, const std::string& what) {
  int n = 0;
  for (size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

TEST(FusionNode, ReportsTrackingOnATopicLogsChangesAndSummarisesLostFrames) {
  // A domain of its own: no other graph's /camera topics.
  setenv("PROBELESS_DOMAIN", ("fusion_node_" + std::to_string(getpid())).c_str(), 1);
  const recon::Intrinsics k = recon::testing::TestIntrinsics();
  const uint32_t w = static_cast<uint32_t>(k.width), h = static_cast<uint32_t>(k.height);
  bus::Subscriber status_sub("/scene/tracking", msgs::TopicTypeOf<msgs::TrackingStatus>(),
                             {.queue_depth = 32});
  bus::Subscriber pose_sub("/scene/pose", msgs::TopicTypeOf<msgs::Pose>(), {.queue_depth = 32});
  bus::Publisher info_pub("/camera/camera_info", msgs::TopicTypeOf<msgs::CameraInfo>(),
                          {.max_message_bytes = sizeof(msgs::CameraInfo), .history = 1});
  bus::Publisher depth_pub(
      "/camera/depth", msgs::TopicTypeOf<msgs::Image>(),
      {.max_message_bytes = msgs::Image::MessageBytesFor(w, h, msgs::Encoding::kFloat32)});
  testing::Process node("fusion",
                        {"--ros-args", "-p", "merge:=false", "-p", "volume_size:=2.0", "-p",
                         "volume_origin:=[-1.0, -1.0, 0.2]", "-p", "fail_on_lost_ratio:=0.1"});
  for (int i = 0; i < 500 && (depth_pub.SubscriberCount() == 0 || info_pub.SubscriberCount() == 0);
       ++i) {
    std::this_thread::sleep_for(10ms);
  }
  ASSERT_EQ(depth_pub.SubscriberCount(), 1u) << node.Err();
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

  const recon::testing::Scene scene = recon::testing::CornerScene();
  const recon::Pose offset = PoseFrom(0, 0, 0, -0.09, -0.06, 0.063);  // 12.6 cm
  std::mt19937 rng(7);
  std::normal_distribution<float> unit(0.0f, 1.0f);
  constexpr int kFrames = 14;
  std::vector<msgs::TrackingStatus> statuses;
  for (int i = 0; i < kFrames; ++i) {
    const recon::Pose truth = PoseFrom(0, 0.0035 * i, 0, 0.005 * i, 0, 0);
    recon::DepthImage depth = scene.Render(i == 8 || i == 9 ? offset * truth : truth, k);
    for (float& z : depth.data) {
      if (z > 0) z += (0.0012f + 0.0019f * (z - 0.4f) * (z - 0.4f)) * unit(rng);
    }
    bus::Loan loan = depth_pub.Borrow(msgs::Image::MessageBytesFor(w, h, msgs::Encoding::kFloat32));
    auto image = msgs::WriteMessage<msgs::Image>(loan.data());
    image->Init(w, h, msgs::Encoding::kFloat32);
    image->header.SetFrameId("camera_depth");
    image->header.stamp_ns = 1'000'000'000LL + i * 33'333'333LL;
    std::memcpy(image.payload.data(), depth.data.data(), depth.data.size() * sizeof(float));
    depth_pub.Publish(std::move(loan));
    // Without a colour image a depth is processed when the next one arrives (or at shutdown):
    // frame i's status comes after depth i + 1.
    if (i == 0) continue;
    auto s = status_sub.Take(20s);
    ASSERT_TRUE(s) << "no status for frame " << i - 1 << "\n" << node.Err();
    statuses.push_back(*msgs::ReadMessage<msgs::TrackingStatus>(s->data()));
  }
  node.Signal(SIGINT);  // processes the last depth, prints the summary
  const int code = node.Wait(20s);
  auto last = status_sub.Take(2s);
  ASSERT_TRUE(last) << node.Err();
  statuses.push_back(*msgs::ReadMessage<msgs::TrackingStatus>(last->data()));
  ASSERT_EQ(statuses.size(), static_cast<size_t>(kFrames));

  int poses = 0;
  while (auto p = pose_sub.TryTake()) {
    const auto pose = msgs::ReadMessage<msgs::Pose>(p->data());
    const int64_t frame = (pose->header.stamp_ns - 1'000'000'000LL) / 33'333'333LL;
    EXPECT_NE(frame, 8) << "a pose for a lost frame";
    EXPECT_NE(frame, 9) << "a pose for a lost frame";
    ++poses;
  }
  EXPECT_EQ(poses, kFrames - 2);
  for (int i = 0; i < kFrames; ++i) {
    const msgs::TrackingStatus& t = statuses[i];
    SCOPED_TRACE("frame " + std::to_string(i) + ": " + std::string(t.ReasonText()));
    EXPECT_NO_THROW(t.Validate());
    EXPECT_EQ(t.header.stamp_ns, 1'000'000'000LL + i * 33'333'333LL);
    EXPECT_EQ(t.frames, static_cast<uint64_t>(i + 1));
    EXPECT_GE(t.score, 0.0f);
    EXPECT_LE(t.score, 1.0f);
    const bool lost = i == 8 || i == 9;
    EXPECT_EQ(t.state,
              lost ? msgs::TrackingStatusState::kLost : msgs::TrackingStatusState::kTracked);
    EXPECT_EQ(t.integrated, lost ? 0 : 1);
    EXPECT_EQ(t.relocalised, i == 10 ? 1 : 0);
    if (lost) {
      EXPECT_EQ(t.score, 0.0f);
      EXPECT_NE(t.reasons, 0u);
      EXPECT_FALSE(t.ReasonText().empty());
    } else {
      EXPECT_GE(t.score, 0.5f);
      EXPECT_EQ(t.reasons, 0u);
    }
  }
  EXPECT_NE(statuses[8].reasons & msgs::kTrackingReasonMotion, 0u) << statuses[8].ReasonText();
  EXPECT_EQ(statuses.back().lost_frames, 2u);
  EXPECT_EQ(statuses.back().tracked_frames, static_cast<uint64_t>(kFrames - 2));
  EXPECT_EQ(statuses.back().relocalisations, 1u);

  const std::string out = node.Out(), err = node.Err();
  EXPECT_NE(out.find("fusion: frames=14 tracked=12 uncertain=0 lost=2 relocalised=1\n"),
            std::string::npos)
      << out;
  // One line per change of state: lost at frame 9 (1-based), resumed at frame 11.
  EXPECT_EQ(Count(err, "tracking lost at frame"), 1) << err;
  EXPECT_NE(err.find("tracking lost at frame 9: "), std::string::npos) << err;
  EXPECT_NE(err.find("tracking resumed at frame 11: relocalised after 2 lost frame(s)"),
            std::string::npos)
      << err;
  EXPECT_NE(err.find("map unreliable: 2 of 14 frames lost"), std::string::npos) << err;
  // 2 / 14 = 0.14 lost > fail_on_lost_ratio 0.1.
  EXPECT_NE(err.find("lost 2 of 14 frames, more than fail_on_lost_ratio 0.1"), std::string::npos)
      << err;
  EXPECT_EQ(code, 3) << err;
}

}  // namespace
}  // namespace probeless
