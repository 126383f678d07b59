// Recorder: records bus topics into MCAP files (the library behind nodes/recorder and
// "probeless bag record").
//
// Pipeline (two threads per Recorder):
// - The receive thread discovers topics (bus::ListTopics every discovery_period), subscribes to
//   the selected ones (queue depth queue_depth), takes their samples zero-copy, stamps them
//   (log time = CLOCK_REALTIME at take), converts them to ROS 2 CDR (log::Ros2Converter) into a
//   pooled buffer and releases the bus slot at once. At most buffer_bytes of converted messages
//   wait for the writer; when that budget is used up the receive thread waits, the bus queues
//   fill and the bus drops their oldest entries (counted per topic, never blocking publishers).
// - The writer thread appends the buffers to log::McapWriter (chunking, CRCs, compression,
//   write(2)), rolls files by size or duration and flushes the open chunk every flush_period.
//
// Per message: one copy into the CDR buffer (receive thread), one into the chunk plus CRC and
// compression (writer thread), so the two halves run on two cores.
//
// Files: without splitting one file, `output` (".mcap" appended unless present); with
// split_bytes or split_seconds, "<prefix>_0.mcap", "<prefix>_1.mcap", ... where prefix is
// `output` without a trailing ".mcap". Each file is complete on its own (schemas and channels are
// repeated), so the union of the files is the whole recording.
//
// Channels: a topic whose type has a ROS 2 converter is recorded with schema encoding "ros2msg",
// message encoding "cdr" and the converter's ChannelMetadata of its first message; any other type
// is recorded raw (the bus bytes as is: struct then payload) on a schemaless channel (schema id 0)
// with message encoding "probeless" and metadata probeless.type / probeless.layout_hash, unless
// record_raw is false (then it is skipped with a warning). A Message record's sequence is the bus
// sequence (truncated to 32 bits), log time the receive time, publish time the bus publish wall
// time (CLOCK_REALTIME ns).
//
// Errors: bad options throw RecordError from the constructor; an output file that cannot be
// created throws log::LogError from Start(). A failure while recording (disk full, write error)
// stops both threads; Failed() turns true and Stop() rethrows it. A message that fails its
// type's validation is not recorded: it is counted in TopicStats::invalid and warned about once
// per topic.
//
// Thread safety: Start, Stop and the destructor from one thread; Stats, Failed and files may be
// called from any thread at any time.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "probeless/error/error.h"
#include "probeless/log/mcap.h"

namespace probeless::record {

// Bad recorder options; what() is one line naming the option and what was expected.
class RecordError : public InputError {
 public:
  using InputError::InputError;
};

// Message encoding of channels recorded raw (types without a ROS 2 converter).
inline constexpr std::string_view kMessageEncodingProbeless = "probeless";

struct RecorderOptions {
  // Selection: a topic is recorded if it is in `topics`, or matches `regex` (std::regex_search,
  // ECMAScript), or `all` is set — and does not match `exclude` (regex_search). At least one of
  // topics, regex and all must be given. Topic names must be absolute bus names.
  std::vector<std::string> topics;
  std::string regex;
  bool all = false;
  std::string exclude;

  // Output file (no split) or file prefix (split); required. Parent directories must exist.
  std::string output;
  // Start a new file once the current one reaches this many bytes (0 = no size split). Files
  // exceed it by at most one message plus the summary.
  uint64_t split_bytes = 0;
  // Start a new file once the current one spans this many seconds of log time (0 = no split).
  double split_seconds = 0;

  log::Compression compression = log::Compression::kNone;
  // Uncompressed chunk size in bytes (see log::WriterOptions::chunk_size); > 0.
  uint64_t chunk_size = 8 * 1024 * 1024;
  // CRC-32 of chunks, data section and summary (log::WriterOptions::write_crcs).
  bool write_crcs = true;

  // Bus queue depth per topic, 1..bus::kMaxQueueDepth. Deep, so bursts wait on the bus.
  uint32_t queue_depth = 64;
  // Converted messages waiting for the writer thread, in bytes (>= 1 MiB).
  uint64_t buffer_bytes = 256ull * 1024 * 1024;
  // How often the bus is scanned for new topics (> 0).
  std::chrono::nanoseconds discovery_period = std::chrono::milliseconds(250);
  // Longest time a written message stays in the open chunk (0 = only when the chunk is full).
  std::chrono::nanoseconds flush_period = std::chrono::seconds(1);
  // Record types without a ROS 2 converter raw (true) or skip them with a warning (false).
  bool record_raw = true;

  // Bus domain to record (default: this process's, $PROBELESS_DOMAIN).
  std::string domain;
  // Node name shown by bus introspection for the recorder's subscribers.
  std::string node_name = "recorder";
  // Receives warnings and notices (one line, no newline), e.g. "subscribed to /a
  // (probeless_msgs/Image as sensor_msgs/msg/Image)". Called from the recorder's threads, one
  // call at a time. Null: discarded.
  std::function<void(std::string_view line)> log;
};

// Per-topic figures.
struct TopicStats {
  std::string topic;
  std::string type;       // probeless type name
  std::string encoding;   // "cdr" or "probeless" (raw)
  uint64_t received = 0;  // samples taken from the bus
  uint64_t dropped = 0;   // lost in the bus queue before being taken (Subscriber::dropped)
  uint64_t invalid = 0;   // taken but not recorded: failed conversion/validation
  uint64_t written = 0;   // messages written to files
  uint64_t bytes = 0;     // their bytes as written (CDR or raw)
};

struct RecorderStats {
  std::vector<TopicStats> topics;  // subscribed topics, sorted by name
  std::vector<std::string> files;  // files opened so far, in order
  uint64_t written = 0;            // messages written (all topics)
  uint64_t bytes = 0;              // their bytes
  uint64_t file_bytes = 0;         // bytes handed to the files so far (all files)
};

// Parses RecorderOptions::output and the split settings into the file name of `index`:
// "<output>[.mcap]" when not splitting, else "<prefix>_<index>.mcap".
std::string RecordFileName(const RecorderOptions& options, uint64_t index);

// The report the recorder node prints at exit: one line per topic
// "<topic>: received=N dropped=D invalid=I bytes=B", then "file: <path>" per file, then
// "summary: topics=T received=N dropped=D bytes=B files=F" (received and dropped summed over the
// topics, bytes = stats.bytes). Every line ends in '\n'.
std::string RecorderReport(const RecorderStats& stats);

class Recorder {
 public:
  // Checks the options (RecordError on a missing output, no selection, an invalid topic name or
  // regex, or a value out of range). Records nothing before Start().
  explicit Recorder(RecorderOptions options);
  // Stops (like Stop) if running; errors go to stderr as one line.
  ~Recorder();
  Recorder(const Recorder&) = delete;
  Recorder& operator=(const Recorder&) = delete;

  // Opens the first file, discovers and subscribes to the topics that exist now, and starts the
  // threads. Throws log::LogError if the file cannot be created, RecordError if called twice.
  void Start();
  // Takes what is still queued on the bus, writes every pending message, closes the file (footer
  // written) and unsubscribes; returns the final figures. Idempotent. Rethrows the error that
  // stopped a failed recording.
  RecorderStats Stop();
  // Current figures (a consistent copy).
  RecorderStats Stats() const;
  // True once a recording error stopped the threads (Stop() rethrows it).
  bool Failed() const;

  // The options as given, with `domain` filled in.
  const RecorderOptions& options() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace probeless::record
