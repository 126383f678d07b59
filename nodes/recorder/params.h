// The recorder's settings: params (launch files) and the command line that overrides them.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "probeless/node/flags.h"
#include "probeless/node/node.h"
#include "probeless/record/recorder.h"

namespace probeless::recorder {

// The params' and flags' values, checked together by MakeOptions (the defaults are the params').
struct RecorderSettings {
  std::vector<std::string> topics;  // relative names are resolved in the node's namespace
  std::string regex;
  std::string exclude;
  bool all = false;
  std::string output;  // "" = probeless_<local time>
  double split_size_mb = 0;
  double split_duration_s = 0;
  std::string compression = "none";
  int64_t queue_depth = 64;
  double chunk_size_mb = 8;
};

// Declares the command line's flags on `flags`, bound to the fields of `s` (which must outlive
// the parse); the topics are its positional arguments.
void DeclareFlags(node::FlagParser& flags, RecorderSettings& s);

// Reads the params into `s`.
void ReadParams(node::Node& node, RecorderSettings& s);

// The recorder's options from `s`: topic names resolved by `node`, its log lines through the
// node's logger (which must outlive the recorder). Throws node::UsageError "<param> <value> out of
// range (expected ...)" for a split size < 0, a queue depth outside 1..bus::kMaxQueueDepth or a
// chunk size outside (0, 1024] MiB, and log::LogError for an unknown compression.
record::RecorderOptions MakeOptions(node::Node& node, const RecorderSettings& s);

}  // namespace probeless::recorder
