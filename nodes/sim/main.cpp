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

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#include "probeless/node/node.h"
#include "probeless/parse/number.h"
#include "probeless/replay/player.h"
#include "probeless/replay/sources.h"
#include "probeless/sim/generate.h"
#include "probeless/sim/simulator.h"
#include "probeless/sim/yaleb_style.h"

namespace {

using namespace probeless;

// Progress lines at most once a second (and at the end): "frame k/N, x fps".
std::function<void(uint64_t, uint64_t)> ProgressPrinter(const std::string& what,
                                                        const std::string& unit = "frame") {
  auto start =
      std::make_shared<std::chrono::steady_clock::time_point>(std::chrono::steady_clock::now());
  auto last = std::make_shared<std::chrono::steady_clock::time_point>(*start);
  return [=](uint64_t done, uint64_t total) {
    const auto now = std::chrono::steady_clock::now();
    if (done != total && now - *last < std::chrono::seconds(1)) return;
    *last = now;
    const double s = std::chrono::duration<double>(now - *start).count();
    std::fprintf(stderr, "[info] [sim] %s: %s %llu/%llu (%.1f %s/s)\n", what.c_str(), unit.c_str(),
                 static_cast<unsigned long long>(done), static_cast<unsigned long long>(total),
                 s > 0 ? done / s : 0.0, unit == "frame" ? "frames" : (unit + "s").c_str());
  };
}

// A contact sheet: up to 8 frames evenly spread over the scenario, RGB above a colour-mapped depth.
void WritePreview(sim::Scenario scenario, uint64_t frames, int threads, const std::string& path) {
  sim::Simulator simulator(std::move(scenario), threads);
  const uint64_t n = std::min<uint64_t>(8, frames);
  const int w = simulator.scenario().camera.width;
  const int h = simulator.scenario().camera.height;
  const int tile_w = std::min(w, 320);
  const int tile_h = h * tile_w / w;
  const int columns = static_cast<int>(std::min<uint64_t>(4, n));
  const int rows = static_cast<int>((n + columns - 1) / columns);
  cv::Mat sheet(rows * tile_h * 2, columns * tile_w, CV_8UC3, cv::Scalar(0, 0, 0));
  auto progress = ProgressPrinter("preview");
  for (uint64_t k = 0; k < n; ++k) {
    const uint64_t index = n == 1 ? 0 : k * (frames - 1) / (n - 1);
    const sim::SimFrame f = simulator.Render(index);
    cv::Mat rgb(h, w, CV_8UC3, const_cast<uint8_t*>(f.rgb.data()));
    cv::Mat bgr;
    cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
    cv::Mat depth(h, w, CV_16UC1, const_cast<uint16_t*>(f.depth_mm.data()));
    cv::Mat depth8;
    depth.convertTo(depth8, CV_8UC1, 255.0 / 5000.0);
    cv::Mat depth_color;
    cv::applyColorMap(depth8, depth_color, cv::COLORMAP_TURBO);
    depth_color.setTo(cv::Scalar(0, 0, 0), depth == 0);
    const int x = static_cast<int>(k % columns) * tile_w;
    const int y = static_cast<int>(k / columns) * tile_h * 2;
    cv::resize(bgr, sheet(cv::Rect(x, y, tile_w, tile_h)), cv::Size(tile_w, tile_h), 0, 0,
               cv::INTER_AREA);
    cv::resize(depth_color, sheet(cv::Rect(x, y + tile_h, tile_w, tile_h)),
               cv::Size(tile_w, tile_h), 0, 0, cv::INTER_NEAREST);
    cv::putText(sheet, "frame " + std::to_string(index), cv::Point(x + 6, y + 18),
                cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(255, 255, 255), 1);
    progress(k + 1, n);
  }
  if (!cv::imwrite(path, sheet)) throw std::runtime_error("cannot write preview '" + path + "'");
  std::printf("sim: wrote %s (%llu frames)\n", path.c_str(), static_cast<unsigned long long>(n));
}

// sim --yaleb-style: the ICT mesh and the light list from the shared data when present.
int WriteYaleBStyle(const std::string& out_dir, sim::YaleBStyleOptions options) {
  if (options.mesh == "ict") {
    const auto ict = sim::FindDataFile("meshes/ict_generic_neutral_mesh.obj");
    if (!ict) {
      throw node::UsageError(
          "--mesh ict: meshes/ict_generic_neutral_mesh.obj not found in $PROBELESS_DATA or the "
          "shared data folder");
    }
    options.ict_path = *ict;
  } else if (options.mesh != "procedural") {
    throw node::UsageError("--mesh: expected 'procedural' or 'ict', got '" + options.mesh + "'");
  }
  std::string light_source = "built-in Yale B table";
  if (const auto first = sim::FindDataFile("yaleb/yaleB01/yaleB01_P00A+000E+00.pgm")) {
    std::vector<sim::YaleBLightDirection> lights =
        sim::YaleBLightDirectionsFromFolder(std::filesystem::path(*first).parent_path().string());
    if (lights.size() == 64) {
      light_source = "file names of " + std::filesystem::path(*first).parent_path().string();
      if (options.behind) {
        for (const auto& l : sim::BehindLightDirections()) lights.push_back(l);
      }
      options.lights = std::move(lights);
    }
  }
  try {
    options.Validate();
  } catch (const sim::ScenarioError& error) {
    throw node::UsageError(error.what());
  }
  std::fprintf(stderr, "[info] [sim] yaleb-style: %d subjects, %dx%d, mesh %s, lights from %s\n",
               options.subjects, options.width, options.height, options.mesh.c_str(),
               light_source.c_str());
  options.progress = ProgressPrinter("yaleb-style " + out_dir, "image");
  const auto start = std::chrono::steady_clock::now();
  const sim::YaleBStyleSummary summary = sim::WriteYaleBStyleDataset(out_dir, options);
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf(
      "sim: wrote %llu images of %d subjects to %s in %.1f s (alignment error <= %.2f px)\n",
      static_cast<unsigned long long>(summary.images), summary.subjects, out_dir.c_str(), s,
      summary.max_alignment_error_px);
  return 0;
}

// sim --generate: N scenes of a split, one after the other, each on every render thread.
int Generate(int count, uint64_t seed, const std::string& split_name, const std::string& out_dir,
             sim::GenerateOptions options, bool resume) {
  const sim::Split split = sim::ParseSplit(split_name);
  if (count < 1) throw node::UsageError("--generate: expected a scene count >= 1");
  if (out_dir.empty()) throw node::UsageError("--generate needs --out DIR");
  if (seed + static_cast<uint64_t>(count) > sim::kSplitSeedStride) {
    throw node::UsageError("--seed + --generate must stay below " +
                           std::to_string(sim::kSplitSeedStride) + " (disjoint split ranges)");
  }
  options.Validate();
  const auto start = std::chrono::steady_clock::now();
  auto last = start;
  int written = 0, skipped = 0;
  options.progress = [&](int scene, int frame, int frames) {
    const auto now = std::chrono::steady_clock::now();
    if (frame != frames && now - last < std::chrono::seconds(2)) return;
    last = now;
    std::fprintf(stderr, "[info] [sim] generate: scene %d/%d, frame %d/%d (%.0f s)\n", scene + 1,
                 count, frame, frames, std::chrono::duration<double>(now - start).count());
  };
  for (int k = 0; k < count; ++k) {
    const uint64_t scene_seed = sim::SplitSeedBase(split) + seed + static_cast<uint64_t>(k);
    const sim::GeneratedScene scene = sim::GenerateScene(scene_seed, split, options);
    if (resume &&
        std::filesystem::exists(std::filesystem::path(out_dir) / scene.name / "scene.json")) {
      ++skipped;
      continue;
    }
    const sim::GeneratedSceneSummary summary = sim::WriteGeneratedScene(scene, options, out_dir, k);
    ++written;
    std::fprintf(stderr,
                 "[info] [sim] generate: %s (%s, %s, object seen in %d/%d frames) in %.1f s\n",
                 summary.folder.c_str(), scene.room.c_str(), scene.light_type.c_str(),
                 summary.frames_object_visible, summary.frames, summary.seconds);
  }
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("sim: wrote %d %s scenes (%d already complete) to %s in %.1f s\n", written,
              split_name.c_str(), skipped, out_dir.c_str(), s);
  return 0;
}

constexpr const char* kUsage =
    "usage: sim SCENARIO.yaml [--out FILE.mcap] [--preview FILE.png] [--frames N] [--threads N]\n"
    "           [--rate R] [--fast] [--loop] [--prefix /camera] [--ground-truth-prefix "
    "/groundtruth]\n"
    "           [--lockstep NODE]... [--no-clock] [--ros-args ...]\n"
    "       sim --yaleb-style OUT_DIR [--subjects N] [--size 168x192] [--rgb] [--behind] [--seed "
    "S]\n"
    "           [--mesh procedural|ict] [--threads N]\n"
    "       sim --generate N --split train|validation|test --out DIR [--seed S] [--frames F]\n"
    "           [--spp P] [--bounces B] [--size 640x480] [--threads N] [--resume]\n"
    "  docs/sim.md\n";

int Run(int argc, char** argv) {
  node::Node node(argc, argv, "sim", kUsage);
  std::string scenario_path = node.Param("scenario", "");
  std::string out = node.Param("out", "");
  std::string preview = node.Param("preview", "");
  sim::SimOptions options;
  options.max_frames = static_cast<uint64_t>(node.Param<int64_t>("frames", 0));
  options.threads = node.Param("threads", 2);
  options.topic_prefix = node.Param("topic_prefix", "/camera");
  options.ground_truth_prefix = node.Param("ground_truth_prefix", "/groundtruth");
  replay::PlayerOptions player_options;
  player_options.rate = node.Param("rate", 1.0);
  player_options.as_fast_as_possible = node.Param("fast", false);
  player_options.loop = node.Param("loop", false);
  player_options.lockstep_nodes = node.Param("lockstep", std::vector<std::string>{});
  node.CheckParamOverrides();

  const std::vector<std::string>& args = node.args();
  bool positional_seen = false;
  std::string yaleb_out;
  sim::YaleBStyleOptions yaleb;
  bool yaleb_option_seen = false;
  int generate_count = -1;
  std::string split;
  sim::GenerateOptions generate;
  bool resume = false;
  uint64_t generate_seed = 0;
  for (size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    auto value = [&]() -> const std::string& {
      if (i + 1 >= args.size()) throw node::UsageError(a + " needs a value");
      return args[++i];
    };
    if (a == "--out") {
      out = value();
    } else if (a == "--preview") {
      preview = value();
    } else if (a == "--frames") {
      options.max_frames = parse::ParseInteger<uint64_t>(a, value());
    } else if (a == "--threads") {
      options.threads = parse::ParseInteger<int>(a, value(), 0);
    } else if (a == "--rate") {
      player_options.rate = node::ParseNumberOption(a, value());
    } else if (a == "--fast") {
      player_options.as_fast_as_possible = true;
    } else if (a == "--loop") {
      player_options.loop = true;
    } else if (a == "--prefix") {
      options.topic_prefix = value();
    } else if (a == "--ground-truth-prefix") {
      options.ground_truth_prefix = value();
    } else if (a == "--lockstep") {
      player_options.lockstep_nodes.push_back(value());
    } else if (a == "--no-clock") {
      player_options.clock_topic.clear();
    } else if (a == "--generate") {
      generate_count = parse::ParseInteger<int>(a, value(), 1);
    } else if (a == "--split") {
      split = value();
    } else if (a == "--spp") {
      generate.samples_per_pixel = parse::ParseInteger<int>(a, value(), 1);
    } else if (a == "--bounces") {
      generate.bounces = parse::ParseInteger<int>(a, value(), 0);
    } else if (a == "--resume") {
      resume = true;
    } else if (a == "--yaleb-style") {
      yaleb_out = value();
    } else if (a == "--subjects") {
      yaleb.subjects = parse::ParseInteger<int>(a, value(), 1);
      yaleb_option_seen = true;
    } else if (a == "--size") {
      const std::string size = value();
      // Whole-text parse, positive sizes (sscanf took "-5x3").
      const size_t x = size.find('x');
      const std::string_view view(size);
      const auto w_parsed = parse::TryParseInteger<int>(view.substr(0, x), 1);
      const auto h_parsed = x == std::string::npos
                                ? std::nullopt
                                : parse::TryParseInteger<int>(view.substr(x + 1), 1);
      if (!w_parsed || !h_parsed) {
        throw node::UsageError("--size: expected WIDTHxHEIGHT, got '" + size + "'");
      }
      const int w = *w_parsed, h = *h_parsed;
      yaleb.width = generate.width = w;
      yaleb.height = generate.height = h;
      yaleb_option_seen = true;
    } else if (a == "--rgb") {
      yaleb.rgb = yaleb_option_seen = true;
    } else if (a == "--behind") {
      yaleb.behind = yaleb_option_seen = true;
    } else if (a == "--seed") {
      yaleb.seed = generate_seed = parse::ParseInteger<uint64_t>(a, value());
      yaleb_option_seen = true;
    } else if (a == "--mesh") {
      yaleb.mesh = value();
      yaleb_option_seen = true;
    } else if (a.starts_with("--")) {
      throw node::UsageError("unknown option '" + a + "'");
    } else if (!positional_seen) {
      scenario_path = a;
      positional_seen = true;
    } else {
      throw node::UsageError("more than one scenario given ('" + scenario_path + "' and '" + a +
                             "')");
    }
  }
  if (options.threads < 1) throw node::UsageError("--threads must be >= 1");
  if (!yaleb_out.empty()) {
    if (positional_seen) throw node::UsageError("--yaleb-style takes no scenario");
    yaleb.threads = options.threads;
    return WriteYaleBStyle(yaleb_out, yaleb);
  }
  if (generate_count >= 0) {
    if (positional_seen) throw node::UsageError("--generate takes no scenario");
    if (split.empty()) throw node::UsageError("--generate needs --split train|validation|test");
    generate.threads = options.threads;
    if (options.max_frames > 0) generate.frames = static_cast<int>(options.max_frames);
    try {
      return Generate(generate_count, generate_seed, split, out, generate, resume);
    } catch (const sim::ScenarioError& error) {
      throw node::UsageError(error.what());
    }
  }
  if (yaleb_option_seen) {
    throw node::UsageError(
        "--subjects, --size, --rgb, --behind, --seed and --mesh need --yaleb-style");
  }
  if (scenario_path.empty())
    throw node::UsageError("no scenario given (a YAML file or param 'scenario')");
  for (auto& name : player_options.lockstep_nodes) {
    if (!name.starts_with('/')) name = "/" + name;
  }

  sim::Scenario scenario = sim::LoadScenario(scenario_path);
  const uint64_t frames =
      options.max_frames == 0 ? scenario.frames : std::min(scenario.frames, options.max_frames);
  if (!preview.empty()) {
    WritePreview(scenario, frames, options.threads, preview);
    if (out.empty()) return 0;
  }
  if (!out.empty()) {
    options.progress = ProgressPrinter("rendering to " + out);
    std::unique_ptr<dataset::Source> source = sim::OpenSimSource(std::move(scenario), options);
    const auto start = std::chrono::steady_clock::now();
    const replay::ConvertStats stats = replay::ConvertToMcap(*source, out);
    const double s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::printf("sim: wrote %llu messages (%llu frames, %llu bytes) to %s in %.1f s\n",
                static_cast<unsigned long long>(stats.messages),
                static_cast<unsigned long long>(frames),
                static_cast<unsigned long long>(stats.file_bytes), out.c_str(), s);
    return 0;
  }

  options.progress = [&node](uint64_t done, uint64_t total) {
    if (done == total || done % 30 == 0) node.Debug() << "rendered frame " << done << "/" << total;
  };
  std::unique_ptr<dataset::Source> source = sim::OpenSimSource(std::move(scenario), options);
  player_options.node_name = node.fully_qualified_name();
  player_options.log = [&node](const std::string& line) {
    if (line.starts_with("[warn] ")) {
      node.Warn() << line.substr(7);
    } else {
      node.Info() << line;
    }
  };
  replay::Player player(*source, player_options);
  node.Info() << "simulating " << scenario_path << " (" << frames << " frames, "
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
