#include "probeless/log/mcap_reader.h"

#include <errno.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <limits>
#include <queue>
#include <string>
#include <utility>
#include <vector>

#include "byte_buffer.h"
#include "byte_io.h"
#include "compression.h"
#include "crc32.h"
#include "mcap_format.h"
#include "records.h"

namespace probeless::log {

using namespace internal;

namespace {

std::string Hex32(uint32_t value) {
  char text[16];
  std::snprintf(text, sizeof(text), "0x%08x", value);
  return text;
}

// Random-access input.
class Source {
 public:
  virtual ~Source() = default;
  virtual uint64_t size() const = 0;
  // Copies [offset, offset + size) into `out`; the caller keeps the range within size().
  virtual void Read(uint64_t offset, void* out, size_t size) const = 0;
};

class FileSource : public Source {
 public:
  explicit FileSource(const std::string& path) : path_(path) {
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) throw LogError(path + ": cannot open: " + std::strerror(errno));
    struct stat info {};
    if (::fstat(fd_, &info) != 0) {
      const int error = errno;
      ::close(fd_);
      throw LogError(path + ": cannot stat: " + std::strerror(error));
    }
    if (!S_ISREG(info.st_mode)) {
      ::close(fd_);
      throw LogError(path + ": not a regular file");
    }
    size_ = static_cast<uint64_t>(info.st_size);
  }
  ~FileSource() override { ::close(fd_); }

  uint64_t size() const override { return size_; }
  void Read(uint64_t offset, void* out, size_t size) const override {
    auto* p = static_cast<uint8_t*>(out);
    while (size > 0) {
      const ssize_t got = ::pread(fd_, p, size, static_cast<off_t>(offset));
      if (got < 0) {
        if (errno == EINTR) continue;
        throw LogError(path_ + ": offset " + std::to_string(offset) +
                       ": read failed: " + std::strerror(errno));
      }
      if (got == 0) {
        throw LogError(path_ + ": offset " + std::to_string(offset) +
                       ": unexpected end of file (the file shrank while being read)");
      }
      p += got;
      offset += static_cast<uint64_t>(got);
      size -= static_cast<size_t>(got);
    }
  }

 private:
  std::string path_;
  int fd_ = -1;
  uint64_t size_ = 0;
};

class MemorySource : public Source {
 public:
  explicit MemorySource(std::span<const std::byte> bytes) : bytes_(bytes) {}
  uint64_t size() const override { return bytes_.size(); }
  void Read(uint64_t offset, void* out, size_t size) const override {
    if (size > 0) std::memcpy(out, bytes_.data() + offset, size);
  }

 private:
  std::span<const std::byte> bytes_;
};

// A chunk or a Message record outside chunks: the unit the cursor loads.
// The record at `position` of `records` (a summary or a decompressed chunk, called `region` in
// errors): its opcode and body, bounds-checked. Fails (LogError) on a cut prefix or a length that
// runs past the region.
struct RecordAt {
  uint8_t opcode;
  std::span<const uint8_t> body;
};
RecordAt NextRecord(std::span<const uint8_t> records, size_t position, const Where& where,
                    const char* cut_prefix_problem, const char* region) {
  if (records.size() - position < kRecordPrefixSize) Fail(where, position, cut_prefix_problem);
  const uint8_t opcode = records[position];
  const uint64_t length = Load<uint64_t>(records.data() + position + 1);
  const size_t left = records.size() - position - kRecordPrefixSize;
  if (length > left) {
    Fail(where, position,
         OpcodeName(opcode) + " record length " + std::to_string(length) +
             " runs past the end of the " + region + " (" + std::to_string(left) + " bytes left)");
  }
  return {opcode, records.subspan(position + kRecordPrefixSize, length)};
}

struct Block {
  uint64_t offset = 0;  // file offset of the record's opcode
  uint64_t length = 0;  // whole record
  uint64_t start_time = 0;
  uint64_t end_time = 0;
  bool is_chunk = false;
  // Chunks only, as announced by the chunk index (checked against the chunk record on load).
  bool from_index = false;
  Compression compression = Compression::kNone;
  uint64_t compressed_size = 0;
  uint64_t uncompressed_size = 0;
  // Channels with messages in the block; empty = unknown.
  std::vector<uint16_t> channels;
};

// A loaded block: the whole record of a loose message, or a chunk's uncompressed records.
struct Loaded {
  ByteBuffer records;
  uint64_t block_offset = 0;
  bool is_chunk = false;
};

}  // namespace

struct McapReader::Impl {
  std::string path;
  ReaderOptions options;
  std::unique_ptr<Source> source;
  std::string profile;
  std::string library;
  std::map<uint16_t, Schema> schemas;
  std::map<uint16_t, Channel> channels;
  Statistics statistics;
  std::vector<Metadata> metadata;
  RecoveryReport report;
  std::vector<Block> blocks;
  Decompressor decompressor;
  ByteBuffer compressed;  // scratch for compressed chunk records
  uint64_t data_start = 0;

  Where FileWhere() const { return Where{&path, 0, false}; }
  [[noreturn]] void FailAt(uint64_t offset, const std::string& problem) const {
    Fail(FileWhere(), offset, problem);
  }

  std::vector<uint8_t> ReadBytes(uint64_t offset, uint64_t size) const {
    std::vector<uint8_t> bytes(size);
    source->Read(offset, bytes.data(), size);
    return bytes;
  }

  void RegisterSchema(Schema schema, const Where& where, uint64_t position) {
    if (schema.id == 0) Fail(where, position, "Schema record with the reserved id 0");
    auto [it, inserted] = schemas.try_emplace(schema.id, schema);
    if (!inserted && !(it->second == schema)) {
      Fail(where, position,
           "Schema id " + std::to_string(schema.id) + " redefined with different fields");
    }
  }

  void RegisterChannel(Channel channel, const Where& where, uint64_t position) {
    if (channel.schema_id != 0 && schemas.count(channel.schema_id) == 0) {
      Fail(where, position,
           "Channel " + std::to_string(channel.id) + " ('" + channel.topic +
               "') refers to unknown schema id " + std::to_string(channel.schema_id));
    }
    auto [it, inserted] = channels.try_emplace(channel.id, channel);
    if (!inserted && !(it->second == channel)) {
      Fail(where, position,
           "Channel id " + std::to_string(channel.id) + " redefined with different fields");
    }
  }

  // Parses and registers a Schema or Channel record whose body is `body`. `record_position` is
  // the record's position in the span `where` describes (a file offset when `where.base` is 0, or
  // a chunk byte).
  void RegisterRecord(uint8_t opcode, std::span<const uint8_t> body, const Where& where,
                      uint64_t record_position) {
    Parser fields(body, where, 0, OpcodeName(opcode) + " record",
                  record_position + kRecordPrefixSize);
    if (opcode == kOpSchema) {
      RegisterSchema(ParseSchema(fields), where, record_position);
    } else {
      RegisterChannel(ParseChannel(fields), where, record_position);
    }
  }

  void Open();
  void ReadHeader(uint64_t limit, bool complete);
  bool TryIndexed(uint64_t footer_offset);
  void Scan(bool complete, uint64_t limit);
  // Reads, checks and decompresses the chunk record at block.offset into `out`. `block` may come
  // from a chunk index (its fields are then checked against the record) or from the scan.
  void LoadChunk(const Block& block, ByteBuffer& out, ChunkHeader* header_out);
  // Walks a chunk's records: registers schemas and channels, calls on_message(header, record
  // position, data size) for every message (after checking its time against the chunk's).
  template <class OnMessage>
  void WalkChunk(const Block& block, const ChunkHeader& header, std::span<const uint8_t> records,
                 OnMessage&& on_message);
};

namespace {

bool HasMagicAt(const Source& source, uint64_t offset) {
  uint8_t bytes[kMagicSize];
  source.Read(offset, bytes, kMagicSize);
  return std::memcmp(bytes, kMagic, kMagicSize) == 0;
}

}  // namespace

void McapReader::Impl::Open() {
  const uint64_t size = source->size();
  report.file_bytes = size;
  if (size < kMagicSize) {
    FailAt(0, "file of " + std::to_string(size) + " bytes is too short for the MCAP magic");
  }
  if (!HasMagicAt(*source, 0)) FailAt(0, "bad magic (not an MCAP file)");
  data_start = kMagicSize;

  // A complete file ends in Footer + magic (and is long enough to hold a Header too).
  const uint64_t minimum_complete =
      kMagicSize + kRecordPrefixSize + 8 + kFooterRecordSize + kMagicSize;
  bool complete = false;
  uint64_t footer_offset = 0;
  if (size >= minimum_complete && HasMagicAt(*source, size - kMagicSize)) {
    footer_offset = size - kMagicSize - kFooterRecordSize;
    uint8_t prefix[kRecordPrefixSize];
    source->Read(footer_offset, prefix, kRecordPrefixSize);
    complete = prefix[0] == kOpFooter && Load<uint64_t>(prefix + 1) == kFooterBodySize;
  }

  ReadHeader(complete ? footer_offset : size, complete);
  if (data_start == 0) return;  // cut inside the Header record: nothing to recover

  if (complete && !options.force_scan && TryIndexed(footer_offset)) return;
  Scan(complete, complete ? footer_offset : size);
}

void McapReader::Impl::ReadHeader(uint64_t limit, bool complete) {
  const uint64_t at = kMagicSize;
  auto truncated_header = [&](const std::string& detail) {
    report.truncated = true;
    report.valid_bytes = kMagicSize;
    report.detail = detail;
    data_start = 0;
  };
  if (limit - at < kRecordPrefixSize) {
    if (complete) FailAt(at, "no room for the Header record");
    truncated_header("file ends inside the Header record at offset 8");
    return;
  }
  uint8_t prefix[kRecordPrefixSize];
  source->Read(at, prefix, kRecordPrefixSize);
  if (prefix[0] != kOpHeader) {
    FailAt(at, "expected a Header record (opcode 0x01), found " + OpcodeName(prefix[0]));
  }
  const uint64_t length = Load<uint64_t>(prefix + 1);
  if (length > limit - at - kRecordPrefixSize) {
    if (complete) {
      FailAt(at, "Header record length " + std::to_string(length) + " runs past the data section");
    }
    truncated_header("file ends inside the Header record at offset 8");
    return;
  }
  const std::vector<uint8_t> body = ReadBytes(at + kRecordPrefixSize, length);
  Parser parser(body, Where{&path, at + kRecordPrefixSize, false}, 0, "Header record");
  profile = parser.String("profile");
  library = parser.String("library");
  data_start = at + kRecordPrefixSize + length;
}

bool McapReader::Impl::TryIndexed(uint64_t footer_offset) {
  uint8_t footer[kFooterBodySize];
  source->Read(footer_offset + kRecordPrefixSize, footer, kFooterBodySize);
  const uint64_t summary_start = Load<uint64_t>(footer);
  const uint64_t summary_offset_start = Load<uint64_t>(footer + 8);
  const uint32_t summary_crc = Load<uint32_t>(footer + 16);
  const uint64_t footer_fields = footer_offset + kRecordPrefixSize;
  if (summary_start == 0) return false;  // no summary: scan
  if (summary_start < data_start || summary_start > footer_offset) {
    FailAt(footer_fields, "Footer: summary_start " + std::to_string(summary_start) +
                              " outside the file's data (" + std::to_string(data_start) + ".." +
                              std::to_string(footer_offset) + ")");
  }
  if (summary_offset_start != 0 &&
      (summary_offset_start < summary_start || summary_offset_start > footer_offset)) {
    FailAt(footer_fields + 8, "Footer: summary_offset_start " +
                                  std::to_string(summary_offset_start) + " outside the summary (" +
                                  std::to_string(summary_start) + ".." +
                                  std::to_string(footer_offset) + ")");
  }

  // The summary, summary offsets and the footer fields before the CRC.
  const std::vector<uint8_t> summary =
      ReadBytes(summary_start, footer_offset - summary_start + kRecordPrefixSize + 16);
  if (options.verify_crcs && summary_crc != 0) {
    const uint32_t computed = Crc32(summary.data(), summary.size());
    if (computed != summary_crc) {
      FailAt(footer_fields + 16, "Footer: summary CRC mismatch (stored " + Hex32(summary_crc) +
                                     ", computed " + Hex32(computed) + ")");
    }
  }

  const uint64_t summary_end = summary_offset_start != 0 ? summary_offset_start : footer_offset;
  const std::span<const uint8_t> records(summary.data(), summary_end - summary_start);
  const Where where{&path, summary_start, false};
  std::vector<ChunkIndexRecord> chunk_indexes;
  std::vector<MetadataIndexRecord> metadata_indexes;
  std::vector<std::pair<Channel, size_t>> summary_channels;
  bool has_statistics = false;
  Statistics summary_statistics;
  size_t position = 0;
  while (position < records.size()) {
    const auto [opcode, body] =
        NextRecord(records, position, where, "summary ends inside a record prefix", "summary");
    const uint64_t length = body.size();
    Parser parser(body, where, 0, OpcodeName(opcode) + " record", position + kRecordPrefixSize);
    switch (opcode) {
      case kOpSchema:
        RegisterSchema(ParseSchema(parser), where, position);
        break;
      case kOpChannel:  // registered after the loop: the summary may list schemas later
        summary_channels.emplace_back(ParseChannel(parser), position);
        break;
      case kOpChunkIndex:
        chunk_indexes.push_back(ParseChunkIndex(parser));
        break;
      case kOpMetadataIndex:
        metadata_indexes.push_back(ParseMetadataIndex(parser));
        break;
      case kOpStatistics:
        if (has_statistics) Fail(where, position, "second Statistics record in the summary");
        summary_statistics = ParseStatistics(parser);
        has_statistics = true;
        break;
      case kOpHeader:
      case kOpFooter:
      case kOpMessage:
      case kOpChunk:
      case kOpDataEnd:
        Fail(where, position, OpcodeName(opcode) + " record inside the summary");
      default:
        break;  // attachment indexes and unknown records are not needed
    }
    position += kRecordPrefixSize + length;
  }
  for (auto& [channel, at] : summary_channels) RegisterChannel(std::move(channel), where, at);

  // Without statistics (or with chunks the indexes do not cover) the data section is scanned.
  if (!has_statistics) return false;
  if (summary_statistics.chunk_count != chunk_indexes.size()) return false;
  if (chunk_indexes.empty() && summary_statistics.message_count > 0) return false;

  for (size_t i = 0; i < chunk_indexes.size(); ++i) {
    const ChunkIndexRecord& index = chunk_indexes[i];
    const std::string name = "ChunkIndex " + std::to_string(i) + ": ";
    if (index.chunk_start_offset < data_start || index.chunk_start_offset > summary_start ||
        index.chunk_length < kRecordPrefixSize ||
        index.chunk_length > summary_start - index.chunk_start_offset) {
      FailAt(summary_start, name + "chunk at offset " + std::to_string(index.chunk_start_offset) +
                                " with length " + std::to_string(index.chunk_length) +
                                " lies outside the data section (" + std::to_string(data_start) +
                                ".." + std::to_string(summary_start) + ")");
    }
    Block block;
    block.offset = index.chunk_start_offset;
    block.length = index.chunk_length;
    block.start_time = index.message_start_time;
    block.end_time = index.message_end_time;
    block.is_chunk = true;
    block.from_index = true;
    try {
      block.compression = CompressionFromName(index.compression);
    } catch (const LogError& error) {
      FailAt(summary_start, name + error.what());
    }
    if (index.uncompressed_size > options.max_chunk_bytes) {
      FailAt(summary_start, name + "uncompressed size " + std::to_string(index.uncompressed_size) +
                                " exceeds the limit of " + std::to_string(options.max_chunk_bytes) +
                                " bytes");
    }
    if (index.message_start_time > index.message_end_time) {
      FailAt(summary_start, name + "message_start_time after message_end_time");
    }
    block.compressed_size = index.compressed_size;
    block.uncompressed_size = index.uncompressed_size;
    for (const auto& entry : index.message_index_offsets) block.channels.push_back(entry.first);
    blocks.push_back(std::move(block));
  }

  for (const MetadataIndexRecord& index : metadata_indexes) {
    if (index.offset < data_start || index.offset > summary_start ||
        index.length < kRecordPrefixSize || index.length > summary_start - index.offset) {
      FailAt(summary_start, "MetadataIndex '" + index.name + "': record at offset " +
                                std::to_string(index.offset) + " with length " +
                                std::to_string(index.length) + " lies outside the data section");
    }
    const std::vector<uint8_t> record = ReadBytes(index.offset, index.length);
    if (record[0] != kOpMetadata || Load<uint64_t>(record.data() + 1) != index.length - 9) {
      FailAt(index.offset, "MetadataIndex '" + index.name +
                               "' does not point at a Metadata record of its length");
    }
    Parser parser(std::span<const uint8_t>(record).subspan(kRecordPrefixSize),
                  Where{&path, index.offset + kRecordPrefixSize, false}, 0, "Metadata record");
    metadata.push_back(ParseMetadata(parser));
  }

  statistics = summary_statistics;
  report.indexed = true;
  report.valid_bytes = report.file_bytes;
  report.messages = statistics.message_count;
  report.chunks = blocks.size();
  return true;
}

void McapReader::Impl::LoadChunk(const Block& block, ByteBuffer& out, ChunkHeader* header_out) {
  // Fixed fields and the compression string's length, then the string and records length.
  constexpr uint64_t kFixed = kRecordPrefixSize + 8 + 8 + 8 + 4 + 4;
  constexpr uint64_t kMaxCompressionName = 64;
  if (block.length < kFixed + 8) {
    FailAt(block.offset, "Chunk record of " + std::to_string(block.length) +
                             " bytes is too short for its fields");
  }
  const uint64_t head_size = std::min<uint64_t>(block.length, kFixed + kMaxCompressionName + 8);
  const std::vector<uint8_t> head = ReadBytes(block.offset, head_size);
  if (head[0] != kOpChunk) {
    FailAt(block.offset, "expected a Chunk record, found " + OpcodeName(head[0]));
  }
  if (Load<uint64_t>(head.data() + 1) != block.length - kRecordPrefixSize) {
    FailAt(block.offset, "Chunk record length " + std::to_string(Load<uint64_t>(head.data() + 1)) +
                             " does not match its ChunkIndex (" +
                             std::to_string(block.length - kRecordPrefixSize) + ")");
  }
  Parser parser(std::span<const uint8_t>(head).subspan(kRecordPrefixSize),
                Where{&path, block.offset + kRecordPrefixSize, false}, 0, "Chunk record");
  ChunkHeader header = ParseChunkHeader(parser);
  const uint64_t records_at = kRecordPrefixSize + header.records_offset;  // from the opcode
  if (header.records_size != block.length - records_at) {
    FailAt(block.offset, "Chunk record: records length " + std::to_string(header.records_size) +
                             " does not match the record length (" +
                             std::to_string(block.length - records_at) + " bytes of records)");
  }
  Compression compression = Compression::kNone;
  try {
    compression = CompressionFromName(header.compression);
  } catch (const LogError& error) {
    FailAt(block.offset, std::string("Chunk record: ") + error.what());
  }
  if (header.message_start_time > header.message_end_time) {
    FailAt(block.offset, "Chunk record: message_start_time " +
                             std::to_string(header.message_start_time) +
                             " after message_end_time " + std::to_string(header.message_end_time));
  }
  if (header.uncompressed_size > options.max_chunk_bytes) {
    FailAt(block.offset, "Chunk record: uncompressed size " +
                             std::to_string(header.uncompressed_size) + " exceeds the limit of " +
                             std::to_string(options.max_chunk_bytes) + " bytes");
  }
  if (compression == Compression::kNone && header.records_size != header.uncompressed_size) {
    FailAt(block.offset, "Chunk record: uncompressed chunk with " +
                             std::to_string(header.records_size) + " bytes of records declares " +
                             std::to_string(header.uncompressed_size));
  }
  if (block.from_index &&
      (header.message_start_time != block.start_time || header.message_end_time != block.end_time ||
       compression != block.compression || header.records_size != block.compressed_size ||
       header.uncompressed_size != block.uncompressed_size)) {
    FailAt(block.offset,
           "Chunk record does not match its ChunkIndex (times, compression or sizes)");
  }

  out.Resize(header.uncompressed_size);
  if (compression == Compression::kNone) {
    source->Read(block.offset + records_at, out.data(), header.records_size);
  } else {
    compressed.Resize(header.records_size);
    source->Read(block.offset + records_at, compressed.data(), header.records_size);
    const std::string problem = decompressor.Decompress(compression, compressed.span(),
                                                        std::span<uint8_t>(out.data(), out.size()));
    if (!problem.empty()) FailAt(block.offset, "Chunk record: " + problem);
  }
  if (options.verify_crcs && header.uncompressed_crc != 0) {
    const uint32_t computed = Crc32(out.data(), out.size());
    if (computed != header.uncompressed_crc) {
      FailAt(block.offset, "Chunk record: CRC mismatch (stored " + Hex32(header.uncompressed_crc) +
                               ", computed " + Hex32(computed) + ")");
    }
  }
  if (header_out != nullptr) *header_out = std::move(header);
}

template <class OnMessage>
void McapReader::Impl::WalkChunk(const Block& block, const ChunkHeader& header,
                                 std::span<const uint8_t> records, OnMessage&& on_message) {
  const Where where{&path, block.offset, true};
  size_t position = 0;
  while (position < records.size()) {
    const auto [opcode, body] =
        NextRecord(records, position, where, "chunk records end inside a record prefix", "chunk");
    const uint64_t length = body.size();
    switch (opcode) {
      case kOpSchema:
      case kOpChannel:
        RegisterRecord(opcode, body, where, position);
        break;
      case kOpMessage: {
        Parser parser(body, where, 0, "Message record", position + kRecordPrefixSize);
        const MessageHeader message = ParseMessageHeader(parser);
        if (channels.count(message.channel_id) == 0) {
          Fail(where, position,
               "Message record on unknown channel id " + std::to_string(message.channel_id));
        }
        if (message.log_time < header.message_start_time ||
            message.log_time > header.message_end_time) {
          Fail(where, position,
               "Message record log time " + std::to_string(message.log_time) +
                   " outside the chunk's range " + std::to_string(header.message_start_time) +
                   ".." + std::to_string(header.message_end_time));
        }
        on_message(message, position, length - kMessageHeaderSize);
        break;
      }
      case kOpHeader:
      case kOpFooter:
      case kOpChunk:
      case kOpMessageIndex:
      case kOpChunkIndex:
      case kOpAttachment:
      case kOpAttachmentIndex:
      case kOpStatistics:
      case kOpMetadata:
      case kOpMetadataIndex:
      case kOpSummaryOffset:
      case kOpDataEnd:
        Fail(where, position, OpcodeName(opcode) + " record inside a chunk");
      default:
        break;  // unknown (future or private) records are skipped, as the spec asks
    }
    position += kRecordPrefixSize + length;
  }
}

void McapReader::Impl::Scan(bool complete, uint64_t limit) {
  const bool check_crc = options.verify_crcs;
  uint32_t data_crc = 0;
  if (check_crc) {
    const std::vector<uint8_t> start = ReadBytes(0, data_start);
    data_crc = Crc32(start.data(), start.size());
  }
  uint64_t position = data_start;
  report.valid_bytes = position;
  report.truncated = !complete;
  bool data_end_found = false;
  std::vector<uint8_t> record;
  ByteBuffer chunk_records;
  uint64_t message_start = 0;
  uint64_t message_end = 0;
  auto count_message = [&](const MessageHeader& message, uint64_t data_size) {
    if (statistics.message_count == 0) {
      message_start = message.log_time;
      message_end = message.log_time;
    } else {
      message_start = std::min(message_start, message.log_time);
      message_end = std::max(message_end, message.log_time);
    }
    ++statistics.message_count;
    ++statistics.channel_message_counts[message.channel_id];
    report.message_bytes += data_size;
  };

  while (position < limit) {
    const uint64_t left = limit - position;
    if (left < kRecordPrefixSize) {
      if (complete) FailAt(position, "data section ends inside a record prefix");
      report.detail = "file ends inside a record prefix at offset " + std::to_string(position);
      break;
    }
    uint8_t prefix[kRecordPrefixSize];
    source->Read(position, prefix, kRecordPrefixSize);
    const uint8_t opcode = prefix[0];
    const uint64_t length = Load<uint64_t>(prefix + 1);
    if (length > left - kRecordPrefixSize) {
      if (complete) {
        FailAt(position, OpcodeName(opcode) + " record length " + std::to_string(length) +
                             " runs past the data section (" +
                             std::to_string(left - kRecordPrefixSize) + " bytes left)");
      }
      report.detail = "file ends inside a " + OpcodeName(opcode) + " record at offset " +
                      std::to_string(position) + " (record needs " +
                      std::to_string(kRecordPrefixSize + length) + " bytes, " +
                      std::to_string(left) + " present)";
      break;
    }
    const uint64_t record_size = kRecordPrefixSize + length;
    if (opcode == kOpDataEnd) {
      if (length < 4) FailAt(position, "DataEnd record of " + std::to_string(length) + " bytes");
      uint8_t body[4];
      source->Read(position + kRecordPrefixSize, body, 4);
      const uint32_t stored = Load<uint32_t>(body);
      if (check_crc && stored != 0 && stored != data_crc) {
        FailAt(position, "DataEnd: data section CRC mismatch (stored " + Hex32(stored) +
                             ", computed " + Hex32(data_crc) + ")");
      }
      data_end_found = true;
      position += record_size;
      report.valid_bytes = position;
      break;
    }
    if (opcode == kOpHeader) FailAt(position, "second Header record");
    if (opcode == kOpFooter) {
      if (complete) FailAt(position, "Footer record inside the data section");
      report.detail =
          "Footer record at offset " + std::to_string(position) + " without the closing magic";
      break;
    }

    if (opcode == kOpChunk) {
      Block block;
      block.offset = position;
      block.length = record_size;
      block.is_chunk = true;
      ChunkHeader header;
      LoadChunk(block, chunk_records, &header);
      block.start_time = header.message_start_time;
      block.end_time = header.message_end_time;
      block.compression = CompressionFromName(header.compression);
      block.compressed_size = header.records_size;
      block.uncompressed_size = header.uncompressed_size;
      std::vector<bool> seen(65536, false);
      WalkChunk(block, header, chunk_records.span(),
                [&](const MessageHeader& message, size_t, uint64_t data_size) {
                  count_message(message, data_size);
                  if (!seen[message.channel_id]) {
                    seen[message.channel_id] = true;
                    block.channels.push_back(message.channel_id);
                  }
                });
      if (check_crc) {
        // The chunk bytes are read once more for the data section CRC (in pieces).
        uint64_t at = position;
        std::vector<uint8_t> piece;
        while (at < position + record_size) {
          const uint64_t n = std::min<uint64_t>(position + record_size - at, 1 << 20);
          piece.resize(n);
          source->Read(at, piece.data(), n);
          data_crc = Crc32Update(data_crc, piece.data(), n);
          at += n;
        }
      }
      ++statistics.chunk_count;
      blocks.push_back(std::move(block));
      chunk_records.Release();
    } else {
      // Every other record is small or skipped; read it in pieces for the CRC and parse the
      // ones that matter from memory.
      const bool parse = opcode == kOpSchema || opcode == kOpChannel || opcode == kOpMetadata ||
                         opcode == kOpMessage;
      if (parse) {
        record = ReadBytes(position, record_size);
        const auto body = std::span<const uint8_t>(record).subspan(kRecordPrefixSize);
        const Where where{&path, 0, false};
        if (opcode == kOpSchema || opcode == kOpChannel) {
          RegisterRecord(opcode, body, where, position);
        } else if (opcode == kOpMetadata) {
          Parser parser(body, Where{&path, position + kRecordPrefixSize, false}, 0,
                        "Metadata record");
          metadata.push_back(ParseMetadata(parser));
        } else {
          Parser parser(body, Where{&path, position + kRecordPrefixSize, false}, 0,
                        "Message record");
          const MessageHeader message = ParseMessageHeader(parser);
          if (channels.count(message.channel_id) == 0) {
            FailAt(position,
                   "Message record on unknown channel id " + std::to_string(message.channel_id));
          }
          count_message(message, length - kMessageHeaderSize);
          Block block;
          block.offset = position;
          block.length = record_size;
          block.start_time = message.log_time;
          block.end_time = message.log_time;
          block.channels.push_back(message.channel_id);
          blocks.push_back(std::move(block));
        }
        if (check_crc) data_crc = Crc32Update(data_crc, record.data(), record.size());
      } else {
        if (opcode == kOpAttachment) ++statistics.attachment_count;
        if (check_crc) {
          uint64_t at = position;
          std::vector<uint8_t> piece;
          while (at < position + record_size) {
            const uint64_t n = std::min<uint64_t>(position + record_size - at, 1 << 20);
            piece.resize(n);
            source->Read(at, piece.data(), n);
            data_crc = Crc32Update(data_crc, piece.data(), n);
            at += n;
          }
        }
      }
    }
    position += record_size;
    report.valid_bytes = position;
  }

  if (complete && !data_end_found) {
    FailAt(position, "data section ends without a DataEnd record");
  }
  if (!complete && data_end_found) {
    report.detail = "file ends after the data section (summary or footer missing or damaged)";
  }
  if (!complete && report.detail.empty()) {
    report.detail = "file ends after a complete record at offset " + std::to_string(position);
  }
  statistics.message_start_time_ns = message_start;
  statistics.message_end_time_ns = message_end;
  statistics.schema_count = static_cast<uint16_t>(schemas.size());
  statistics.channel_count = static_cast<uint32_t>(channels.size());
  statistics.metadata_count = static_cast<uint32_t>(metadata.size());
  report.messages = statistics.message_count;
  report.chunks = statistics.chunk_count;
}

// ---- McapReader ----

McapReader::McapReader(const std::string& path, const ReaderOptions& options)
    : impl_(std::make_unique<Impl>()) {
  impl_->path = path;
  impl_->options = options;
  impl_->source = std::make_unique<FileSource>(path);
  impl_->Open();
}

McapReader McapReader::FromBuffer(std::string name, std::span<const std::byte> bytes,
                                  const ReaderOptions& options) {
  McapReader reader;
  reader.impl_ = std::make_unique<Impl>();
  reader.impl_->path = std::move(name);
  reader.impl_->options = options;
  reader.impl_->source = std::make_unique<MemorySource>(bytes);
  reader.impl_->Open();
  return reader;
}

McapReader::~McapReader() = default;
McapReader::McapReader(McapReader&&) noexcept = default;
McapReader& McapReader::operator=(McapReader&&) noexcept = default;

const std::string& McapReader::profile() const { return impl_->profile; }
const std::string& McapReader::library() const { return impl_->library; }
const std::map<uint16_t, Schema>& McapReader::schemas() const { return impl_->schemas; }
const std::map<uint16_t, Channel>& McapReader::channels() const { return impl_->channels; }
const Statistics& McapReader::statistics() const { return impl_->statistics; }
const std::vector<Metadata>& McapReader::metadata() const { return impl_->metadata; }
const RecoveryReport& McapReader::recovery() const { return impl_->report; }
const std::string& McapReader::path() const { return impl_->path; }

const Schema* McapReader::FindSchema(uint16_t id) const {
  const auto it = impl_->schemas.find(id);
  return it == impl_->schemas.end() ? nullptr : &it->second;
}

const Channel* McapReader::FindChannel(uint16_t id) const {
  const auto it = impl_->channels.find(id);
  return it == impl_->channels.end() ? nullptr : &it->second;
}

const Channel* McapReader::FindChannelByTopic(std::string_view topic) const {
  for (const auto& [id, channel] : impl_->channels) {
    if (channel.topic == topic) return &channel;
  }
  return nullptr;
}

// ---- MessageCursor ----

struct MessageCursor::State {
  McapReader::Impl* reader = nullptr;
  ReadOptions options;
  std::vector<size_t> order;  // block indices by (start time, offset)
  size_t next = 0;
  // -1 unknown, 0 not wanted, 1 wanted; by channel id.
  std::vector<int8_t> wanted = std::vector<int8_t>(65536, -1);

  struct Entry {
    uint64_t log_time;
    uint64_t block_offset;
    uint64_t position;
    std::shared_ptr<Loaded> loaded;
    bool operator>(const Entry& other) const {
      if (log_time != other.log_time) return log_time > other.log_time;
      if (block_offset != other.block_offset) return block_offset > other.block_offset;
      return position > other.position;
    }
  };
  std::priority_queue<Entry, std::vector<Entry>, std::greater<Entry>> heap;
  std::shared_ptr<Loaded> current;

  bool Wanted(uint16_t channel_id) {
    int8_t& flag = wanted[channel_id];
    if (flag < 0) {
      flag = 1;
      if (!options.topics.empty()) {
        const auto it = reader->channels.find(channel_id);
        flag = it != reader->channels.end() &&
                       std::find(options.topics.begin(), options.topics.end(), it->second.topic) !=
                           options.topics.end()
                   ? 1
                   : 0;
      }
    }
    return flag == 1;
  }

  // end_time_ns is exclusive, except that the maximum means "no upper bound".
  bool BeforeEnd(uint64_t log_time) const {
    return log_time < options.end_time_ns ||
           options.end_time_ns == std::numeric_limits<uint64_t>::max();
  }
  bool InRange(uint64_t log_time) const {
    return log_time >= options.start_time_ns && BeforeEnd(log_time);
  }

  void Load(const Block& block) {
    if (block.end_time < options.start_time_ns || !BeforeEnd(block.start_time)) return;
    if (!block.channels.empty() && !options.topics.empty()) {
      bool any = false;
      for (uint16_t id : block.channels) any = any || Wanted(id);
      if (!any) return;
    }
    auto loaded = std::make_shared<Loaded>();
    loaded->block_offset = block.offset;
    loaded->is_chunk = block.is_chunk;
    if (block.is_chunk) {
      ChunkHeader header;
      reader->LoadChunk(block, loaded->records, &header);
      reader->WalkChunk(block, header, loaded->records.span(),
                        [&](const MessageHeader& message, size_t position, uint64_t) {
                          if (InRange(message.log_time) && Wanted(message.channel_id)) {
                            heap.push(Entry{message.log_time, block.offset, position, loaded});
                          }
                        });
    } else {
      loaded->records.Resize(block.length);
      reader->source->Read(block.offset, loaded->records.data(), block.length);
      const MessageHeader message = LooseHeader(*loaded);
      if (InRange(message.log_time) && Wanted(message.channel_id)) {
        heap.push(Entry{message.log_time, block.offset, 0, loaded});
      }
    }
  }

  MessageHeader LooseHeader(const Loaded& loaded) const {
    Parser parser(loaded.records.span().subspan(kRecordPrefixSize),
                  Where{&reader->path, loaded.block_offset + kRecordPrefixSize, false}, 0,
                  "Message record");
    return ParseMessageHeader(parser);
  }
};

MessageCursor::MessageCursor(std::unique_ptr<State> state) : state_(std::move(state)) {}
MessageCursor::~MessageCursor() = default;
MessageCursor::MessageCursor(MessageCursor&&) noexcept = default;
MessageCursor& MessageCursor::operator=(MessageCursor&&) noexcept = default;

MessageCursor McapReader::Messages(const ReadOptions& options) const {
  auto state = std::make_unique<MessageCursor::State>();
  state->reader = impl_.get();
  state->options = options;
  const std::vector<Block>& blocks = impl_->blocks;
  state->order.resize(blocks.size());
  for (size_t i = 0; i < blocks.size(); ++i) state->order[i] = i;
  std::sort(state->order.begin(), state->order.end(), [&](size_t a, size_t b) {
    if (blocks[a].start_time != blocks[b].start_time) {
      return blocks[a].start_time < blocks[b].start_time;
    }
    return blocks[a].offset < blocks[b].offset;
  });
  return MessageCursor(std::move(state));
}

bool MessageCursor::Next(MessageView& message) {
  State& s = *state_;
  s.current.reset();
  const std::vector<Block>& blocks = s.reader->blocks;
  while (s.next < s.order.size() &&
         (s.heap.empty() || blocks[s.order[s.next]].start_time <= s.heap.top().log_time)) {
    s.Load(blocks[s.order[s.next++]]);
  }
  if (s.heap.empty()) return false;
  State::Entry entry = s.heap.top();
  s.heap.pop();
  const uint8_t* record = entry.loaded->records.data() + entry.position;
  const uint64_t length = Load<uint64_t>(record + 1);
  const uint8_t* body = record + kRecordPrefixSize;
  const uint16_t channel_id = Load<uint16_t>(body);
  const auto channel = s.reader->channels.find(channel_id);
  message.channel = &channel->second;
  message.schema = nullptr;
  if (channel->second.schema_id != 0) {
    message.schema = &s.reader->schemas.find(channel->second.schema_id)->second;
  }
  message.sequence = Load<uint32_t>(body + 2);
  message.log_time_ns = Load<uint64_t>(body + 6);
  message.publish_time_ns = Load<uint64_t>(body + 14);
  message.data = std::span<const std::byte>(
      reinterpret_cast<const std::byte*>(body + kMessageHeaderSize), length - kMessageHeaderSize);
  s.current = std::move(entry.loaded);
  return true;
}

}  // namespace probeless::log
