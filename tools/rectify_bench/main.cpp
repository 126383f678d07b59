// rectify_bench: single-core time of rectify::Rectifier on a 640x480 frame of the Freiburg 1
// camera, written straight into a bus-slot-sized buffer (what the node does with its loans):
// rgb8 bilinear, depth16 nearest and edge-aware, the colour + depth pair (the budget), mono8, and
// the pass-through of a camera without distortion; plus the one-off map construction. Prints JSON
// (median and p90 wall ms, median thread-CPU ms, frames per second) on stdout, and to --json FILE.
// Budget: <= 2 ms per pair.
//
//   rectify_bench [--json OUT] [--iterations N]
#include "probeless/node/main.h"

#include <time.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <vector>

#include "probeless/node/flags.h"
#include "probeless/rectify/rectify.h"

namespace {

using namespace probeless;

struct Figure {
  std::string name;
  double median_ms;
  double p90_ms;
  double median_cpu_ms;  // this thread's CPU time: the cost on a machine shared with other jobs
};

double ThreadCpuMs() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) * 1e3 + static_cast<double>(t.tv_nsec) * 1e-6;
}

Figure Time(const std::string& name, int iterations, const std::function<void()>& body) {
  body();  // warm-up
  std::vector<double> ms, cpu;
  for (int i = 0; i < iterations; ++i) {
    const double c0 = ThreadCpuMs();
    const auto t0 = std::chrono::steady_clock::now();
    body();
    ms.push_back(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    cpu.push_back(ThreadCpuMs() - c0);
  }
  std::sort(ms.begin(), ms.end());
  std::sort(cpu.begin(), cpu.end());
  return {name, ms[ms.size() / 2], ms[ms.size() * 9 / 10], cpu[cpu.size() / 2]};
}

msgs::CameraInfo Freiburg1() {
  msgs::CameraInfo info;
  info.width = 640;
  info.height = 480;
  info.fx = 517.3;
  info.fy = 516.5;
  info.cx = 318.6;
  info.cy = 255.3;
  info.distortion_model = msgs::DistortionModel::kPlumbBob;
  info.distortion_count = 5;
  const double d[5] = {0.2624, -0.9531, -0.0054, 0.0026, 1.1633};
  for (int i = 0; i < 5; ++i) info.distortion[i] = d[i];
  info.depth_scale = 0.001;
  return info;
}

// A frame and its output slot.
struct Frame {
  msgs::Image in, out;
  std::vector<std::byte> pixels, slot;
  explicit Frame(msgs::Encoding e) {
    in.Init(640, 480, e);
    pixels.resize(in.PayloadBytes());
    slot.resize(in.PayloadBytes());
    // Texture and, for depth, two surfaces with an edge and holes.
    for (size_t i = 0; i < pixels.size(); ++i) pixels[i] = std::byte((i * 7 + i / 1920) % 251);
    if (e == msgs::Encoding::kDepth16) {
      auto* d = reinterpret_cast<uint16_t*>(pixels.data());
      for (size_t i = 0; i < 640 * 480; ++i) {
        d[i] = static_cast<uint16_t>((i % 640) < 320 ? 1200 + (i % 640) : 2400);
        if (i % 97 == 0) d[i] = 0;
      }
    }
  }
  void Run(const rectify::Rectifier& r) { r.Rectify(in, pixels, out, slot); }
};

}  // namespace

int Run(int argc, char** argv) {
  std::string json_path;
  int iterations = 300;
  probeless::node::FlagParser flags(
      "rectify_bench",
      "single-core time of rectify::Rectifier on a 640x480 Freiburg 1 frame into a\n"
      "bus-slot-sized buffer (rgb8, depth16 nearest and edge-aware, the pair, mono8, "
      "pass-through,\n"
      "map construction); prints JSON");
  flags.Add("--json", &json_path, "OUT", "also write the JSON to OUT");
  flags.Add("--iterations", &iterations, "N", "timed runs per figure", 1);
  if (!flags.Parse(argc, argv)) return 0;
  rectify::SetThreads(1);  // the budget is per core
  const msgs::CameraInfo info = Freiburg1();
  rectify::RectifyOptions edge;
  edge.depth_interpolation = rectify::DepthInterpolation::kEdgeAware;
  std::vector<Figure> figures;
  figures.push_back(
      Time("maps_plumb_bob (once per calibration)", 5, [&] { rectify::Rectifier r(info); }));
  const rectify::Rectifier nearest(info), edge_aware(info, edge);
  msgs::CameraInfo none = info;
  none.distortion_model = msgs::DistortionModel::kNone;
  none.distortion_count = 0;
  const rectify::Rectifier passthrough(none);
  Frame rgb(msgs::Encoding::kRgb8), depth(msgs::Encoding::kDepth16), mono(msgs::Encoding::kMono8);
  figures.push_back(Time("rgb8_bilinear", iterations, [&] { rgb.Run(nearest); }));
  figures.push_back(Time("depth16_nearest", iterations, [&] { depth.Run(nearest); }));
  figures.push_back(Time("depth16_edge_aware", iterations, [&] { depth.Run(edge_aware); }));
  figures.push_back(Time("pair_rgb8_depth16_nearest (budget)", iterations, [&] {
    rgb.Run(nearest);
    depth.Run(nearest);
  }));
  figures.push_back(Time("pair_rgb8_depth16_edge_aware", iterations, [&] {
    rgb.Run(edge_aware);
    depth.Run(edge_aware);
  }));
  figures.push_back(Time("mono8_bilinear", iterations, [&] { mono.Run(nearest); }));
  figures.push_back(Time("pair_passthrough (no distortion: copy)", iterations, [&] {
    rgb.Run(passthrough);
    depth.Run(passthrough);
  }));

  std::ostringstream json;
  json << "{\n  \"frame\": \"640x480\",\n  \"camera\": \"TUM Freiburg 1 (plumb_bob)\",\n"
       << "  \"threads\": 1,\n  \"iterations\": " << iterations
       << ",\n  \"budget_ms\": 2.0,\n  \"results\": [\n";
  for (size_t i = 0; i < figures.size(); ++i) {
    char line[256];
    std::snprintf(
        line, sizeof(line),
        "    {\"name\": \"%s\", \"median_ms\": %.3f, \"p90_ms\": %.3f, \"median_cpu_ms\": %.3f, "
        "\"fps\": %.0f}%s\n",
        figures[i].name.c_str(), figures[i].median_ms, figures[i].p90_ms, figures[i].median_cpu_ms,
        1000.0 / figures[i].median_ms, i + 1 < figures.size() ? "," : "");
    json << line;
  }
  json << "  ]\n}\n";
  std::fputs(json.str().c_str(), stdout);
  if (!json_path.empty()) std::ofstream(json_path) << json.str();
  return 0;
}

int main(int argc, char** argv) {
  return probeless::node::RunMain("rectify_bench", [&] { return Run(argc, argv); });
}
