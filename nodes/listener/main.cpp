// listener: example node receiving the talker's Images on "chatter".
//
// Params:
//   count (int, 0)          stop after this many messages (0 = until SIGINT/SIGTERM)
//   queue_depth (int, 8)    subscriber queue depth
// Logs every received sequence number (info), checks each message (valid Image, payload bytes all
// equal to sequence % 256) and at exit prints on stdout
//   summary: received=N dropped=D gaps=G invalid=I last=S
// (dropped: lost to the bounded queue; gaps: sequence numbers skipped; invalid: failed checks).
// Exits 1 if any message was invalid.
#include <cstdio>
#include <exception>

#include "probeless/msgs/image.h"
#include "probeless/node/node.h"

namespace {

using probeless::msgs::Image;

int Run(int argc, char** argv) {
  probeless::node::Node node(argc, argv, "listener");
  const int64_t count = node.Param<int64_t>("count", 0);
  const int queue_depth = node.Param("queue_depth", 8);

  probeless::bus::SubscriberOptions options;
  options.queue_depth = static_cast<uint32_t>(queue_depth);
  probeless::bus::Subscriber subscriber = node.CreateSubscriber<Image>("chatter", options);
  node.Info() << "listening on " << subscriber.topic();

  int64_t received = 0;
  uint64_t gaps = 0;
  uint64_t invalid = 0;
  uint64_t last = 0;
  auto on_sample = [&](probeless::bus::Sample&& sample) {
    ++received;
    try {
      const auto in = probeless::msgs::ReadMessage<Image>(sample.data());
      in->Validate(in.payload.size());
      const uint64_t sequence = in->header.sequence;
      const auto expected = static_cast<std::byte>(sequence % 256);
      for (size_t i = 0; i < in->PayloadBytes(); ++i) {
        if (in.payload[i] != expected) {
          throw probeless::msgs::MessageError("payload byte " + std::to_string(i) +
                                              " does not match sequence " +
                                              std::to_string(sequence));
        }
      }
      if (last != 0 && sequence > last + 1) gaps += sequence - last - 1;
      last = sequence;
      node.Info() << "received #" << sequence << " (" << in->Describe() << ", total " << received
                  << ")";
    } catch (const probeless::msgs::MessageError& e) {
      ++invalid;
      node.Error() << "invalid message: " << e.what();
    }
    if (count != 0 && received >= count) probeless::node::RequestShutdown();
  };
  node.Spin({{&subscriber, on_sample}});  // acknowledges every image (lock-step replay)

  node.Info() << "received " << received << " messages, " << subscriber.dropped() << " dropped, "
              << gaps << " gaps, " << invalid << " invalid";
  std::printf("summary: received=%lld dropped=%llu gaps=%llu invalid=%llu last=%llu\n",
              static_cast<long long>(received),
              static_cast<unsigned long long>(subscriber.dropped()),
              static_cast<unsigned long long>(gaps), static_cast<unsigned long long>(invalid),
              static_cast<unsigned long long>(last));
  std::fflush(stdout);
  return invalid == 0 ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return Run(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "[error] [listener] %s\n", e.what());
    return 1;
  }
}
