// record_bench: sustained recording throughput of probeless::record::Recorder.
//
// Publishes N RGB-D streams (per stream one 640x480 rgb8 Image, 921,600 B of pixels, and one
// 640x480 depth16 Image, 614,400 B, per frame) from threads of this process at a paced frame
// rate, records them with the Recorder library into --dir, and reports per row (compression x
// frame rate) the recorded MB/s (10^6 bytes of message data written per second of wall time,
// from the first publish to the closed file), messages published/received/dropped per topic,
// file bytes and the process's CPU use. Frames are synthetic gradients with sensor-like noise
// (fixed seed), 4 distinct frames per stream, copied into each loan as a driver would.
//
// Usage: record_bench [--seconds S] [--streams N] [--fps F] [--max-fps F2] [--dir D]
//                     [--compressions none,lz4,zstd] [--json FILE] [--keep]
// Rows: every compression at --fps (the requirement: 4 streams at 30 fps, zero drops), then at
// --max-fps (headroom; 0 skips). Runs in its own bus domain (record_bench_<pid>) unless
// PROBELESS_DOMAIN is set. Exit status 1 if a file fails to read back completely.
#include <stdlib.h>
#include <sys/resource.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "probeless/bus/bus.h"
#include "probeless/log/mcap_reader.h"
#include "probeless/msgs/image.h"
#include "probeless/node/flags.h"
#include "probeless/node/main.h"
#include "probeless/parse/number.h"
#include "probeless/record/recorder.h"

namespace {

namespace bus = probeless::bus;
namespace log = probeless::log;
namespace parse = probeless::parse;
namespace msgs = probeless::msgs;
namespace node = probeless::node;
namespace record = probeless::record;
using Clock = std::chrono::steady_clock;

constexpr uint32_t kWidth = 640;
constexpr uint32_t kHeight = 480;
constexpr int kFramesPerStream = 4;

struct Config {
  double seconds = 4;
  int streams = 4;
  double fps = 30;
  double max_fps = 60;
  std::string dir = "/tmp";
  std::vector<std::string> compressions = {"none", "lz4", "zstd"};
  std::string json;
  bool keep = false;
};

// Payload of one synthetic frame: gradient plus noise.
std::vector<std::byte> MakePixels(msgs::Encoding encoding, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> noise(0.f, 3.f);
  const size_t bytes = msgs::Image::PackedPayloadBytes(kWidth, kHeight, encoding);
  std::vector<std::byte> pixels(bytes);
  if (encoding == msgs::Encoding::kRgb8) {
    for (uint32_t y = 0; y < kHeight; ++y) {
      for (uint32_t x = 0; x < kWidth; ++x) {
        for (uint32_t c = 0; c < 3; ++c) {
          const float v =
              static_cast<float>((x * (c + 1) + y * (3 - c) + seed * 17) % 256) + noise(rng);
          pixels[(y * kWidth + x) * 3 + c] =
              static_cast<std::byte>(std::clamp(static_cast<int>(v), 0, 255));
        }
      }
    }
  } else {
    for (uint32_t y = 0; y < kHeight; ++y) {
      for (uint32_t x = 0; x < kWidth; ++x) {
        const float mm = 800.f + static_cast<float>(x + 2 * y + seed) + noise(rng) * 2.f;
        const uint16_t v = static_cast<uint16_t>(std::clamp(mm, 0.f, 65535.f));
        std::memcpy(&pixels[(y * kWidth + x) * 2], &v, 2);
      }
    }
  }
  return pixels;
}

struct Stream {
  std::string image_topic;
  std::string depth_topic;
  std::vector<std::vector<std::byte>> rgb_frames;
  std::vector<std::vector<std::byte>> depth_frames;
  uint64_t published = 0;
};

void Publish(bus::Publisher& publisher, msgs::Encoding encoding,
             const std::vector<std::byte>& pixels, uint64_t sequence) {
  const size_t bytes = msgs::Image::MessageBytesFor(kWidth, kHeight, encoding);
  bus::Loan loan = publisher.Borrow(bytes);
  auto out = msgs::WriteMessage<msgs::Image>(loan.data());
  out->header.StampNow();
  out->header.sequence = sequence;
  out->header.SetFrameId("camera");
  out->Init(kWidth, kHeight, encoding);
  std::memcpy(out.payload.data(), pixels.data(), pixels.size());
  publisher.Publish(std::move(loan));
}

struct TopicRow {
  std::string topic;
  uint64_t published = 0;
  record::TopicStats stats;
};

struct Row {
  std::string compression;
  double fps = 0;
  double seconds = 0;
  double offered_mb_per_s = 0;
  double mb_per_s = 0;
  uint64_t published = 0;
  uint64_t written = 0;
  uint64_t dropped = 0;
  uint64_t bytes = 0;
  uint64_t file_bytes = 0;
  double cpu_percent = 0;  // of one core, whole process (publishers included)
  bool complete = false;
  std::vector<TopicRow> topics;
};

double CpuSeconds() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) +
         static_cast<double>(usage.ru_utime.tv_usec + usage.ru_stime.tv_usec) * 1e-6;
}

Row RunRow(const Config& config, std::vector<Stream>& streams, const std::string& compression,
           double fps) {
  Row row;
  row.compression = compression;
  row.fps = fps;
  std::vector<bus::Publisher> rgb;
  std::vector<bus::Publisher> depth;
  for (const Stream& s : streams) {
    bus::PublisherOptions options;
    options.slot_count = 72;  // more than the recorder's queue: slots never force drops
    options.node_name = "record_bench";
    options.max_message_bytes =
        msgs::Image::MessageBytesFor(kWidth, kHeight, msgs::Encoding::kRgb8);
    rgb.emplace_back(s.image_topic, msgs::TopicTypeOf<msgs::Image>(), options);
    options.max_message_bytes =
        msgs::Image::MessageBytesFor(kWidth, kHeight, msgs::Encoding::kDepth16);
    depth.emplace_back(s.depth_topic, msgs::TopicTypeOf<msgs::Image>(), options);
  }

  record::RecorderOptions options;
  options.regex = "^/bench/";
  options.output = config.dir + "/record_bench_" + std::to_string(getpid()) + "_" + compression;
  options.compression = log::ParseCompressionOption(compression);
  options.log = [](std::string_view line) {
    if (line.starts_with("warning")) std::fprintf(stderr, "%.*s\n", int(line.size()), line.data());
  };
  record::Recorder recorder(options);
  recorder.Start();

  const double cpu0 = CpuSeconds();
  const auto start = Clock::now();
  const auto period = std::chrono::duration<double>(1.0 / fps);
  const uint64_t frames = static_cast<uint64_t>(config.seconds * fps);
  std::vector<std::thread> threads;
  for (size_t i = 0; i < streams.size(); ++i) {
    threads.emplace_back([&, i] {
      Stream& s = streams[i];
      s.published = 0;
      for (uint64_t f = 0; f < frames; ++f) {
        std::this_thread::sleep_until(start +
                                      std::chrono::duration_cast<Clock::duration>(period * f));
        Publish(rgb[i], msgs::Encoding::kRgb8, s.rgb_frames[f % kFramesPerStream], f + 1);
        Publish(depth[i], msgs::Encoding::kDepth16, s.depth_frames[f % kFramesPerStream], f + 1);
        ++s.published;
      }
    });
  }
  for (std::thread& t : threads) t.join();
  const record::RecorderStats stats = recorder.Stop();
  row.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  row.cpu_percent = 100.0 * (CpuSeconds() - cpu0) / row.seconds;

  row.bytes = stats.bytes;
  row.written = stats.written;
  row.file_bytes = stats.file_bytes;
  row.mb_per_s = static_cast<double>(stats.bytes) / row.seconds / 1e6;
  const double frame_bytes = static_cast<double>(
      msgs::Image::PackedPayloadBytes(kWidth, kHeight, msgs::Encoding::kRgb8) +
      msgs::Image::PackedPayloadBytes(kWidth, kHeight, msgs::Encoding::kDepth16));
  row.offered_mb_per_s = frame_bytes * fps * static_cast<double>(streams.size()) / 1e6;
  for (const record::TopicStats& t : stats.topics) {
    TopicRow tr;
    tr.topic = t.topic;
    tr.stats = t;
    for (const Stream& s : streams) {
      if (s.image_topic == t.topic || s.depth_topic == t.topic) tr.published = s.published;
    }
    row.published += tr.published;
    row.dropped += t.dropped;
    row.topics.push_back(tr);
  }
  uint64_t in_files = 0;
  row.complete = true;
  for (const std::string& file : stats.files) {
    log::McapReader reader(file);
    row.complete = row.complete && !reader.truncated();
    in_files += reader.statistics().message_count;
    if (!config.keep) std::filesystem::remove(file);
  }
  row.complete = row.complete && in_files == stats.written;
  return row;
}

std::string Json(const Config& config, const std::vector<Row>& rows) {
  std::ostringstream j;
  j.setf(std::ios::fixed);
  j.precision(1);
  j << "{\"streams\":" << config.streams << ",\"width\":" << kWidth << ",\"height\":" << kHeight
    << ",\"frame_bytes\":1536000,\"seconds_per_row\":" << config.seconds << ",\"dir\":\""
    << config.dir << "\",\"cores\":" << std::thread::hardware_concurrency() << ",\"results\":[";
  for (size_t r = 0; r < rows.size(); ++r) {
    const Row& row = rows[r];
    j << (r ? "," : "") << "{\"compression\":\"" << row.compression << "\",\"fps\":" << row.fps
      << ",\"seconds\":" << row.seconds << ",\"offered_mb_per_s\":" << row.offered_mb_per_s
      << ",\"mb_per_s\":" << row.mb_per_s << ",\"published\":" << row.published
      << ",\"written\":" << row.written << ",\"dropped\":" << row.dropped
      << ",\"bytes\":" << row.bytes << ",\"file_bytes\":" << row.file_bytes
      << ",\"cpu_percent\":" << row.cpu_percent
      << ",\"complete\":" << (row.complete ? "true" : "false") << ",\"topics\":[";
    for (size_t t = 0; t < row.topics.size(); ++t) {
      const TopicRow& tr = row.topics[t];
      j << (t ? "," : "") << "{\"topic\":\"" << tr.topic << "\",\"published\":" << tr.published
        << ",\"received\":" << tr.stats.received << ",\"dropped\":" << tr.stats.dropped
        << ",\"invalid\":" << tr.stats.invalid << ",\"bytes\":" << tr.stats.bytes << "}";
    }
    j << "]}";
  }
  j << "]}\n";
  return j.str();
}

std::vector<std::string> SplitList(const std::string& text) {
  std::vector<std::string> out;
  std::stringstream in(text);
  for (std::string item; std::getline(in, item, ',');) out.push_back(item);
  return out;
}

int Run(int argc, char** argv) {
  Config config;
  node::FlagParser flags(
      "record_bench",
      "sustained recording throughput of record::Recorder: N paced RGB-D streams published from\n"
      "this process and recorded into --dir; per compression and frame rate the recorded MB/s,\n"
      "messages published/received/dropped, file bytes and CPU");
  flags.AddPositive("--seconds", &config.seconds, "S", "recording time per row");
  flags.Add("--streams", &config.streams, "N", "RGB-D streams", 1);
  flags.AddPositive("--fps", &config.fps, "F", "frame rate of the first rows");
  flags.Add("--max-fps", &config.max_fps, "F", "frame rate of the headroom rows (0 skips)", 0);
  flags.Add("--dir", &config.dir, "DIR", "where the recordings go");
  std::string compressions;
  for (const std::string& c : config.compressions) {
    compressions += (compressions.empty() ? "" : ",") + c;
  }
  flags.AddCallback(
      "--compressions", "LIST", "comma-separated: none, lz4, zstd",
      [&](const std::string& text) { config.compressions = SplitList(text); }, compressions);
  flags.Add("--json", &config.json, "OUT", "also write the rows as JSON");
  flags.Add("--keep", &config.keep, "keep the recordings");
  if (!flags.Parse(argc, argv)) return 0;
  if (!(config.seconds > 0) || config.streams < 1 || !(config.fps > 0) || config.max_fps < 0) {
    throw node::UsageError("--seconds, --streams and --fps must be > 0, --max-fps >= 0");
  }
  for (const std::string& c : config.compressions) log::ParseCompressionOption(c);
  if (getenv("PROBELESS_DOMAIN") == nullptr) {
    setenv("PROBELESS_DOMAIN", ("record_bench_" + std::to_string(getpid())).c_str(), 1);
  }

  std::vector<Stream> streams(static_cast<size_t>(config.streams));
  for (int i = 0; i < config.streams; ++i) {
    Stream& s = streams[static_cast<size_t>(i)];
    s.image_topic = "/bench/cam" + std::to_string(i) + "/image";
    s.depth_topic = "/bench/cam" + std::to_string(i) + "/depth";
    for (int f = 0; f < kFramesPerStream; ++f) {
      const uint32_t seed = static_cast<uint32_t>(i * 100 + f);
      s.rgb_frames.push_back(MakePixels(msgs::Encoding::kRgb8, seed));
      s.depth_frames.push_back(MakePixels(msgs::Encoding::kDepth16, seed));
    }
  }

  std::vector<Row> rows;
  std::printf("%-5s %5s %8s %9s %9s %9s %8s %13s %6s %s\n", "comp", "fps", "seconds", "offered",
              "MB/s", "published", "dropped", "file bytes", "cpu%", "complete");
  for (double fps : {config.fps, config.max_fps}) {
    if (fps <= 0) continue;
    for (const std::string& compression : config.compressions) {
      const Row row = RunRow(config, streams, compression, fps);
      std::printf("%-5s %5.0f %8.2f %9.1f %9.1f %9llu %8llu %13llu %6.0f %s\n",
                  row.compression.c_str(), row.fps, row.seconds, row.offered_mb_per_s, row.mb_per_s,
                  static_cast<unsigned long long>(row.published),
                  static_cast<unsigned long long>(row.dropped),
                  static_cast<unsigned long long>(row.file_bytes), row.cpu_percent,
                  row.complete ? "yes" : "NO");
      for (const TopicRow& t : row.topics) {
        if (t.stats.dropped != 0) {
          std::printf("      %s: published=%llu received=%llu dropped=%llu\n", t.topic.c_str(),
                      static_cast<unsigned long long>(t.published),
                      static_cast<unsigned long long>(t.stats.received),
                      static_cast<unsigned long long>(t.stats.dropped));
        }
      }
      std::fflush(stdout);
      rows.push_back(row);
    }
  }
  const std::string json = Json(config, rows);
  if (!config.json.empty()) {
    std::ofstream out(config.json);
    out << json;
    if (!out) throw std::runtime_error("cannot write " + config.json);
  }
  std::fputs(json.c_str(), stdout);
  for (const Row& row : rows) {
    if (!row.complete) return 1;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return probeless::node::RunMain("record_bench", [&] { return Run(argc, argv); });
}
