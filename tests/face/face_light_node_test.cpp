// The face_light node as a process on synthetic observations (samples from the model's linear
// forward model, LinearLightConverter::Predict, frontal head): a lit face is published as linear
// light with a confident direction; then a backlit face (ambient only) is published with a low
// confidence and the held light fading to its ambient term, never lit from the front
// (docs/face_light.md, "face_light node", Hold); linear_output false says units face_model; bad
// params (also a JSON export of non-linear light) exit 2 with one line.
#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <cmath>
#include <memory>
#include <numbers>
#include <string>
#include <thread>

#include "probeless/bus/bus.h"
#include "probeless/face_light/linear_light.h"
#include "probeless/face_light/model.h"
#include "probeless/msgs/face_observation.h"
#include "probeless/msgs/sh_light.h"
#include "probeless/testing/testing.h"

namespace probeless {
namespace {

using namespace std::chrono_literals;
namespace fl = probeless::face_light;

msgs::FaceObservation Observation(const fl::LinearLightConverter& converter, int64_t stamp_ns,
                                  const std::array<double, 3>& d, double power, double ambient) {
  msgs::FaceObservation o;
  o.header.stamp_ns = stamp_ns;
  o.header.SetFrameId("camera");
  o.face_detected = 1;
  o.head_pose.rotation.w = 1;  // frontal: face frame = camera frame
  o.sample_count = static_cast<uint32_t>(converter.SampleCount());
  o.quality = 1;
  const std::vector<float> rgb =
      converter.Predict(d, {power, power, power}, {ambient, ambient, ambient});
  for (uint32_t i = 0; i < o.sample_count; ++i) {
    for (int c = 0; c < 3; ++c) o.sample_rgb[i][c] = rgb[3 * i + c];
    o.SetSampleValid(i, true);
  }
  return o;
}

TEST(FaceLightNodeTest, BacklitFaceHoldsTheLastConfidentLight) {
  const fl::FaceLightModel model =
      fl::LoadModel(std::string(PROBELESS_SOURCE_DIR) + "/data/face_light/default_model.txt");
  const fl::LinearLightConverter converter(model);  // the node's defaults
  bus::Subscriber lights("/fl_test/light", msgs::TopicTypeOf<msgs::ShLight>(), {.queue_depth = 16});
  bus::Publisher observations("/fl_test/observation", msgs::TopicTypeOf<msgs::FaceObservation>(),
                              {.max_message_bytes = sizeof(msgs::FaceObservation)});
  probeless::testing::Process node(
      "face_light", {"--ros-args", "-r", "face/observation:=/fl_test/observation", "-r",
                     "face/light:=/fl_test/light", "-p", "smoothing:=false"});
  for (int i = 0; i < 500 && observations.SubscriberCount() == 0; ++i) {
    std::this_thread::sleep_for(10ms);
  }
  ASSERT_EQ(observations.SubscriberCount(), 1u) << node.Err();
  const std::array<double, 3> side{0.5 / std::sqrt(0.98), -0.3 / std::sqrt(0.98),
                                   -0.8 / std::sqrt(0.98)};
  const int64_t t0 = 5'000'000'000;
  const auto lit =
      std::make_unique<msgs::FaceObservation>(Observation(converter, t0, side, 2.0, 0.05));
  observations.PublishCopy(std::as_bytes(std::span(lit.get(), 1)));
  auto first = lights.Take(5s);
  ASSERT_TRUE(first) << node.Err();
  const msgs::ShLight a = *msgs::ReadMessage<msgs::ShLight>(first->data());
  EXPECT_EQ(a.units, msgs::ShLightUnits::kLinear);
  // Linear: the directional power comes back (the default conversion: within 6 %), confident.
  EXPECT_NEAR(a.intensity, 2.0, 0.12);
  EXPECT_GT(a.confidence, 0.3f);
  const double cosine = a.dominant_direction[0] * side[0] + a.dominant_direction[1] * side[1] +
                        a.dominant_direction[2] * side[2];
  EXPECT_GT(cosine, std::cos(5 * std::numbers::pi / 180));
  // The light goes behind the head: only the environment reaches the face.
  for (int k = 1; k <= 3; ++k) {
    const auto dark = std::make_unique<msgs::FaceObservation>(
        Observation(converter, t0 + k * int64_t{1'000'000'000}, {0, 0, 1}, 0.0, 0.08));
    observations.PublishCopy(std::as_bytes(std::span(dark.get(), 1)));
    auto next = lights.Take(5s);
    ASSERT_TRUE(next) << node.Err();
    const msgs::ShLight b = *msgs::ReadMessage<msgs::ShLight>(next->data());
    EXPECT_LT(b.confidence, 0.05f) << "frame " << k;  // ignored by light_fusion
    // The held light: its ambient term, its directional part fading as exp(-t / 2 s), its
    // direction; never a light from the front.
    const double w = std::exp(-k / 2.0);
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(b.coefficients[0][c], a.coefficients[0][c], 1e-5);
      for (int n = 1; n < 9; ++n) {
        EXPECT_NEAR(b.coefficients[n][c], w * a.coefficients[n][c], 1e-4) << n;
      }
    }
    for (int j = 0; j < 3; ++j) EXPECT_FLOAT_EQ(b.dominant_direction[j], a.dominant_direction[j]);
    EXPECT_NEAR(b.intensity, w * a.intensity, 1e-4);
  }
  node.Signal(SIGINT);
  EXPECT_EQ(node.Wait(5s), 0) << node.Err();
}

TEST(FaceLightNodeTest, BadParamsExitTwoWithOneLine) {
  const probeless::testing::TempDir dir("face_light_node_test");
  const auto a = probeless::testing::RunCommand(
      std::string(PROBELESS_BIN_DIR) + "/face_light --ros-args -p 'skin_albedo:=[0.5, 0.4]'",
      dir.path());
  EXPECT_EQ(a.code, 2);
  EXPECT_EQ(a.err,
            "[error] [face_light] face_light: skin_albedo must hold 3 values (linear R, G, B), got "
            "2\n");
  const auto b = probeless::testing::RunCommand(
      std::string(PROBELESS_BIN_DIR) + "/face_light --ros-args -p hold_blend_s:=0", dir.path());
  EXPECT_EQ(b.code, 2);
  EXPECT_EQ(
      b.err,
      "[error] [face_light] node '/face_light': parameter 'hold_blend_s' = 0.0 (from -p) is out "
      "of range: expected a value in (0, inf) s\n");
  const auto c = probeless::testing::RunCommand(
      std::string(PROBELESS_BIN_DIR) +
          "/face_light --ros-args -p linear_output:=false -p json_path:=lights.jsonl",
      dir.path());
  EXPECT_EQ(c.code, 2);
  EXPECT_EQ(c.err,
            "[error] [face_light] face_light: json_path exports ARKit / WebXR light, which is "
            "linear radiance; it needs linear_output true\n");
}

TEST(FaceLightNodeTest, ModelUnitsSayFaceModel) {
  const fl::FaceLightModel model =
      fl::LoadModel(std::string(PROBELESS_SOURCE_DIR) + "/data/face_light/default_model.txt");
  const fl::LinearLightConverter converter(model);
  bus::Subscriber lights("/fl_units/light", msgs::TopicTypeOf<msgs::ShLight>(), {.queue_depth = 4});
  bus::Publisher observations("/fl_units/observation", msgs::TopicTypeOf<msgs::FaceObservation>(),
                              {.max_message_bytes = sizeof(msgs::FaceObservation)});
  probeless::testing::Process node(
      "face_light",
      {"--ros-args", "-r", "face/observation:=/fl_units/observation", "-r",
       "face/light:=/fl_units/light", "-p", "smoothing:=false", "-p", "linear_output:=false"});
  for (int i = 0; i < 500 && observations.SubscriberCount() == 0; ++i) {
    std::this_thread::sleep_for(10ms);
  }
  ASSERT_EQ(observations.SubscriberCount(), 1u) << node.Err();
  const auto lit = std::make_unique<msgs::FaceObservation>(
      Observation(converter, 1'000'000'000, {0, 0, -1}, 2.0, 0.05));
  observations.PublishCopy(std::as_bytes(std::span(lit.get(), 1)));
  auto light = lights.Take(5s);
  ASSERT_TRUE(light) << node.Err();
  EXPECT_EQ(msgs::ReadMessage<msgs::ShLight>(light->data())->units, msgs::ShLightUnits::kFaceModel);
  node.Signal(SIGINT);
  EXPECT_EQ(node.Wait(5s), 0) << node.Err();
}

}  // namespace
}  // namespace probeless
