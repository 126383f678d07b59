// recorder: records bus topics into MCAP files until SIGINT/SIGTERM (probeless::record::Recorder).
//
// Params (ROS 2 style, -p name:=value or a params file):
//   topics (string array, [])    topics to record (relative names are resolved in the namespace)
//   regex (string, "")           also record topics matching this ECMAScript regex (search)
//   exclude (string, "")         never record topics matching this regex
//   all (bool, false)            record every topic
//   output (string, "")          file name (no split) or prefix; default probeless_<local time>
//   split_size_mb (double, 0)    new file every this many MB (10^6 bytes; 0 = no size split)
//   split_duration_s (double, 0) new file every this many seconds (0 = no time split)
//   compression (string, none)   none, lz4 or zstd
//   queue_depth (int, 64)        bus queue depth per topic (1..64)
//   chunk_size_mb (double, 8)    MCAP chunk size in MiB
// Command line (own arguments before --ros-args; they override the params):
//   recorder [-o OUTPUT] [-a|--all] [-e REGEX] [-x REGEX] [--compression none|lz4|zstd]
//            [--split-size-mb MB] [--split-duration-s S] [--queue-depth N]
//            [--chunk-size-mb MIB] [TOPIC...]
// At exit prints on stdout one line per topic
//   <topic>: received=N dropped=D invalid=I bytes=B
// (dropped: lost in the bus queue; invalid: failed conversion), then "file: <path>" per file
// and "summary: topics=T received=N dropped=D bytes=B files=F".
// Exit status: 0 after a clean stop; 2 for bad params/options or an output that cannot be
// created (one line on stderr); 1 if recording failed (the report is printed first).
#include <time.h>

#include <charconv>
#include <cstdio>
#include <exception>
#include <string>
#include <vector>

#include "probeless/log/mcap.h"
#include "probeless/node/node.h"
#include "probeless/parse/number.h"
#include "probeless/record/recorder.h"

namespace {

using probeless::node::NodeError;
using probeless::record::RecordError;

// A bad command line or parameter: exit status 2.
class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

constexpr const char* kUsage =
    "usage: recorder [-o OUTPUT] [-a|--all] [-e|--regex REGEX] [-x|--exclude REGEX]\n"
    "                [--compression none|lz4|zstd] [--split-size-mb MB] [--split-duration-s S]\n"
    "                [--queue-depth N] [--chunk-size-mb MIB] [TOPIC...] [--ros-args ...]\n";

// Settings from params, then overridden by the command line.
struct Settings {
  std::vector<std::string> topics;
  std::string regex;
  std::string exclude;
  bool all = false;
  std::string output;
  double split_size_mb = 0;
  double split_duration_s = 0;
  std::string compression = "none";
  int64_t queue_depth = 64;
  double chunk_size_mb = 8;
};

double ParseNumber(const std::string& option, const std::string& text) {
  // parse::'s rules (whole text, finite: from_chars alone took "inf"); ranges are checked with the
  // params' values in MakeOptions.
  const auto value = probeless::parse::TryParseDouble(text);
  if (!value) throw UsageError("option " + option + ": '" + text + "' is not a number");
  return *value;
}

// Returns false if --help was given.
bool ParseCommandLine(const std::vector<std::string>& args, Settings& s) {
  for (size_t i = 0; i < args.size(); ++i) {
    std::string arg = args[i];
    std::string value;
    bool has_value = false;
    if (arg.starts_with("--") && arg.find('=') != std::string::npos) {
      value = arg.substr(arg.find('=') + 1);
      arg = arg.substr(0, arg.find('='));
      has_value = true;
    }
    auto next = [&]() -> std::string {
      if (has_value) return value;
      if (i + 1 >= args.size()) throw UsageError("option " + arg + " needs a value");
      return args[++i];
    };
    if (arg == "-h" || arg == "--help") return false;
    if (arg == "-o" || arg == "--output") {
      s.output = next();
    } else if (arg == "-a" || arg == "--all") {
      if (has_value) throw UsageError("option " + arg + " takes no value");
      s.all = true;
    } else if (arg == "-e" || arg == "--regex") {
      s.regex = next();
    } else if (arg == "-x" || arg == "--exclude") {
      s.exclude = next();
    } else if (arg == "--compression") {
      s.compression = next();
    } else if (arg == "--split-size-mb") {
      s.split_size_mb = ParseNumber(arg, next());
    } else if (arg == "--split-duration-s") {
      s.split_duration_s = ParseNumber(arg, next());
    } else if (arg == "--queue-depth") {
      const std::string text = next();
      const auto depth = probeless::parse::TryParseInteger<int64_t>(text);
      if (!depth) throw UsageError("option --queue-depth: '" + text + "' is not an integer");
      s.queue_depth = *depth;
    } else if (arg == "--chunk-size-mb") {
      s.chunk_size_mb = ParseNumber(arg, next());
    } else if (arg.size() > 1 && arg[0] == '-') {
      throw UsageError("unknown option '" + args[i] + "' (see --help)");
    } else {
      s.topics.push_back(arg);
    }
  }
  return true;
}

std::string DefaultOutput() {
  const time_t now = time(nullptr);
  tm local{};
  localtime_r(&now, &local);
  char name[64];
  strftime(name, sizeof(name), "probeless_%Y_%m_%d-%H_%M_%S", &local);
  return name;
}

probeless::record::RecorderOptions MakeOptions(probeless::node::Node& node, Settings& s) {
  probeless::record::RecorderOptions o;
  for (const std::string& topic : s.topics) o.topics.push_back(node.ResolveTopicName(topic));
  o.regex = s.regex;
  o.exclude = s.exclude;
  o.all = s.all;
  o.output = s.output.empty() ? DefaultOutput() : s.output;
  if (!(s.split_size_mb >= 0)) {
    throw UsageError("split_size_mb " + std::to_string(s.split_size_mb) + " must be >= 0");
  }
  o.split_bytes = static_cast<uint64_t>(s.split_size_mb * 1e6);
  o.split_seconds = s.split_duration_s;
  o.compression = probeless::log::ParseCompressionOption(s.compression);
  if (s.queue_depth < 1 || s.queue_depth > probeless::bus::kMaxQueueDepth) {
    throw UsageError("queue_depth " + std::to_string(s.queue_depth) +
                     " out of range (expected 1.." +
                     std::to_string(probeless::bus::kMaxQueueDepth) + ")");
  }
  o.queue_depth = static_cast<uint32_t>(s.queue_depth);
  if (!(s.chunk_size_mb > 0) || s.chunk_size_mb > 1024) {
    throw UsageError("chunk_size_mb " + std::to_string(s.chunk_size_mb) +
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

void PrintReport(const probeless::record::RecorderStats& stats) {
  uint64_t received = 0, dropped = 0;
  for (const auto& t : stats.topics) {
    std::printf(
        "%s: received=%llu dropped=%llu invalid=%llu bytes=%llu\n", t.topic.c_str(),
        static_cast<unsigned long long>(t.received), static_cast<unsigned long long>(t.dropped),
        static_cast<unsigned long long>(t.invalid), static_cast<unsigned long long>(t.bytes));
    received += t.received;
    dropped += t.dropped;
  }
  for (const std::string& file : stats.files) std::printf("file: %s\n", file.c_str());
  std::printf("summary: topics=%zu received=%llu dropped=%llu bytes=%llu files=%zu\n",
              stats.topics.size(), static_cast<unsigned long long>(received),
              static_cast<unsigned long long>(dropped),
              static_cast<unsigned long long>(stats.bytes), stats.files.size());
  std::fflush(stdout);
}

int Run(int argc, char** argv) {
  std::string name = "recorder";
  // The recorder's log callback uses the node: declared after it, destroyed before it.
  std::unique_ptr<probeless::node::Node> node;
  std::unique_ptr<probeless::record::Recorder> recorder;
  try {
    node = std::make_unique<probeless::node::Node>(argc, argv, "recorder", kUsage);
    name = node->fully_qualified_name();
    Settings s;
    s.topics = node->Param<std::vector<std::string>>("topics", {});
    s.regex = node->Param("regex", "");
    s.exclude = node->Param("exclude", "");
    s.all = node->Param("all", false);
    s.output = node->Param("output", "");
    s.split_size_mb = node->Param("split_size_mb", 0.0);
    s.split_duration_s = node->Param("split_duration_s", 0.0);
    s.compression = node->Param("compression", "none");
    s.queue_depth = node->Param<int64_t>("queue_depth", 64);
    s.chunk_size_mb = node->Param("chunk_size_mb", 8.0);
    node->CheckParamOverrides();
    if (!ParseCommandLine(node->args(), s)) {
      std::fputs(kUsage, stdout);
      return 0;
    }
    recorder = std::make_unique<probeless::record::Recorder>(MakeOptions(*node, s));
    recorder->Start();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "[error] [%s] %s\n", name.c_str(), e.what());
    return 2;
  }

  node->Info() << "recording to " << recorder->Stats().files.front();
  while (node->ok() && !recorder->Failed()) {
    node->WaitForShutdown(std::chrono::milliseconds(200));
  }
  try {
    const probeless::record::RecorderStats stats = recorder->Stop();
    PrintReport(stats);
    node->Info() << "wrote " << stats.written << " messages (" << stats.file_bytes << " bytes) to "
                 << stats.files.size() << " file(s)";
  } catch (const std::exception& e) {
    PrintReport(recorder->Stats());
    std::fprintf(stderr, "[error] [%s] recording failed: %s\n", name.c_str(), e.what());
    return 1;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) { return Run(argc, argv); }
