// sim: the synthetic RGB-D camera. Renders a scenario (data/scenarios/*.yaml, docs/sim.md) and
// publishes it on the bus like a camera (through the replay Player: timed, --fast, --loop,
// lock-step), or writes it straight to an MCAP log (--out), or writes a contact sheet (--preview).
//
//   sim SCENARIO.yaml [--out FILE.mcap] [--preview FILE.png] [--frames N] [--threads N]
//       [--rate R] [--fast] [--loop] [--prefix /camera] [--ground-truth-prefix /groundtruth]
//       [--lockstep NODE]... [--no-clock] [--ros-args ...]
//   sim --yaleb-style OUT_DIR [--subjects N] [--size 168x192] [--rgb] [--behind] [--seed S]
//       [--mesh procedural|ict] [--threads N]
//   sim --generate N --split train|validation|test --out DIR [--seed S] [--frames F] [--spp P]
//       [--bounces B] [--size 640x480] [--threads N] [--resume]
//
// --yaleb-style renders a Yale-B-style face data set (sim/yaleb_style.h, docs/sim.md) and exits.
// --generate writes N randomised evaluation scenes (sim/generate.h, docs/sim.md) and exits;
// --resume skips scenes whose folder is complete (scene.json written last).
// Params (launch files; the options above override them): scenario, out, preview, frames,
// threads, rate, fast, loop, topic_prefix, ground_truth_prefix, lockstep.
// Topics: <prefix>/image (rgb8), <prefix>/depth (depth16, mm), <prefix>/camera_info,
// <gt>/pose, <gt>/light, <gt>/face, /clock. Progress goes to stderr. Exit: 0 done (or SIGINT),
// 2 bad options or scenario, 1 otherwise.
#include "probeless/node/main.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <memory>
#include <string>

#include "offline.h"
#include "params.h"
#include "probeless/node/flags.h"
#include "probeless/node/node.h"
#include "probeless/replay/player.h"
#include "probeless/replay/sources.h"

namespace {

using namespace probeless;

int Run(int argc, char** argv) {
  sim_node::SimSettings s;
  // The command line: declared first for the node's usage text, parsed after the params.
  node::FlagParser flags("sim",
                         "the synthetic RGB-D camera (docs/sim.md): publishes SCENARIO like a\n"
                         "camera, or writes it to MCAP (--out) or a contact sheet (--preview);\n"
                         "or writes a Yale-B-style face set (--yaleb-style OUT_DIR) or\n"
                         "evaluation scenes (--generate N --split S --out DIR)");
  sim_node::DeclareFlags(flags, s);
  node::Node node(argc, argv, "sim", flags.Usage());
  sim_node::ReadParams(node, s);
  node.CheckParamOverrides();
  if (!flags.Parse(node.args())) return 0;
  if (s.options.threads < 1) throw node::UsageError("--threads must be >= 1");
  if (!s.yaleb_out.empty()) {
    if (flags.Given("SCENARIO")) throw node::UsageError("--yaleb-style takes no scenario");
    s.yaleb.threads = s.options.threads;
    return sim_node::WriteYaleBStyle(s.yaleb_out, s.yaleb);
  }
  if (s.generate_count >= 0) {
    if (flags.Given("SCENARIO")) throw node::UsageError("--generate takes no scenario");
    if (s.split.empty()) throw node::UsageError("--generate needs --split train|validation|test");
    s.generate.threads = s.options.threads;
    if (s.options.max_frames > 0) s.generate.frames = static_cast<int>(s.options.max_frames);
    try {
      return sim_node::Generate(s.generate_count, s.generate_seed, s.split, s.out, s.generate,
                                s.resume);
    } catch (const sim::ScenarioError& error) {
      throw node::UsageError(error.what());
    }
  }
  if (sim_node::YaleBStyleFlagGiven(flags)) {
    throw node::UsageError(
        "--subjects, --size, --rgb, --behind, --seed and --mesh need --yaleb-style");
  }
  if (s.scenario.empty())
    throw node::UsageError("no scenario given (a YAML file or param 'scenario')");
  for (auto& name : s.player.lockstep_nodes) {
    if (!name.starts_with('/')) name = "/" + name;
  }

  sim::Scenario scenario = sim::LoadScenario(s.scenario);
  const uint64_t frames =
      s.options.max_frames == 0 ? scenario.frames : std::min(scenario.frames, s.options.max_frames);
  if (!s.preview.empty()) {
    sim_node::WritePreview(scenario, frames, s.options.threads, s.preview);
    if (s.out.empty()) return 0;
  }
  if (!s.out.empty()) {
    s.options.progress = sim_node::ProgressPrinter("rendering to " + s.out);
    std::unique_ptr<dataset::Source> source = sim::OpenSimSource(std::move(scenario), s.options);
    const auto start = std::chrono::steady_clock::now();
    const replay::ConvertStats stats = replay::ConvertToMcap(*source, s.out);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::printf("sim: wrote %llu messages (%llu frames, %llu bytes) to %s in %.1f s\n",
                static_cast<unsigned long long>(stats.messages),
                static_cast<unsigned long long>(frames),
                static_cast<unsigned long long>(stats.file_bytes), s.out.c_str(), seconds);
    return 0;
  }

  s.options.progress = [&node](uint64_t done, uint64_t total) {
    if (done == total || done % 30 == 0) node.Debug() << "rendered frame " << done << "/" << total;
  };
  std::unique_ptr<dataset::Source> source = sim::OpenSimSource(std::move(scenario), s.options);
  s.player.node_name = node.fully_qualified_name();
  s.player.log = [&node](const std::string& line) {
    if (line.starts_with("[warn] ")) {
      node.Warn() << line.substr(7);
    } else {
      node.Info() << line;
    }
  };
  replay::Player player(*source, s.player);
  node.Info() << "simulating " << s.scenario << " (" << frames << " frames, "
              << source->message_count() << " messages)";
  const replay::PlayerStats stats = player.Run([] { return node::ok(); });
  std::printf("sim: published %llu messages, %llu pass(es)\n",
              static_cast<unsigned long long>(stats.published),
              static_cast<unsigned long long>(stats.passes));
  std::fflush(stdout);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return probeless::node::RunMain("sim", [&] { return Run(argc, argv); });
}
