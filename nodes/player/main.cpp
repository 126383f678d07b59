// player: publishes a recorded stream — an MCAP log or a dataset folder (7-Scenes, TUM RGB-D,
// Extended Yale B, images, video) — on the bus, timed, as fast as possible, or in lock-step with
// named nodes. `probeless bag play` runs this binary.
//
//   player SOURCE [--rate R] [--fast] [--loop] [--start S] [--duration S] [--topics REGEX]...
//          [--exclude REGEX]... [--remap FROM:=TO]... [--clock TOPIC | --no-clock]
//          [--control TOPIC] [--lockstep NODE]... [--paused] [--delay S] [--fps F]
//          [--camera-info FILE] [--prefix /camera] [--max-frames N] [--subjects 1,5]
//          [--slots N] [--no-keyboard] [--ros-args ...]
//
// Free-running (timed or --fast) the player never waits for subscribers: one that falls more than
// --slots messages behind loses the oldest (counted by `probeless topic info`). --lockstep loses
// nothing.
//
// Params (launch files; the options above override them): source, rate, fast, loop, start,
// duration, topics, exclude, remap ("from:=to" strings), clock_topic, control_topic, lockstep,
// paused, delay, fps, camera_info, topic_prefix, max_frames, subjects, slots, keyboard.
// Keyboard (when stdin is a terminal): space pause/resume, s step, + / - rate x1.25 / /1.25, q
// quit. Exit: 0 at the end of the source (or on SIGINT/SIGTERM), 2 on bad options or input, 1
// otherwise.
#include "probeless/node/main.h"

#include <chrono>
#include <cstdio>
#include <memory>
#include <string>

#include "keyboard.h"
#include "params.h"
#include "probeless/node/flags.h"
#include "probeless/node/node.h"
#include "probeless/replay/player.h"
#include "probeless/replay/sources.h"

namespace {

using namespace probeless;

int Run(int argc, char** argv) {
  player::PlayerSettings s;
  // The command line: declared first for the node's usage text, parsed after the params.
  node::FlagParser flags("player", "publishes a recorded stream on the bus (docs/replay.md)");
  player::DeclareFlags(flags, s);
  node::Node node(argc, argv, "player", flags.Usage());
  player::ReadParams(node, s);
  node.CheckParamOverrides();
  if (!flags.Parse(node.args())) return 0;
  replay::PlayerOptions& options = s.options;
  if (s.source.empty()) {
    throw node::UsageError("no source given (an MCAP log or a dataset folder, or param 'source')");
  }
  for (auto& name : options.lockstep_nodes) {
    if (!name.starts_with('/')) name = "/" + name;
  }

  std::unique_ptr<dataset::Source> source = replay::OpenSource(s.source, s.dataset);
  for (const auto& skipped : replay::SkippedMcapChannels(*source)) {
    node.Warn() << "skipping channel " << skipped << ": no probeless conversion";
  }
  options.node_name = node.fully_qualified_name();
  options.log = [&node](const std::string& line) {
    // Lines come as "[warn] player: ..." from the library.
    if (line.starts_with("[warn] ")) {
      node.Warn() << line.substr(7);
    } else {
      node.Info() << line;
    }
  };
  replay::Player player(*source, options);
  std::string topics;
  for (const auto& t : player.published_topics()) {
    if (!t.empty()) topics += (topics.empty() ? "" : ", ") + t;
  }
  node.Info() << "playing " << source->kind() << " " << source->path() << " ("
              << source->message_count() << " messages) on " << topics
              << (options.lockstep_nodes.empty() ? "" : ", lock-step");
  if (s.delay_s > 0 &&
      node.WaitForShutdown(std::chrono::nanoseconds(static_cast<int64_t>(s.delay_s * 1e9)))) {
    return 0;
  }
  std::unique_ptr<player::Keyboard> keys;
  if (s.keyboard) keys = std::make_unique<player::Keyboard>(player);
  const auto start = std::chrono::steady_clock::now();
  const replay::PlayerStats stats = player.Run([] { return node::ok(); });
  keys.reset();
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("%s\n", replay::PlaybackSummary(stats, player.published_topics(), seconds,
                                              !options.lockstep_nodes.empty())
                          .c_str());
  std::fflush(stdout);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return probeless::node::RunMain("player", [&] { return Run(argc, argv); });
}
