#include "params.h"

#include <sstream>
#include <utility>
#include <vector>

#include "probeless/parse/number.h"

namespace probeless::player {
namespace {

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

}  // namespace

void DeclareFlags(node::FlagParser& flags, PlayerSettings& s) {
  flags.AddPositional("SOURCE", &s.source, "an MCAP log or a dataset folder (docs/dataset.md)");
  flags.Add("--rate", &s.options.rate, "R", "playback speed (1 = as recorded)");
  flags.Add("--fast", &s.options.as_fast_as_possible, "as fast as possible, untimed");
  flags.Add("--loop", &s.options.loop, "start again at the end");
  flags.Add("--start", &s.options.start_s, "S", "skip the first S seconds");
  flags.Add("--duration", &s.options.duration_s, "S", "play S seconds (0 = all)");
  flags.Add("--topics", &s.options.include, "REGEX", "play only matching topics");
  flags.Add("--exclude", &s.options.exclude, "REGEX", "never play matching topics");
  flags.AddCallback("--remap", "FROM:=TO", "publish a topic under another name (repeatable)",
                    [&](const std::string& v) { s.options.remaps.push_back(ParseRemap(v)); });
  flags.Add("--clock", &s.options.clock_topic, "TOPIC", "clock topic");
  flags.AddSwitch(
      "--no-clock", [&] { s.options.clock_topic.clear(); }, "publish no clock");
  flags.Add("--control", &s.options.control_topic, "TOPIC", "pause/step/rate control topic");
  flags.Add("--lockstep", &s.options.lockstep_nodes, "NODE", "wait for NODE's acks");
  flags.Add("--paused", &s.options.start_paused, "start paused");
  flags.Add("--delay", &s.delay_s, "S", "wait S seconds before the first message");
  flags.AddPositive("--fps", &s.dataset.fps, "F", "frame rate of a dataset folder");
  flags.Add("--camera-info", &s.dataset.camera_info_path, "FILE", "camera calibration");
  flags.Add("--prefix", &s.dataset.topic_prefix, "PREFIX", "dataset topics' prefix");
  flags.Add("--max-frames", &s.dataset.max_frames, "N", "at most N frames (0 = all)");
  flags.AddCallback("--subjects", "1,5", "Yale B subjects to play",
                    [&](const std::string& v) { s.dataset.yaleb_subjects = ParseSubjects(v); });
  flags.Add("--slots", &s.options.slot_count, "N", "queue slots per topic", 1u);
  flags.AddSwitch(
      "--no-keyboard", [&] { s.keyboard = false; }, "ignore the terminal's keys");
}

void ReadParams(node::Node& node, PlayerSettings& s) {
  s.source = node.Param("source", "");
  s.options.rate = node.Param("rate", 1.0);
  s.options.as_fast_as_possible = node.Param("fast", false);
  s.options.loop = node.Param("loop", false);
  s.options.start_s = node.Param("start", 0.0);
  s.options.duration_s = node.Param("duration", 0.0);
  s.options.include = node.Param("topics", std::vector<std::string>{});
  s.options.exclude = node.Param("exclude", std::vector<std::string>{});
  for (const auto& r : node.Param("remap", std::vector<std::string>{})) {
    s.options.remaps.push_back(ParseRemap(r));
  }
  s.options.clock_topic = node.Param("clock_topic", "/clock");
  s.options.control_topic = node.Param("control_topic", "/player/control");
  s.options.lockstep_nodes = node.Param("lockstep", std::vector<std::string>{});
  s.options.start_paused = node.Param("paused", false);
  s.delay_s = node.Param("delay", 0.0);
  s.dataset.fps = node.Param("fps", 30.0);
  s.dataset.camera_info_path = node.Param("camera_info", "");
  s.dataset.topic_prefix = node.Param("topic_prefix", "/camera");
  s.dataset.max_frames = static_cast<uint64_t>(node.Param<int64_t>("max_frames", 0));
  for (int64_t subject : node.Param("subjects", std::vector<int64_t>{})) {
    s.dataset.yaleb_subjects.push_back(static_cast<int>(subject));
  }
  s.keyboard = node.Param("keyboard", true);
  s.options.slot_count = static_cast<uint32_t>(node.Param<int64_t>("slots", 8));
}

}  // namespace probeless::player
