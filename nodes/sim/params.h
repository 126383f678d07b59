// sim's settings: params (launch files) and the command line that overrides them, for its four
// modes (publish a scenario, write it to MCAP or a contact sheet, --yaleb-style, --generate).
#pragma once

#include <cstdint>
#include <string>

#include "probeless/node/flags.h"
#include "probeless/node/node.h"
#include "probeless/replay/player.h"
#include "probeless/sim/generate.h"
#include "probeless/sim/simulator.h"
#include "probeless/sim/yaleb_style.h"

namespace probeless::sim_node {

struct SimSettings {
  std::string scenario;  // a scenario YAML (publish, --out, --preview)
  std::string out;       // an MCAP file, or --generate's output folder
  std::string preview;   // a contact-sheet PNG
  sim::SimOptions options;
  replay::PlayerOptions player;
  std::string yaleb_out;  // --yaleb-style's output folder; "" = not that mode
  sim::YaleBStyleOptions yaleb;
  int generate_count = -1;  // --generate's scene count; -1 = not that mode
  std::string split;
  sim::GenerateOptions generate;
  uint64_t generate_seed = 0;
  bool resume = false;
};

// Declares the command line's flags on `flags`, bound to the fields of `s` (which must outlive
// the parse); the scenario is the positional SCENARIO.
void DeclareFlags(node::FlagParser& flags, SimSettings& s);

// Reads the params into `s`.
void ReadParams(node::Node& node, SimSettings& s);

// Whether any flag of --yaleb-style alone was given in the last parse of `flags`.
bool YaleBStyleFlagGiven(const node::FlagParser& flags);

}  // namespace probeless::sim_node
