// A recorded stream: time-ordered probeless messages on named topics, read from an MCAP log or a
// dataset folder. The player publishes a Source on the bus; `probeless bag convert` writes one to
// an MCAP log.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "probeless/error/error.h"
#include "probeless/log/ros2.h"

namespace probeless::dataset {

// Bad input of a source (missing or malformed file, unknown kind, inconsistent folder): one line
// naming the file or folder and what was expected.
class DatasetError : public InputError {
 public:
  using InputError::InputError;
};

// One topic of a source.
struct TopicInfo {
  std::string topic;         // absolute bus topic, e.g. "/camera/image"
  std::string type_name;     // probeless type, msgs::M::kTypeName, e.g. "probeless_msgs/Image"
  uint64_t layout_hash = 0;  // msgs::M::kLayoutHash
  // Upper bound of one message's size in bytes (struct + payload): the publisher's capacity.
  size_t max_message_bytes = 0;
  uint64_t message_count = 0;  // messages of this topic in one pass; 0 if unknown
};

// One message of a source.
struct StreamMessage {
  size_t topic_index = 0;  // index into Source::topics()
  // Time of the message in the stream, nanoseconds (a dataset's own time base, e.g. the TUM
  // timestamps or frame index / fps; an MCAP log time). Non-decreasing along a pass.
  uint64_t log_time_ns = 0;
  // The probeless message: the struct at byte 0 (64-byte aligned), then its payload. Its
  // header.stamp_ns is the dataset's wall-clock stamp when it has one, else log_time_ns.
  log::MessageBuffer message;
};

class Source {
 public:
  virtual ~Source() = default;
  // "mcap", "sim", "7scenes", "tum", "yaleb", "images" or "video".
  virtual std::string_view kind() const = 0;
  // The path the source was opened from.
  virtual const std::string& path() const = 0;
  // Every topic the source will produce, known before the first message (so publishers can be
  // created up front). Indices are stable.
  virtual const std::vector<TopicInfo>& topics() const = 0;
  // The next message in log-time order, or nullopt at the end of the pass. Throws DatasetError on a
  // malformed file (naming it); the source stays usable for Rewind().
  virtual std::optional<StreamMessage> Next() = 0;
  // Starts the pass again from the first message (for --loop).
  virtual void Rewind() = 0;
  // Messages in one pass over all topics; 0 if unknown.
  virtual uint64_t message_count() const;
  // [first, last] log time of a pass in ns, if known without reading every message.
  virtual std::optional<std::pair<uint64_t, uint64_t>> time_range() const { return std::nullopt; }
};

inline uint64_t Source::message_count() const {
  uint64_t n = 0;
  for (const auto& t : topics()) {
    if (t.message_count == 0) return 0;
    n += t.message_count;
  }
  return n;
}

}  // namespace probeless::dataset
