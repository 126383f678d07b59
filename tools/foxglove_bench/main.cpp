// foxglove_bench: the foxglove_bridge process between a bus publisher and a WebSocket client
// (the raw test client of common/foxglove/testing, reading as fast as it can), on loopback.
// Phases, each a fresh bridge:
//   idle      a 30 fps 640x480 rgb8 stream on the bus, no client subscribed: the bridge's CPU
//   raw_30    that stream, one client subscribed to the raw channel (sensor_msgs/Image CDR)
//   jpeg_30   that stream, one client subscribed to <topic>/compressed (JPEG quality 80)
//   raw_max   the same frames published unpaced (as fast as the bridge forwards them)
// Per phase: frames published and received, latency (bus publish -> client has the whole frame;
// both stamps CLOCK_REALTIME on this host) median/p90/max, received frames/s and MB/s, the
// bridge's CPU (utime + stime of its process over the phase / wall time, 100 % = one core).
//   foxglove_bench [--seconds S] [--json FILE]
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
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "probeless/bus/bus.h"
#include "probeless/launch/proc_stat.h"
#include "probeless/msgs/msgs.h"
#include "probeless/node/flags.h"
#include "raw_ws_client.h"

extern char** environ;

namespace {

using namespace probeless;
using foxglove::test_client::RawClient;
using nlohmann::json;
using Clock = std::chrono::steady_clock;

constexpr uint32_t kWidth = 640;
constexpr uint32_t kHeight = 480;
const std::string kTopic = "/bench/image";

int64_t RealtimeNs() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return int64_t{ts.tv_sec} * 1'000'000'000 + ts.tv_nsec;
}

// CPU seconds (user + system) of process `pid` so far; the bridge must still run.
double CpuSeconds(pid_t pid) {
  const std::optional<probeless::launch::ProcStat> stat = probeless::launch::ReadProcStat(pid);
  if (!stat) throw std::runtime_error("the bridge (pid " + std::to_string(pid) + ") is gone");
  return stat->CpuSeconds();
}

// The bridge as a child process; its stderr goes to a file, read for the port.
class Bridge {
 public:
  Bridge(const std::string& exe, const std::string& log) {
    std::vector<std::string> args = {exe,  "--ros-args",
                                     "-p", "port:=0",
                                     "-p", "topic_regex:=^/bench/",
                                     "-p", "jpeg_topics:=[" + kTopic + "]",
                                     "-p", "stats_period_s:=0"};
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, "/dev/null", O_WRONLY, 0);
    posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, log.c_str(),
                                     O_WRONLY | O_CREAT | O_TRUNC, 0600);
    if (posix_spawn(&pid_, exe.c_str(), &actions, nullptr, argv.data(), environ) != 0) {
      throw std::runtime_error("cannot start " + exe);
    }
    posix_spawn_file_actions_destroy(&actions);
    for (int i = 0; i < 500 && port_ == 0; ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
      std::ifstream f(log);
      const std::string text((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
      const size_t at = text.find("listening on ws://127.0.0.1:");
      if (at != std::string::npos) port_ = static_cast<uint16_t>(std::stoi(text.substr(at + 28)));
    }
    if (port_ == 0)
      throw std::runtime_error("the bridge did not start listening (log " + log + ")");
  }
  ~Bridge() {
    kill(pid_, SIGINT);
    int status = 0;
    waitpid(pid_, &status, 0);
  }
  pid_t pid() const { return pid_; }
  uint16_t port() const { return port_; }

 private:
  pid_t pid_ = -1;
  uint16_t port_ = 0;
};

struct Result {
  std::string name;
  double seconds = 0;
  uint64_t published = 0;
  uint64_t received = 0;
  std::vector<double> latency_ms;
  uint64_t bytes = 0;
  double cpu_percent = 0;
};

double Percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[static_cast<size_t>(p * static_cast<double>(v.size() - 1) + 0.5)];
}

// One phase: channel "" = no client.
Result Phase(const std::string& name, const std::string& exe, const std::string& channel_topic,
             double hz, double seconds) {
  bus::PublisherOptions po;
  po.max_message_bytes = msgs::Image::MessageBytesFor(kWidth, kHeight, msgs::Encoding::kRgb8);
  po.slot_count = 16;
  po.node_name = "/foxglove_bench";
  bus::Publisher pub(kTopic, msgs::TopicTypeOf<msgs::Image>(), po);
  const std::string log = "/tmp/foxglove_bench_" + std::to_string(getpid()) + ".log";
  Bridge bridge(exe, log);

  std::atomic<bool> done{false};
  std::atomic<uint64_t> published{0};
  uint32_t frame = 0;
  auto publish_one = [&] {
    bus::Loan loan = pub.Borrow(po.max_message_bytes);
    auto [image, payload] = msgs::WriteMessage<msgs::Image>(loan.data());
    image->Init(kWidth, kHeight, msgs::Encoding::kRgb8);
    image->header.SetFrameId("camera_optical");
    image->header.sequence = ++frame;
    // A moving gradient: JPEG sizes like a camera's, not a flat frame's.
    for (uint32_t y = 0; y < kHeight; ++y) {
      std::byte* row = payload.data() + size_t{y} * image->step;
      for (uint32_t x = 0; x < kWidth * 3; ++x) row[x] = std::byte((x + y + frame * 4) & 0xff);
    }
    image->header.stamp_ns = RealtimeNs();
    pub.Publish(std::move(loan));
    ++published;
  };

  Result r;
  r.name = name;
  std::optional<RawClient> client;
  if (!channel_topic.empty()) {
    client.emplace(bridge.port());
    if (client->Handshake("foxglove.websocket.v1").find(" 101 ") == std::string::npos) {
      throw std::runtime_error("handshake refused");
    }
    uint32_t channel = 0;
    for (int i = 0; i < 200 && channel == 0; ++i) {
      const json m = client->NextJson();
      if (m.is_null()) break;
      if (m.value("op", "") != "advertise") continue;
      for (const json& c : m["channels"]) {
        if (c["topic"] == channel_topic) channel = c["id"];
      }
      if (channel == 0) publish_one();  // the topic is new: let the bridge's rescan find it
    }
    if (channel == 0) throw std::runtime_error(channel_topic + " was not advertised");
    client->Send(R"({"op":"subscribe","subscriptions":[{"id":1,"channelId":)" +
                     std::to_string(channel) + "}]}",
                 1);
  }
  // Warm-up: the bridge subscribes (within ~20 ms) and the first frames pass.
  for (int i = 0; i < 15; ++i) {
    publish_one();
    std::this_thread::sleep_for(std::chrono::milliseconds(33));
  }
  if (client) {  // drain what the warm-up produced (time frames keep coming: by the clock)
    const auto until = Clock::now() + std::chrono::milliseconds(500);
    while (Clock::now() < until && client->Next(std::chrono::milliseconds(100))) {
    }
  }
  published = 0;
  const double cpu0 = CpuSeconds(bridge.pid());
  const auto start = Clock::now();
  const auto end =
      start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds));
  std::thread publisher([&] {
    auto next = Clock::now();
    while (Clock::now() < end) {
      if (hz > 0) {
        next += std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1 / hz));
        std::this_thread::sleep_until(next);
        publish_one();
      } else {
        // Unpaced, but never more than the bus pool holds in flight.
        publish_one();
        std::this_thread::sleep_for(std::chrono::microseconds(500));
      }
    }
    done = true;
  });
  if (client) {
    while (!done || Clock::now() < end + std::chrono::milliseconds(300)) {
      const auto f = client->Next(std::chrono::milliseconds(300));
      if (!f) {
        if (done) break;
        continue;
      }
      if (f->first != 2 || f->second.size() < 13 + 12 || f->second[0] != 0x01) continue;
      int32_t sec = 0;
      uint32_t nsec = 0;
      std::memcpy(&sec, f->second.data() + 13 + 4, 4);
      std::memcpy(&nsec, f->second.data() + 13 + 8, 4);
      const int64_t stamp = int64_t{sec} * 1'000'000'000 + nsec;
      r.latency_ms.push_back(static_cast<double>(RealtimeNs() - stamp) * 1e-6);
      r.bytes += f->second.size();
      ++r.received;
    }
  }
  publisher.join();
  const double wall = std::chrono::duration<double>(Clock::now() - start).count();
  r.cpu_percent = 100.0 * (CpuSeconds(bridge.pid()) - cpu0) / wall;
  r.seconds = std::chrono::duration<double>(end - start).count();
  r.published = published;
  std::filesystem::remove(log);
  return r;
}

int Main(int argc, char** argv) {
  std::string json_path;
  double seconds = 10;
  node::FlagParser flags("foxglove_bench",
                         "the foxglove_bridge process between a bus publisher and a WebSocket "
                         "client on loopback:\nidle, raw_30, jpeg_30 and raw_max phases (latency, "
                         "frames/s, MB/s, the bridge's CPU)");
  flags.Add("--seconds", &seconds, "S", "length of each phase (> 0)");
  flags.Add("--json", &json_path, "FILE", "write the figures as JSON");
  if (!flags.Parse(argc, argv)) return 0;
  if (!(seconds > 0)) throw node::UsageError("--seconds must be > 0");
  const std::string exe =
      (std::filesystem::read_symlink("/proc/self/exe").parent_path() / "foxglove_bridge").string();
  setenv("PROBELESS_DOMAIN", ("foxbench" + std::to_string(getpid())).c_str(), 1);
  std::vector<Result> results;
  results.push_back(Phase("idle", exe, "", 30, seconds));
  results.push_back(Phase("raw_30", exe, kTopic, 30, seconds));
  results.push_back(Phase("jpeg_30", exe, kTopic + "/compressed", 30, seconds));
  results.push_back(Phase("raw_max", exe, kTopic, 0, seconds));
  bus::CleanDeadSegments();

  json out = {{"frame", "640x480 rgb8 (921600 B payload)"},
              {"seconds_per_phase", seconds},
              {"cpus", std::thread::hardware_concurrency()},
              {"phases", json::array()}};
  std::printf("%-8s %9s %9s %9s %9s %9s %9s %9s %8s\n", "phase", "published", "received", "lat p50",
              "lat p90", "lat max", "frames/s", "MB/s", "CPU %");
  for (const Result& r : results) {
    const double fps = static_cast<double>(r.received) / r.seconds;
    const double mbps = static_cast<double>(r.bytes) / r.seconds * 1e-6;
    const double p50 = Percentile(r.latency_ms, 0.5), p90 = Percentile(r.latency_ms, 0.9),
                 max = Percentile(r.latency_ms, 1.0);
    std::printf("%-8s %9llu %9llu %7.2fms %7.2fms %7.2fms %9.1f %9.1f %8.1f\n", r.name.c_str(),
                static_cast<unsigned long long>(r.published),
                static_cast<unsigned long long>(r.received), p50, p90, max, fps, mbps,
                r.cpu_percent);
    out["phases"].push_back({{"name", r.name},
                             {"published", r.published},
                             {"received", r.received},
                             {"latency_ms_p50", p50},
                             {"latency_ms_p90", p90},
                             {"latency_ms_max", max},
                             {"received_fps", fps},
                             {"received_mb_per_s", mbps},
                             {"bytes_per_frame", r.received ? r.bytes / r.received : 0},
                             {"bridge_cpu_percent", r.cpu_percent}});
  }
  if (!json_path.empty()) std::ofstream(json_path) << out.dump(2) << "\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return probeless::node::RunMain("foxglove_bench", [&] { return Main(argc, argv); });
}
