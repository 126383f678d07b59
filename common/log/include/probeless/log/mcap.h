// Types shared by the MCAP writer and reader of probeless::log.
//
// probeless records topics into MCAP files (https://mcap.dev, format version 0): a magic, a Header
// record, a data section of Schema, Channel, Metadata and Chunk records (each Chunk holding Message
// records, zstd- or lz4-compressed or stored as is, followed by its MessageIndex records), a
// DataEnd record with the CRC-32 of the data section, a summary (Schemas, Channels, Statistics,
// ChunkIndexes, MetadataIndexes), SummaryOffsets, a Footer and the closing magic. All integers are
// little-endian; CRCs are CRC-32 (IEEE 802.3, the zlib polynomial). See docs/log.md.
#pragma once

#include <cstdint>
#include <map>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "probeless/error/error.h"

namespace probeless::log {

// The single exception type of the log library (CdrError derives from it). what() is one line;
// for file problems it starts with "<path>: offset <byte offset>: ".
class LogError : public InputError {
 public:
  using InputError::InputError;
};

// Compression of the records inside a Chunk.
enum class Compression : uint8_t {
  kNone = 0,  // stored as is (MCAP compression string "")
  kZstd = 1,  // one zstd frame ("zstd")
  kLz4 = 2,   // one LZ4 frame, lz4frame format ("lz4")
};

// The MCAP compression string: "", "zstd" or "lz4".
std::string_view CompressionName(Compression compression);
// Parses an MCAP compression string; throws LogError for any other value (the message names it).
Compression CompressionFromName(std::string_view name);
// "none", "zstd" or "lz4": the name used on command lines and in JSON (ParseCompressionOption
// accepts these).
std::string_view CompressionOptionName(Compression compression);
// Parses "none", "zstd" or "lz4"; throws LogError otherwise.
Compression ParseCompressionOption(std::string_view name);

// Well-known encodings (mcap.dev registry).
inline constexpr std::string_view kProfileRos2 = "ros2";
inline constexpr std::string_view kSchemaEncodingRos2Msg = "ros2msg";
inline constexpr std::string_view kMessageEncodingCdr = "cdr";

// A Schema record: the type description messages of a channel conform to. Ids start at 1 (0 means
// "no schema").
struct Schema {
  uint16_t id = 0;
  std::string name;      // e.g. "sensor_msgs/msg/Image"
  std::string encoding;  // e.g. "ros2msg"
  std::string data;      // the definition bytes, e.g. the concatenated ros2msg text

  bool operator==(const Schema&) const = default;
};

// A Channel record: one recorded topic.
struct Channel {
  uint16_t id = 0;
  uint16_t schema_id = 0;        // 0 = schemaless
  std::string topic;             // e.g. "/camera/image"
  std::string message_encoding;  // e.g. "cdr"
  std::map<std::string, std::string> metadata;

  bool operator==(const Channel&) const = default;
};

// A Metadata record: named key/value pairs (e.g. the launch file of a recording).
struct Metadata {
  std::string name;
  std::map<std::string, std::string> entries;

  bool operator==(const Metadata&) const = default;
};

// The Statistics record of a file (or, for files without one, the same figures counted by the
// reader). Times are log times in nanoseconds; both are 0 when there is no message.
struct Statistics {
  uint64_t message_count = 0;
  uint16_t schema_count = 0;
  uint32_t channel_count = 0;
  uint32_t attachment_count = 0;
  uint32_t metadata_count = 0;
  uint32_t chunk_count = 0;
  uint64_t message_start_time_ns = 0;                   // earliest message log time
  uint64_t message_end_time_ns = 0;                     // latest message log time
  std::map<uint16_t, uint64_t> channel_message_counts;  // channel id -> messages

  bool operator==(const Statistics&) const = default;
};

}  // namespace probeless::log
