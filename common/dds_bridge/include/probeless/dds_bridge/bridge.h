// probeless DDS bridge: forwards bus topics to DDS and DDS topics onto the bus with ROS 2's
// conventions (Eclipse Cyclone DDS 0.10), so ROS 2 nodes on other hosts see our topics and we see
// theirs.
//
// - Names: a ROS topic "/camera/image" is the DDS topic "rt/camera/image"; the ROS 2 type
//   "sensor_msgs/msg/Image" is the DDS type "sensor_msgs::msg::dds_::Image_".
// - Payloads: the probeless_log ROS 2 converters (log/ros2.h) encode a bus message into XCDR1
//   little-endian bytes with the 4-byte encapsulation header; those bytes travel as they are
//   through a custom Cyclone sertype ("opaque CDR", src/opaque_cdr.cpp). No IDL per type.
// - Bus → DDS: topics by list or ECMAScript regex (searched in the resolved bus name), each with an
//   optional remap to another ROS name. DDS → bus: remote publications are discovered through the
//   DCPSPublication built-in topic, matched by list or regex on their ROS name, and their type
//   name picks the converter.
// - Queues are bounded everywhere: the bus subscriber queue (drop-oldest, counted), DDS KEEP_LAST
//   histories on both sides, sample-lost status counted on DDS readers.
// - Network: loopback-only by default (a generated Cyclone XML config: interface 127.0.0.1,
//   multicast off, unicast discovery to the localhost peers). Interfaces and peers can be chosen
//   explicitly; a raw Cyclone XML config replaces the generated one.
//
// Cyclone headers stay in src/; this header only needs the standard library.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "probeless/error/error.h"

namespace probeless::dds_bridge {

// Bad configuration or a DDS failure; what() is one line.
class DdsBridgeError : public InputError {
 public:
  using InputError::InputError;
};

enum class Reliability { kReliable, kBestEffort };
enum class Durability { kVolatile, kTransientLocal };

struct Qos {
  Reliability reliability = Reliability::kReliable;
  uint32_t depth = 10;  // KEEP_LAST depth (1..1000)
  Durability durability = Durability::kVolatile;
};

// "reliable"/"best_effort", "volatile"/"transient_local"; throws DdsBridgeError otherwise.
Reliability ParseReliability(std::string_view text);
Durability ParseDurability(std::string_view text);
// "REGEX=reliability,depth,durability" (any of the three may be empty:
// "/camera/.*=best_effort,2,").
struct QosRule {
  std::string regex;  // searched in the ROS (bus) topic name
  std::optional<Reliability> reliability;
  std::optional<uint32_t> depth;
  std::optional<Durability> durability;
};
QosRule ParseQosRule(std::string_view text);

// An explicit topic with optional remap: "from" or "from:=to" (ROS names, absolute).
struct Route {
  std::string from;
  std::string to;  // == from when not remapped
};
Route ParseRoute(std::string_view text);

struct BridgeOptions {
  // DDS domain; < 0: $ROS_DOMAIN_ID, else 0.
  int domain_id = -1;
  // Network interfaces (addresses or names). Empty: loopback only (127.0.0.1).
  std::vector<std::string> interfaces;
  // Unicast discovery peers. Empty with loopback interfaces: 127.0.0.1.
  std::vector<std::string> peers;
  // Multicast discovery and data (off by default; only meaningful on real interfaces).
  bool multicast = false;
  // A whole Cyclone XML configuration (or file:// URI) that replaces the generated one.
  std::string cyclone_config;

  // Bus → DDS.
  std::vector<Route> to_dds;
  std::string to_dds_regex;
  // DDS → bus (ROS names of the remote topics, e.g. "/camera/image").
  std::vector<Route> from_dds;
  std::string from_dds_regex;

  // QoS: default for every topic, image default (sensor_msgs/msg/Image), then rules in order
  // (later rules override earlier ones field by field).
  Qos default_qos{Reliability::kReliable, 10, Durability::kVolatile};
  Qos image_qos{Reliability::kBestEffort, 2, Durability::kVolatile};
  std::vector<QosRule> qos_rules;

  // Bus subscriber queue depth (drop-oldest beyond it) for topics sent to DDS.
  uint32_t bus_queue_depth = 2;
  // Bus publisher slots for topics received from DDS (2..1024): messages of one topic that bus
  // subscribers may hold or have queued at once before the oldest queued one is dropped.
  uint32_t bus_slot_count = 8;
  // How often the bus topic list and DDS publications are rescanned.
  double rescan_period_s = 0.25;
  // Shown in bus introspection.
  std::string node_name = "/dds_bridge";
  // Log lines ("warning: ..." for warnings); may be empty.
  std::function<void(std::string_view)> log;
};

struct TopicStats {
  std::string bus_topic;
  std::string dds_topic;  // "rt/..."
  std::string dds_type;   // "pkg::msg::dds_::Type_"
  bool to_dds = true;     // direction
  uint64_t forwarded = 0;
  uint64_t dropped = 0;  // bus queue drops (to DDS) or DDS samples lost (from DDS)
  uint64_t errors = 0;   // conversion or write failures
  uint64_t bytes = 0;    // CDR bytes
};

// "/camera/image" → "rt/camera/image".
std::string DdsTopicName(std::string_view ros_name);
// "rt/camera/image" → "/camera/image"; empty unless it starts with "rt/".
std::string RosTopicName(std::string_view dds_name);
// "sensor_msgs/msg/Image" → "sensor_msgs::msg::dds_::Image_".
std::string DdsTypeName(std::string_view ros2_type);
// The inverse; empty if `dds_type` is not of that form.
std::string Ros2TypeName(std::string_view dds_type);
// options.domain_id or $ROS_DOMAIN_ID or 0; throws DdsBridgeError on a bad value.
int ResolveDomainId(int domain_id);
// The generated Cyclone XML configuration (or options.cyclone_config if set).
std::string CycloneConfig(const BridgeOptions& options);

class Bridge {
 public:
  // Creates the DDS participant; throws DdsBridgeError on bad options or a DDS failure.
  explicit Bridge(BridgeOptions options);
  ~Bridge();  // Stop()
  Bridge(const Bridge&) = delete;
  Bridge& operator=(const Bridge&) = delete;

  // Starts the two forwarding threads.
  void Start();
  // Stops and joins them (idempotent).
  void Stop();
  // A snapshot of every bridged topic.
  std::vector<TopicStats> Stats() const;
  int domain_id() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace probeless::dds_bridge
