// libFuzzer target: parses arbitrary bytes as a launch file, in memory (no process is started, no
// real file is read). The only exception the parser may throw is LaunchError; anything else
// escapes and is reported by libFuzzer as a crash. Successful parses are checked for invariants.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <map>
#include <optional>
#include <string>

#include "probeless/launch/launch.h"

namespace {

using probeless::launch::LaunchDescription;
using probeless::launch::LaunchError;
using probeless::launch::ParseOptions;

constexpr size_t kMaxInputBytes = 64 * 1024;
constexpr const char* kMainFile = "fuzz/main.launch.yaml";

void Check(bool condition) {
  if (!condition) std::abort();
}

void CheckDescription(const LaunchDescription& description) {
  for (const auto& node : description.nodes) {
    Check(!node.name.empty());
    Check(!node.node_namespace.empty() && node.node_namespace[0] == '/');
    Check(node.fully_qualified_name.size() > node.name.size());
    Check(node.argv == probeless::launch::BuildNodeArgv(node));
    Check(!node.environment.empty() && node.environment.back().first == "PROBELESS_NODE_NAME");
    Check(node.respawn_delay_s >= 0 && node.respawn_max_retries >= -1);
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size > kMaxInputBytes) return 0;
  const std::string text(reinterpret_cast<const char*>(data), size);
  // A tiny virtual file system: the input itself (so self-includes hit cycle detection), one
  // well-formed include and one parameter file.
  const std::map<std::string, std::string> files{
      {kMainFile, text},
      {"fuzz/inc.yaml",
       "launch:\n- arg: {name: inc_arg, default: x}\n- node: {exec: inc, name: $(arg inc_arg)}\n"}};
  ParseOptions options;
  options.resolve_executables = false;
  options.read_file = [&files](const std::string& path) -> std::optional<std::string> {
    auto it = files.find(path);
    if (it == files.end()) return std::nullopt;
    return it->second;
  };
  options.file_exists = [](const std::string& path) {
    return path.size() >= 11 && path.compare(path.size() - 11, 11, "params.yaml") == 0;
  };
  options.get_env = [](const std::string& name) -> std::optional<std::string> {
    if (name == "HOME") return std::string("/home/fuzz");
    return std::nullopt;
  };
  try {
    CheckDescription(probeless::launch::ParseLaunchText(text, kMainFile, options));
  } catch (const LaunchError& e) {
    const std::string message = e.what();
    // "<file>:<line>:<column>: ..." on one line.
    Check(message.find(':') != std::string::npos);
    Check(message.find('\n') == std::string::npos);
    Check(message.rfind("fuzz/", 0) == 0);
  }
  return 0;
}
