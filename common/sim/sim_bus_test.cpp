// The simulator's stream passes through the bus: the Player publishes a "sim" Source and a
// subscriber receives images, depth and ground truth intact.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <thread>

#include "probeless/bus/bus.h"
#include "probeless/msgs/image.h"
#include "probeless/msgs/sh_light.h"
#include "probeless/replay/player.h"
#include "probeless/sim/simulator.h"

namespace probeless::sim {
namespace {

using namespace std::chrono_literals;

TEST(SimBus, PlayerPublishesTheSimulatedStream) {
  Scenario s = LoadScenario(std::string(PROBELESS_SOURCE_DIR) + "/data/scenarios/face_orbit.yaml");
  s.camera.width = 160;
  s.camera.height = 120;
  s.camera.fx = s.camera.fy = 131.25;
  s.camera.cx = 79.5;
  s.camera.cy = 59.5;
  s.frames = 4;
  std::unique_ptr<dataset::Source> source = OpenSimSource(s);
  // Reference frames, rendered by a second source.
  std::unique_ptr<dataset::Source> reference = OpenSimSource(s);
  std::vector<log::MessageBuffer> expected_images;
  while (auto m = reference->Next()) {
    if (m->topic_index == 1) expected_images.push_back(std::move(m->message));
  }

  bus::Subscriber images("/camera/image", msgs::TopicTypeOf<msgs::Image>(), {.queue_depth = 16});
  bus::Subscriber lights("/groundtruth/light", msgs::TopicTypeOf<msgs::ShLight>(),
                         {.queue_depth = 16});
  replay::PlayerOptions options;
  options.as_fast_as_possible = true;
  options.log = [](const std::string&) {};
  options.slot_count = 16;
  replay::Player player(*source, options);
  const replay::PlayerStats stats = player.Run([] { return true; });
  EXPECT_EQ(stats.published, source->message_count());

  std::vector<std::vector<std::byte>> received;
  while (auto sample = images.Take(200ms)) {
    received.emplace_back(sample->data().begin(), sample->data().end());
  }
  ASSERT_EQ(received.size(), expected_images.size());
  for (size_t i = 0; i < received.size(); ++i) {
    ASSERT_EQ(received[i].size(), expected_images[i].size());
    // Same pixels (the payload after the 128-byte struct) and the same sequence number.
    EXPECT_TRUE(std::equal(received[i].begin() + sizeof(msgs::Image), received[i].end(),
                           expected_images[i].bytes().begin() + sizeof(msgs::Image)));
  }
  int light_count = 0;
  while (auto sample = lights.Take(100ms)) {
    const auto light = msgs::ReadMessage<msgs::ShLight>(sample->data());
    light->Validate();
    ++light_count;
  }
  EXPECT_EQ(light_count, 4);
}

}  // namespace
}  // namespace probeless::sim
