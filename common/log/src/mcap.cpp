#include "probeless/log/mcap.h"

#include <cstdio>
#include <string>

#include "mcap_format.h"

namespace probeless::log {

std::string_view CompressionName(Compression compression) {
  switch (compression) {
    case Compression::kNone:
      return "";
    case Compression::kZstd:
      return "zstd";
    case Compression::kLz4:
      return "lz4";
  }
  return "invalid";
}

Compression CompressionFromName(std::string_view name) {
  if (name.empty()) return Compression::kNone;
  if (name == "zstd") return Compression::kZstd;
  if (name == "lz4") return Compression::kLz4;
  throw LogError("unknown chunk compression '" + std::string(name) +
                 "' (supported: '', 'zstd', 'lz4')");
}

std::string_view CompressionOptionName(Compression compression) {
  return compression == Compression::kNone ? "none" : CompressionName(compression);
}

Compression ParseCompressionOption(std::string_view name) {
  if (name == "none") return Compression::kNone;
  if (name == "zstd") return Compression::kZstd;
  if (name == "lz4") return Compression::kLz4;
  throw LogError("unknown compression '" + std::string(name) + "' (expected none, zstd or lz4)");
}

namespace internal {

std::string OpcodeName(uint8_t opcode) {
  switch (opcode) {
    case kOpHeader:
      return "Header";
    case kOpFooter:
      return "Footer";
    case kOpSchema:
      return "Schema";
    case kOpChannel:
      return "Channel";
    case kOpMessage:
      return "Message";
    case kOpChunk:
      return "Chunk";
    case kOpMessageIndex:
      return "MessageIndex";
    case kOpChunkIndex:
      return "ChunkIndex";
    case kOpAttachment:
      return "Attachment";
    case kOpAttachmentIndex:
      return "AttachmentIndex";
    case kOpStatistics:
      return "Statistics";
    case kOpMetadata:
      return "Metadata";
    case kOpMetadataIndex:
      return "MetadataIndex";
    case kOpSummaryOffset:
      return "SummaryOffset";
    case kOpDataEnd:
      return "DataEnd";
  }
  char text[16];
  std::snprintf(text, sizeof(text), "opcode 0x%02x", opcode);
  return text;
}

}  // namespace internal
}  // namespace probeless::log
