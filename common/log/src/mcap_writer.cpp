#include "probeless/log/mcap_writer.h"

#include <errno.h>
#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <limits>
#include <string>
#include <tuple>
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

// The output file: small records are gathered in a buffer, large blocks (chunks) go straight to
// write(2). Keeps the file offset and a running CRC of the bytes since the last ResetCrc().
class FileSink {
 public:
  explicit FileSink(const std::string& path) : path_(path) {
    fd_ = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (fd_ < 0) throw LogError(path + ": cannot create: " + std::strerror(errno));
    buffer_.Reserve(kBufferBytes);
  }
  ~FileSink() {
    if (fd_ >= 0) ::close(fd_);
  }
  FileSink(const FileSink&) = delete;
  FileSink& operator=(const FileSink&) = delete;

  void Write(const void* data, size_t size) {
    if (crc_enabled_) crc_ = Crc32Update(crc_, data, size);
    offset_ += size;
    if (buffer_.size() + size <= kBufferBytes) {
      buffer_.Append(data, size);
      return;
    }
    FlushBuffer();
    if (size >= kBufferBytes / 2) {
      WriteAll(static_cast<const uint8_t*>(data), size);
    } else {
      buffer_.Append(data, size);
    }
  }
  void Write(const std::vector<uint8_t>& bytes) { Write(bytes.data(), bytes.size()); }
  // Write() for bytes whose CRC is already known (saves a pass over them).
  void WriteWithCrc(const void* data, size_t size, uint32_t crc_of_data) {
    const bool enabled = crc_enabled_;
    crc_enabled_ = false;
    Write(data, size);
    crc_enabled_ = enabled;
    if (enabled) crc_ = Crc32Combine(crc_, crc_of_data, size);
  }

  // Hands every buffered byte to the OS.
  void Flush() { FlushBuffer(); }

  void Close() {
    FlushBuffer();
    const int fd = fd_;
    fd_ = -1;
    if (::close(fd) != 0) throw LogError(path_ + ": close failed: " + std::strerror(errno));
  }

  uint64_t offset() const { return offset_; }
  void ResetCrc(bool enabled) {
    crc_ = 0;
    crc_enabled_ = enabled;
  }
  uint32_t crc() const { return crc_; }

 private:
  static constexpr size_t kBufferBytes = 256 * 1024;

  void FlushBuffer() {
    if (buffer_.empty()) return;
    WriteAll(buffer_.data(), buffer_.size());
    buffer_.Clear();
  }

  void WriteAll(const uint8_t* data, size_t size) {
    while (size > 0) {
      const ssize_t written = ::write(fd_, data, size);
      if (written < 0) {
        if (errno == EINTR) continue;
        throw LogError(path_ + ": offset " + std::to_string(written_) +
                       ": write failed: " + std::strerror(errno));
      }
      data += written;
      size -= static_cast<size_t>(written);
      written_ += static_cast<uint64_t>(written);
    }
  }

  std::string path_;
  int fd_ = -1;
  ByteBuffer buffer_;
  uint64_t offset_ = 0;   // bytes accepted by Write
  uint64_t written_ = 0;  // bytes handed to the OS
  uint32_t crc_ = 0;
  bool crc_enabled_ = true;
};

}  // namespace

// Throws LogError unless the options are usable.
const WriterOptions& CheckedOptions(const std::string& path, const WriterOptions& options) {
  if (options.chunk_size == 0) throw LogError(path + ": WriterOptions::chunk_size must be > 0");
  const std::string level_problem =
      CheckCompressionLevel(options.compression, options.compression_level);
  if (!level_problem.empty()) throw LogError(path + ": " + level_problem);
  return options;
}

struct McapWriter::Impl {
  Impl(const std::string& file_path, const WriterOptions& writer_options)
      : path(file_path),
        options(CheckedOptions(file_path, writer_options)),
        compressor(options.compression, options.compression_level),
        sink(file_path) {
    sink.ResetCrc(options.write_crcs);
    sink.Write(kMagic, kMagicSize);
    AppendHeader(scratch, options.profile, kLibraryName);
    WriteScratch();
  }

  std::string path;
  WriterOptions options;
  Compressor compressor;
  FileSink sink;
  bool closed = false;

  // The open chunk.
  ByteBuffer chunk;
  uint32_t chunk_crc = 0;
  uint64_t chunk_start_time = 0;
  uint64_t chunk_end_time = 0;
  uint64_t chunk_messages = 0;
  // Per channel id: (log time, offset in the chunk) of the open chunk's messages.
  std::vector<std::vector<std::pair<uint64_t, uint64_t>>> message_index;
  std::vector<uint16_t> touched_channels;

  std::vector<uint8_t> compressed;
  std::vector<uint8_t> scratch;

  std::vector<Schema> schemas;
  std::vector<Channel> channels;
  std::vector<ChunkIndexRecord> chunk_indexes;
  std::vector<MetadataIndexRecord> metadata_indexes;
  Statistics statistics;
  WriterStats stats;

  void CheckOpen(std::string_view operation) const {
    if (closed) throw LogError(path + ": " + std::string(operation) + " after Close()");
  }

  // Writes `scratch` and clears it.
  void WriteScratch() {
    sink.Write(scratch);
    scratch.clear();
    stats.file_bytes = sink.offset();
  }

  void AppendMessage(uint16_t channel_id, uint32_t sequence, uint64_t log_time,
                     uint64_t publish_time, std::span<const std::byte> data) {
    const uint64_t at = chunk.size();
    const uint64_t record_size = kRecordPrefixSize + kMessageHeaderSize + data.size();
    uint8_t* p = chunk.Extend(record_size);
    p[0] = kOpMessage;
    const uint64_t body_size = kMessageHeaderSize + data.size();
    std::memcpy(p + 1, &body_size, 8);
    std::memcpy(p + 9, &channel_id, 2);
    std::memcpy(p + 11, &sequence, 4);
    std::memcpy(p + 15, &log_time, 8);
    std::memcpy(p + 23, &publish_time, 8);
    if (!data.empty()) std::memcpy(p + 31, data.data(), data.size());
    if (options.write_crcs) chunk_crc = Crc32Update(chunk_crc, p, record_size);

    if (chunk_messages == 0) {
      chunk_start_time = log_time;
      chunk_end_time = log_time;
    } else {
      chunk_start_time = std::min(chunk_start_time, log_time);
      chunk_end_time = std::max(chunk_end_time, log_time);
    }
    ++chunk_messages;
    if (options.write_message_indexes) {
      auto& entries = message_index[channel_id];
      if (entries.empty()) touched_channels.push_back(channel_id);
      entries.emplace_back(log_time, at);
    }

    if (statistics.message_count == 0) {
      statistics.message_start_time_ns = log_time;
      statistics.message_end_time_ns = log_time;
    } else {
      statistics.message_start_time_ns = std::min(statistics.message_start_time_ns, log_time);
      statistics.message_end_time_ns = std::max(statistics.message_end_time_ns, log_time);
    }
    ++statistics.message_count;
    ++statistics.channel_message_counts[channel_id];
    ++stats.messages;
    stats.message_bytes += data.size();
  }

  // Compresses and writes the open chunk and its message indexes (nothing if it is empty), then
  // hands all buffered bytes to the OS.
  void FlushChunk() {
    if (chunk_messages == 0) {
      sink.Flush();
      return;
    }
    std::span<const uint8_t> records = chunk.span();
    if (options.compression != Compression::kNone) {
      compressor.Compress(chunk.span(), compressed);
      records = compressed;
    }
    ChunkHeader header;
    header.message_start_time = chunk_start_time;
    header.message_end_time = chunk_end_time;
    header.uncompressed_size = chunk.size();
    header.uncompressed_crc = options.write_crcs ? chunk_crc : 0;
    header.compression = std::string(CompressionName(options.compression));
    header.records_size = records.size();

    ChunkIndexRecord index;
    index.message_start_time = chunk_start_time;
    index.message_end_time = chunk_end_time;
    index.chunk_start_offset = sink.offset();
    index.compression = header.compression;
    index.compressed_size = records.size();
    index.uncompressed_size = chunk.size();

    AppendChunkHeader(scratch, header);
    WriteScratch();
    if (options.compression == Compression::kNone && options.write_crcs) {
      sink.WriteWithCrc(records.data(), records.size(), chunk_crc);  // chunk CRC = records CRC
    } else {
      sink.Write(records.data(), records.size());
    }
    index.chunk_length = sink.offset() - index.chunk_start_offset;

    const uint64_t message_index_start = sink.offset();
    std::sort(touched_channels.begin(), touched_channels.end());
    for (uint16_t channel_id : touched_channels) {
      auto& entries = message_index[channel_id];
      index.message_index_offsets[channel_id] = message_index_start + scratch.size();
      const size_t begin = BeginRecord(scratch, kOpMessageIndex);
      Put<uint16_t>(scratch, channel_id);
      Put<uint32_t>(scratch, static_cast<uint32_t>(entries.size() * 16));
      for (const auto& [log_time, offset] : entries) {
        Put<uint64_t>(scratch, log_time);
        Put<uint64_t>(scratch, offset);
      }
      EndRecord(scratch, begin);
      entries.clear();
    }
    touched_channels.clear();
    WriteScratch();
    index.message_index_length = sink.offset() - message_index_start;
    if (options.write_chunk_indexes) chunk_indexes.push_back(std::move(index));

    ++statistics.chunk_count;
    ++stats.chunks;
    chunk.Clear();
    chunk_crc = 0;
    chunk_messages = 0;
    sink.Flush();
    stats.file_bytes = sink.offset();
  }

  // Everything after the last chunk: DataEnd, summary, summary offsets, Footer, magic.
  void Finish() {
    FlushChunk();
    AppendDataEnd(scratch, options.write_crcs ? sink.crc() : 0);
    WriteScratch();

    sink.ResetCrc(options.write_crcs);
    const uint64_t summary_start = sink.offset();
    std::vector<std::tuple<uint8_t, uint64_t, uint64_t>> groups;
    auto write_group = [&](uint8_t opcode) {
      if (scratch.empty()) return;
      const uint64_t start = sink.offset();
      const uint64_t length = scratch.size();
      WriteScratch();
      groups.emplace_back(opcode, start, length);
    };
    for (const Schema& schema : schemas) AppendSchema(scratch, schema);
    write_group(kOpSchema);
    for (const Channel& channel : channels) AppendChannel(scratch, channel);
    write_group(kOpChannel);
    if (options.write_statistics) {
      statistics.schema_count = static_cast<uint16_t>(schemas.size());
      statistics.channel_count = static_cast<uint32_t>(channels.size());
      statistics.metadata_count = static_cast<uint32_t>(metadata_indexes.size());
      AppendStatistics(scratch, statistics);
      write_group(kOpStatistics);
    }
    for (const ChunkIndexRecord& index : chunk_indexes) AppendChunkIndex(scratch, index);
    write_group(kOpChunkIndex);
    for (const MetadataIndexRecord& index : metadata_indexes) AppendMetadataIndex(scratch, index);
    write_group(kOpMetadataIndex);

    uint64_t summary_offset_start = 0;
    if (options.write_summary_offsets && !groups.empty()) {
      summary_offset_start = sink.offset();
      for (const auto& [opcode, start, length] : groups) {
        AppendSummaryOffset(scratch, opcode, start, length);
      }
      WriteScratch();
    }
    const bool has_summary = !groups.empty();
    AppendFooter(scratch, has_summary ? summary_start : 0, summary_offset_start, 0);
    if (has_summary && options.write_crcs) {
      const uint32_t crc = Crc32Update(sink.crc(), scratch.data(), scratch.size() - 4);
      PutAt<uint32_t>(scratch, scratch.size() - 4, crc);
    }
    PutBytes(scratch, kMagic, kMagicSize);
    WriteScratch();
    sink.Close();
  }
};

McapWriter::McapWriter(const std::string& path, const WriterOptions& options)
    : impl_(std::make_unique<Impl>(path, options)) {}

McapWriter::~McapWriter() {
  if (impl_ == nullptr || impl_->closed) return;
  try {
    Close();
  } catch (const std::exception& error) {
    std::fprintf(stderr, "probeless::log::McapWriter: %s\n", error.what());
  }
}

McapWriter::McapWriter(McapWriter&&) noexcept = default;

McapWriter& McapWriter::operator=(McapWriter&& other) noexcept {
  if (this != &other) {
    McapWriter old(std::move(*this));  // finishes the file this writer had
    impl_ = std::move(other.impl_);
  }
  return *this;
}

uint16_t McapWriter::AddSchema(std::string_view name, std::string_view encoding,
                               std::string_view data) {
  Impl& w = *impl_;
  w.CheckOpen("AddSchema");
  for (const Schema& schema : w.schemas) {
    if (schema.name == name && schema.encoding == encoding && schema.data == data) {
      return schema.id;
    }
  }
  if (w.schemas.size() >= std::numeric_limits<uint16_t>::max()) {
    throw LogError(w.path + ": too many schemas (at most 65535)");
  }
  Schema schema;
  schema.id = static_cast<uint16_t>(w.schemas.size() + 1);
  schema.name = std::string(name);
  schema.encoding = std::string(encoding);
  schema.data = std::string(data);
  AppendSchema(w.scratch, schema);
  w.WriteScratch();
  w.schemas.push_back(std::move(schema));
  return w.schemas.back().id;
}

uint16_t McapWriter::AddChannel(std::string_view topic, std::string_view message_encoding,
                                uint16_t schema_id,
                                const std::map<std::string, std::string>& metadata) {
  Impl& w = *impl_;
  w.CheckOpen("AddChannel");
  if (topic.empty()) throw LogError(w.path + ": AddChannel: empty topic");
  if (schema_id > w.schemas.size()) {
    throw LogError(w.path + ": AddChannel '" + std::string(topic) + "': unknown schema id " +
                   std::to_string(schema_id));
  }
  if (w.channels.size() >= std::numeric_limits<uint16_t>::max()) {
    throw LogError(w.path + ": too many channels (at most 65535)");
  }
  Channel channel;
  channel.id = static_cast<uint16_t>(w.channels.size() + 1);
  channel.schema_id = schema_id;
  channel.topic = std::string(topic);
  channel.message_encoding = std::string(message_encoding);
  channel.metadata = metadata;
  AppendChannel(w.scratch, channel);
  w.WriteScratch();
  w.channels.push_back(std::move(channel));
  w.message_index.resize(w.channels.size() + 1);
  return w.channels.back().id;
}

void McapWriter::Write(uint16_t channel_id, uint32_t sequence, uint64_t log_time_ns,
                       uint64_t publish_time_ns, std::span<const std::byte> data) {
  Impl& w = *impl_;
  w.CheckOpen("Write");
  if (channel_id == 0 || channel_id > w.channels.size()) {
    throw LogError(w.path + ": Write to unknown channel id " + std::to_string(channel_id));
  }
  w.AppendMessage(channel_id, sequence, log_time_ns, publish_time_ns, data);
  if (w.chunk.size() >= w.options.chunk_size) w.FlushChunk();
}

void McapWriter::AddMetadata(std::string_view name,
                             const std::map<std::string, std::string>& entries) {
  Impl& w = *impl_;
  w.CheckOpen("AddMetadata");
  MetadataIndexRecord index;
  index.offset = w.sink.offset();
  index.name = std::string(name);
  AppendMetadata(w.scratch, Metadata{std::string(name), entries});
  index.length = w.scratch.size();
  w.WriteScratch();
  w.metadata_indexes.push_back(std::move(index));
}

void McapWriter::Flush() {
  impl_->CheckOpen("Flush");
  impl_->FlushChunk();
}

void McapWriter::Close() {
  if (impl_ == nullptr || impl_->closed) return;
  impl_->closed = true;  // no second attempt on a half-written file
  impl_->Finish();
}

const WriterStats& McapWriter::stats() const { return impl_->stats; }
const std::string& McapWriter::path() const { return impl_->path; }

}  // namespace probeless::log
