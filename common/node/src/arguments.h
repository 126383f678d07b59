// Internal: parsing of the ROS 2 command-line convention.
#pragma once

#include <string>
#include <vector>

#include "params.h"

namespace probeless::node::internal {

// "-r [node:]from:=to". `from` is "__node"/"__ns" for the special rules.
struct RemapRule {
  std::string node;  // "" = every node
  std::string from;
  std::string to;
  std::string text;  // the rule as given
};

// "-p [node:]name:=value".
struct ParamRule {
  std::string node;  // "" = every node
  std::string name;
  ParamValue value;
};

// "--log-level LEVEL" (logger "") or "--log-level LOGGER:=LEVEL".
struct LogLevelRule {
  std::string logger;
  std::string level;
};

struct ParsedArguments {
  std::string program;
  std::vector<std::string> own_args;
  std::vector<RemapRule> remaps;
  std::vector<ParamRule> params;
  std::vector<std::string> params_files;
  std::vector<LogLevelRule> log_levels;
};

// Parses argv (argv[0] = program). Throws NodeError "--ros-args: ..." on a malformed ROS argument.
ParsedArguments ParseArguments(const std::vector<std::string>& argv);

}  // namespace probeless::node::internal
