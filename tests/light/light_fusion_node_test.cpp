// The light_fusion node as a process: a face and a scene light in, their confidence-weighted fusion
// out on `light` (inverse-variance weights on the ShLight confidence scale); a disagreeing less
// confident input left out; an input in face-model units (declared by its units field, or by
// face_units for a message without one) refused; bad params exit 2 with one line.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <numbers>
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
  l.units = msgs::ShLightUnits::kLinear;
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
  // 10 deg apart (consistent): weights c / (1 - c) = 3 and 1/3.
  const float t = static_cast<float>(10 * std::numbers::pi / 180);
  const msgs::ShLight a = Light(0.75f, 1, 0, 0);
  const msgs::ShLight b = Light(0.25f, std::cos(t), std::sin(t), 0);
  face.PublishCopy(std::as_bytes(std::span(&a, 1)));
  auto first = fused.Take(2s);
  ASSERT_TRUE(first);
  EXPECT_FLOAT_EQ(msgs::ReadMessage<msgs::ShLight>(first->data())->confidence, 0.75f);
  scene.PublishCopy(std::as_bytes(std::span(&b, 1)));
  auto second = fused.Take(2s);
  ASSERT_TRUE(second);
  const auto out = msgs::ReadMessage<msgs::ShLight>(second->data());
  EXPECT_NEAR(out->confidence, (10.0 / 3) / (1 + 10.0 / 3), 1e-6);
  const double x = 3 + std::cos(t) / 3, y = std::sin(t) / 3;
  EXPECT_NEAR(out->dominant_direction[0], x / std::hypot(x, y), 1e-6);
  EXPECT_NEAR(out->dominant_direction[1], y / std::hypot(x, y), 1e-6);
  // 90 deg apart: the scene light (expected error 17 deg) is left out, the face light followed.
  const msgs::ShLight c = Light(0.25f, 0, 1, 0);
  scene.PublishCopy(std::as_bytes(std::span(&c, 1)));
  auto third = fused.Take(2s);
  ASSERT_TRUE(third);
  const auto alone = msgs::ReadMessage<msgs::ShLight>(third->data());
  EXPECT_FLOAT_EQ(alone->confidence, 0.75f);
  EXPECT_FLOAT_EQ(alone->dominant_direction[0], 1.0f);
  EXPECT_EQ(alone->units, msgs::ShLightUnits::kLinear);
  node.Signal(SIGINT);
  EXPECT_EQ(node.Wait(5s), 0) << node.Err();
}

TEST(LightFusionNodeTest, FaceModelUnitsAreRefused) {
  bus::Subscriber fused("/light", msgs::TopicTypeOf<msgs::ShLight>(), {.queue_depth = 8});
  bus::Publisher face("/face/light", msgs::TopicTypeOf<msgs::ShLight>(),
                      {.max_message_bytes = sizeof(msgs::ShLight)});
  bus::Publisher scene("/scene/light", msgs::TopicTypeOf<msgs::ShLight>(),
                       {.max_message_bytes = sizeof(msgs::ShLight)});
  probeless::testing::Process node(
      "light_fusion",
      {"--ros-args", "-r", "face/light:=/face/light", "-r", "scene/light:=/scene/light", "-r",
       "light:=/light", "-p", "face_units:=face_model"});
  for (int i = 0; i < 300 && (face.SubscriberCount() == 0 || scene.SubscriberCount() == 0); ++i) {
    std::this_thread::sleep_for(10ms);
  }
  ASSERT_EQ(scene.SubscriberCount(), 1u);
  // A face light of an old log (no units field): face_units says face_model.
  msgs::ShLight a = Light(0.75f, 1, 0, 0);
  a.units = msgs::ShLightUnits::kUnknown;
  msgs::ShLight b = Light(0.5f, 0, 1, 0);
  b.units = msgs::ShLightUnits::kUnknown;  // scene_units: linear (the default)
  face.PublishCopy(std::as_bytes(std::span(&a, 1)));
  EXPECT_FALSE(fused.Take(300ms));  // refused, nothing to publish
  scene.PublishCopy(std::as_bytes(std::span(&b, 1)));
  auto out = fused.Take(2s);
  ASSERT_TRUE(out);
  // The scene light alone: never averaged with the face-model light; published as linear.
  EXPECT_FLOAT_EQ(msgs::ReadMessage<msgs::ShLight>(out->data())->confidence, 0.5f);
  EXPECT_FLOAT_EQ(msgs::ReadMessage<msgs::ShLight>(out->data())->dominant_direction[1], 1.0f);
  EXPECT_EQ(msgs::ReadMessage<msgs::ShLight>(out->data())->units, msgs::ShLightUnits::kLinear);
  // A face light that declares face-model units is refused by its field.
  a.units = msgs::ShLightUnits::kFaceModel;
  a.header.stamp_ns += 1000;
  face.PublishCopy(std::as_bytes(std::span(&a, 1)));
  out = fused.Take(2s);
  ASSERT_TRUE(out);
  EXPECT_FLOAT_EQ(msgs::ReadMessage<msgs::ShLight>(out->data())->confidence, 0.5f);
  node.Signal(SIGINT);
  EXPECT_EQ(node.Wait(5s), 0) << node.Err();
  EXPECT_NE(node.Err().find("/face/light is in face_model units (face_units); it is refused, "
                            "only linear lights are fused"),
            std::string::npos)
      << node.Err();
  EXPECT_NE(node.Err().find("/face/light is in face_model units (its units field); it is "
                            "refused, only linear lights are fused"),
            std::string::npos)
      << node.Err();
}

TEST(LightFusionNodeTest, BadParamsExitTwoWithOneLine) {
  const probeless::testing::TempDir dir("light_fusion_node_test");
  const auto r = probeless::testing::RunCommand(
      std::string(PROBELESS_BIN_DIR) + "/light_fusion --ros-args -p max_age_s:=0", dir.path());
  EXPECT_EQ(r.code, 2);
  EXPECT_EQ(r.err,
            "[error] [light_fusion] node '/light_fusion': parameter 'max_age_s' = 0.0 (from -p) is "
            "out of range: expected a value in (0, inf) s\n");
  const auto u = probeless::testing::RunCommand(
      std::string(PROBELESS_BIN_DIR) + "/light_fusion --ros-args -p face_units:=gamma", dir.path());
  EXPECT_EQ(u.code, 2);
  EXPECT_EQ(u.err,
            "[error] [light_fusion] param face_units must be linear, face_model or "
            "linear_unscaled, got 'gamma'\n");
  const auto c = probeless::testing::RunCommand(
      std::string(PROBELESS_BIN_DIR) + "/light_fusion --ros-args -p 'scene_calibration:=[0.5]'",
      dir.path());
  EXPECT_EQ(c.code, 2);
  EXPECT_EQ(c.err,
            "[error] [light_fusion] confidence calibration: 1 values, expected pairs (raw "
            "confidence, expected error in degrees)\n");
}

}  // namespace
}  // namespace probeless
