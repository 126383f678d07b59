// log_bench: McapWriter throughput for 640x480 RGB-D frames (one rgb8 and one 16UC1 image per
// frame, CDR-encoded sensor_msgs/msg/Image), per chunk compression, on one core.
//
//   log_bench [--frames N] [--chunk-size BYTES] [--dir DIR] [--json FILE]
//
// Prints one line per compression and, with --json, writes
//   {"width":640,"height":480,"frames":N,"payload_bytes":B,"results":[
//     {"compression":"none","seconds":s,"mb_per_s":x,"file_bytes":f,"ratio":r},...]}
// MB/s counts message payload bytes (10^6 bytes per MB) over the time of all Write calls and
// Close (data handed to the page cache, no fsync). The frames are synthetic: smooth gradients with
// sensor-like noise, a few distinct frames cycled, so compression ratios are realistic-ish.
#include <time.h>

#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <span>
#include <string>
#include <vector>

#include "probeless/log/mcap_writer.h"
#include "probeless/log/ros2.h"
#include "probeless/msgs/image.h"
#include "probeless/node/flags.h"
#include "probeless/node/main.h"

namespace {

using namespace probeless;

constexpr uint32_t kWidth = 640;
constexpr uint32_t kHeight = 480;
constexpr int kDistinctFrames = 4;

double NowSeconds() {
  timespec t{};
  clock_gettime(CLOCK_MONOTONIC, &t);
  return static_cast<double>(t.tv_sec) + static_cast<double>(t.tv_nsec) * 1e-9;
}

// xorshift64: deterministic noise.
uint64_t Next(uint64_t& state) {
  state ^= state << 13;
  state ^= state >> 7;
  state ^= state << 17;
  return state;
}

// CDR bytes of one synthetic image (frame index f).
std::vector<std::byte> MakeFrame(msgs::Encoding encoding, int f, uint64_t& noise) {
  log::MessageBuffer buffer(msgs::Image::MessageBytesFor(kWidth, kHeight, encoding));
  msgs::WriteView<msgs::Image> image = msgs::WriteMessage<msgs::Image>(buffer.bytes());
  image->header.stamp_ns = 1'700'000'000'000'000'000 + int64_t{f} * 33'333'333;
  image->header.SetFrameId("camera_optical");
  image->Init(kWidth, kHeight, encoding);
  if (encoding == msgs::Encoding::kRgb8) {
    auto rgb = msgs::ImageChannels<uint8_t>(*image, image.payload);
    for (uint32_t y = 0; y < kHeight; ++y) {
      for (uint32_t x = 0; x < kWidth; ++x) {
        const uint64_t n = Next(noise);
        uint8_t* p = &rgb[(static_cast<size_t>(y) * kWidth + x) * 3];
        p[0] = static_cast<uint8_t>((x + f * 7) / 3 + (n & 3));
        p[1] = static_cast<uint8_t>((y + f * 5) / 2 + ((n >> 2) & 3));
        p[2] = static_cast<uint8_t>(((x + y) / 5) + ((n >> 4) & 3));
      }
    }
  } else {
    auto depth = msgs::ImageChannels<uint16_t>(*image, image.payload);
    for (uint32_t y = 0; y < kHeight; ++y) {
      for (uint32_t x = 0; x < kWidth; ++x) {
        const uint64_t n = Next(noise);
        depth[static_cast<size_t>(y) * kWidth + x] =
            static_cast<uint16_t>(800 + y * 2 + x / 4 + f * 3 + (n & 7));
      }
    }
  }
  return log::EncodeRos2(log::Ros2ConverterFor<msgs::Image>(), buffer.bytes());
}

struct Result {
  log::Compression compression;
  double seconds = 0;
  double mb_per_s = 0;
  uint64_t file_bytes = 0;
  double ratio = 0;
};

}  // namespace

int Run(int argc, char** argv) {
  int frames = 300;
  uint64_t chunk_size = 4 * 1024 * 1024;
  std::string dir = std::getenv("TMPDIR") != nullptr ? std::getenv("TMPDIR") : "/tmp";
  std::string json_path;
  probeless::node::FlagParser flags(
      "log_bench",
      "McapWriter throughput for 640x480 RGB-D frames (rgb8 + 16UC1, CDR sensor_msgs/msg/Image)\n"
      "per chunk compression, on one core");
  flags.Add("--frames", &frames, "N", "frames written per compression", 1);
  flags.Add("--chunk-size", &chunk_size, "BYTES", "MCAP chunk size", 1);
  flags.Add("--dir", &dir, "DIR", "where the logs are written ($TMPDIR or /tmp)");
  flags.Add("--json", &json_path, "FILE", "also write the figures as JSON");
  if (!flags.Parse(argc, argv)) return 0;

  uint64_t noise = 0x9E3779B97F4A7C15ull;
  std::vector<std::vector<std::byte>> rgb;
  std::vector<std::vector<std::byte>> depth;
  for (int f = 0; f < kDistinctFrames; ++f) {
    rgb.push_back(MakeFrame(msgs::Encoding::kRgb8, f, noise));
    depth.push_back(MakeFrame(msgs::Encoding::kDepth16, f, noise));
  }
  const uint64_t payload_per_frame = rgb[0].size() + depth[0].size();
  const uint64_t payload_bytes = payload_per_frame * static_cast<uint64_t>(frames);

  std::vector<Result> results;
  for (log::Compression compression :
       {log::Compression::kNone, log::Compression::kLz4, log::Compression::kZstd}) {
    const std::string path =
        dir + "/log_bench_" + std::string(log::CompressionOptionName(compression)) + ".mcap";
    log::WriterOptions options;
    options.compression = compression;
    options.chunk_size = chunk_size;
    const double start = NowSeconds();
    log::WriterStats stats;
    {
      log::McapWriter writer(path, options);
      const auto& converter = log::Ros2ConverterFor<msgs::Image>();
      const uint16_t schema = writer.AddSchema(converter.ros2_type(), log::kSchemaEncodingRos2Msg,
                                               converter.schema_text());
      const uint16_t color_channel =
          writer.AddChannel("/camera/color/image", log::kMessageEncodingCdr, schema);
      const uint16_t depth_channel =
          writer.AddChannel("/camera/depth/image", log::kMessageEncodingCdr, schema);
      for (int f = 0; f < frames; ++f) {
        const uint64_t t = 1'700'000'000'000'000'000ull + static_cast<uint64_t>(f) * 33'333'333;
        writer.Write(color_channel, static_cast<uint32_t>(f + 1), t, t,
                     rgb[static_cast<size_t>(f % kDistinctFrames)]);
        writer.Write(depth_channel, static_cast<uint32_t>(f + 1), t, t,
                     depth[static_cast<size_t>(f % kDistinctFrames)]);
      }
      writer.Close();
      stats = writer.stats();
    }
    Result result;
    result.compression = compression;
    result.seconds = NowSeconds() - start;
    result.mb_per_s = static_cast<double>(payload_bytes) / 1e6 / result.seconds;
    result.file_bytes = stats.file_bytes;
    result.ratio = static_cast<double>(payload_bytes) / static_cast<double>(stats.file_bytes);
    results.push_back(result);
    std::remove(path.c_str());
    std::printf("%-5s %8.1f MB/s  %7.3f s  file %llu bytes  ratio %.2f\n",
                std::string(log::CompressionOptionName(compression)).c_str(), result.mb_per_s,
                result.seconds, static_cast<unsigned long long>(result.file_bytes), result.ratio);
  }

  if (!json_path.empty()) {
    FILE* out = std::fopen(json_path.c_str(), "w");
    if (out == nullptr) {
      std::fprintf(stderr, "log_bench: cannot write %s: %s\n", json_path.c_str(),
                   std::strerror(errno));
      return 1;
    }
    std::fprintf(out,
                 "{\"width\":%u,\"height\":%u,\"frames\":%d,\"chunk_size\":%llu,"
                 "\"payload_bytes\":%llu,\"results\":[",
                 kWidth, kHeight, frames, static_cast<unsigned long long>(chunk_size),
                 static_cast<unsigned long long>(payload_bytes));
    for (size_t i = 0; i < results.size(); ++i) {
      const Result& r = results[i];
      std::fprintf(out,
                   "%s{\"compression\":\"%s\",\"seconds\":%.6f,\"mb_per_s\":%.1f,"
                   "\"file_bytes\":%llu,\"ratio\":%.4f}",
                   i == 0 ? "" : ",",
                   std::string(log::CompressionOptionName(r.compression)).c_str(), r.seconds,
                   r.mb_per_s, static_cast<unsigned long long>(r.file_bytes), r.ratio);
    }
    std::fprintf(out, "]}\n");
    if (std::fclose(out) != 0) {
      std::fprintf(stderr, "log_bench: cannot write %s\n", json_path.c_str());
      return 1;
    }
  }
  return 0;
}

int main(int argc, char** argv) {
  return probeless::node::RunMain("log_bench", [&] { return Run(argc, argv); });
}
