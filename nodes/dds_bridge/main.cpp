// dds_bridge: forwards bus topics to DDS and DDS topics onto the bus with ROS 2's conventions
// (rt/<name>, pkg::msg::dds_::Type_, XCDR1), so ROS 2 nodes on other hosts see our topics and we
// see theirs. See docs/dds_bridge.md and probeless/dds_bridge/bridge.h.
//
// Params (-p name:=value or a params file):
//   to_dds (string array, [])       bus topics to publish on DDS: "/topic" or "/topic:=/ros_name"
//   to_dds_regex (string, "")       also every bus topic matching this regex
//   from_dds (string array, [])     ROS topics to bring onto the bus: "/ros_name" or "/ros_name:=/topic"
//   from_dds_regex (string, "")     also every remote DDS publication "rt/..." whose ROS name matches
//   domain_id (int, -1)             DDS domain; -1: $ROS_DOMAIN_ID, else 0
//   interfaces (string array, [])   network interfaces (addresses or names); empty: 127.0.0.1 only
//   peers (string array, [])        unicast discovery peers; empty: 127.0.0.1 when loopback-only
//   multicast (bool, false)         multicast discovery (non-loopback interfaces only)
//   cyclone_config (string, "")     a whole Cyclone XML config (or file://...) instead of the above
//   reliability, depth, durability  default QoS (reliable, 10, volatile)
//   image_reliability, image_depth, image_durability   sensor_msgs/Image QoS (best_effort, 2, volatile)
//   qos (string array, [])          per-topic rules "REGEX=reliability,depth,durability"
//   bus_queue_depth (int, 2)        bus queue per forwarded topic (drop-oldest, counted)
//   bus_slot_count (int, 8)         bus publisher slots per topic received from DDS (2..1024)
//   stats_period_s (double, 5)      log a stats line per topic this often (0: only at exit)
// At exit prints on stdout one line per topic
//   <bus topic> -> <dds topic> | <dds topic> -> <bus topic>: forwarded=N dropped=D errors=E bytes=B
// Exit status: 0 after SIGINT/SIGTERM; 2 for bad params; 1 for a DDS failure.
#include <cstdio>
#include <map>
#include <string>
#include <vector>

#include "probeless/dds_bridge/bridge.h"
#include "probeless/node/main.h"
#include "probeless/node/node.h"

namespace {

using namespace probeless;
using dds_bridge::BridgeOptions;

dds_bridge::Qos ReadQos(node::Node& node, const std::string& prefix, dds_bridge::Qos q) {
  q.reliability = dds_bridge::ParseReliability(node.Param(
      prefix + "reliability",
      std::string(q.reliability == dds_bridge::Reliability::kReliable ? "reliable" : "best_effort")));
  const int64_t depth = node.Param<int64_t>(prefix + "depth", q.depth);
  if (depth < 1 || depth > 1000) {
    throw std::invalid_argument(prefix + "depth " + std::to_string(depth) + " out of range (1..1000)");
  }
  q.depth = static_cast<uint32_t>(depth);
  q.durability = dds_bridge::ParseDurability(node.Param(
      prefix + "durability",
      std::string(q.durability == dds_bridge::Durability::kVolatile ? "volatile" : "transient_local")));
  return q;
}

std::string Line(const dds_bridge::TopicStats& s) {
  char buf[512];
  std::snprintf(buf, sizeof(buf), "%s -> %s: forwarded=%llu dropped=%llu errors=%llu bytes=%llu",
                (s.to_dds ? s.bus_topic : s.dds_topic).c_str(),
                (s.to_dds ? s.dds_topic : s.bus_topic).c_str(),
                static_cast<unsigned long long>(s.forwarded),
                static_cast<unsigned long long>(s.dropped),
                static_cast<unsigned long long>(s.errors),
                static_cast<unsigned long long>(s.bytes));
  return buf;
}

int Run(int argc, char** argv) {
  node::Node node(argc, argv, "dds_bridge");
  BridgeOptions o;
  // "from" or "from:=to", both sides resolved in the node's namespace.
  auto route = [&node](const std::string& text) {
    const size_t sep = text.find(":=");
    const std::string from = node.ResolveTopicName(text.substr(0, sep));
    const std::string to =
        sep == std::string::npos ? from : node.ResolveTopicName(text.substr(sep + 2));
    return dds_bridge::ParseRoute(from + ":=" + to);
  };
  for (const std::string& r : node.Param<std::vector<std::string>>("to_dds", {})) {
    o.to_dds.push_back(route(r));
  }
  o.to_dds_regex = node.Param("to_dds_regex", "");
  for (const std::string& r : node.Param<std::vector<std::string>>("from_dds", {})) {
    o.from_dds.push_back(route(r));
  }
  o.from_dds_regex = node.Param("from_dds_regex", "");
  o.domain_id = node.Param<int>("domain_id", -1);
  o.interfaces = node.Param<std::vector<std::string>>("interfaces", {});
  o.peers = node.Param<std::vector<std::string>>("peers", {});
  o.multicast = node.Param("multicast", false);
  o.cyclone_config = node.Param("cyclone_config", "");
  o.default_qos = ReadQos(node, "", o.default_qos);
  o.image_qos = ReadQos(node, "image_", o.image_qos);
  for (const std::string& rule : node.Param<std::vector<std::string>>("qos", {})) {
    o.qos_rules.push_back(dds_bridge::ParseQosRule(rule));
  }
  const int64_t queue = node.Param<int64_t>("bus_queue_depth", 2);
  if (queue < 1 || queue > probeless::bus::kMaxQueueDepth) {
    throw std::invalid_argument("bus_queue_depth " + std::to_string(queue) + " out of range (1..64)");
  }
  o.bus_queue_depth = static_cast<uint32_t>(queue);
  const int64_t slots = node.Param<int64_t>("bus_slot_count", 8);
  if (slots < 2 || slots > 1024) {
    throw std::invalid_argument("bus_slot_count " + std::to_string(slots) +
                                " out of range (2..1024)");
  }
  o.bus_slot_count = static_cast<uint32_t>(slots);
  const double stats_period = node.Param("stats_period_s", 5.0);
  node.CheckParamOverrides();
  if (o.to_dds.empty() && o.to_dds_regex.empty() && o.from_dds.empty() && o.from_dds_regex.empty()) {
    node.Warn() << "nothing to bridge (set to_dds, to_dds_regex, from_dds or from_dds_regex)";
  }
  o.node_name = node.fully_qualified_name();
  o.log = [&node](std::string_view line) {
    constexpr std::string_view kWarning = "warning: ";
    if (line.starts_with(kWarning)) node.Warn() << line.substr(kWarning.size());
    else node.Info() << line;
  };

  dds_bridge::Bridge bridge(o);
  node.Info() << "DDS domain " << bridge.domain_id() << ", "
              << (o.cyclone_config.empty() ? (o.interfaces.empty() ? "loopback only" : "interfaces set")
                                           : "custom Cyclone config");
  bridge.Start();
  std::map<std::string, uint64_t> last_dropped;
  auto report = [&](bool final_report) {
    for (const auto& s : bridge.Stats()) {
      const std::string key = s.bus_topic + (s.to_dds ? ">" : "<");
      const uint64_t before = last_dropped[key];
      last_dropped[key] = s.dropped;
      if (final_report) {
        std::printf("%s\n", Line(s).c_str());
      } else if (s.dropped > before) {
        node.Warn() << Line(s) << " (" << (s.dropped - before) << " new drops)";
      } else {
        node.Info() << Line(s);
      }
    }
  };
  while (node.ok()) {
    node.WaitForShutdown(stats_period > 0 ? std::chrono::duration_cast<std::chrono::nanoseconds>(
                                                std::chrono::duration<double>(stats_period))
                                          : std::chrono::hours(1));
    if (node.ok() && stats_period > 0) report(false);
  }
  bridge.Stop();
  report(true);
  std::fflush(stdout);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return probeless::node::RunMain(
      "dds_bridge", [&] { return Run(argc, argv); });
}
