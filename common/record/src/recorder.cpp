#include "probeless/record/recorder.h"

#include <time.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <exception>
#include <map>
#include <mutex>
#include <regex>
#include <set>
#include <thread>
#include <utility>

#include "probeless/bus/bus.h"
#include "probeless/log/cdr.h"
#include "probeless/log/mcap_writer.h"
#include "probeless/log/ros2.h"

namespace probeless::record {
namespace {

using Clock = std::chrono::steady_clock;

// Samples taken from one subscriber before the receive thread looks at the next ready one.
constexpr int kTakeBurst = 8;
// Longest wait on the bus before the receive thread re-checks for Stop().
constexpr std::chrono::milliseconds kStopPollPeriod{20};
// Free conversion buffers kept for reuse (each keeps the capacity of its largest message).
constexpr size_t kMaxFreeBuffers = 32;
// Bytes of a Message record besides its data (opcode, length, channel, sequence, two times).
constexpr uint64_t kMessageRecordOverhead = 1 + 8 + 2 + 4 + 8 + 8;
constexpr uint64_t kMinBufferBytes = 1024 * 1024;

uint64_t RealtimeNs() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<uint64_t>(ts.tv_sec) * 1'000'000'000ull + static_cast<uint64_t>(ts.tv_nsec);
}

std::string HexHash(uint64_t hash) {
  char text[32];
  std::snprintf(text, sizeof(text), "0x%016llx", static_cast<unsigned long long>(hash));
  return text;
}

std::regex CompileRegex(const std::string& pattern, std::string_view option) {
  try {
    return std::regex(pattern, std::regex::ECMAScript);
  } catch (const std::regex_error& e) {
    throw RecordError("invalid " + std::string(option) + " regex '" + pattern + "': " + e.what());
  }
}

void ValidateOptions(const RecorderOptions& o) {
  if (o.output.empty()) throw RecordError("no output given (expected a file name or prefix)");
  if (o.topics.empty() && o.regex.empty() && !o.all) {
    throw RecordError("no topics selected (expected topic names, a regex or all)");
  }
  for (const std::string& topic : o.topics) {
    try {
      bus::ValidateTopicName(topic);
    } catch (const bus::BusError& e) {
      throw RecordError(e.what());
    }
  }
  if (o.queue_depth < 1 || o.queue_depth > bus::kMaxQueueDepth) {
    throw RecordError("queue_depth " + std::to_string(o.queue_depth) +
                      " out of range (expected 1.." + std::to_string(bus::kMaxQueueDepth) + ")");
  }
  if (o.chunk_size == 0) throw RecordError("chunk_size 0 out of range (expected > 0)");
  if (!(o.split_seconds >= 0) || !std::isfinite(o.split_seconds)) {
    throw RecordError("split_seconds " + std::to_string(o.split_seconds) +
                      " out of range (expected >= 0)");
  }
  if (o.buffer_bytes < kMinBufferBytes) {
    throw RecordError("buffer_bytes " + std::to_string(o.buffer_bytes) +
                      " out of range (expected >= " + std::to_string(kMinBufferBytes) + ")");
  }
  if (o.discovery_period <= std::chrono::nanoseconds::zero()) {
    throw RecordError("discovery_period out of range (expected > 0)");
  }
  if (o.flush_period < std::chrono::nanoseconds::zero()) {
    throw RecordError("flush_period out of range (expected >= 0)");
  }
}

}  // namespace

std::string RecordFileName(const RecorderOptions& options, uint64_t index) {
  std::string prefix = options.output;
  if (prefix.size() > 5 && prefix.ends_with(".mcap")) prefix.resize(prefix.size() - 5);
  if (options.split_bytes == 0 && options.split_seconds == 0) return prefix + ".mcap";
  return prefix + "_" + std::to_string(index) + ".mcap";
}

struct Recorder::Impl {
  // One subscribed topic. Set up by the receive thread (or Start), fields as marked.
  struct Topic {
    std::string name;
    bus::TopicType type;
    const log::Ros2Converter* converter = nullptr;  // null: recorded raw
    std::unique_ptr<bus::Subscriber> subscriber;    // receive thread
    size_t stats_index = 0;
    // Set by the receive thread before the first message of the topic is queued (the queue's
    // mutex orders it before the writer's reads).
    std::map<std::string, std::string> metadata;
    bool has_metadata = false;
    bool warned_invalid = false;  // receive thread
    bool warned_drops = false;    // receive thread
    // Writer thread: channel id in the file of index channel_file.
    uint16_t channel_id = 0;
    uint64_t channel_file = UINT64_MAX;
  };

  // One converted message on its way to the writer; reused.
  struct Buffer {
    Topic* topic = nullptr;
    log::CdrWriter cdr;
    std::vector<std::byte> raw;
    bool is_raw = false;
    uint32_t sequence = 0;
    uint64_t log_time_ns = 0;
    uint64_t publish_time_ns = 0;
    std::span<const std::byte> data() const {
      return is_raw ? std::span<const std::byte>(raw) : cdr.data();
    }
  };

  explicit Impl(RecorderOptions o) : options(std::move(o)) {
    ValidateOptions(options);
    if (options.domain.empty()) options.domain = bus::CurrentDomain();
    selected_topics.insert(options.topics.begin(), options.topics.end());
    if (!options.regex.empty()) include = CompileRegex(options.regex, "include");
    if (!options.exclude.empty()) exclude = CompileRegex(options.exclude, "exclude");
  }

  void Log(const std::string& line) {
    if (!options.log) return;
    std::lock_guard lock(log_mutex);
    options.log(line);
  }

  bool Selected(const std::string& topic) const {
    const bool in = options.all || selected_topics.contains(topic) ||
                    (include && std::regex_search(topic, *include));
    return in && !(exclude && std::regex_search(topic, *exclude));
  }

  // --- Files (writer thread after Start) ---------------------------------------------------------

  void OpenFile(uint64_t index) {
    log::WriterOptions w;
    w.chunk_size = options.chunk_size;
    w.compression = options.compression;
    w.write_crcs = options.write_crcs;
    const std::string path = RecordFileName(options, index);
    writer = std::make_unique<log::McapWriter>(path, w);
    file_index = index;
    file_messages = 0;
    open_chunk_bytes = 0;
    last_chunks = 0;
    std::lock_guard lock(stats_mutex);
    stats.files.push_back(path);
    stats.file_bytes = closed_file_bytes + writer->stats().file_bytes;
  }

  void CloseFile() {
    writer->Close();
    closed_file_bytes += writer->stats().file_bytes;
    std::lock_guard lock(stats_mutex);
    stats.file_bytes = closed_file_bytes;
  }

  bool NeedsSplit(const Buffer& b) const {
    if (file_messages == 0) return false;
    if (options.split_bytes != 0) {
      const uint64_t estimate =
          writer->stats().file_bytes + open_chunk_bytes + kMessageRecordOverhead + b.data().size();
      if (estimate > options.split_bytes) return true;
    }
    if (options.split_seconds > 0) {
      const double span_s = static_cast<double>(b.log_time_ns - file_first_log_time_ns) * 1e-9;
      if (b.log_time_ns >= file_first_log_time_ns && span_s >= options.split_seconds) return true;
    }
    return false;
  }

  void WriteOne(const Buffer& b) {
    if (NeedsSplit(b)) {
      CloseFile();
      OpenFile(file_index + 1);
    }
    Topic& t = *b.topic;
    if (t.channel_file != file_index) {
      uint16_t schema = 0;
      if (t.converter != nullptr) {
        schema = writer->AddSchema(t.converter->ros2_type(), log::kSchemaEncodingRos2Msg,
                                   t.converter->schema_text());
      }
      t.channel_id = writer->AddChannel(
          t.name, t.converter != nullptr ? log::kMessageEncodingCdr : kMessageEncodingProbeless,
          schema, t.metadata);
      t.channel_file = file_index;
    }
    const std::span<const std::byte> data = b.data();
    writer->Write(t.channel_id, b.sequence, b.log_time_ns, b.publish_time_ns, data);
    if (file_messages == 0) file_first_log_time_ns = b.log_time_ns;
    ++file_messages;
    ++unflushed_messages;
    const log::WriterStats& ws = writer->stats();
    if (ws.chunks != last_chunks) {
      last_chunks = ws.chunks;
      open_chunk_bytes = 0;
    } else {
      open_chunk_bytes += kMessageRecordOverhead + data.size();
    }
    std::lock_guard lock(stats_mutex);
    TopicStats& s = stats.topics[t.stats_index];
    ++s.written;
    s.bytes += data.size();
    ++stats.written;
    stats.bytes += data.size();
    stats.file_bytes = closed_file_bytes + ws.file_bytes;
  }

  void FlushIfDue() {
    if (options.flush_period == std::chrono::nanoseconds::zero()) return;
    const auto now = Clock::now();
    if (now - last_flush < options.flush_period) return;
    if (unflushed_messages == 0) {  // nothing to flush: the next wake-up is a period away (no spin)
      last_flush = now;
      return;
    }
    writer->Flush();
    last_flush = now;
    unflushed_messages = 0;
    last_chunks = writer->stats().chunks;
    open_chunk_bytes = 0;
  }

  void WriterLoop() {
    last_flush = Clock::now();
    try {
      for (;;) {
        std::unique_ptr<Buffer> b;
        {
          std::unique_lock lock(mutex);
          const auto wake = options.flush_period == std::chrono::nanoseconds::zero()
                                ? Clock::now() + std::chrono::hours(1)
                                : last_flush + options.flush_period;
          queue_cv.wait_until(lock, wake, [&] { return !queue.empty() || input_done; });
          if (queue.empty() && input_done) break;
          if (!queue.empty()) {
            b = std::move(queue.front());
            queue.pop_front();
          }
        }
        if (b) {
          WriteOne(*b);
          std::lock_guard lock(mutex);
          queued_bytes -= b->data().size();
          if (free_buffers.size() < kMaxFreeBuffers) free_buffers.push_back(std::move(b));
          space_cv.notify_one();
        }
        FlushIfDue();
      }
      CloseFile();
    } catch (...) {
      Fail(std::current_exception());
      try {
        writer->Close();
      } catch (...) {
        // The first error is the one reported; closing after it may fail for the same reason.
      }
    }
  }

  // --- Bus side (receive thread after Start)
  // ------------------------------------------------------

  void Discover() {
    for (const bus::TopicSnapshot& s : bus::ListTopics(options.domain)) {
      if (s.type.name.empty() || known_topics.contains(s.topic) || !Selected(s.topic)) continue;
      known_topics.insert(s.topic);
      const log::Ros2Converter* converter = log::FindRos2ConverterByProbelessType(s.type.name);
      if (converter != nullptr && converter->layout_hash() != s.type.layout_hash) {
        Log("warning: " + s.topic + ": type " + s.type.name + " has layout hash " +
            HexHash(s.type.layout_hash) + ", this build converts " +
            HexHash(converter->layout_hash()) + "; recording it raw");
        converter = nullptr;
      }
      if (converter == nullptr && !options.record_raw) {
        Log("warning: skipping " + s.topic + ": type " + s.type.name + " has no ROS 2 conversion");
        continue;
      }
      auto topic = std::make_unique<Topic>();
      topic->name = s.topic;
      topic->type = s.type;
      topic->converter = converter;
      bus::SubscriberOptions so;
      so.queue_depth = options.queue_depth;
      so.receive_history = true;
      so.node_name = options.node_name;
      try {
        topic->subscriber = std::make_unique<bus::Subscriber>(s.topic, s.type, so);
      } catch (const bus::BusError& e) {
        Log(std::string("warning: not recording ") + s.topic + ": " + e.what());
        continue;
      }
      wait_set.Add(*topic->subscriber);
      {
        std::lock_guard lock(stats_mutex);
        topic->stats_index = stats.topics.size();
        TopicStats ts;
        ts.topic = s.topic;
        ts.type = s.type.name;
        ts.encoding = converter != nullptr ? std::string(log::kMessageEncodingCdr)
                                           : std::string(kMessageEncodingProbeless);
        stats.topics.push_back(std::move(ts));
      }
      Log("recording " + s.topic + " (" + s.type.name + " as " +
          (converter != nullptr ? std::string(converter->ros2_type()) + " cdr" : "raw") + ")");
      topics.push_back(std::move(topic));
    }
  }

  // A buffer for the next message, once the budget allows; null if the recording failed.
  std::unique_ptr<Buffer> AcquireBuffer() {
    std::unique_lock lock(mutex);
    space_cv.wait(lock, [&] { return failed.load() || queued_bytes < options.buffer_bytes; });
    if (failed) return nullptr;
    if (free_buffers.empty()) return std::make_unique<Buffer>();
    std::unique_ptr<Buffer> b = std::move(free_buffers.back());
    free_buffers.pop_back();
    return b;
  }

  void Handle(Topic& t, bus::Sample&& sample) {
    const uint64_t log_time = RealtimeNs();
    {
      std::lock_guard lock(stats_mutex);
      ++stats.topics[t.stats_index].received;
    }
    std::unique_ptr<Buffer> b = AcquireBuffer();
    if (!b) return;
    const std::span<const std::byte> message = sample.data();
    try {
      if (t.converter != nullptr) {
        b->cdr.Reset();
        t.converter->Encode(message, b->cdr);
        b->is_raw = false;
      } else {
        b->raw.assign(message.begin(), message.end());
        b->is_raw = true;
      }
      if (!t.has_metadata) {
        if (t.converter != nullptr) {
          t.metadata = t.converter->ChannelMetadata(message);
        } else {
          t.metadata = {{std::string(log::kMetadataProbelessType), t.type.name},
                        {std::string(log::kMetadataLayoutHash), HexHash(t.type.layout_hash)}};
        }
        t.has_metadata = true;
      }
    } catch (const log::LogError& e) {
      {
        std::lock_guard lock(stats_mutex);
        ++stats.topics[t.stats_index].invalid;
      }
      if (!t.warned_invalid) {
        t.warned_invalid = true;
        Log("warning: " + t.name + ": message " + std::to_string(sample.info().sequence) +
            " not recorded: " + e.what() + " (further invalid messages are only counted)");
      }
      std::lock_guard lock(mutex);
      if (free_buffers.size() < kMaxFreeBuffers) free_buffers.push_back(std::move(b));
      return;
    }
    b->topic = &t;
    b->sequence = static_cast<uint32_t>(sample.info().sequence);
    b->log_time_ns = log_time;
    b->publish_time_ns = static_cast<uint64_t>(sample.info().publish_wall_ns);
    sample.Release();
    std::lock_guard lock(mutex);
    queued_bytes += b->data().size();
    queue.push_back(std::move(b));
    queue_cv.notify_one();
  }

  void UpdateDropped() {
    for (auto& t : topics) {
      const uint64_t dropped = t->subscriber->dropped();
      {
        std::lock_guard lock(stats_mutex);
        stats.topics[t->stats_index].dropped = dropped;
      }
      if (dropped > 0 && !t->warned_drops) {
        t->warned_drops = true;
        Log("warning: " + t->name + ": the bus dropped messages (queue depth " +
            std::to_string(options.queue_depth) + " full); see the report at exit");
      }
    }
  }

  // Takes at most `limit` samples of topic i; returns how many were taken.
  int Drain(size_t i, int limit) {
    int taken = 0;
    Topic& t = *topics[i];
    while (taken < limit && !failed) {
      std::optional<bus::Sample> sample = t.subscriber->TryTake();
      if (!sample) break;
      ++taken;
      Handle(t, std::move(*sample));
    }
    return taken;
  }

  void ReceiveLoop() {
    try {
      auto next_discovery = Clock::now() + options.discovery_period;
      while (!stop_requested && !failed) {
        if (Clock::now() >= next_discovery) {
          Discover();
          next_discovery = Clock::now() + options.discovery_period;
        }
        if (topics.empty()) {
          std::unique_lock lock(mutex);
          stop_cv.wait_until(lock, std::min(next_discovery, Clock::now() + kStopPollPeriod),
                             [&] { return stop_requested.load(); });
          continue;
        }
        const auto timeout = std::clamp<std::chrono::nanoseconds>(
            next_discovery - Clock::now(), std::chrono::nanoseconds::zero(), kStopPollPeriod);
        const std::vector<size_t> ready = wait_set.Wait(timeout);
        // Round robin over the ready topics until they are empty, kTakeBurst samples at a time.
        bool more = !ready.empty();
        while (more && !failed) {
          more = false;
          for (size_t i : ready) more |= Drain(i, kTakeBurst) == kTakeBurst;
        }
        UpdateDropped();
      }
      if (!failed) {
        // What was queued when Stop() was called (bounded: a publisher may go on publishing).
        for (size_t i = 0; i < topics.size(); ++i) Drain(i, static_cast<int>(options.queue_depth));
        UpdateDropped();
      }
    } catch (...) {
      Fail(std::current_exception());
    }
    std::lock_guard lock(mutex);
    input_done = true;
    queue_cv.notify_one();
  }

  void Fail(std::exception_ptr e) {
    std::lock_guard lock(mutex);
    if (!error) error = std::move(e);
    failed = true;
    space_cv.notify_all();
    queue_cv.notify_all();
  }

  RecorderOptions options;
  std::set<std::string> selected_topics;
  std::optional<std::regex> include;
  std::optional<std::regex> exclude;
  std::mutex log_mutex;

  // Receive thread (Start before it runs).
  std::set<std::string> known_topics;
  std::vector<std::unique_ptr<Topic>> topics;  // index = WaitSet index
  bus::WaitSet wait_set;

  // Writer thread (Start before it runs).
  std::unique_ptr<log::McapWriter> writer;
  uint64_t file_index = 0;
  uint64_t file_messages = 0;
  uint64_t file_first_log_time_ns = 0;
  uint64_t open_chunk_bytes = 0;
  uint64_t last_chunks = 0;
  uint64_t closed_file_bytes = 0;
  uint64_t unflushed_messages = 0;
  Clock::time_point last_flush;

  // Hand-over between the threads.
  std::mutex mutex;
  std::condition_variable queue_cv;  // writer: a buffer is queued or input is done
  std::condition_variable space_cv;  // receiver: budget freed or failure
  std::condition_variable stop_cv;   // receiver without topics: Stop()
  std::deque<std::unique_ptr<Buffer>> queue;
  std::vector<std::unique_ptr<Buffer>> free_buffers;
  uint64_t queued_bytes = 0;
  bool input_done = false;
  std::atomic<bool> stop_requested{false};
  std::atomic<bool> failed{false};
  std::exception_ptr error;

  mutable std::mutex stats_mutex;
  RecorderStats stats;

  bool started = false;
  bool stopped = false;
  std::thread receive_thread;
  std::thread writer_thread;
};

Recorder::Recorder(RecorderOptions options) : impl_(std::make_unique<Impl>(std::move(options))) {}

Recorder::~Recorder() {
  if (!impl_->started || impl_->stopped) return;
  try {
    Stop();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "[error] [recorder] %s\n", e.what());
  }
}

void Recorder::Start() {
  Impl& d = *impl_;
  if (d.started) throw RecordError("recorder already started");
  d.OpenFile(0);
  d.started = true;
  try {
    d.Discover();
  } catch (...) {
    d.stopped = true;
    d.writer->Close();
    throw;
  }
  d.writer_thread = std::thread([&d] { d.WriterLoop(); });
  d.receive_thread = std::thread([&d] { d.ReceiveLoop(); });
}

RecorderStats Recorder::Stop() {
  Impl& d = *impl_;
  if (!d.started || d.stopped) return Stats();
  {
    std::lock_guard lock(d.mutex);
    d.stop_requested = true;
    d.stop_cv.notify_all();
  }
  d.receive_thread.join();
  d.writer_thread.join();
  d.wait_set = bus::WaitSet();
  for (auto& t : d.topics) t->subscriber.reset();
  d.stopped = true;
  if (d.error) std::rethrow_exception(d.error);
  return Stats();
}

RecorderStats Recorder::Stats() const {
  RecorderStats copy;
  {
    std::lock_guard lock(impl_->stats_mutex);
    copy = impl_->stats;
  }
  std::sort(copy.topics.begin(), copy.topics.end(),
            [](const TopicStats& a, const TopicStats& b) { return a.topic < b.topic; });
  return copy;
}

bool Recorder::Failed() const { return impl_->failed; }

const RecorderOptions& Recorder::options() const { return impl_->options; }

std::string RecorderReport(const RecorderStats& stats) {
  std::string report;
  uint64_t received = 0, dropped = 0;
  for (const TopicStats& t : stats.topics) {
    report += t.topic + ": received=" + std::to_string(t.received) +
              " dropped=" + std::to_string(t.dropped) + " invalid=" + std::to_string(t.invalid) +
              " bytes=" + std::to_string(t.bytes) + "\n";
    received += t.received;
    dropped += t.dropped;
  }
  for (const std::string& file : stats.files) report += "file: " + file + "\n";
  report += "summary: topics=" + std::to_string(stats.topics.size()) +
            " received=" + std::to_string(received) + " dropped=" + std::to_string(dropped) +
            " bytes=" + std::to_string(stats.bytes) +
            " files=" + std::to_string(stats.files.size()) + "\n";
  return report;
}

}  // namespace probeless::record
