// The player's settings: params (launch files) and the command line that overrides them.
#pragma once

#include <string>

#include "probeless/dataset/datasets.h"
#include "probeless/node/flags.h"
#include "probeless/node/node.h"
#include "probeless/replay/player.h"

namespace probeless::player {

struct PlayerSettings {
  replay::PlayerOptions options;
  dataset::DatasetOptions dataset;
  std::string source;  // an MCAP log or a dataset folder; required
  double delay_s = 0;  // seconds to wait before the first message
  bool keyboard = true;
};

// Declares the command line's flags on `flags`, bound to the fields of `s` (which must outlive
// the parse).
void DeclareFlags(node::FlagParser& flags, PlayerSettings& s);

// Reads the params into `s` (the defaults are the fields' values); throws node::UsageError for a
// remap not of the form "from:=to" or a subject < 1.
void ReadParams(node::Node& node, PlayerSettings& s);

}  // namespace probeless::player
