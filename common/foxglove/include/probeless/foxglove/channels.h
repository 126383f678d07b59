// Which bus topics the bridge advertises, and the channel table: one channel per selected topic
// whose type has a ROS 2 conversion (probeless/log/ros2.h), with that converter's ROS 2 type and
// ros2msg schema and message encoding "cdr" — the schema and bytes the recorder writes into MCAP —
// plus, for the chosen image topics, a JPEG channel "<topic>/compressed" of
// sensor_msgs/msg/CompressedImage.
//
// Channel ids start at 1 and are never reused for anything else: a topic that disappears and
// comes back with the same type gets its old id again (the protocol allows that, and clients keep
// their cached decoder).
//
// Thread safety: none; the bridge guards its table with its own mutex.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "probeless/foxglove/protocol.h"

namespace probeless::log {
class Ros2Converter;
}

namespace probeless::foxglove {

inline constexpr std::string_view kJpegSuffix = "/compressed";

// A topic is selected if `all` is set, or it is in `topics`, or matches `regex` (ECMAScript,
// searched) — and does not match `exclude`. Topic names are absolute bus names.
struct TopicSelection {
  bool all = false;
  std::vector<std::string> topics;
  std::string regex;
  std::string exclude;
};

class TopicFilter {
 public:
  // Throws FoxgloveError for an invalid topic name or regex, or an empty selection (no all, no
  // topics, no regex).
  explicit TopicFilter(const TopicSelection& selection);
  ~TopicFilter();
  TopicFilter(TopicFilter&&) noexcept;
  TopicFilter& operator=(TopicFilter&&) noexcept;
  bool Selected(std::string_view topic) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// What a channel carries.
enum class ChannelKind { kCdr, kJpeg };

// A topic as the bus lists it (bus::TopicSnapshot).
struct BusTopic {
  std::string topic;
  std::string type;  // probeless type name
  uint64_t layout_hash = 0;
};

struct ChannelEntry {
  Channel channel;
  std::string bus_topic;
  std::string type;  // probeless type name
  uint64_t layout_hash = 0;
  ChannelKind kind = ChannelKind::kCdr;
  const log::Ros2Converter* converter = nullptr;  // the bus type's converter (both kinds)
};

struct ChannelChanges {
  std::vector<Channel> added;
  std::vector<uint32_t> removed;
  // One line per selected topic newly seen whose type has no ROS 2 conversion (routine: /clock,
  // player control), e.g. "/clock: type probeless_msgs/Header has no ROS 2 conversion; not
  // advertised".
  std::vector<std::string> notices;
  // One line per selected topic newly seen that cannot be advertised for another reason (layout
  // hash of another build, a JPEG channel on a non-image type or on a name taken).
  std::vector<std::string> warnings;
};

struct ChannelTableOptions {
  TopicSelection selection;
  // Image topics that also get a JPEG channel "<topic>/compressed" (whether or not selected).
  std::vector<std::string> jpeg_topics;
};

class ChannelTable {
 public:
  // Throws FoxgloveError as TopicFilter does, or for an invalid JPEG topic name.
  explicit ChannelTable(const ChannelTableOptions& options);
  ~ChannelTable();

  // Brings the table in line with the topics on the bus now (a full listing): channels of
  // selected topics that appeared are added, those of topics gone or retyped are removed.
  ChannelChanges Update(std::span<const BusTopic> topics);
  // The channel of `id`, or null.
  const ChannelEntry* Find(uint32_t id) const;
  // Every current channel, by id.
  std::vector<Channel> Channels() const;
  std::vector<const ChannelEntry*> Entries() const;

 private:
  TopicFilter filter_;
  std::vector<std::string> jpeg_topics_;
  std::map<uint32_t, ChannelEntry> channels_;  // current, by id
  std::map<std::string, uint32_t> ids_;        // "kind|topic|type|hash" -> id
  std::map<std::string, std::string> warned_;  // "topic|line" already reported -> the type
  uint32_t next_id_ = 1;
};

}  // namespace probeless::foxglove
