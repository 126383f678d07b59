#include "params.h"

#include <time.h>

#include "probeless/log/mcap.h"

namespace probeless::recorder {
namespace {

std::string DefaultOutput() {
  const time_t now = time(nullptr);
  tm local{};
  localtime_r(&now, &local);
  char name[64];
  strftime(name, sizeof(name), "probeless_%Y_%m_%d-%H_%M_%S", &local);
  return name;
}

}  // namespace

void DeclareFlags(node::FlagParser& flags, RecorderSettings& s) {
  flags.AddPositionals("TOPIC", &s.topics, "topics to record");
  for (const char* name : {"-o", "--output"}) {
    flags.Add(name, &s.output, "OUTPUT", "file name (no split) or prefix");
  }
  for (const char* name : {"-a", "--all"}) flags.Add(name, &s.all, "record every topic");
  for (const char* name : {"-e", "--regex"}) {
    flags.Add(name, &s.regex, "REGEX", "also record topics matching this regex");
  }
  for (const char* name : {"-x", "--exclude"}) {
    flags.Add(name, &s.exclude, "REGEX", "never record topics matching this regex");
  }
  flags.Add("--compression", &s.compression, "none|lz4|zstd", "chunk compression");
  flags.Add("--split-size-mb", &s.split_size_mb, "MB", "new file every MB 10^6 bytes (0 = no)");
  flags.Add("--split-duration-s", &s.split_duration_s, "S", "new file every S seconds (0 = no)");
  flags.Add("--queue-depth", &s.queue_depth, "N", "bus queue depth per topic (1..64)");
  flags.Add("--chunk-size-mb", &s.chunk_size_mb, "MIB", "MCAP chunk size");
}

void ReadParams(node::Node& node, RecorderSettings& s) {
  s.topics = node.Param<std::vector<std::string>>("topics", {});
  s.regex = node.Param("regex", "");
  s.exclude = node.Param("exclude", "");
  s.all = node.Param("all", false);
  s.output = node.Param("output", "");
  s.split_size_mb = node.Param("split_size_mb", 0.0);
  s.split_duration_s = node.Param("split_duration_s", 0.0);
  s.compression = node.Param("compression", "none");
  s.queue_depth = node.Param<int64_t>("queue_depth", 64);
  s.chunk_size_mb = node.Param("chunk_size_mb", 8.0);
}

record::RecorderOptions MakeOptions(node::Node& node, const RecorderSettings& s) {
  record::RecorderOptions o;
  for (const std::string& topic : s.topics) o.topics.push_back(node.ResolveTopicName(topic));
  o.regex = s.regex;
  o.exclude = s.exclude;
  o.all = s.all;
  o.output = s.output.empty() ? DefaultOutput() : s.output;
  if (!(s.split_size_mb >= 0)) {
    throw node::UsageError("split_size_mb " + std::to_string(s.split_size_mb) + " must be >= 0");
  }
  o.split_bytes = static_cast<uint64_t>(s.split_size_mb * 1e6);
  o.split_seconds = s.split_duration_s;
  o.compression = log::ParseCompressionOption(s.compression);
  if (s.queue_depth < 1 || s.queue_depth > bus::kMaxQueueDepth) {
    throw node::UsageError("queue_depth " + std::to_string(s.queue_depth) +
                           " out of range (expected 1.." + std::to_string(bus::kMaxQueueDepth) +
                           ")");
  }
  o.queue_depth = static_cast<uint32_t>(s.queue_depth);
  if (!(s.chunk_size_mb > 0) || s.chunk_size_mb > 1024) {
    throw node::UsageError("chunk_size_mb " + std::to_string(s.chunk_size_mb) +
                           " out of range (expected > 0 and <= 1024)");
  }
  o.chunk_size = static_cast<uint64_t>(s.chunk_size_mb * 1024 * 1024);
  if (o.chunk_size == 0) o.chunk_size = 1;
  o.node_name = node.fully_qualified_name();
  o.log = [&node](std::string_view line) {
    constexpr std::string_view kWarning = "warning: ";
    if (line.starts_with(kWarning)) {
      node.Warn() << line.substr(kWarning.size());
    } else {
      node.Info() << line;
    }
  };
  return o;
}

}  // namespace probeless::recorder
