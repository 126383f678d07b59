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

#include <poll.h>
#include <termios.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <exception>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "probeless/node/node.h"
#include "probeless/parse/number.h"
#include "probeless/replay/player.h"
#include "probeless/replay/sources.h"

namespace {

using namespace probeless;

std::pair<std::string, std::string> ParseRemap(const std::string& text) {
  const size_t at = text.find(":=");
  if (at == std::string::npos || at == 0 || at + 2 == text.size()) {
    throw node::UsageError("remap '" + text + "' is not of the form /from:=/to");
  }
  return {text.substr(0, at), text.substr(at + 2)};
}

std::vector<int> ParseSubjects(const std::string& text) {
  std::vector<int> subjects;
  std::stringstream in(text);
  for (std::string item; std::getline(in, item, ',');) {
    subjects.push_back(parse::ParseInteger<int>("--subjects", item, 1));
  }
  return subjects;
}

// Raw keyboard on a terminal: restores the terminal on destruction.
class Keyboard {
 public:
  explicit Keyboard(replay::Player& player) : player_(player) {
    if (tcgetattr(STDIN_FILENO, &saved_) != 0) return;
    termios raw = saved_;
    raw.c_lflag &= ~static_cast<tcflag_t>(ICANON | ECHO);
    raw.c_cc[VMIN] = 0;
    raw.c_cc[VTIME] = 0;
    if (tcsetattr(STDIN_FILENO, TCSANOW, &raw) != 0) return;
    active_ = true;
    std::fprintf(stderr, "[info] player: keys: space pause/resume, s step, +/- rate, q quit\n");
    thread_ = std::thread([this] { Loop(); });
  }
  ~Keyboard() {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
    if (active_) tcsetattr(STDIN_FILENO, TCSANOW, &saved_);
  }

 private:
  void Loop() {
    while (!stop_ && node::ok()) {
      pollfd fd{STDIN_FILENO, POLLIN, 0};
      if (poll(&fd, 1, 100) <= 0) continue;
      char c = 0;
      if (read(STDIN_FILENO, &c, 1) != 1) continue;
      switch (c) {
        case ' ':
          player_.TogglePause();
          std::fprintf(stderr, "[info] player: %s\n", player_.paused() ? "paused" : "playing");
          break;
        case 's':
          player_.Step();
          break;
        case '+':
          player_.SetRate(player_.rate() * 1.25);
          std::fprintf(stderr, "[info] player: rate %.3g\n", player_.rate());
          break;
        case '-':
          player_.SetRate(player_.rate() / 1.25);
          std::fprintf(stderr, "[info] player: rate %.3g\n", player_.rate());
          break;
        case 'q':
          node::RequestShutdown();
          break;
        default:
          break;
      }
    }
  }
  replay::Player& player_;
  termios saved_{};
  bool active_ = false;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

constexpr const char* kUsage =
    "usage: player SOURCE [--rate R] [--fast] [--loop] [--start S] [--duration S]\n"
    "              [--topics REGEX]... [--exclude REGEX]... [--remap FROM:=TO]...\n"
    "              [--clock TOPIC | --no-clock] [--control TOPIC] [--lockstep NODE]... [--paused]\n"
    "              [--delay S] [--fps F] [--camera-info FILE] [--prefix /camera] [--max-frames N]\n"
    "              [--subjects 1,5] [--slots N] [--no-keyboard] [--ros-args ...]\n"
    "  SOURCE: an MCAP log or a dataset folder (docs/replay.md, docs/dataset.md)\n";

int Run(int argc, char** argv) {
  node::Node node(argc, argv, "player", kUsage);
  replay::PlayerOptions options;
  dataset::DatasetOptions dataset_options;
  std::string source_spec = node.Param("source", "");
  options.rate = node.Param("rate", 1.0);
  options.as_fast_as_possible = node.Param("fast", false);
  options.loop = node.Param("loop", false);
  options.start_s = node.Param("start", 0.0);
  options.duration_s = node.Param("duration", 0.0);
  options.include = node.Param("topics", std::vector<std::string>{});
  options.exclude = node.Param("exclude", std::vector<std::string>{});
  for (const auto& r : node.Param("remap", std::vector<std::string>{})) {
    options.remaps.push_back(ParseRemap(r));
  }
  options.clock_topic = node.Param("clock_topic", "/clock");
  options.control_topic = node.Param("control_topic", "/player/control");
  options.lockstep_nodes = node.Param("lockstep", std::vector<std::string>{});
  options.start_paused = node.Param("paused", false);
  double delay_s = node.Param("delay", 0.0);
  dataset_options.fps = node.Param("fps", 30.0);
  dataset_options.camera_info_path = node.Param("camera_info", "");
  dataset_options.topic_prefix = node.Param("topic_prefix", "/camera");
  dataset_options.max_frames = static_cast<uint64_t>(node.Param<int64_t>("max_frames", 0));
  for (int64_t s : node.Param("subjects", std::vector<int64_t>{})) {
    dataset_options.yaleb_subjects.push_back(static_cast<int>(s));
  }
  bool keyboard = node.Param("keyboard", true);
  options.slot_count = static_cast<uint32_t>(node.Param<int64_t>("slots", 8));
  node.CheckParamOverrides();

  const std::vector<std::string>& args = node.args();
  bool positional_seen = false;  // a positional SOURCE overrides param 'source'
  for (size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    auto value = [&]() -> const std::string& {
      if (i + 1 >= args.size()) throw node::UsageError(a + " needs a value");
      return args[++i];
    };
    if (a == "--rate") {
      options.rate = node::ParseNumberOption(a, value());
    } else if (a == "--fast") {
      options.as_fast_as_possible = true;
    } else if (a == "--loop") {
      options.loop = true;
    } else if (a == "--start") {
      options.start_s = node::ParseNumberOption(a, value());
    } else if (a == "--duration") {
      options.duration_s = node::ParseNumberOption(a, value());
    } else if (a == "--topics") {
      options.include.push_back(value());
    } else if (a == "--exclude") {
      options.exclude.push_back(value());
    } else if (a == "--remap") {
      options.remaps.push_back(ParseRemap(value()));
    } else if (a == "--clock") {
      options.clock_topic = value();
    } else if (a == "--no-clock") {
      options.clock_topic.clear();
    } else if (a == "--control") {
      options.control_topic = value();
    } else if (a == "--lockstep") {
      options.lockstep_nodes.push_back(value());
    } else if (a == "--paused") {
      options.start_paused = true;
    } else if (a == "--delay") {
      delay_s = node::ParseNumberOption(a, value());
    } else if (a == "--fps") {
      dataset_options.fps = parse::ParsePositiveDouble(a, value());
    } else if (a == "--camera-info") {
      dataset_options.camera_info_path = value();
    } else if (a == "--prefix") {
      dataset_options.topic_prefix = value();
    } else if (a == "--max-frames") {
      dataset_options.max_frames = parse::ParseInteger<uint64_t>(a, value());
    } else if (a == "--subjects") {
      dataset_options.yaleb_subjects = ParseSubjects(value());
    } else if (a == "--slots") {
      options.slot_count = parse::ParseInteger<uint32_t>(a, value(), 1);
    } else if (a == "--no-keyboard") {
      keyboard = false;
    } else if (a.starts_with("--")) {
      throw node::UsageError("unknown option '" + a + "'");
    } else if (!positional_seen) {
      source_spec = a;
      positional_seen = true;
    } else {
      throw node::UsageError("more than one source given ('" + source_spec + "' and '" + a + "')");
    }
  }
  if (source_spec.empty()) {
    throw node::UsageError("no source given (an MCAP log or a dataset folder, or param 'source')");
  }
  for (auto& name : options.lockstep_nodes) {
    if (!name.starts_with('/')) name = "/" + name;
  }

  std::unique_ptr<dataset::Source> source = replay::OpenSource(source_spec, dataset_options);
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
  if (delay_s > 0 &&
      node.WaitForShutdown(std::chrono::nanoseconds(static_cast<int64_t>(delay_s * 1e9)))) {
    return 0;
  }
  std::unique_ptr<Keyboard> keys;
  if (keyboard && isatty(STDIN_FILENO)) keys = std::make_unique<Keyboard>(player);
  const auto start = std::chrono::steady_clock::now();
  const replay::PlayerStats stats = player.Run([] { return node::ok(); });
  keys.reset();
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::vector<double> lateness = stats.lateness_us;
  std::sort(lateness.begin(), lateness.end());
  std::ostringstream summary;
  summary << "player: published " << stats.published << " messages in " << seconds << " s, "
          << stats.passes << " pass(es)";
  for (size_t t = 0; t < stats.per_topic.size(); ++t) {
    if (!player.published_topics()[t].empty()) {
      summary << "; " << player.published_topics()[t] << " " << stats.per_topic[t];
    }
  }
  if (!lateness.empty()) {
    summary << "; lateness median " << lateness[lateness.size() / 2] << " us, p99 "
            << lateness[std::min(lateness.size() - 1, lateness.size() * 99 / 100)] << " us";
  }
  if (!options.lockstep_nodes.empty())
    summary << "; lock-step wait " << stats.lockstep_wait_s << " s";
  std::printf("%s\n", summary.str().c_str());
  std::fflush(stdout);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return probeless::node::RunMain("player", [&] { return Run(argc, argv); });
}
