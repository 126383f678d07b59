// MCAP format constants (https://mcap.dev/spec, version 0).
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

namespace probeless::log::internal {

// "\x89MCAP0\r\n" at the start and the end of every file.
inline constexpr uint8_t kMagic[8] = {0x89, 'M', 'C', 'A', 'P', '0', '\r', '\n'};
inline constexpr uint64_t kMagicSize = 8;
// Opcode (uint8) + body length (uint64).
inline constexpr uint64_t kRecordPrefixSize = 9;
// Footer body: summary_start, summary_offset_start (uint64), summary_crc (uint32).
inline constexpr uint64_t kFooterBodySize = 20;
inline constexpr uint64_t kFooterRecordSize = kRecordPrefixSize + kFooterBodySize;
// Message record fields before the data: channel_id, sequence, log_time, publish_time.
inline constexpr uint64_t kMessageHeaderSize = 2 + 4 + 8 + 8;

enum Opcode : uint8_t {
  kOpHeader = 0x01,
  kOpFooter = 0x02,
  kOpSchema = 0x03,
  kOpChannel = 0x04,
  kOpMessage = 0x05,
  kOpChunk = 0x06,
  kOpMessageIndex = 0x07,
  kOpChunkIndex = 0x08,
  kOpAttachment = 0x09,
  kOpAttachmentIndex = 0x0A,
  kOpStatistics = 0x0B,
  kOpMetadata = 0x0C,
  kOpMetadataIndex = 0x0D,
  kOpSummaryOffset = 0x0E,
  kOpDataEnd = 0x0F,
};

// "Chunk", "Message", ... or "opcode 0x42" for unknown ones.
std::string OpcodeName(uint8_t opcode);

inline constexpr std::string_view kLibraryName = "probeless-log 0.1";

}  // namespace probeless::log::internal
