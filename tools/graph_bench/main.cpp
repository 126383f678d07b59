// graph_bench: the live scene graph measured as a whole (docs/benchmarks/graph.md, issue #24).
//
//   graph_bench [--graph scene|face] [--source PATH] [--duration S] [--live | --lockstep]
//               [--json FILE] [--timeline FILE] [--work DIR] [--delay S] [--arg NAME:=VALUE ...]
//
// Runs launch/replay.yaml with face:=false render:=true record:=true (player -> rectify -> fusion
// -> scene_light -> renderer -> recorder) on a 7-Scenes log, in its own bus domain, once
// free-running at the source's rate ("live": slow nodes lose frames) and once in lock-step
// ("lockstep": every frame through every node, as fast as they go: the ceiling), each for
// --duration seconds of playing (default 10: the 300 shared frames; the graph ends earlier with the
// stream).
//   --graph     scene (above, the default) or face: face:=true scene:=false (player -> rectify ->
//               face_tracker -> face_light -> renderer in face mode -> recorder) on the synthetic
//               world's face_orbit scenario (120 frames, rendered once to <work>/face.mcap)
//   --source    a 7-Scenes folder (converted once to <work>/source.mcap by the library behind
//               `probeless bag convert`) or an MCAP log; default $PROBELESS_DATA/7scenes-redkitchen
//               (else the shared data folder beside the source tree)
//   --live, --lockstep   only that run (default both)
//   --delay     seconds the player waits before playing (replay.yaml record_delay; default 2), so
//               every node has subscribed when the first frame goes out
//   --arg       one more replay.yaml argument (e.g. subsample:=4 for OursFast), repeatable
//   --work      keep the log, recordings, node logs and statistics there (default: a temporary
//               folder, removed at the end)
//   --timeline  every handler call of every node of the first run, for plot_timeline.py
// Per run and node: frames received, handled and dropped per input, published per output, CPU
// seconds and percent of one core, processing time p50/p99 (the handler of the input that does the
// work: the one with the largest total time), from the node runtime's run statistics
// ($PROBELESS_NODE_STATS, node.h) or, for player and recorder, the bus registry polled every 50 ms
// and /proc. End-to-end latency, seen by a probe subscriber of this process (zero-copy, header
// only): the player's publish of /camera/image with stamp S (the moment a camera would deliver
// the frame) to the publish of /scene/light (face graph: /face/light) and /render/composite with
// stamp S (p50/p99/max).
// Camera frames played: the most that the probe, the polls or a node's input counted; the player's
// lateness against the source's timing (p50/p99) from its summary line in the launch log.
// Prints a table, writes the JSON to FILE. Exit: 0; 2 on a bad option or a missing source; 1 if a
// run fails.
#include "probeless/node/main.h"

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "probeless/bus/bus.h"
#include "probeless/launch/proc_stat.h"
#include "probeless/log/mcap.h"
#include "probeless/log/mcap_writer.h"
#include "probeless/msgs/msgs.h"
#include "probeless/node/flags.h"
#include "probeless/replay/sources.h"

extern char** environ;

namespace {

namespace fs = std::filesystem;
using namespace probeless;
using nlohmann::json;
using Clock = std::chrono::steady_clock;

constexpr char kDescription[] =
    "The scene graph of launch/replay.yaml (player -> rectify -> fusion -> scene_light ->\n"
    "renderer -> recorder) on a 7-Scenes log, live and in lock-step: per node frames, drops,\n"
    "CPU, processing time; camera -> /scene/light and -> /render/composite latency\n"
    "(docs/benchmarks/graph.md).";

struct Options {
  bool face = false;  // --graph face
  std::string source;
  double duration_s = 10.0;
  bool live = true;
  bool lockstep = true;
  std::string json_path;
  std::string timeline_path;
  std::string work;
  double delay_s = 2.0;
  std::vector<std::string> launch_args;
};

// The options of the command line; nothing after --help (the usage is printed).
std::optional<Options> ParseOptions(int argc, char** argv) {
  Options o;
  bool only_live = false, only_lockstep = false;
  std::string graph = "scene";
  node::FlagParser flags("graph_bench", kDescription);
  flags.AddChoice("--graph", &graph, {"scene", "face"},
                  "the scene graph on a 7-Scenes log, or the face graph on face_orbit");
  flags.Add("--source", &o.source, "PATH",
            "a 7-Scenes folder or an MCAP log (default: $PROBELESS_DATA/7scenes-redkitchen)");
  flags.Add("--duration", &o.duration_s, "S", "seconds of playing per run");
  flags.Add("--live", &only_live, "only the live run (default both)");
  flags.Add("--lockstep", &only_lockstep, "only the lock-step run (default both)");
  flags.Add("--json", &o.json_path, "FILE", "write the figures as JSON");
  flags.Add("--timeline", &o.timeline_path, "FILE",
            "every handler call of every node of the first run, for plot_timeline.py");
  flags.Add("--work", &o.work, "DIR",
            "keep the logs, recordings and statistics there (default: a temporary folder)");
  flags.Add("--delay", &o.delay_s, "S", "seconds the player waits before playing");
  flags.AddCallback("--arg", "NAME:=VALUE", "one more replay.yaml argument (repeatable)",
                    [&](const std::string& arg) {
                      if (arg.find(":=") == std::string::npos || arg.starts_with(":=")) {
                        throw node::UsageError("--arg expects NAME:=VALUE, got '" + arg + "'");
                      }
                      o.launch_args.push_back(arg);
                    });
  if (!flags.Parse(argc, argv)) return std::nullopt;
  o.face = graph == "face";
  if (!(o.duration_s > 0)) throw node::UsageError("--duration expects seconds > 0");
  if (!(o.delay_s >= 0)) throw node::UsageError("--delay expects seconds >= 0");
  if (only_live && only_lockstep)
    throw node::UsageError("--live and --lockstep exclude each other");
  if (only_live) o.lockstep = false;
  if (only_lockstep) o.live = false;
  if (o.source.empty() && o.face) {
    o.source = "sim:" + std::string(PROBELESS_SOURCE_DIR) + "/data/scenarios/face_orbit.yaml";
  } else if (o.source.empty()) {
    const char* env = std::getenv("PROBELESS_DATA");
    o.source =
        (fs::path(env != nullptr && *env != '\0' ? env : PROBELESS_DATA_DIR) / "7scenes-redkitchen")
            .string();
  }
  if (!fs::exists(o.source.starts_with("sim:") ? o.source.substr(4) : o.source)) {
    throw node::UsageError("--source '" + o.source +
                           "' not found (set PROBELESS_DATA to the shared data folder)");
  }
  return o;
}

int64_t MonotonicNs() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return int64_t{ts.tv_sec} * 1'000'000'000 + ts.tv_nsec;
}

// CPU seconds (user + system, all threads) of process `pid`, or nullopt once it is gone.
std::optional<double> CpuSeconds(pid_t pid) {
  const std::optional<probeless::launch::ProcStat> stat = probeless::launch::ReadProcStat(pid);
  if (!stat) return std::nullopt;
  return stat->CpuSeconds();
}

std::vector<double> LoadAverage() {
  std::ifstream f("/proc/loadavg");
  double a = 0, b = 0, c = 0;
  f >> a >> b >> c;
  return {a, b, c};
}

json Percentiles(std::vector<double> v) {
  json out = {{"count", v.size()}};
  if (v.empty()) return out;
  std::sort(v.begin(), v.end());
  auto at = [&](double q) { return v[std::min(v.size() - 1, static_cast<size_t>(q * v.size()))]; };
  out["p50"] = at(0.5);
  out["p99"] = at(0.99);
  out["max"] = v.back();
  return out;
}

// What the 50 ms polls of the bus registry and /proc saw of one process.
struct Polled {
  std::string node;
  double cpu_s = 0;
  int64_t first_seen_ns = 0, last_seen_ns = 0;
  std::map<std::string, uint64_t> published;
  std::map<std::string, std::pair<uint64_t, uint64_t>> received_dropped;
};

class Child {
 public:
  Child(const std::vector<std::string>& args, const std::string& log) {
    std::vector<char*> argv;
    for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
    posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, log.c_str(),
                                     O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&actions, STDOUT_FILENO, STDERR_FILENO);
    const int rc = posix_spawn(&pid_, args[0].c_str(), &actions, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    if (rc != 0) throw std::runtime_error("cannot start " + args[0] + ": " + std::strerror(rc));
  }
  ~Child() {
    if (!exited_) {
      kill(pid_, SIGKILL);
      Wait(std::chrono::seconds(5));
    }
  }
  // True once the process has ended (status() valid).
  bool Poll() {
    if (exited_) return true;
    int status = 0;
    if (waitpid(pid_, &status, WNOHANG) == pid_) {
      exited_ = true;
      status_ = status;
    }
    return exited_;
  }
  bool Wait(std::chrono::nanoseconds timeout) {
    const auto end = Clock::now() + timeout;
    while (!Poll() && Clock::now() < end)
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    return exited_;
  }
  void Signal(int signal) const {
    if (!exited_) kill(pid_, signal);
  }
  int exit_code() const {
    return WIFEXITED(status_) ? WEXITSTATUS(status_) : 128 + WTERMSIG(status_);
  }

 private:
  pid_t pid_ = -1;
  bool exited_ = false;
  int status_ = 0;
};

fs::path ExeDir() { return fs::read_symlink("/proc/self/exe").parent_path(); }

// The probe: one subscriber each on /camera/image, /scene/light and /render/composite (queue 64,
// zero-copy; it reads the header and the bus publish times and releases the slot at once), so
// the latencies depend neither on the recorder's discovery nor on its drops.
class Probe {
 public:
  // /camera/image, the light (/scene/light or /face/light), /render/composite.
  explicit Probe(const std::string& light_topic) {
    bus::SubscriberOptions options;
    options.queue_depth = 64;
    options.node_name = "/graph_bench_probe";
    subscribers_.emplace_back("/camera/image", msgs::TopicTypeOf<msgs::Image>(), options);
    subscribers_.emplace_back(light_topic, msgs::TopicTypeOf<msgs::ShLight>(), options);
    subscribers_.emplace_back("/render/composite", msgs::TopicTypeOf<msgs::Image>(), options);
    for (bus::Subscriber& s : subscribers_) wait_set_.Add(s);
    thread_ = std::thread([this] { Loop(); });
  }
  ~Probe() { Stop(); }
  void Stop() {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
  }
  struct Seen {
    int64_t stamp_ns, publish_wall_ns, publish_mono_ns;
  };
  // Per topic (the order above), after Stop().
  const std::vector<Seen>& seen(size_t topic) const { return seen_[topic]; }
  // Messages the probe's queues lost (it shares the cores with the graph).
  uint64_t dropped() const {
    uint64_t n = 0;
    for (const bus::Subscriber& s : subscribers_) n += s.dropped();
    return n;
  }

 private:
  void Loop() {
    while (!stop_) {
      for (size_t i : wait_set_.Wait(std::chrono::milliseconds(20))) {
        while (auto sample = subscribers_[i].TryTake()) {
          const auto* header = reinterpret_cast<const msgs::Header*>(sample->data().data());
          seen_[i].push_back(
              {header->stamp_ns, sample->info().publish_wall_ns, sample->info().publish_mono_ns});
        }
      }
    }
  }
  std::vector<bus::Subscriber> subscribers_;
  bus::WaitSet wait_set_;
  std::vector<Seen> seen_[3];
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

// Camera -> /scene/light and -> /render/composite latencies, matched by header stamp.
json Latencies(const Probe& probe, bool face) {
  std::map<int64_t, int64_t> camera;  // stamp -> the player's publish of /camera/image
  for (const Probe::Seen& s : probe.seen(0)) camera.emplace(s.stamp_ns, s.publish_wall_ns);
  auto latency = [&](size_t topic) {
    std::vector<double> ms;
    size_t unmatched = 0;
    for (const Probe::Seen& s : probe.seen(topic)) {
      const auto it = camera.find(s.stamp_ns);
      if (it == camera.end()) {
        ++unmatched;
        continue;
      }
      ms.push_back((s.publish_wall_ns - it->second) * 1e-6);
    }
    json j = Percentiles(ms);
    j["unmatched"] = unmatched;
    return j;
  };
  json out;
  out[face ? "camera_to_face_light_ms" : "camera_to_scene_light_ms"] = latency(1);
  out["camera_to_composite_ms"] = latency(2);
  const auto& images = probe.seen(0);
  out["probe_camera_frames"] = images.size();
  out["probe_dropped"] = probe.dropped();
  out[face ? "face_lights" : "scene_lights"] = probe.seen(1).size();
  out["composites"] = probe.seen(2).size();
  if (images.size() > 1) {
    out["played_s"] = (images.back().publish_wall_ns - images.front().publish_wall_ns) * 1e-9;
    out["camera_fps"] = (images.size() - 1) / (out["played_s"].get<double>());
  }
  return out;
}

// One run of the graph; `timeline` gets every handler call when non-null.
json RunGraph(const Options& o, const fs::path& mcap, const fs::path& dir, bool lockstep,
              json* timeline) {
  const fs::path stats_dir = dir / "stats";
  const fs::path out_dir = dir / "out";
  fs::remove_all(dir);
  fs::create_directories(stats_dir);
  fs::create_directories(out_dir);
  setenv("PROBELESS_NODE_STATS", stats_dir.c_str(), 1);
  std::vector<std::string> args = {(ExeDir() / "probeless").string(),
                                   "launch",
                                   std::string(PROBELESS_SOURCE_DIR) + "/launch/replay.yaml",
                                   "source:=" + mcap.string(),
                                   std::string("face:=") + (o.face ? "true" : "false"),
                                   std::string("scene:=") + (o.face ? "false" : "true"),
                                   "render:=true",
                                   "record:=true",
                                   "out:=" + out_dir.string(),
                                   std::string("lockstep:=") + (lockstep ? "true" : "false"),
                                   "record_delay:=" + std::to_string(o.delay_s)};
  args.insert(args.end(), o.launch_args.begin(), o.launch_args.end());
  const std::string domain = bus::CurrentDomain();
  const json load_before = LoadAverage();
  const double own_cpu_at_start = CpuSeconds(getpid()).value_or(0.0);
  Probe probe(o.face ? "/face/light" : "/scene/light");
  Child launch(args, (dir / "launch.log").string());
  std::map<pid_t, Polled> polled;
  std::optional<Clock::time_point> playing_since;
  const auto started = Clock::now();
  bool stopped = false;
  bool stopped_by_stream = false;
  while (!launch.Poll()) {
    const int64_t now = MonotonicNs();
    bool camera_publisher = false;
    for (const bus::TopicSnapshot& topic : bus::ListTopics(domain)) {
      for (const bus::PublisherSnapshot& p : topic.publishers) {
        if (!p.alive) continue;
        if (topic.topic == "/camera/image") camera_publisher = true;
        Polled& proc = polled[p.pid];
        proc.node = p.node_name;
        proc.published[topic.topic] = std::max(proc.published[topic.topic], p.published);
        if (!playing_since && topic.topic == "/camera/image" && p.published > 0) {
          playing_since = Clock::now();
        }
      }
      for (const bus::SubscriberSnapshot& s : topic.subscribers) {
        if (!s.alive) continue;
        Polled& proc = polled[s.pid];
        proc.node = s.node_name;
        auto& [received, dropped] = proc.received_dropped[topic.topic];
        received = std::max(received, s.received);
        dropped = std::max(dropped, s.dropped);
      }
    }
    for (auto& [pid, proc] : polled) {
      if (const auto cpu = CpuSeconds(pid)) {
        // This process (the probe) counts from the run's start, not from the conversion.
        proc.cpu_s = pid == getpid() ? *cpu - own_cpu_at_start : *cpu;
        if (proc.first_seen_ns == 0) proc.first_seen_ns = now;
        proc.last_seen_ns = now;
      }
    }
    // The stream has ended (the player is gone): the supervisor stops the graph itself, and a
    // second SIGINT would make it escalate to SIGTERM before the nodes wrote their statistics.
    if (playing_since && !camera_publisher && !stopped) stopped_by_stream = true;
    if (!stopped && !stopped_by_stream && playing_since &&
        Clock::now() - *playing_since >= std::chrono::duration<double>(o.duration_s)) {
      launch.Signal(SIGINT);
      stopped = true;
    }
    // A graph that never starts playing or does not stop: SIGINT, then the supervisor's
    // escalation; our child alone is killed in the end (~Child).
    const auto overdue = std::chrono::duration<double>(o.delay_s + o.duration_s + 60.0);
    if (Clock::now() - started >= overdue && !stopped && !stopped_by_stream) {
      std::fprintf(stderr, "graph_bench: the graph did not end in time, stopping it\n");
      launch.Signal(SIGINT);
      stopped = true;
    }
    if (Clock::now() - started >= overdue + std::chrono::seconds(30)) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  json run = {{"mode", lockstep ? "lockstep" : "live"},
              {"launch_exit_code", launch.exit_code()},
              {"stopped_after_duration", stopped},
              {"stream_ended", stopped_by_stream},
              {"load_before", load_before},
              {"load_after", LoadAverage()}};

  // Nodes: the runtime's statistics where the node spins, else the polls.
  json nodes = json::object();
  std::set<std::string> with_stats;
  for (const auto& entry : fs::directory_iterator(stats_dir)) {
    std::ifstream f(entry.path());
    const json s = json::parse(f);
    const std::string name = s["node"];
    with_stats.insert(name);
    json n = {{"pid", s["pid"]}};
    json inputs = json::object();
    const json* busiest = nullptr;
    for (const json& in : s["inputs"]) {
      inputs[in["topic"].get<std::string>()] = {{"received", in["received"]},
                                                {"handled", in["handled"]},
                                                {"dropped", in["dropped"]},
                                                {"handler_ms", in["handler_ms"]}};
      if (busiest == nullptr ||
          in["handler_total_s"].get<double>() > (*busiest)["handler_total_s"].get<double>()) {
        busiest = &in;
      }
    }
    json outputs = json::object();
    for (const json& out : s["outputs"]) {
      const std::string topic = out["topic"];
      if (!topic.ends_with("/ack")) outputs[topic] = out["published"];
    }
    const double cpu = s["cpu_user_s"].get<double>() + s["cpu_system_s"].get<double>();
    const double wall = s["wall_s"];
    n["inputs"] = inputs;
    n["outputs"] = outputs;
    n["cpu_s"] = cpu;
    n["wall_s"] = wall;
    n["cpu_percent"] = wall > 0 ? 100.0 * cpu / wall : 0.0;
    if (busiest != nullptr) {
      n["process_input"] = (*busiest)["topic"];
      n["process_frames"] = (*busiest)["handled"];
      n["process_ms"] = (*busiest)["handler_ms"];
      n["process_received"] = (*busiest)["received"];
      n["process_dropped"] = (*busiest)["dropped"];
    }
    nodes[name] = n;
    if (timeline != nullptr) {
      json calls = json::array();
      for (const json& c : s["calls"]) {
        calls.push_back({(c[0].get<int64_t>()) * 1e-9, c[1].get<int64_t>() * 1e-9, c[2]});
      }
      json topics = json::array();
      for (const json& in : s["inputs"]) topics.push_back(in["topic"]);
      (*timeline)["nodes"][name] = {{"inputs", topics}, {"calls", calls}};
    }
  }
  for (const auto& [pid, proc] : polled) {
    if (proc.node.empty() || with_stats.contains(proc.node)) continue;
    json n = {{"pid", pid}, {"source", "bus registry and /proc, polled every 50 ms"}};
    json inputs = json::object();
    for (const auto& [topic, rd] : proc.received_dropped) {
      if (topic.ends_with("/ack")) continue;
      inputs[topic] = {{"received", rd.first}, {"dropped", rd.second}};
    }
    json outputs = json::object();
    for (const auto& [topic, count] : proc.published) outputs[topic] = count;
    const double wall = (proc.last_seen_ns - proc.first_seen_ns) * 1e-9;
    n["inputs"] = inputs;
    n["outputs"] = outputs;
    n["cpu_s"] = proc.cpu_s;
    n["wall_s"] = wall;
    n["cpu_percent"] = wall > 0 ? 100.0 * proc.cpu_s / wall : 0.0;
    nodes[proc.node] = n;
  }
  run["nodes"] = nodes;
  probe.Stop();
  run["latency"] = Latencies(probe, o.face);
  // The camera frames played: the largest count anyone saw (the probe and the polls can each miss
  // a few, a node that subscribed from the start none).
  uint64_t camera_frames = probe.seen(0).size();
  for (const auto& [name, n] : nodes.items()) {
    if (n["outputs"].contains("/camera/image")) {
      camera_frames = std::max(camera_frames, n["outputs"]["/camera/image"].get<uint64_t>());
    }
    if (n["inputs"].contains("/camera/image")) {
      camera_frames =
          std::max(camera_frames, n["inputs"]["/camera/image"]["received"].get<uint64_t>());
    }
  }
  run["camera_frames"] = camera_frames;
  // How late the player published against the source's timing (its summary line in the log).
  {
    std::ifstream log(dir / "launch.log");
    std::string line;
    while (std::getline(log, line)) {
      const size_t at = line.find("lateness median ");
      if (line.find("player: published") == std::string::npos || at == std::string::npos) continue;
      double median_us = 0, p99_us = 0;
      if (std::sscanf(line.c_str() + at, "lateness median %lf us, p99 %lf us", &median_us,
                      &p99_us) == 2) {
        run["player_lateness_ms"] = {{"p50", median_us * 1e-3}, {"p99", p99_us * 1e-3}};
      }
    }
  }
  for (auto& [name, n] : run["nodes"].items()) {
    if (n.contains("process_frames") && camera_frames > 0) {
      n["process_percent"] = 100.0 * n["process_frames"].get<double>() / camera_frames;
    }
  }
  if (timeline != nullptr) {
    (*timeline)["mode"] = run["mode"];
    (*timeline)["note"] =
        "calls: [start CLOCK_MONOTONIC s, duration s, input index]; camera_s: the player's "
        "publish of each /camera/image, on CLOCK_MONOTONIC";
    json camera = json::array();
    for (const Probe::Seen& seen : probe.seen(0)) camera.push_back(seen.publish_mono_ns * 1e-9);
    (*timeline)["camera_s"] = camera;
  }
  return run;
}

// The rows of one run for the printed table.
void PrintRun(const json& run) {
  const json& l = run["latency"];
  const uint64_t frames = run.value("camera_frames", uint64_t{0});
  std::printf("%s run (exit %d, load %.2f -> %.2f): %llu camera frames in %.1f s\n",
              run["mode"].get<std::string>().c_str(), run["launch_exit_code"].get<int>(),
              run["load_before"][0].get<double>(), run["load_after"][0].get<double>(),
              static_cast<unsigned long long>(frames), l.value("played_s", 0.0));
  std::printf("  %-18s %-20s %8s %8s %8s %6s %6s %9s %9s\n", "node", "input", "received", "handled",
              "dropped", "%", "cpu%", "p50 ms", "p99 ms");
  for (const auto& [name, n] : run["nodes"].items()) {
    if (!n.contains("process_ms")) {
      std::printf("  %-18s %-20s %8s %8s %8s %6s %6.0f\n", name.c_str(), "-", "-", "-", "-", "-",
                  n["cpu_percent"].get<double>());
      continue;
    }
    const uint64_t handled = n["process_frames"];
    std::printf("  %-18s %-20s %8llu %8llu %8llu %6.1f %6.0f %9.2f %9.2f\n", name.c_str(),
                n["process_input"].get<std::string>().c_str(),
                static_cast<unsigned long long>(n["process_received"].get<uint64_t>()),
                static_cast<unsigned long long>(handled),
                static_cast<unsigned long long>(n["process_dropped"].get<uint64_t>()),
                frames > 0 ? 100.0 * handled / frames : 0.0, n["cpu_percent"].get<double>(),
                n["process_ms"]["p50"].get<double>(), n["process_ms"]["p99"].get<double>());
  }
  if (run.contains("player_lateness_ms")) {
    std::printf("  player lateness p50 %.1f ms, p99 %.1f ms\n",
                run["player_lateness_ms"]["p50"].get<double>(),
                run["player_lateness_ms"]["p99"].get<double>());
  }
  for (const char* key :
       {"camera_to_scene_light_ms", "camera_to_face_light_ms", "camera_to_composite_ms"}) {
    if (!l.contains(key) || !l[key].contains("p50")) continue;
    std::printf("  %-26s n=%llu p50 %.1f ms, p99 %.1f ms\n", key,
                static_cast<unsigned long long>(l[key]["count"].get<uint64_t>()),
                l[key]["p50"].get<double>(), l[key]["p99"].get<double>());
  }
}

int Run(int argc, char** argv) {
  const std::optional<Options> parsed = ParseOptions(argc, argv);
  if (!parsed) return 0;
  const Options& o = *parsed;
  // A bus domain of our own: the graph never meets another run's topics.
  const std::string domain = "graph_bench_" + std::to_string(getpid());
  setenv("PROBELESS_DOMAIN", domain.c_str(), 1);
  const bool temporary = o.work.empty();
  const fs::path work =
      temporary ? fs::temp_directory_path() / ("graph_bench." + std::to_string(getpid()))
                : fs::path(o.work);
  fs::create_directories(work);

  fs::path mcap = o.source;
  uint64_t source_frames = 0;
  if (fs::is_directory(o.source) || o.source.starts_with("sim:")) {
    mcap = work / (o.face ? "face.mcap" : "source.mcap");
    auto source = replay::OpenSource(o.source);
    for (const auto& t : source->topics()) {
      if (t.topic == "/camera/image") source_frames = t.message_count;
    }
    if (!fs::exists(mcap)) {
      std::fprintf(stderr, "graph_bench: converting %s to %s\n", o.source.c_str(), mcap.c_str());
      log::WriterOptions writer;
      writer.compression = log::ParseCompressionOption("lz4");
      replay::ConvertToMcap(*source, mcap.string(), writer);
    }
  } else {
    auto source = replay::OpenSource(o.source);
    for (const auto& t : source->topics()) {
      if (t.topic == "/camera/image") source_frames = t.message_count;
    }
  }

  json result = {
      {"tool", "graph_bench"},
      {"graph", o.face ? "launch/replay.yaml face:=true scene:=false render:=true record:=true"
                       : "launch/replay.yaml face:=false render:=true record:=true"},
      {"source", o.source},
      {"source_camera_frames", source_frames},
      {"duration_s", o.duration_s},
      {"delay_s", o.delay_s},
      {"launch_args", o.launch_args},
      {"cores", std::thread::hardware_concurrency()}};
  json timeline;
  json runs = json::object();
  int code = 0;
  for (const bool lockstep : {false, true}) {
    if (lockstep ? !o.lockstep : !o.live) continue;
    const std::string mode = lockstep ? "lockstep" : "live";
    std::fprintf(stderr, "graph_bench: %s run, %.1f s\n", mode.c_str(), o.duration_s);
    const bool want_timeline = !o.timeline_path.empty() && timeline.is_null();
    json run = RunGraph(o, mcap, work / mode, lockstep, want_timeline ? &timeline : nullptr);
    bus::CleanDeadSegments(domain);
    if (run["launch_exit_code"].get<int>() != 0 && !run["stopped_after_duration"].get<bool>()) {
      std::fprintf(stderr, "graph_bench: the %s run failed (see %s)\n", mode.c_str(),
                   (work / mode / "launch.log").c_str());
      code = 1;
    }
    PrintRun(run);
    runs[mode] = run;
  }
  result["runs"] = runs;
  if (!o.json_path.empty()) {
    std::ofstream f(o.json_path);
    f << result.dump(2) << "\n";
    if (!f) throw std::runtime_error("cannot write " + o.json_path);
  }
  if (!o.timeline_path.empty()) {
    std::ofstream f(o.timeline_path);
    f << timeline.dump() << "\n";
  }
  if (temporary) fs::remove_all(work);
  return code;
}

}  // namespace

int main(int argc, char** argv) {
  return node::RunMain("graph_bench", [&] { return Run(argc, argv); });
}
