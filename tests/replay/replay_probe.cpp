// replay_probe: a deliberately slow node under test for the replay integration tests. Subscribes
// to an Image topic with a queue of 1, sleeps `delay_ms` per image (so a free-running stream would
// lose frames), and appends "<header.sequence> <FNV-1a of the pixels>" per image to `output`
// (flushed per line). Acknowledges every image through Node::Spin (lock-step replay).
//   params: topic (/camera/image), delay_ms (10), output (required)
#include <chrono>
#include <cstdio>
#include <exception>
#include <fstream>
#include <thread>

#include "probeless/msgs/image.h"
#include "probeless/node/node.h"

int main(int argc, char** argv) {
  try {
    probeless::node::Node node(argc, argv, "probe");
    const std::string topic = node.Param("topic", "/camera/image");
    const int delay_ms = node.Param("delay_ms", 10);
    const std::string output = node.RequireParam<std::string>("output");
    std::ofstream out(output, std::ios::app);
    if (!out) throw std::runtime_error("cannot write '" + output + "'");
    probeless::bus::Subscriber sub =
        node.CreateSubscriber<probeless::msgs::Image>(topic, {.queue_depth = 1});
    node.Spin({{&sub, [&](probeless::bus::Sample&& sample) {
                  const auto image =
                      probeless::msgs::ReadMessage<probeless::msgs::Image>(sample.data());
                  uint64_t hash = 1469598103934665603ull;
                  for (std::byte b : image.payload) {
                    hash = (hash ^ static_cast<uint8_t>(b)) * 1099511628211ull;
                  }
                  std::this_thread::sleep_for(std::chrono::milliseconds(delay_ms));
                  out << image->header.sequence << " " << hash << std::endl;
                }}});
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "[error] [probe] %s\n", e.what());
    return 1;
  }
}
