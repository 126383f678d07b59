// The light_fusion node as a process: a face and a scene light in, their confidence-weighted fusion
// out on `light`; bad params exit 2 with one line.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <string>
#include <thread>

#include "probeless/bus/bus.h"
#include "probeless/msgs/sh_light.h"
#include "probeless/testing/testing.h"

namespace probeless {
namespace {

using namespace std::chrono_literals;

msgs::ShLight Light(float confidence, float x, float y, float z) {
  msgs::ShLight l;
  l.header.stamp_ns = 1'000'000'000;
  l.header.SetFrameId("camera");
  l.bands = 3;
  l.coefficients[0][0] = l.coefficients[0][1] = l.coefficients[0][2] = 1;
  l.dominant_direction[0] = x;
  l.dominant_direction[1] = y;
  l.dominant_direction[2] = z;
  l.intensity = 1;
  l.confidence = confidence;
  return l;
}

TEST(LightFusionNodeTest, FusesTheFaceAndSceneLights) {
  bus::Subscriber fused("/light", msgs::TopicTypeOf<msgs::ShLight>(), {.queue_depth = 8});
  bus::Publisher face("/face/light", msgs::TopicTypeOf<msgs::ShLight>(),
                      {.max_message_bytes = sizeof(msgs::ShLight)});
  bus::Publisher scene("/scene/light", msgs::TopicTypeOf<msgs::ShLight>(),
                       {.max_message_bytes = sizeof(msgs::ShLight)});
  probeless::testing::Process node("light_fusion",
                                   {"--ros-args", "-r", "face/light:=/face/light", "-r",
                                    "scene/light:=/scene/light", "-r", "light:=/light"});
  // Wait until the node subscribes both inputs.
  for (int i = 0; i < 300 && (face.SubscriberCount() == 0 || scene.SubscriberCount() == 0); ++i) {
    std::this_thread::sleep_for(10ms);
  }
  ASSERT_EQ(face.SubscriberCount(), 1u);
  ASSERT_EQ(scene.SubscriberCount(), 1u);
  const msgs::ShLight a = Light(0.75f, 1, 0, 0);
  const msgs::ShLight b = Light(0.25f, 0, 1, 0);
  face.PublishCopy(std::as_bytes(std::span(&a, 1)));
  auto first = fused.Take(2s);
  ASSERT_TRUE(first);
  EXPECT_FLOAT_EQ(msgs::ReadMessage<msgs::ShLight>(first->data())->confidence, 0.75f);
  scene.PublishCopy(std::as_bytes(std::span(&b, 1)));
  auto second = fused.Take(2s);
  ASSERT_TRUE(second);
  const auto out = msgs::ReadMessage<msgs::ShLight>(second->data());
  EXPECT_NEAR(out->confidence, 1 - 0.25 * 0.75, 1e-6);
  const double n = std::sqrt(0.75 * 0.75 + 0.25 * 0.25);
  EXPECT_NEAR(out->dominant_direction[0], 0.75 / n, 1e-6);
  EXPECT_NEAR(out->dominant_direction[1], 0.25 / n, 1e-6);
  node.Signal(SIGINT);
  EXPECT_EQ(node.Wait(5s), 0) << node.Err();
}

TEST(LightFusionNodeTest, BadParamsExitTwoWithOneLine) {
  const probeless::testing::TempDir dir("light_fusion_node_test");
  const auto r = probeless::testing::RunCommand(
      std::string(PROBELESS_BIN_DIR) + "/light_fusion --ros-args -p max_age_s:=0", dir.path());
  EXPECT_EQ(r.code, 2);
  EXPECT_EQ(r.err, "[error] [light_fusion] param max_age_s must be > 0\n");
}

}  // namespace
}  // namespace probeless
