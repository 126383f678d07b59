// `probeless bag info|record|play|convert`: MCAP logs and dataset sources. `record` and `play` run
// the recorder and player nodes (build/bin/recorder, build/bin/player) in this process's place;
// `info` and `convert` work in-process.
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "commands.h"
#include "probeless/error/error.h"
#include "probeless/log/mcap.h"
#include "probeless/log/mcap_reader.h"
#include "probeless/parse/number.h"
#include "probeless/replay/sources.h"

namespace probeless::tools {
namespace {

constexpr const char* kBagUsage =
    "usage: probeless bag <command> ...\n"
    "\n"
    "commands:\n"
    "  info FILE.mcap                 topics, types, counts, rates, duration; says whether the\n"
    "                                 file was cut short and how much was recovered\n"
    "  record [options] [TOPIC...]    record bus topics to MCAP (runs the recorder node;\n"
    "                                 'probeless bag record --help' lists its options)\n"
    "  play SOURCE [options]          publish an MCAP log or a dataset folder on the bus (runs\n"
    "                                 the player node; 'probeless bag play --help')\n"
    "  convert SOURCE OUT.mcap [--compression none|lz4|zstd] [--chunk-size BYTES] [--fps F]\n"
    "                                 [--camera-info FILE] [--prefix /camera] [--max-frames N]\n"
    "                                 write a dataset folder (7scenes, tum, yaleb, images, video;\n"
    "                                 detected, or KIND:PATH) or a log to an MCAP log\n"
    "\n"
    "exit code: 0 success, 1 failure, 2 bad command line or input\n";

int BagUsageError(const std::string& message) {
  std::fprintf(stderr, "probeless bag: %s\n%s", message.c_str(), kBagUsage);
  return 2;
}

std::string SiblingExecutable(const std::string& name) {
  std::error_code error;
  const auto self = std::filesystem::read_symlink("/proc/self/exe", error);
  if (!error) {
    const auto candidate = self.parent_path() / name;
    if (access(candidate.c_str(), X_OK) == 0) return candidate.string();
  }
  return name;  // from PATH
}

// Replaces this process with build/bin/<node> and the given arguments.
int ExecNode(const std::string& node, int argc, char** argv) {
  const std::string path = SiblingExecutable(node);
  std::vector<char*> args;
  args.push_back(const_cast<char*>(path.c_str()));
  for (int i = 1; i < argc; ++i) args.push_back(argv[i]);
  args.push_back(nullptr);
  execvp(path.c_str(), args.data());
  std::fprintf(stderr, "probeless bag: cannot run '%s': %s (build the '%s' target)\n", path.c_str(),
               std::strerror(errno), node.c_str());
  return 1;
}

std::string Duration(double seconds) {
  char text[64];
  std::snprintf(text, sizeof(text), "%.3f s", seconds);
  return text;
}

std::string Bytes(uint64_t bytes) {
  char text[64];
  if (bytes >= 1'000'000'000) {
    std::snprintf(text, sizeof(text), "%.2f GB", bytes / 1e9);
  } else if (bytes >= 1'000'000) {
    std::snprintf(text, sizeof(text), "%.2f MB", bytes / 1e6);
  } else {
    std::snprintf(text, sizeof(text), "%.1f KB", bytes / 1e3);
  }
  return text;
}

int Info(int argc, char** argv) {
  if (argc != 2 || std::strcmp(argv[1], "-h") == 0 || std::strcmp(argv[1], "--help") == 0) {
    return BagUsageError("info takes exactly one FILE.mcap");
  }
  const std::string path = argv[1];
  try {
    const log::McapReader reader(path);
    const auto& stats = reader.statistics();
    const auto& rec = reader.recovery();
    const double duration =
        stats.message_count > 1
            ? static_cast<double>(stats.message_end_time_ns - stats.message_start_time_ns) / 1e9
            : 0.0;
    std::printf("path:      %s\n", path.c_str());
    std::printf("size:      %s\n", Bytes(rec.file_bytes).c_str());
    std::printf("library:   %s\n", reader.library().c_str());
    std::printf("profile:   %s\n", reader.profile().c_str());
    if (rec.truncated) {
      std::printf(
          "state:     TRUNCATED (no footer: the writer did not close it); recovered %llu "
          "messages in %llu complete chunks, %s of %s readable; %s\n",
          static_cast<unsigned long long>(rec.messages),
          static_cast<unsigned long long>(rec.chunks), Bytes(rec.valid_bytes).c_str(),
          Bytes(rec.file_bytes).c_str(), rec.detail.c_str());
    } else {
      std::printf("state:     complete (%s)\n", rec.indexed ? "indexed" : "scanned");
    }
    std::printf("duration:  %s\n", Duration(duration).c_str());
    std::printf("start:     %.9f\n", stats.message_start_time_ns / 1e9);
    std::printf("end:       %.9f\n", stats.message_end_time_ns / 1e9);
    std::printf("messages:  %llu\n", static_cast<unsigned long long>(stats.message_count));
    std::printf("chunks:    %u\n", stats.chunk_count);
    std::printf("channels:  %zu\n", reader.channels().size());
    for (const auto& [id, channel] : reader.channels()) {
      const auto count = stats.channel_message_counts.find(id);
      const uint64_t n = count == stats.channel_message_counts.end() ? 0 : count->second;
      const log::Schema* schema = reader.FindSchema(channel.schema_id);
      const auto type = channel.metadata.find("probeless.type");
      std::printf("  %-32s %8llu msgs", channel.topic.c_str(), static_cast<unsigned long long>(n));
      if (duration > 0 && n > 1) std::printf("  %7.2f Hz", (n - 1) / duration);
      std::printf("  %s (%s)", schema ? schema->name.c_str() : "no schema",
                  channel.message_encoding.c_str());
      if (type != channel.metadata.end()) std::printf("  <- %s", type->second.c_str());
      std::printf("\n");
    }
    for (const auto& m : reader.metadata()) {
      std::printf("metadata:  %s", m.name.c_str());
      for (const auto& [k, v] : m.entries) std::printf(" %s=%s", k.c_str(), v.c_str());
      std::printf("\n");
    }
    return 0;
  } catch (const log::LogError& e) {
    std::fprintf(stderr, "probeless bag info: %s\n", e.what());
    return 2;
  }
}

int Convert(int argc, char** argv) {
  std::vector<std::string> positional;
  log::WriterOptions writer_options;
  dataset::DatasetOptions dataset_options;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw InputError(a + " needs a value");
      return argv[++i];
    };
    try {
      if (a == "-h" || a == "--help") {
        std::printf("%s", kBagUsage);
        return 0;
      } else if (a == "--compression") {
        writer_options.compression = log::ParseCompressionOption(value());
      } else if (a == "--chunk-size") {
        writer_options.chunk_size = parse::ParseInteger<uint64_t>(a, value(), 1);
      } else if (a == "--fps") {
        dataset_options.fps = parse::ParsePositiveDouble(a, value());
      } else if (a == "--camera-info") {
        dataset_options.camera_info_path = value();
      } else if (a == "--prefix") {
        dataset_options.topic_prefix = value();
      } else if (a == "--max-frames") {
        dataset_options.max_frames = parse::ParseInteger<uint64_t>(a, value());
      } else if (a.starts_with("--")) {
        return BagUsageError("convert: unknown option '" + a + "'");
      } else {
        positional.push_back(a);
      }
    } catch (const InputError& e) {  // a bad number (parse::NumberError) or topic filter (LogError)
      return BagUsageError("convert: " + std::string(e.what()));
    }
  }
  if (positional.size() != 2) return BagUsageError("convert takes SOURCE and OUT.mcap");
  try {
    auto source = replay::OpenSource(positional[0], dataset_options);
    std::fprintf(stderr, "converting %s %s (%llu messages) to %s\n",
                 std::string(source->kind()).c_str(), source->path().c_str(),
                 static_cast<unsigned long long>(source->message_count()), positional[1].c_str());
    const bool tty = isatty(STDERR_FILENO);
    const auto stats = replay::ConvertToMcap(
        *source, positional[1], writer_options, [&](uint64_t done, uint64_t total) {
          if (total > 0) {
            std::fprintf(stderr, "%s%llu/%llu messages (%.0f%%)%s", tty ? "\r" : "",
                         static_cast<unsigned long long>(done),
                         static_cast<unsigned long long>(total), 100.0 * done / total,
                         tty ? "" : "\n");
          }
        });
    if (tty) std::fprintf(stderr, "\n");
    std::printf("wrote %s: %llu messages, %s\n", positional[1].c_str(),
                static_cast<unsigned long long>(stats.messages), Bytes(stats.file_bytes).c_str());
    for (size_t t = 0; t < stats.per_topic.size(); ++t) {
      std::printf("  %-32s %llu\n", source->topics()[t].topic.c_str(),
                  static_cast<unsigned long long>(stats.per_topic[t]));
    }
    return 0;
  } catch (const dataset::DatasetError& e) {
    std::fprintf(stderr, "probeless bag convert: %s\n", e.what());
    return 2;
  } catch (const log::LogError& e) {
    std::fprintf(stderr, "probeless bag convert: %s\n", e.what());
    return 1;
  }
}

}  // namespace

int RunBagCommand(int argc, char** argv) {
  if (argc < 2) return BagUsageError("missing command");
  const std::string command = argv[1];
  if (command == "-h" || command == "--help") {
    std::printf("%s", kBagUsage);
    return 0;
  }
  if (command == "info") return Info(argc - 1, argv + 1);
  if (command == "convert") return Convert(argc - 1, argv + 1);
  if (command == "record") return ExecNode("recorder", argc - 1, argv + 1);
  if (command == "play") return ExecNode("player", argc - 1, argv + 1);
  return BagUsageError("unknown command '" + command + "'");
}

}  // namespace probeless::tools
