#include "params.h"

#include <optional>
#include <string_view>
#include <vector>

#include "probeless/node/main.h"
#include "probeless/parse/number.h"

namespace probeless::sim_node {
namespace {

constexpr const char* kYaleBStyleFlags[] = {"--subjects", "--size", "--rgb",
                                            "--behind",   "--seed", "--mesh"};

}  // namespace

void DeclareFlags(node::FlagParser& flags, SimSettings& s) {
  flags.AddPositional("SCENARIO", &s.scenario, "a scenario YAML (data/scenarios, docs/sim.md)");
  flags.Add("--out", &s.out, "FILE", "write an MCAP log (--generate: a folder) instead");
  flags.Add("--preview", &s.preview, "FILE.png", "write a contact sheet of up to 8 frames");
  flags.Add("--frames", &s.options.max_frames, "N", "frames per pass at most (0 = all)");
  flags.Add("--threads", &s.options.threads, "N", "render threads (>= 1)", 0);
  flags.Add("--rate", &s.player.rate, "R", "playback speed");
  flags.Add("--fast", &s.player.as_fast_as_possible, "as fast as possible, untimed");
  flags.Add("--loop", &s.player.loop, "start again at the end");
  flags.Add("--prefix", &s.options.topic_prefix, "PREFIX", "camera topics' prefix");
  flags.Add("--ground-truth-prefix", &s.options.ground_truth_prefix, "PREFIX",
            "ground-truth topics' prefix");
  flags.Add("--lockstep", &s.player.lockstep_nodes, "NODE", "wait for NODE's acks");
  flags.AddSwitch(
      "--no-clock", [&s] { s.player.clock_topic.clear(); }, "publish no clock");
  flags.AddCallback("--generate", "N", "write N evaluation scenes (docs/sim.md) and exit",
                    [&s](const std::string& v) {
                      s.generate_count = parse::ParseInteger<int>("--generate", v, 1);
                    });
  flags.Add("--split", &s.split, "train|validation|test", "--generate's split");
  flags.Add("--spp", &s.generate.samples_per_pixel, "P", "--generate's paths per pixel", 1);
  flags.Add("--bounces", &s.generate.bounces, "B", "--generate's path-tracing bounces", 0);
  flags.Add("--resume", &s.resume, "--generate skips scenes already complete");
  flags.Add("--yaleb-style", &s.yaleb_out, "OUT_DIR", "write a Yale-B-style face set and exit");
  flags.Add("--subjects", &s.yaleb.subjects, "N", "--yaleb-style's subjects", 1);
  flags.AddCallback(
      "--size", "WxH", "--yaleb-style's or --generate's image size", [&s](const std::string& size) {
        const size_t x = size.find('x');
        const std::string_view view(size);
        const auto w = parse::TryParseInteger<int>(view.substr(0, x), 1);
        const auto h = x == std::string::npos ? std::nullopt
                                              : parse::TryParseInteger<int>(view.substr(x + 1), 1);
        if (!w || !h) throw node::UsageError("--size: expected WIDTHxHEIGHT, got '" + size + "'");
        s.yaleb.width = s.generate.width = *w;
        s.yaleb.height = s.generate.height = *h;
      });
  flags.Add("--rgb", &s.yaleb.rgb, "--yaleb-style writes colour images");
  flags.Add("--behind", &s.yaleb.behind, "--yaleb-style adds lights behind the head");
  flags.AddCallback("--seed", "S", "--yaleb-style's or --generate's first seed",
                    [&s](const std::string& v) {
                      s.yaleb.seed = s.generate_seed = parse::ParseInteger<uint64_t>("--seed", v);
                    });
  flags.Add("--mesh", &s.yaleb.mesh, "procedural|ict", "--yaleb-style's head");
}

void ReadParams(node::Node& node, SimSettings& s) {
  s.scenario = node.Param("scenario", "");
  s.out = node.Param("out", "");
  s.preview = node.Param("preview", "");
  s.options.max_frames = static_cast<uint64_t>(node.Param<int64_t>("frames", 0));
  s.options.threads = node.Param("threads", 2);
  s.options.topic_prefix = node.Param("topic_prefix", "/camera");
  s.options.ground_truth_prefix = node.Param("ground_truth_prefix", "/groundtruth");
  s.player.rate = node.Param("rate", 1.0);
  s.player.as_fast_as_possible = node.Param("fast", false);
  s.player.loop = node.Param("loop", false);
  s.player.lockstep_nodes = node.Param("lockstep", std::vector<std::string>{});
}

bool YaleBStyleFlagGiven(const node::FlagParser& flags) {
  for (const char* name : kYaleBStyleFlags) {
    if (flags.Given(name)) return true;
  }
  return false;
}

}  // namespace probeless::sim_node
