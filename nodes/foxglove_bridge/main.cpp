// foxglove_bridge: a live graph in Foxglove. A Foxglove WebSocket server (foxglove.sdk.v1 and
// foxglove.websocket.v1) that advertises bus topics with their ROS 2 schemas (ros2msg) and CDR —
// the bytes the recorder writes into MCAP — plus JPEG sensor_msgs/msg/CompressedImage channels
// "<topic>/compressed" for chosen image topics. See docs/foxglove.md and
// probeless/foxglove/server.h.
//
// Params: address ("127.0.0.1"), port (8765), topics ([]: with topic_regex empty, every topic),
// topic_regex (""), exclude (""), jpeg_topics ([/render/composite, /camera/image]), jpeg_quality
// (80), client_queue_depth (10 messages), client_queue_mb (64), send_buffer_mb (4),
// bus_queue_depth (4), rescan_period_s (0.25), time_period_s (0.1), clock_topic ("": the wall
// clock; "/clock": a replay's time, as use_sim_time), stats_period_s (5; 0: only at exit). Every
// param is served read-only to clients as "<node>.<param>". At exit prints on stdout one line per
// channel and per bus topic:
//   channel <id> <topic>: messages=N bytes=B dropped=D subscribers=S
//   bus <topic>: received=N dropped=D errors=E
// Exit status: 0 after SIGINT/SIGTERM; 2 for bad params or an address that cannot be bound.
#include "probeless/node/main.h"

#include <chrono>
#include <cstdio>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "probeless/foxglove/server.h"
#include "probeless/node/node.h"

namespace {

using namespace probeless;

int64_t IntParam(node::Node& node, const std::string& name, int64_t value, int64_t lo, int64_t hi) {
  const int64_t v = node.Param<int64_t>(name, value);
  if (v < lo || v > hi) {
    throw node::UsageError("param " + name + " " + std::to_string(v) + " out of range (" +
                           std::to_string(lo) + ".." + std::to_string(hi) + ")");
  }
  return v;
}

std::string ChannelLine(const foxglove::ChannelStats& c) {
  return "channel " + std::to_string(c.id) + " " + c.topic +
         ": messages=" + std::to_string(c.messages) + " bytes=" + std::to_string(c.bytes) +
         " dropped=" + std::to_string(c.dropped) + " subscribers=" + std::to_string(c.subscribers);
}

std::string BusLine(const foxglove::BusTopicStats& t) {
  return "bus " + t.topic + ": received=" + std::to_string(t.received) +
         " dropped=" + std::to_string(t.dropped) + " errors=" + std::to_string(t.errors);
}

int Run(int argc, char** argv) {
  node::Node node(argc, argv, "foxglove_bridge");
  foxglove::ServerOptions o;
  o.address = node.Param("address", "127.0.0.1");
  o.port = static_cast<uint16_t>(IntParam(node, "port", 8765, 0, 65535));
  foxglove::ChannelTableOptions& channels = o.hub.channels;
  for (const std::string& t : node.Param<std::vector<std::string>>("topics", {})) {
    channels.selection.topics.push_back(node.ResolveTopicName(t));
  }
  channels.selection.regex = node.Param("topic_regex", "");
  channels.selection.exclude = node.Param("exclude", "");
  channels.selection.all = channels.selection.topics.empty() && channels.selection.regex.empty();
  for (const std::string& t : node.Param<std::vector<std::string>>(
           "jpeg_topics", {"/render/composite", "/camera/image"})) {
    channels.jpeg_topics.push_back(node.ResolveTopicName(t));
  }
  o.jpeg_quality = static_cast<int>(IntParam(node, "jpeg_quality", 80, 1, 100));
  o.hub.limits.max_messages =
      static_cast<size_t>(IntParam(node, "client_queue_depth", 10, 1, 10000));
  o.hub.limits.max_bytes = static_cast<size_t>(IntParam(node, "client_queue_mb", 64, 1, 16384))
                           << 20;
  o.send_buffer_bytes = static_cast<size_t>(IntParam(node, "send_buffer_mb", 4, 1, 1024)) << 20;
  o.bus_queue_depth = static_cast<uint32_t>(
      IntParam(node, "bus_queue_depth", 4, 1, probeless::bus::kMaxQueueDepth));
  o.rescan_period_s = node.Param("rescan_period_s", 0.25);
  o.time_period_s = node.Param("time_period_s", 0.1);
  if (const std::string clock = node.Param("clock_topic", ""); !clock.empty()) {
    o.clock_topic = node.ResolveTopicName(clock);
  }
  const double stats_period = node.Param("stats_period_s", 5.0);
  if (!(o.rescan_period_s > 0) || !(o.time_period_s > 0) || !(stats_period >= 0)) {
    throw node::UsageError(
        "params rescan_period_s and time_period_s must be > 0, stats_period_s >= 0");
  }
  node.CheckParamOverrides();
  for (const node::ParamInfo& p : node.DeclaredParams()) {
    o.hub.parameters.push_back({node.fully_qualified_name() + "." + p.name, p.type, p.value});
  }
  o.hub.server_name = "probeless " + node.fully_qualified_name();
  o.hub.session_id = std::to_string(std::chrono::duration_cast<std::chrono::milliseconds>(
                                        std::chrono::system_clock::now().time_since_epoch())
                                        .count());
  o.node_name = node.fully_qualified_name();
  o.log = [&node](std::string_view line) {
    constexpr std::string_view kWarning = "warning: ";
    if (line.starts_with(kWarning)) {
      node.Warn() << line.substr(kWarning.size());
    } else {
      node.Info() << line;
    }
  };

  const std::string address = o.address;
  foxglove::Server server(std::move(o));
  server.Start();
  node.Info() << "listening on ws://" << address << ":" << server.port()
              << " (foxglove.sdk.v1, foxglove.websocket.v1)";
  std::map<uint32_t, uint64_t> last_dropped;
  std::map<std::string, uint64_t> last_bus_dropped;
  while (node.ok()) {
    node.WaitForShutdown(stats_period > 0 ? std::chrono::duration_cast<std::chrono::nanoseconds>(
                                                std::chrono::duration<double>(stats_period))
                                          : std::chrono::hours(1));
    if (!node.ok() || stats_period <= 0) continue;
    const foxglove::ServerStats stats = server.Stats();
    for (const foxglove::ChannelStats& c : stats.channels) {
      const uint64_t before = std::exchange(last_dropped[c.id], c.dropped);
      if (c.dropped > before) {
        node.Warn() << ChannelLine(c) << " (" << (c.dropped - before)
                    << " new drops in slow clients' queues)";
      } else if (c.subscribers > 0) {
        node.Info() << ChannelLine(c);
      }
    }
    for (const foxglove::BusTopicStats& t : stats.topics) {
      const uint64_t before = std::exchange(last_bus_dropped[t.topic], t.dropped);
      if (t.dropped > before) {
        node.Warn() << BusLine(t) << " (" << (t.dropped - before) << " new drops in the bus queue)";
      }
    }
    for (const foxglove::ClientStats& c : stats.clients) {
      node.Info() << "client " << c.id << " (" << c.remote << "): subscriptions=" << c.subscriptions
                  << " sent=" << c.sent << " dropped=" << c.dropped << " errors=" << c.errors
                  << " queued=" << c.queued;
    }
  }
  server.Stop();
  const foxglove::ServerStats stats = server.Stats();
  for (const foxglove::ChannelStats& c : stats.channels)
    std::printf("%s\n", ChannelLine(c).c_str());
  for (const foxglove::BusTopicStats& t : stats.topics) std::printf("%s\n", BusLine(t).c_str());
  std::fflush(stdout);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return probeless::node::RunMain("foxglove_bridge", [&] { return Run(argc, argv); });
}
