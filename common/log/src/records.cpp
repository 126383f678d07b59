#include "records.h"

namespace probeless::log::internal {
namespace {

std::map<std::string, std::string> ParseStringMap(Parser& parser, std::string_view field) {
  const uint64_t map_at = parser.reported_position() + 4;
  const auto bytes = parser.U32Prefixed(field);
  Parser entries(bytes, parser.where(), 0, field, map_at);
  std::map<std::string, std::string> map;
  while (entries.remaining() > 0) {
    std::string key = entries.String("key");
    std::string value = entries.String("value");
    map[std::move(key)] = std::move(value);
  }
  return map;
}

}  // namespace

void PutStringMap(std::vector<uint8_t>& out, const std::map<std::string, std::string>& map) {
  const size_t length_at = out.size();
  Put<uint32_t>(out, 0);
  for (const auto& [key, value] : map) {
    PutString(out, key);
    PutString(out, value);
  }
  PutAt<uint32_t>(out, length_at, static_cast<uint32_t>(out.size() - length_at - 4));
}

void AppendHeader(std::vector<uint8_t>& out, std::string_view profile, std::string_view library) {
  const size_t begin = BeginRecord(out, kOpHeader);
  PutString(out, profile);
  PutString(out, library);
  EndRecord(out, begin);
}

void AppendSchema(std::vector<uint8_t>& out, const Schema& schema) {
  const size_t begin = BeginRecord(out, kOpSchema);
  Put<uint16_t>(out, schema.id);
  PutString(out, schema.name);
  PutString(out, schema.encoding);
  PutString(out, schema.data);  // Bytes: uint32 length prefix too
  EndRecord(out, begin);
}

void AppendChannel(std::vector<uint8_t>& out, const Channel& channel) {
  const size_t begin = BeginRecord(out, kOpChannel);
  Put<uint16_t>(out, channel.id);
  Put<uint16_t>(out, channel.schema_id);
  PutString(out, channel.topic);
  PutString(out, channel.message_encoding);
  PutStringMap(out, channel.metadata);
  EndRecord(out, begin);
}

void AppendStatistics(std::vector<uint8_t>& out, const Statistics& s) {
  const size_t begin = BeginRecord(out, kOpStatistics);
  Put<uint64_t>(out, s.message_count);
  Put<uint16_t>(out, s.schema_count);
  Put<uint32_t>(out, s.channel_count);
  Put<uint32_t>(out, s.attachment_count);
  Put<uint32_t>(out, s.metadata_count);
  Put<uint32_t>(out, s.chunk_count);
  Put<uint64_t>(out, s.message_start_time_ns);
  Put<uint64_t>(out, s.message_end_time_ns);
  Put<uint32_t>(out, static_cast<uint32_t>(s.channel_message_counts.size() * 10));
  for (const auto& [channel, count] : s.channel_message_counts) {
    Put<uint16_t>(out, channel);
    Put<uint64_t>(out, count);
  }
  EndRecord(out, begin);
}

void AppendChunkIndex(std::vector<uint8_t>& out, const ChunkIndexRecord& index) {
  const size_t begin = BeginRecord(out, kOpChunkIndex);
  Put<uint64_t>(out, index.message_start_time);
  Put<uint64_t>(out, index.message_end_time);
  Put<uint64_t>(out, index.chunk_start_offset);
  Put<uint64_t>(out, index.chunk_length);
  Put<uint32_t>(out, static_cast<uint32_t>(index.message_index_offsets.size() * 10));
  for (const auto& [channel, offset] : index.message_index_offsets) {
    Put<uint16_t>(out, channel);
    Put<uint64_t>(out, offset);
  }
  Put<uint64_t>(out, index.message_index_length);
  PutString(out, index.compression);
  Put<uint64_t>(out, index.compressed_size);
  Put<uint64_t>(out, index.uncompressed_size);
  EndRecord(out, begin);
}

void AppendMetadata(std::vector<uint8_t>& out, const Metadata& metadata) {
  const size_t begin = BeginRecord(out, kOpMetadata);
  PutString(out, metadata.name);
  PutStringMap(out, metadata.entries);
  EndRecord(out, begin);
}

void AppendMetadataIndex(std::vector<uint8_t>& out, const MetadataIndexRecord& index) {
  const size_t begin = BeginRecord(out, kOpMetadataIndex);
  Put<uint64_t>(out, index.offset);
  Put<uint64_t>(out, index.length);
  PutString(out, index.name);
  EndRecord(out, begin);
}

void AppendSummaryOffset(std::vector<uint8_t>& out, uint8_t group_opcode, uint64_t group_start,
                         uint64_t group_length) {
  const size_t begin = BeginRecord(out, kOpSummaryOffset);
  Put<uint8_t>(out, group_opcode);
  Put<uint64_t>(out, group_start);
  Put<uint64_t>(out, group_length);
  EndRecord(out, begin);
}

void AppendDataEnd(std::vector<uint8_t>& out, uint32_t data_section_crc) {
  const size_t begin = BeginRecord(out, kOpDataEnd);
  Put<uint32_t>(out, data_section_crc);
  EndRecord(out, begin);
}

void AppendFooter(std::vector<uint8_t>& out, uint64_t summary_start, uint64_t summary_offset_start,
                  uint32_t summary_crc) {
  const size_t begin = BeginRecord(out, kOpFooter);
  Put<uint64_t>(out, summary_start);
  Put<uint64_t>(out, summary_offset_start);
  Put<uint32_t>(out, summary_crc);
  EndRecord(out, begin);
}

void AppendChunkHeader(std::vector<uint8_t>& out, const ChunkHeader& header) {
  Put<uint8_t>(out, kOpChunk);
  Put<uint64_t>(out, 8 + 8 + 8 + 4 + 4 + header.compression.size() + 8 + header.records_size);
  Put<uint64_t>(out, header.message_start_time);
  Put<uint64_t>(out, header.message_end_time);
  Put<uint64_t>(out, header.uncompressed_size);
  Put<uint32_t>(out, header.uncompressed_crc);
  PutString(out, header.compression);
  Put<uint64_t>(out, header.records_size);
}

Schema ParseSchema(Parser& parser) {
  Schema schema;
  schema.id = parser.U16("id");
  schema.name = parser.String("name");
  schema.encoding = parser.String("encoding");
  schema.data = parser.String("data");
  return schema;
}

Channel ParseChannel(Parser& parser) {
  Channel channel;
  channel.id = parser.U16("id");
  channel.schema_id = parser.U16("schema_id");
  channel.topic = parser.String("topic");
  channel.message_encoding = parser.String("message_encoding");
  channel.metadata = ParseStringMap(parser, "metadata");
  return channel;
}

Statistics ParseStatistics(Parser& parser) {
  Statistics s;
  s.message_count = parser.U64("message_count");
  s.schema_count = parser.U16("schema_count");
  s.channel_count = parser.U32("channel_count");
  s.attachment_count = parser.U32("attachment_count");
  s.metadata_count = parser.U32("metadata_count");
  s.chunk_count = parser.U32("chunk_count");
  s.message_start_time_ns = parser.U64("message_start_time");
  s.message_end_time_ns = parser.U64("message_end_time");
  const auto counts = parser.U32Prefixed("channel_message_counts");
  if (counts.size() % 10 != 0) {
    parser.FailHere("channel_message_counts of " + std::to_string(counts.size()) +
                    " bytes is not a whole number of 10-byte entries");
  }
  for (size_t at = 0; at < counts.size(); at += 10) {
    s.channel_message_counts[Load<uint16_t>(counts.data() + at)] =
        Load<uint64_t>(counts.data() + at + 2);
  }
  return s;
}

ChunkIndexRecord ParseChunkIndex(Parser& parser) {
  ChunkIndexRecord index;
  index.message_start_time = parser.U64("message_start_time");
  index.message_end_time = parser.U64("message_end_time");
  index.chunk_start_offset = parser.U64("chunk_start_offset");
  index.chunk_length = parser.U64("chunk_length");
  const auto offsets = parser.U32Prefixed("message_index_offsets");
  if (offsets.size() % 10 != 0) {
    parser.FailHere("message_index_offsets of " + std::to_string(offsets.size()) +
                    " bytes is not a whole number of 10-byte entries");
  }
  for (size_t at = 0; at < offsets.size(); at += 10) {
    index.message_index_offsets[Load<uint16_t>(offsets.data() + at)] =
        Load<uint64_t>(offsets.data() + at + 2);
  }
  index.message_index_length = parser.U64("message_index_length");
  index.compression = parser.String("compression");
  index.compressed_size = parser.U64("compressed_size");
  index.uncompressed_size = parser.U64("uncompressed_size");
  return index;
}

Metadata ParseMetadata(Parser& parser) {
  Metadata metadata;
  metadata.name = parser.String("name");
  metadata.entries = ParseStringMap(parser, "metadata");
  return metadata;
}

MetadataIndexRecord ParseMetadataIndex(Parser& parser) {
  MetadataIndexRecord index;
  index.offset = parser.U64("offset");
  index.length = parser.U64("length");
  index.name = parser.String("name");
  return index;
}

MessageHeader ParseMessageHeader(Parser& parser) {
  MessageHeader header;
  header.channel_id = parser.U16("channel_id");
  header.sequence = parser.U32("sequence");
  header.log_time = parser.U64("log_time");
  header.publish_time = parser.U64("publish_time");
  return header;
}

ChunkHeader ParseChunkHeader(Parser& parser) {
  ChunkHeader header;
  header.message_start_time = parser.U64("message_start_time");
  header.message_end_time = parser.U64("message_end_time");
  header.uncompressed_size = parser.U64("uncompressed_size");
  header.uncompressed_crc = parser.U32("uncompressed_crc");
  header.compression = parser.String("compression");
  header.records_size = parser.U64("records_length");
  header.records_offset = parser.position();
  return header;
}

}  // namespace probeless::log::internal
