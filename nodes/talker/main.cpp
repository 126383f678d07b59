// talker: example node publishing synthetic Images on "chatter" at a fixed rate.
//
// Params:
//   width, height (int, 640 x 480)   image size in pixels, 1..65535
//   encoding (string, "rgb8")        rgb8, bgr8, mono8, mono16, depth16, float32 or rgb32f
//   rate_hz (double, 10)             publishing rate, Hz (> 0)
//   count (int, 0)                   stop after this many messages (0 = until SIGINT/SIGTERM)
//   wait_for_subscribers (int, 0)    do not start before this many subscribers joined
//   history (int, 0)                 messages kept for late-joining subscribers
//   frame_id (string, "camera")      header.frame_id
// Message i (1, 2, ...) has header.sequence i and every payload byte equal to i % 256, which the
// listener checks. Prints "summary: published=N" on stdout at exit.
#include <cstdio>
#include <cstring>
#include <exception>

#include "probeless/msgs/image.h"
#include "probeless/node/node.h"

namespace {

using probeless::msgs::Encoding;
using probeless::msgs::Image;

int Run(int argc, char** argv) {
  probeless::node::Node node(argc, argv, "talker");
  using probeless::node::ParamDescriptor;
  const ParamDescriptor size{.unit = "px", .min = 1.0, .max = 65535.0};
  const int width = node.Param("width", 640, size);
  const int height = node.Param("height", 480, size);
  const Encoding encoding = probeless::msgs::EncodingFromName(
      node.Param("encoding", "rgb8",
                 {.choices = {"rgb8", "bgr8", "mono8", "mono16", "depth16", "float32", "rgb32f"}}));
  const double rate_hz =
      node.Param("rate_hz", 10.0, {.unit = "Hz", .min = 0.0, .min_exclusive = true});
  const int64_t count = node.Param<int64_t>(
      "count", 0, {.description = "messages to publish, 0: until a signal", .min = 0.0});
  const int wait_for_subscribers = node.Param("wait_for_subscribers", 0, {.min = 0.0});
  const int history = node.Param("history", 0, {.min = 0.0});
  const std::string frame_id = node.Param("frame_id", "camera");
  node.CheckParamOverrides();

  const size_t message_bytes =
      Image::MessageBytesFor(static_cast<uint32_t>(width), static_cast<uint32_t>(height), encoding);
  probeless::bus::PublisherOptions options;
  options.max_message_bytes = message_bytes;
  options.history = static_cast<uint32_t>(history);
  probeless::bus::Publisher publisher = node.CreatePublisher<Image>("chatter", options);
  node.Info() << "publishing " << width << "x" << height << " "
              << probeless::msgs::EncodingName(encoding) << " on " << publisher.topic() << " at "
              << rate_hz << " Hz";

  while (node.ok() && static_cast<int>(publisher.SubscriberCount()) < wait_for_subscribers) {
    node.WaitForShutdown(std::chrono::milliseconds(10));
  }

  probeless::node::Rate rate(rate_hz);
  int64_t published = 0;
  while (node.ok() && (count == 0 || published < count)) {
    probeless::bus::Loan loan = publisher.Borrow(message_bytes);
    auto out = probeless::msgs::WriteMessage<Image>(loan.data());
    const uint64_t sequence = static_cast<uint64_t>(published) + 1;
    out->header.StampNow();
    out->header.sequence = sequence;
    out->header.SetFrameId(frame_id);
    out->Init(static_cast<uint32_t>(width), static_cast<uint32_t>(height), encoding);
    std::memset(out.payload.data(), static_cast<int>(sequence % 256), out->PayloadBytes());
    publisher.Publish(std::move(loan));
    ++published;
    node.Debug() << "published #" << sequence;
    if (count != 0 && published == count) break;
    rate.Sleep();
  }
  node.Info() << "published " << published << " messages";
  std::printf("summary: published=%lld\n", static_cast<long long>(published));
  std::fflush(stdout);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return Run(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "[error] [talker] %s\n", e.what());
    return 1;
  }
}
