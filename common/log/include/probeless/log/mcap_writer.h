// McapWriter: streams messages into an MCAP file, chunk by chunk.
//
// Messages are appended to an in-memory chunk; when the chunk's uncompressed records reach
// WriterOptions::chunk_size bytes it is compressed and written to the file together with its
// MessageIndex records, and the file descriptor is handed the bytes at once. Nothing else is
// buffered (apart from the summary: a few dozen bytes per chunk, schema and channel), so a writer
// killed at any moment leaves a file whose complete chunks McapReader recovers.
//
// Thread safety: one thread at a time per writer.
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <string_view>

#include "probeless/log/mcap.h"

namespace probeless::log {

struct WriterOptions {
  // Uncompressed bytes of records after which the open chunk is closed and written. A message
  // larger than this gets a chunk of its own (chunks are never split).
  uint64_t chunk_size = 4 * 1024 * 1024;
  Compression compression = Compression::kZstd;
  // Compression level: 0 = the library's fast default (zstd level 1, lz4 fast mode); otherwise
  // zstd 1..19 or lz4 high-compression 1..12.
  int compression_level = 0;
  // Header record profile ("ros2" for CDR messages with ros2msg schemas, "" for none).
  std::string profile = std::string(kProfileRos2);
  // MessageIndex records after every chunk (let readers seek to single messages).
  bool write_message_indexes = true;
  // ChunkIndex records in the summary (let readers find chunks without scanning the file).
  bool write_chunk_indexes = true;
  // A Statistics record in the summary.
  bool write_statistics = true;
  // SummaryOffset records after the summary (one per summary group).
  bool write_summary_offsets = true;
  // CRC-32 of every chunk's uncompressed records, of the data section (DataEnd) and of the
  // summary (Footer). false writes 0 ("not available") and saves the CPU.
  bool write_crcs = true;
};

// Bytes and counts written so far.
struct WriterStats {
  uint64_t messages = 0;       // messages accepted by Write
  uint64_t message_bytes = 0;  // their payload bytes
  uint64_t chunks = 0;         // chunks written to the file
  uint64_t file_bytes = 0;     // bytes handed to the file so far
};

class McapWriter {
 public:
  // Creates (or truncates) `path` (mode 0644) and writes the magic and the Header record. Throws
  // LogError naming the path if it cannot be created, or if options.chunk_size is 0 or the
  // compression level is out of range.
  McapWriter(const std::string& path, const WriterOptions& options = {});
  // Finishes the file like Close() if that was not called. Errors cannot propagate from a
  // destructor: they are printed to stderr (one line); call Close() to get them as LogError.
  ~McapWriter();
  McapWriter(McapWriter&&) noexcept;
  McapWriter& operator=(McapWriter&&) noexcept;
  McapWriter(const McapWriter&) = delete;
  McapWriter& operator=(const McapWriter&) = delete;

  // Adds a Schema record (written at once, outside chunks) and returns its id (1, 2, ...). Adding
  // a schema identical to an earlier one (name, encoding and data) returns the earlier id. Throws
  // LogError after 65535 schemas or after Close().
  uint16_t AddSchema(std::string_view name, std::string_view encoding, std::string_view data);
  // Adds a Channel record (written at once) and returns its id (1, 2, ...). schema_id is 0 for
  // schemaless channels or an id returned by AddSchema. Throws LogError for an unknown schema id,
  // an empty topic, after 65535 channels or after Close().
  uint16_t AddChannel(std::string_view topic, std::string_view message_encoding, uint16_t schema_id,
                      const std::map<std::string, std::string>& metadata = {});
  // Appends one Message record to the open chunk. Times are nanoseconds (log time: when it was
  // recorded, the order readers iterate in; publish time: when it was published). Messages need
  // not be in time order. Throws LogError for an unknown channel, after Close(), or if writing a
  // full chunk fails.
  void Write(uint16_t channel_id, uint32_t sequence, uint64_t log_time_ns, uint64_t publish_time_ns,
             std::span<const std::byte> data);
  // Writes a Metadata record (outside chunks; indexed in the summary). Throws LogError after
  // Close() or on a write error.
  void AddMetadata(std::string_view name, const std::map<std::string, std::string>& entries);
  // Closes the open chunk early and hands every byte written so far to the OS (so a crash of this
  // process loses nothing written before). Throws LogError on a write error.
  void Flush();
  // Writes the last chunk, DataEnd, the summary, SummaryOffsets, the Footer and the closing magic,
  // and closes the file. Idempotent. Throws LogError on a write or close error.
  void Close();

  const WriterStats& stats() const;
  const std::string& path() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace probeless::log
