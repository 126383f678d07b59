// Serialisation and parsing of MCAP record bodies (shared by the writer, the reader and tests).
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "byte_io.h"
#include "mcap_format.h"
#include "probeless/log/mcap.h"

namespace probeless::log::internal {

struct ChunkIndexRecord {
  uint64_t message_start_time = 0;
  uint64_t message_end_time = 0;
  uint64_t chunk_start_offset = 0;  // file offset of the Chunk record's opcode
  uint64_t chunk_length = 0;        // whole Chunk record, opcode and length included
  std::map<uint16_t, uint64_t> message_index_offsets;  // channel -> MessageIndex record offset
  uint64_t message_index_length = 0;  // bytes of the MessageIndex records after the chunk
  std::string compression;
  uint64_t compressed_size = 0;
  uint64_t uncompressed_size = 0;
};

struct MetadataIndexRecord {
  uint64_t offset = 0;  // file offset of the Metadata record's opcode
  uint64_t length = 0;  // whole Metadata record
  std::string name;
};

// Fields of a Chunk record before its records.
struct ChunkHeader {
  uint64_t message_start_time = 0;
  uint64_t message_end_time = 0;
  uint64_t uncompressed_size = 0;
  uint32_t uncompressed_crc = 0;
  std::string compression;
  uint64_t records_size = 0;
  // Parser position (in the record body) of the first byte of the (compressed) records.
  uint64_t records_offset = 0;
};

// Fields of a Message record before its data.
struct MessageHeader {
  uint16_t channel_id = 0;
  uint32_t sequence = 0;
  uint64_t log_time = 0;
  uint64_t publish_time = 0;
};

// Appends the opcode and a length placeholder; returns the record's start for EndRecord.
inline size_t BeginRecord(std::vector<uint8_t>& out, uint8_t opcode) {
  const size_t begin = out.size();
  Put<uint8_t>(out, opcode);
  Put<uint64_t>(out, 0);
  return begin;
}
// Patches the length of the record started at `begin` to everything appended since.
inline void EndRecord(std::vector<uint8_t>& out, size_t begin) {
  PutAt<uint64_t>(out, begin + 1, out.size() - begin - kRecordPrefixSize);
}

void PutStringMap(std::vector<uint8_t>& out, const std::map<std::string, std::string>& map);

void AppendHeader(std::vector<uint8_t>& out, std::string_view profile, std::string_view library);
void AppendSchema(std::vector<uint8_t>& out, const Schema& schema);
void AppendChannel(std::vector<uint8_t>& out, const Channel& channel);
void AppendStatistics(std::vector<uint8_t>& out, const Statistics& statistics);
void AppendChunkIndex(std::vector<uint8_t>& out, const ChunkIndexRecord& index);
void AppendMetadata(std::vector<uint8_t>& out, const Metadata& metadata);
void AppendMetadataIndex(std::vector<uint8_t>& out, const MetadataIndexRecord& index);
void AppendSummaryOffset(std::vector<uint8_t>& out, uint8_t group_opcode, uint64_t group_start,
                         uint64_t group_length);
void AppendDataEnd(std::vector<uint8_t>& out, uint32_t data_section_crc);
// The Footer record; summary_crc covers [summary_start, this record's crc field).
void AppendFooter(std::vector<uint8_t>& out, uint64_t summary_start, uint64_t summary_offset_start,
                  uint32_t summary_crc);
// The Chunk record prefix and fields up to the records' length (the records follow).
void AppendChunkHeader(std::vector<uint8_t>& out, const ChunkHeader& header);

// Parsers of record bodies (the Parser is positioned after the opcode and length). They throw
// LogError on fields running past the body.
Schema ParseSchema(Parser& parser);
Channel ParseChannel(Parser& parser);
Statistics ParseStatistics(Parser& parser);
ChunkIndexRecord ParseChunkIndex(Parser& parser);
Metadata ParseMetadata(Parser& parser);
MetadataIndexRecord ParseMetadataIndex(Parser& parser);
MessageHeader ParseMessageHeader(Parser& parser);
// Parses the fields before the records; records_offset is set from the parser position.
ChunkHeader ParseChunkHeader(Parser& parser);

}  // namespace probeless::log::internal
