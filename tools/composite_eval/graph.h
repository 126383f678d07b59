// composite_eval: one run of launch/composite_eval.yaml (player in lock-step -> fusion ->
// scene_light -> three renderers) on a scene log, with the tool subscribed to the composites and
// to /scene/light over the bus of a private domain.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "probeless/msgs/sh_light.h"

namespace probeless::composite_eval {

struct GraphArgs {
  std::string probeless;                 // the probeless binary
  std::string launch_file;               // launch/composite_eval.yaml
  std::vector<std::string> launch_args;  // name:=value
  std::string domain;                    // PROBELESS_DOMAIN of this run
  std::string log_path;                  // the launch's stdout and stderr
  double timeout_s = 600;                // SIGINT to the launch after this long
};

struct Rgb8 {
  int width = 0, height = 0;
  std::vector<uint8_t> rgb;  // packed
};

// Set by the tool's SIGINT/SIGTERM handler: RunGraph stops the launch (SIGINT) and returns with
// `interrupted`.
void RequestStop();
bool StopRequested();

struct GraphOutput {
  std::map<int64_t, Rgb8> ours, oracle, baseline;  // by header.stamp_ns
  std::map<int64_t, msgs::ShLight> lights;         // /scene/light by stamp
  int exit_code = 0;
  bool timed_out = false;
  bool interrupted = false;
};

// Runs the graph and collects its outputs until the launch ends. `progress(done)` is called with
// the number of baseline composites (one per frame) whenever it grows. Throws std::runtime_error
// when the launch cannot be started.
GraphOutput RunGraph(const GraphArgs& args, const std::function<void(size_t)>& progress);

}  // namespace probeless::composite_eval
