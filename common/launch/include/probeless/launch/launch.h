// probeless launch files: parsing a YAML launch file (ROS 2 launch_yaml vocabulary) into a plain,
// fully resolved LaunchDescription. Nothing here starts a process; see supervisor.h for that.
//
// A launch file is a mapping with one key, `launch`, holding a list of actions:
//
//   launch:
//   - arg: {name: rate, default: "10", description: "publish rate in Hz"}
//   - node: {exec: talker, name: talker, args: "--rate $(arg rate)", respawn: true}
//   - group: {namespace: robot, children: [{node: {exec: listener}}]}
//
// The complete vocabulary is documented in docs/launch.md.
//
// Errors: every problem in a launch file (YAML syntax, unknown action or key, missing key, unknown
// `$(arg x)`, bad boolean, include cycle, missing file, executable not found, ...) throws
// LaunchError whose what() is one line "<file>:<line>:<column>: <problem> (expected <what>)"; line
// and column are 1-based and point at the offending YAML node.
#pragma once

#include <functional>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "probeless/error/error.h"

namespace probeless::launch {

// The single exception type of launch file parsing.
class LaunchError : public InputError {
 public:
  using InputError::InputError;
};

// Where something was declared: file as given/resolved (absolute for files read from disk), 1-based
// line and column.
struct SourceLocation {
  std::string file;
  int line = 0;
  int column = 0;
};

// Where a node's stdout/stderr go: kScreen = the supervisor's stdout/stderr, each line prefixed
// with
// "[<name>] "; kLog = the same plus a log file <log dir>/<fully qualified name>.log.
enum class OutputMode { kScreen, kLog };

// An inline parameter: `value` is YAML text the node parses (e.g. "10", "true", "'text'", "[1,
// 2]").
struct Parameter {
  std::string name;
  std::string value;
};

// A topic/name remapping `from:=to`.
struct Remap {
  std::string from;
  std::string to;
};

// One node to run, fully resolved (no substitutions left).
struct NodeSpec {
  std::string name;                      // node name, e.g. "talker" ([A-Za-z0-9_]+)
  std::string node_namespace;            // absolute namespace, "/" or e.g. "/robot/arm"
  std::string fully_qualified_name;      // node_namespace + "/" + name, e.g. "/robot/arm/talker"
  std::string executable;                // path of the executable (absolute when resolved)
  std::vector<std::string> arguments;    // the node's own arguments (after `args` splitting)
  std::vector<std::string> param_files;  // absolute paths, in declaration order
  std::vector<Parameter> parameters;     // inline parameters, in declaration order
  std::vector<Remap> remaps;             // in declaration order
  // Environment variables set on top of the supervisor's environment, applied in order (later
  // entries win): `set_env` actions in scope, the node's `env` list, then PROBELESS_NODE_NAME.
  std::vector<std::pair<std::string, std::string>> environment;
  std::vector<std::string> prefix;  // launch-prefix words (prefix[0] looked up in PATH), or empty
  // The complete command line without the prefix: BuildNodeArgv(*this).
  std::vector<std::string> argv;
  OutputMode output = OutputMode::kScreen;
  bool respawn = false;
  double respawn_delay_s = 0.0;  // seconds between an exit and the restart, >= 0
  int respawn_max_retries = -1;  // restarts allowed; -1 = unlimited
  bool required = false;         // its exit shuts the whole launch down
  SourceLocation location;       // the `node` action
};

// The result of parsing: nodes in declaration order plus the launch arguments of the top-level
// file with their final values.
struct LaunchDescription {
  std::vector<NodeSpec> nodes;
  std::vector<std::pair<std::string, std::string>> arguments;
};

struct ParseOptions {
  // Command-line overrides `name:=value`, already split. Every name must be declared by an `arg`
  // somewhere in the launched tree.
  std::vector<std::pair<std::string, std::string>> arguments;
  // Resolve node executables (bin_dir, then relative to the launch file, then PATH) and the first
  // word of launch-prefix (PATH). When false, `exec` is kept as written (used by the fuzzer).
  bool resolve_executables = true;
  // Directory searched first for node executables (normally the directory of `probeless`).
  std::string bin_dir;
  // Reads a file (launch files and includes); nullopt if it cannot be read. Empty = the real disk.
  std::function<std::optional<std::string>(const std::string& path)> read_file;
  // Whether a (parameter) file exists. Empty = the real disk.
  std::function<bool(const std::string& path)> file_exists;
  // Looks up an environment variable ($(env X), PATH). Empty = getenv.
  std::function<std::optional<std::string>(const std::string& name)> get_env;
};

// Parses the launch file at `path` (relative paths are made absolute against the current
// directory). Throws LaunchError on any problem.
LaunchDescription LoadLaunchFile(const std::string& path, const ParseOptions& options = {});

// Parses `text` as if it were the content of the file `file_name` (used for error messages,
// `$(dirname)` and relative includes, which go through options.read_file). Throws LaunchError only.
LaunchDescription ParseLaunchText(std::string_view text, const std::string& file_name,
                                  const ParseOptions& options = {});

// The node command-line contract (ROS 2's): executable, the node's own arguments, then
//   --ros-args -r __node:=<name> -r __ns:=<namespace> [--params-file <file>]...
//   [-p <name>:=<value>]... [-r <from>:=<to>]...
std::vector<std::string> BuildNodeArgv(const NodeSpec& node);

// Splits `text` into words like a POSIX shell without expansions: blanks separate words, '...'
// is literal, "..." allows \" \\ \$ \` escapes, a backslash outside quotes escapes the next
// character. Throws LaunchError("unterminated quote ...") without location on bad input.
std::vector<std::string> SplitShellWords(std::string_view text);

// Parses a command-line override "name:=value"; nullopt if `text` has no ":=" or an empty name.
std::optional<std::pair<std::string, std::string>> ParseArgumentOverride(std::string_view text);

}  // namespace probeless::launch
