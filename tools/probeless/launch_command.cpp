// `probeless launch`: parses a launch file and runs it under the supervisor.
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "commands.h"
#include "probeless/bus/bus.h"
#include "probeless/launch/launch.h"
#include "probeless/launch/supervisor.h"
#include "probeless/parse/number.h"

namespace probeless::tools {
namespace {

constexpr const char* kLaunchUsage =
    "usage: probeless launch FILE [name:=value ...] [options]\n"
    "\n"
    "Runs the nodes of a YAML launch file (see docs/launch.md) until they all finish or the\n"
    "launch is interrupted (Ctrl-C, SIGTERM).\n"
    "\n"
    "options:\n"
    "  --sigterm-timeout S  seconds from SIGINT to SIGTERM at shutdown (default 5)\n"
    "  --sigkill-timeout S  seconds from SIGTERM to SIGKILL at shutdown (default 5)\n"
    "  --log-dir DIR        directory of output: log files (default $PROBELESS_LOG_DIR or\n"
    "                       ~/.probeless/log/<time>-<pid>)\n"
    "  --show-args          print the launch arguments with their values and exit\n"
    "  --dry-run            print the resolved command line of every node and exit\n"
    "  -h, --help           this help\n"
    "\n"
    "exit code: 0 all nodes finished with 0 (or were stopped), 1 a node failed,\n"
    "           2 bad command line or launch file\n";

int UsageError(const std::string& message) {
  std::fprintf(stderr, "probeless launch: %s\n%s", message.c_str(), kLaunchUsage);
  return 2;
}

// Parses a timeout in seconds (finite, >= 0).
bool ParseSeconds(const std::string& text, double* seconds) {
  const auto value = parse::TryParseDouble(text, 0);
  if (value) *seconds = *value;
  return value.has_value();
}

// Directory of the running executable (build/bin), searched first for node executables.
std::string ExecutableDirectory() {
  std::error_code error;
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", error);
  return error ? std::string() : self.parent_path().string();
}

// Shell-quotes a word for --dry-run output.
std::string Quote(const std::string& word) {
  if (!word.empty() && word.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ"
                                              "0123456789_-./:=,@%+") == std::string::npos) {
    return word;
  }
  std::string out = "'";
  for (char c : word) {
    if (c == '\'') {
      out += "'\\''";
    } else {
      out += c;
    }
  }
  return out + "'";
}

void PrintDryRun(const launch::LaunchDescription& description) {
  for (const launch::NodeSpec& node : description.nodes) {
    std::string line = node.fully_qualified_name + ":";
    auto add = [&line](const std::string& word) {
      line += ' ';
      line += Quote(word);
    };
    for (const auto& [name, value] : node.environment) add(name + "=" + value);
    for (const auto& word : node.prefix) add(word);
    for (const auto& word : node.argv) add(word);
    std::printf("%s\n", line.c_str());
  }
}

}  // namespace

int RunLaunchCommand(int argc, char** argv) {
  std::string file;
  launch::ParseOptions parse_options;
  launch::SupervisorOptions supervisor_options;
  bool dry_run = false;
  bool show_args = false;
  for (int i = 1; i < argc; ++i) {
    std::string arg = argv[i];
    std::string value;
    bool has_value = false;
    if (arg.starts_with("--") && arg.find('=') != std::string::npos) {
      value = arg.substr(arg.find('=') + 1);
      arg = arg.substr(0, arg.find('='));
      has_value = true;
    }
    auto take_value = [&]() -> bool {
      if (has_value) return true;
      if (i + 1 >= argc) return false;
      value = argv[++i];
      return true;
    };
    if (arg == "-h" || arg == "--help") {
      std::fputs(kLaunchUsage, stdout);
      return 0;
    } else if (arg == "--sigterm-timeout" || arg == "--sigkill-timeout") {
      double* target = arg == "--sigterm-timeout" ? &supervisor_options.sigterm_timeout_s
                                                  : &supervisor_options.sigkill_timeout_s;
      if (!take_value()) return UsageError(arg + " needs a value in seconds");
      if (!ParseSeconds(value, target)) {
        return UsageError("invalid " + arg + " '" + value + "' (expected seconds >= 0)");
      }
    } else if (arg == "--log-dir") {
      if (!take_value()) return UsageError("--log-dir needs a directory");
      supervisor_options.log_dir = value;
    } else if (arg == "--dry-run" && !has_value) {
      dry_run = true;
    } else if (arg == "--show-args" && !has_value) {
      show_args = true;
    } else if (arg.starts_with("-")) {
      return UsageError("unknown option '" + std::string(argv[i]) + "'");
    } else if (auto override = launch::ParseArgumentOverride(arg)) {
      parse_options.arguments.push_back(*override);
    } else if (file.empty()) {
      file = arg;
    } else {
      return UsageError("unexpected argument '" + arg + "' (expected name:=value)");
    }
  }
  if (file.empty()) return UsageError("missing launch file");

  parse_options.bin_dir = ExecutableDirectory();
  launch::LaunchDescription description;
  try {
    description = launch::LoadLaunchFile(file, parse_options);
  } catch (const launch::LaunchError& e) {
    std::fprintf(stderr, "probeless launch: %s\n", e.what());
    return 2;
  }
  if (show_args) {
    for (const auto& [name, value] : description.arguments) {
      std::printf("%s:=%s\n", name.c_str(), value.c_str());
    }
    return 0;
  }
  if (dry_run) {
    PrintDryRun(description);
    return 0;
  }
  std::fflush(stdout);
  const int code = launch::RunSupervisor(description, supervisor_options);
  try {
    const std::vector<std::string> removed = bus::CleanDeadSegments();
    if (!removed.empty()) {
      std::fprintf(stderr, "[probeless] removed %zu shared-memory segment(s) of dead nodes\n",
                   removed.size());
    }
  } catch (const bus::BusError& e) {
    std::fprintf(stderr, "[probeless] warning: cleaning shared memory failed: %s\n", e.what());
  }
  return code;
}

}  // namespace probeless::tools
