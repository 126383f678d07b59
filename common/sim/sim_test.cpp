// Scenario parsing (and its error messages), simulator determinism and the "sim" Source.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>

#include "probeless/msgs/camera_info.h"
#include "probeless/msgs/face_observation.h"
#include "probeless/msgs/image.h"
#include "probeless/msgs/pose.h"
#include "probeless/msgs/sh_light.h"
#include "probeless/sim/scenario.h"
#include "probeless/sim/simulator.h"
#include "probeless/testing/expect.h"

namespace probeless::sim {
namespace {

const std::string kScenarios = std::string(PROBELESS_SOURCE_DIR) + "/data/scenarios/";

// A quarter-resolution copy (160 x 120) of a scenario, for fast tests.
Scenario Small(Scenario s, uint64_t frames) {
  s.camera.width /= 4;
  s.camera.height /= 4;
  s.camera.fx /= 4;
  s.camera.fy /= 4;
  s.camera.cx = (s.camera.width - 1) / 2.0;
  s.camera.cy = (s.camera.height - 1) / 2.0;
  s.frames = frames;
  return s;
}

// The message of the ScenarioError parsing `yaml` as f.yaml throws.
std::string ScenarioErrorOf(const std::string& yaml) {
  return probeless::testing::ThrownMessage<ScenarioError>(
      [&] { ParseScenario(yaml, "f.yaml", "/nonexistent"); });
}

TEST(Scenario, ShippedScenariosLoad) {
  const Scenario face = LoadScenario(kScenarios + "face_orbit.yaml");
  EXPECT_EQ(face.name, "face_orbit");
  EXPECT_EQ(face.frames, 120u);
  ASSERT_EQ(face.lights.size(), 1u);
  EXPECT_TRUE(face.lights[0].orbit.has_value());
  const Scenario room = LoadScenario(kScenarios + "room_dynamic.yaml");
  EXPECT_GT(room.objects.size(), 10u);
  EXPECT_TRUE(room.sensor.depth_noise);
}

TEST(Scenario, ErrorsNameFileAndLine) {
  const std::string camera =
      "camera:\n  path:\n    - {t: 0, position: [0, 0, 0], look_at: [0, 0, 1]}\n";
  PROBELESS_EXPECT_THROWS_MESSAGE_THAT(
      ParseScenario("frames: 3\ncamera:\n  widht: 3\n", "f.yaml", "/nonexistent"), ScenarioError,
      ::testing::StartsWith("f.yaml:3: camera.widht: unknown key (expected one of cx, cy, "));
  EXPECT_EQ(ScenarioErrorOf(camera + "objects:\n  - shape: sphere\n    radius: big\n"),
            "f.yaml:6: objects[0].radius: expected a number, got 'big'");
  EXPECT_EQ(ScenarioErrorOf(camera + "objects:\n  - shape: cone\n"),
            "f.yaml:5: objects[0].shape: unknown shape 'cone' (expected plane, box, sphere, "
            "cylinder, head or mesh)");
  EXPECT_EQ(ScenarioErrorOf(camera + "objects:\n  - shape: mesh\n    file: nope.obj\n"),
            "f.yaml:6: objects[0].file: file '/nonexistent/nope.obj' not found");
  EXPECT_EQ(ScenarioErrorOf(camera + "lights:\n  - type: spot\n"),
            "f.yaml:5: lights[0].type: expected 'directional' or 'point'");
  EXPECT_EQ(ScenarioErrorOf(camera + "fps: -2\n"),
            "f.yaml:4: fps: value -2 out of range [0.1, 1000]");
  EXPECT_EQ(ScenarioErrorOf("frames: 3\n"),
            "f.yaml:1: camera: missing (a camera with a path is required)");
  EXPECT_EQ(
      ScenarioErrorOf("camera:\n  path:\n    - {t: 1, position: [0, 0, 0], look_at: [0, 0, 1]}\n"
                      "    - {t: 0, position: [0, 0, 0], look_at: [0, 0, 1]}\n"),
      "f.yaml:4: camera.path[1].t: keyframe times must increase");
  PROBELESS_EXPECT_THROWS_MESSAGE_THAT(
      ParseScenario("camera: [1, 2\n", "f.yaml", "/nonexistent"), ScenarioError,
      ::testing::AllOf(::testing::StartsWith("f.yaml:"),
                       ::testing::HasSubstr(": YAML syntax error: ")));
  PROBELESS_EXPECT_THROWS_MESSAGE(LoadScenario("/nonexistent/x.yaml"), ScenarioError,
                                  "/nonexistent/x.yaml: cannot open scenario file");
}

TEST(Simulator, SameSeedGivesByteIdenticalFrames) {
  const Scenario room = Small(LoadScenario(kScenarios + "room_dynamic.yaml"), 10);
  Simulator a(room, 2);
  Simulator b(room, 1);
  for (uint64_t i = 0; i < 4; ++i) a.Render(i);
  const SimFrame fa = a.Render(5);
  const SimFrame fb = b.Render(5);  // directly, single-threaded
  EXPECT_EQ(fa.rgb, fb.rgb);
  EXPECT_EQ(fa.depth_mm, fb.depth_mm);
  EXPECT_EQ(fa.render.linear_rgb, fb.render.linear_rgb);
  Scenario other = room;
  other.seed = room.seed + 1;
  Simulator c(other, 2);
  const SimFrame fc = c.Render(5);
  EXPECT_NE(fa.rgb, fc.rgb);                        // colour noise differs
  EXPECT_NE(fa.depth_mm, fc.depth_mm);              // depth noise differs
  EXPECT_EQ(fa.render.depth_m, fc.render.depth_m);  // the scene does not
  // The waved box moves.
  const SimFrame f0 = a.Render(0);
  EXPECT_NE(f0.render.object_ids, fa.render.object_ids);
}

TEST(Simulator, DepthNoiseAndHolesFollowTheSensorModel) {
  Scenario room = Small(LoadScenario(kScenarios + "room_dynamic.yaml"), 1);
  Simulator sim(room, 2);
  const SimFrame f = sim.Render(0);
  size_t valid = 0, holes = 0;
  double max_error = 0;
  for (size_t p = 0; p < f.depth_mm.size(); ++p) {
    const float z = f.render.depth_m[p];
    if (z <= 0) continue;
    if (f.depth_mm[p] == 0) {
      ++holes;
      continue;
    }
    ++valid;
    const double sigma = 0.0012 + 0.0019 * (z - 0.4) * (z - 0.4) + 0.00285 * z * z;
    max_error = std::max(max_error, std::abs(f.depth_mm[p] / 1000.0 - z) / sigma);
  }
  EXPECT_GT(valid, f.depth_mm.size() / 2);
  EXPECT_GT(holes, 0u);
  EXPECT_LT(max_error, 7);  // within a few sigma
}

TEST(SimSource, FaceOrbitStream) {
  const Scenario face = Small(LoadScenario(kScenarios + "face_orbit.yaml"), 3);
  uint64_t progress = 0;
  SimOptions options;
  options.progress = [&](uint64_t done, uint64_t total) {
    EXPECT_EQ(total, 3u);
    progress = done;
  };
  std::unique_ptr<dataset::Source> source = OpenSimSource(face, options);
  EXPECT_EQ(source->kind(), "sim");
  const auto& topics = source->topics();
  ASSERT_EQ(topics.size(), 7u);
  EXPECT_EQ(topics[0].topic, "/camera/camera_info");
  EXPECT_EQ(topics[1].topic, "/camera/image");
  EXPECT_EQ(topics[2].topic, "/camera/depth");
  EXPECT_EQ(topics[3].topic, "/groundtruth/pose");
  EXPECT_EQ(topics[4].topic, "/groundtruth/light");
  EXPECT_EQ(topics[5].topic, "/groundtruth/face");
  EXPECT_EQ(topics[6].topic, "/groundtruth/face_light");
  EXPECT_EQ(source->message_count(), 21u);
  std::vector<int> count(7, 0);
  std::vector<std::array<float, 3>> at_camera;
  std::vector<std::array<float, 3>> at_face;
  uint64_t last_time = 0;
  while (auto m = source->Next()) {
    ++count[m->topic_index];
    EXPECT_GE(m->log_time_ns, last_time);
    last_time = m->log_time_ns;
    const auto bytes = m->message.bytes();
    switch (m->topic_index) {
      case 0: {
        const auto info = msgs::ReadMessage<msgs::CameraInfo>(bytes);
        info->Validate();
        EXPECT_EQ(info->width, 160u);
        EXPECT_DOUBLE_EQ(info->depth_scale, 0.001);
        EXPECT_EQ(info->distortion_model, msgs::DistortionModel::kPlumbBob);
        EXPECT_EQ(info->distortion_count, 5u);
        EXPECT_EQ(info->distortion[0], 0.0);
        break;
      }
      case 1:
      case 2: {
        const auto image = msgs::ReadMessage<msgs::Image>(bytes);
        image->Validate(image.payload.size());
        EXPECT_EQ(image->encoding,
                  m->topic_index == 1 ? msgs::Encoding::kRgb8 : msgs::Encoding::kDepth16);
        EXPECT_EQ(image->header.FrameId(), "camera");
        break;
      }
      case 3: {
        const auto pose = msgs::ReadMessage<msgs::Pose>(bytes);
        EXPECT_EQ(pose->ParentFrameId(), "world");
        EXPECT_EQ(pose->ChildFrameId(), "camera");
        EXPECT_NEAR(pose->transform.translation.y, 1.62, 0.03);
        break;
      }
      case 4:
      case 6: {
        const auto light = msgs::ReadMessage<msgs::ShLight>(bytes);
        light->Validate();
        auto& series = m->topic_index == 4 ? at_camera : at_face;
        series.push_back({light->dominant_direction[0], light->dominant_direction[1],
                          light->dominant_direction[2]});
        EXPECT_EQ(light->bands, 3u);
        EXPECT_GT(light->coefficients[0][0], 0);
        EXPECT_GT(light->intensity, 0);
        const float* d = light->dominant_direction;
        EXPECT_NEAR(d[0] * d[0] + d[1] * d[1] + d[2] * d[2], 1, 1e-4);
        break;
      }
      case 5: {
        const auto face_msg = msgs::ReadMessage<msgs::FaceObservation>(bytes);
        face_msg->Validate();
        ASSERT_EQ(face_msg->face_detected, 1);
        ASSERT_EQ(face_msg->landmark_count, 68u);
        for (uint32_t i = 0; i < 68; ++i) {
          EXPECT_GT(face_msg->landmarks[i][0], 0);
          EXPECT_LT(face_msg->landmarks[i][0], 160);
          EXPECT_GT(face_msg->landmarks[i][1], 0);
          EXPECT_LT(face_msg->landmarks[i][1], 120);
        }
        // Subject's right eye (36) on the image left of the left eye (45); nose tip central.
        EXPECT_LT(face_msg->landmarks[36][0], face_msg->landmarks[45][0]);
        EXPECT_NEAR(face_msg->landmarks[30][0], 79.5, 8);
        // The face looks into the camera: head pose rotation near identity, 0.6 m away.
        EXPECT_GT(std::abs(face_msg->head_pose.rotation.w), 0.97);
        EXPECT_NEAR(face_msg->head_pose.translation.z, 0.6, 0.05);
        EXPECT_GT(face_msg->ValidSampleCount(), 50u);
        break;
      }
    }
  }
  EXPECT_EQ(count, std::vector<int>({3, 3, 3, 3, 3, 3, 3}));
  // The orbiting light is near the head: seen from the face it is far from where it is seen from
  // the camera (the first frame: ~70 deg up from the camera, ~27 deg up from the face).
  ASSERT_EQ(at_face.size(), 3u);
  const auto& c = at_camera[0];
  const auto& f = at_face[0];
  EXPECT_LT(c[0] * f[0] + c[1] * f[1] + c[2] * f[2], std::cos(30.0 * M_PI / 180.0));
  EXPECT_EQ(progress, 3u);
  source->Rewind();
  EXPECT_TRUE(source->Next().has_value());
}

TEST(SimSource, IctMeshWhenAvailable) {
  const std::optional<std::string> ict = FindDataFile("meshes/ict_generic_neutral_mesh.obj");
  if (!ict) GTEST_SKIP() << "shared data (meshes/ict_generic_neutral_mesh.obj) not found";
  Scenario s = ParseScenario(
      "frames: 1\n"
      "camera:\n  width: 160\n  height: 120\n  fx: 130\n"
      "  path: [{t: 0, position: [0, 0, -0.6], look_at: [0, 0, 0]}]\n"
      "environment: {constant: [0.3, 0.3, 0.3]}\n"
      "objects:\n"
      "  - {name: ict, shape: mesh, file: 'data:meshes/ict_generic_neutral_mesh.obj', scale: "
      "0.01,\n"
      "     mesh_rotation_deg: [180, 0, 0], rotation_deg: [0, 0, 180], color: [0.6, 0.45, 0.4]}\n"
      "lights: [{type: directional, direction: [0.3, 0.5, -1]}]\n",
      "ict.yaml", ".");
  ASSERT_EQ(s.objects[0].file, *ict);
  Simulator sim(s, 2);
  const SimFrame f = sim.Render(0);
  size_t on_face = 0;
  for (uint32_t id : f.render.object_ids) on_face += id == 1 ? 1 : 0;
  EXPECT_GT(on_face, 2000u);
}

}  // namespace
}  // namespace probeless::sim
