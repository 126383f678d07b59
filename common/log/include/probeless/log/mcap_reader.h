// McapReader: reads MCAP files, complete or cut short, and iterates their messages in log-time
// order.
//
// Opening a file validates the magic and the Header record, then
// - if the file ends in a valid Footer and closing magic and its summary has ChunkIndex and
//   Statistics records ("indexed" mode): the summary is read (and its CRC checked) and chunks are
//   loaded on demand from the chunk indexes;
// - otherwise (no summary, or the writer was killed: no Footer, possibly a partial last record)
//   the data section is scanned record by record ("scan" mode): every complete chunk is
//   decompressed and CRC-checked once, and every message up to the last complete record is
//   recovered. A file without a valid Footer is reported as truncated().
//
// Corrupt input (bad magic, bad CRCs, lengths past the end or the summary, unknown compression,
// sizes beyond ReaderOptions limits, inconsistent indexes, undecodable chunks) throws LogError with
// one line "<path>: offset <byte offset>: <problem>"; allocations never exceed the input size or
// the ReaderOptions limits.
//
// Thread safety: a reader and its cursors are used by one thread at a time.
#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "probeless/log/mcap.h"

namespace probeless::log {

struct ReaderOptions {
  // Largest uncompressed chunk accepted (protects against absurd sizes in corrupt files).
  uint64_t max_chunk_bytes = uint64_t{1} << 30;
  // Check chunk CRCs when chunks are loaded, the data section CRC when it is scanned and the
  // summary CRC at open (a stored CRC of 0 means "not available" and is never checked).
  bool verify_crcs = true;
  // Scan the data section even if the file has a usable summary (for tests and repair tools).
  bool force_scan = false;
};

// Which messages a cursor returns.
struct ReadOptions {
  // Topics to return; empty = all.
  std::vector<std::string> topics;
  // Log-time range [start_time_ns, end_time_ns) in nanoseconds; the default end (the maximum
  // value) means no upper bound, so messages logged at UINT64_MAX are included too.
  uint64_t start_time_ns = 0;
  uint64_t end_time_ns = std::numeric_limits<uint64_t>::max();
};

// One message returned by a cursor. The pointers and the span stay valid until the cursor's next
// Next() call or its destruction (the channel and schema: as long as the reader).
struct MessageView {
  const Channel* channel = nullptr;  // never null
  const Schema* schema = nullptr;    // null for schemaless channels
  uint32_t sequence = 0;
  uint64_t log_time_ns = 0;
  uint64_t publish_time_ns = 0;
  std::span<const std::byte> data;
};

// What opening the file found. For complete files truncated is false and the counts are those of
// the Statistics record.
struct RecoveryReport {
  bool truncated = false;      // no valid Footer and closing magic: the data section was scanned
  bool indexed = false;        // messages are read through the summary's chunk indexes
  uint64_t file_bytes = 0;     // size of the input
  uint64_t valid_bytes = 0;    // scan mode: end of the last complete record; else file_bytes
  uint64_t messages = 0;       // messages available (recovered, for a truncated file)
  uint64_t message_bytes = 0;  // their payload bytes (scan mode only; 0 in indexed mode)
  uint64_t chunks = 0;         // complete chunks
  std::string detail;          // one line on where a truncated file ends; empty otherwise
};

class MessageCursor;

class McapReader {
 public:
  // Opens and validates `path` (see the file comment). Throws LogError naming the path.
  explicit McapReader(const std::string& path, const ReaderOptions& options = {});
  // Reads an MCAP image held in memory; `name` stands for the path in error messages. The bytes
  // must outlive the reader.
  static McapReader FromBuffer(std::string name, std::span<const std::byte> bytes,
                               const ReaderOptions& options = {});
  ~McapReader();
  McapReader(McapReader&&) noexcept;
  McapReader& operator=(McapReader&&) noexcept;
  McapReader(const McapReader&) = delete;
  McapReader& operator=(const McapReader&) = delete;

  // Header record fields.
  const std::string& profile() const;
  const std::string& library() const;
  // Schemas and channels by id. In indexed mode, schemas and channels first met inside a chunk
  // (files of other writers) are added when that chunk is loaded.
  const std::map<uint16_t, Schema>& schemas() const;
  const std::map<uint16_t, Channel>& channels() const;
  // The schema/channel with this id, or null.
  const Schema* FindSchema(uint16_t id) const;
  const Channel* FindChannel(uint16_t id) const;
  // The first channel with this topic, or null.
  const Channel* FindChannelByTopic(std::string_view topic) const;
  // Statistics record, or the figures counted by the scan.
  const Statistics& statistics() const;
  // Metadata records (read through the summary's metadata indexes or found by the scan).
  const std::vector<Metadata>& metadata() const;
  const RecoveryReport& recovery() const;
  bool truncated() const { return recovery().truncated; }
  const std::string& path() const;

  // A cursor over the messages selected by `options`, in log-time order (ties in file order).
  // The reader must outlive the cursor.
  MessageCursor Messages(const ReadOptions& options = {}) const;

  // Implementation detail (shared with MessageCursor); not part of the API.
  struct Impl;

 private:
  McapReader() = default;
  std::unique_ptr<Impl> impl_;
};

class MessageCursor {
 public:
  ~MessageCursor();
  MessageCursor(MessageCursor&&) noexcept;
  MessageCursor& operator=(MessageCursor&&) noexcept;

  // The next message, or false at the end. Loads (and checks) chunks as needed; throws LogError on
  // corrupt chunks.
  bool Next(MessageView& message);

  // Implementation detail; not part of the API.
  struct State;

 private:
  friend class McapReader;
  explicit MessageCursor(std::unique_ptr<State> state);
  std::unique_ptr<State> state_;
};

}  // namespace probeless::log
