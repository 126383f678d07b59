// python_bench_sub: the C++ subscriber of python_bench.py (docs/benchmarks/python.md).
//
//   python_bench_sub TOPIC OUT.json
//
// Subscribes TOPIC (probeless_msgs/Image, queue depth 64) and, per phase named by the frames'
// header.frame_id ("paced", "burst"; "end" stops), records the one-way latency of every sample
// (CLOCK_MONOTONIC once Take returned and the image is viewed, minus
// bus::MessageInfo::publish_mono_ns), the samples received and dropped, the wall time between the
// first and last sample and the process CPU time over it. Reads the frame's header and one pixel,
// as python_bench.py's Python subscriber does. Writes {"phase": {"latency_ns": [...], "received":
// n, "dropped": n, "wall_s": s, "cpu_s": s}} to OUT.json. Exit: 0, 2 on bad arguments or a bus
// error (one line on stderr).
#include <time.h>

#include <cstdio>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include "probeless/bus/bus.h"
#include "probeless/msgs/image.h"
#include "probeless/node/flags.h"
#include "probeless/node/main.h"

namespace {

using namespace probeless;

int64_t Now(clockid_t clock) {
  timespec t{};
  clock_gettime(clock, &t);
  return static_cast<int64_t>(t.tv_sec) * 1'000'000'000 + t.tv_nsec;
}

struct Phase {
  std::vector<int64_t> latency_ns;
  uint64_t dropped_before = 0;
  uint64_t dropped = 0;
  int64_t first_wall = 0, last_wall = 0, first_cpu = 0, last_cpu = 0;
};

int Run(const std::string& topic, const std::string& out_path) {
  bus::Subscriber subscriber(
      topic, msgs::TopicTypeOf<msgs::Image>(),
      {.queue_depth = 64, .receive_history = false, .node_name = "/python_bench_cpp"});
  std::map<std::string, Phase> phases;
  std::string current;
  uint64_t checksum = 0;
  while (true) {
    std::optional<bus::Sample> sample = subscriber.Take(std::chrono::seconds(30));
    if (!sample) {
      std::fprintf(stderr, "[error] [python_bench_sub] no frame for 30 s on %s\n", topic.c_str());
      return 2;
    }
    const auto image = msgs::ReadMessage<msgs::Image>(sample->data());
    const int64_t received = Now(CLOCK_MONOTONIC);
    const std::string phase(image->header.FrameId());
    if (phase == "end") break;
    checksum += static_cast<uint8_t>(image.payload[0]);
    Phase& p = phases[phase];
    if (phase != current) {
      p.dropped_before = subscriber.dropped();
      p.first_wall = received;
      p.first_cpu = Now(CLOCK_PROCESS_CPUTIME_ID);
      current = phase;
    }
    p.latency_ns.push_back(received - sample->info().publish_mono_ns);
    p.last_wall = received;
    p.last_cpu = Now(CLOCK_PROCESS_CPUTIME_ID);
    p.dropped = subscriber.dropped() - p.dropped_before;
  }
  std::ofstream out(out_path);
  out << "{";
  bool first_phase = true;
  for (const auto& [name, p] : phases) {
    out << (first_phase ? "" : ", ") << "\"" << name << "\": {\"latency_ns\": [";
    for (size_t i = 0; i < p.latency_ns.size(); ++i) out << (i ? ", " : "") << p.latency_ns[i];
    out << "], \"received\": " << p.latency_ns.size() << ", \"dropped\": " << p.dropped
        << ", \"wall_s\": " << (p.last_wall - p.first_wall) * 1e-9
        << ", \"cpu_s\": " << (p.last_cpu - p.first_cpu) * 1e-9 << "}";
    first_phase = false;
  }
  out << ", \"checksum\": " << checksum << "}\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return probeless::node::RunMain("python_bench_sub", [&] {
    std::string topic, out;
    probeless::node::FlagParser flags(
        "python_bench_sub",
        "the C++ subscriber of python_bench.py: per phase one-way latency, samples received and\n"
        "dropped, wall and CPU time (docs/benchmarks/python.md)");
    flags.AddPositional("TOPIC", &topic, "the probeless_msgs/Image topic (required)");
    flags.AddPositional("OUT.json", &out, "the figures (required)");
    if (!flags.Parse(argc, argv)) return 0;
    if (!flags.Given("TOPIC") || !flags.Given("OUT.json")) {
      throw probeless::node::UsageError("usage: python_bench_sub TOPIC OUT.json");
    }
    return Run(topic, out);
  });
}
