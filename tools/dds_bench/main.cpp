// dds_bench: 1.5 MB frames (1000x500 rgb8, 1'500'000 bytes of pixels) from one probeless graph to
// another across two dds_bridge processes over Cyclone DDS on loopback (two PROBELESS_DOMAIN
// values, one DDS domain). Phases:
//   latency   reliable, 30 Hz paced: bus publish -> bus receive on the other graph
//   (p50/p90/p99/max) throughput reliable, unpaced for --seconds: frames/s and MB/s delivered,
//   drops best_effort 30 Hz paced with the default image QoS (best effort, depth 2): delivered
//   fraction rgbd_30hz  640x480 rgb8 + depth16 on two topics (regex routes) at 30 Hz, default image
//   QoS:
//              frames delivered per topic and the drops the two bridges reported at exit
// usage: dds_bench [--json OUT] [--frames N] [--seconds S] [--domain-id D]
#include "probeless/node/main.h"

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <new>
#include <string>
#include <thread>
#include <vector>

#include "probeless/bus/bus.h"
#include "probeless/msgs/image.h"
#include "probeless/msgs/layout.h"
#include "probeless/node/flags.h"
#include "probeless/parse/number.h"

extern char** environ;

namespace {

using namespace probeless;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

constexpr uint32_t kWidth = 1000, kHeight = 500;
constexpr int64_t kBaseStamp = 1'700'000'000'000'000'000;

class Child {
 public:
  Child(const std::string& exe, std::vector<std::string> args, const std::string& bus_domain,
        const std::string& out = "/dev/null") {
    setenv("PROBELESS_DOMAIN", bus_domain.c_str(), 1);
    args.insert(args.begin(), exe);
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, out.c_str(),
                                     O_WRONLY | O_CREAT | O_TRUNC, 0600);
    if (posix_spawn(&pid_, exe.c_str(), &actions, nullptr, argv.data(), environ) != 0) {
      throw std::runtime_error("cannot start " + exe);
    }
    posix_spawn_file_actions_destroy(&actions);
  }
  ~Child() {
    kill(pid_, SIGINT);
    int status = 0;
    waitpid(pid_, &status, 0);
  }

 private:
  pid_t pid_ = -1;
};

struct Run {
  std::vector<Clock::time_point> sent;
  std::vector<double> latency_ms;
  uint64_t published = 0, received = 0, out_of_order = 0;
  double seconds = 0;
};

void Publish(bus::Publisher& pub, uint32_t index, uint32_t width = kWidth,
             uint32_t height = kHeight, msgs::Encoding encoding = msgs::Encoding::kRgb8) {
  bus::Loan loan = pub.Borrow(msgs::Image::MessageBytesFor(width, height, encoding));
  auto* image = new (loan.data().data()) msgs::Image();
  image->header.stamp_ns = kBaseStamp + int64_t{index} * 1'000'000;
  image->header.SetFrameId("camera_optical");
  image->Init(width, height, encoding);
  std::byte* payload = loan.data().data() + sizeof(msgs::Image);
  std::memset(payload, static_cast<int>(index & 0xff), image->PayloadBytes());
  pub.Publish(std::move(loan));
}

// Publishes `count` frames (paced at `hz`, or as fast as the bridge accepts them if hz == 0,
// for at most `max_seconds`) starting at index `first`, receiving on `sub` meanwhile.
Run Measure(bus::Publisher& pub, bus::Subscriber& sub, uint32_t first, uint32_t count, double hz,
            double max_seconds) {
  Run run;
  std::map<uint32_t, Clock::time_point> sent;
  int64_t last = -1;
  auto receive = [&](std::chrono::nanoseconds wait) {
    while (auto s = sub.Take(wait)) {
      wait = 0ns;
      const auto now = Clock::now();
      const auto index =
          static_cast<uint32_t>((s->As<msgs::Image>()->header.stamp_ns - kBaseStamp) / 1'000'000);
      if (index < first) continue;
      if (static_cast<int64_t>(index) <= last) ++run.out_of_order;
      last = index;
      ++run.received;
      if (auto it = sent.find(index); it != sent.end()) {
        run.latency_ms.push_back(
            std::chrono::duration<double, std::milli>(now - it->second).count());
      }
    }
  };
  const auto start = Clock::now();
  auto next = start;
  for (uint32_t i = 0; i < count; ++i) {
    if (std::chrono::duration<double>(Clock::now() - start).count() > max_seconds) break;
    sent[first + i] = Clock::now();
    Publish(pub, first + i);
    ++run.published;
    if (hz > 0) {
      next += std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / hz));
      while (Clock::now() < next) receive(next - Clock::now());
    } else {
      // Unpaced, but keep at most a few frames in flight so the bus queue is not the bottleneck.
      receive(0ns);
      if (i >= run.received + 4) receive(5ms);
    }
  }
  const auto end_publish = Clock::now();
  const auto drain_end = Clock::now() + 1500ms;
  while (Clock::now() < drain_end) receive(50ms);
  run.seconds = std::chrono::duration<double>(end_publish - start).count();
  return run;
}

double Percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(p * (v.size() - 1) + 0.5))];
}

// Waits until frames cross (discovery), returns the next free index.
uint32_t Warm(bus::Publisher& pub, bus::Subscriber& sub, uint32_t next) {
  const auto deadline = Clock::now() + 20s;
  while (Clock::now() < deadline) {
    Publish(pub, next++);
    if (sub.Take(50ms)) {
      while (sub.Take(300ms)) {
      }
      return next;
    }
  }
  throw std::runtime_error("no frame crossed the bridges within 20 s");
}

int Main(int argc, char** argv) {
  std::string json;
  uint32_t frames = 300;
  double seconds = 10;
  int domain_id = 40 + getpid() % 100;
  node::FlagParser flags("dds_bench",
                         "1.5 MB frames from one probeless graph to another across two dds_bridge "
                         "processes over\nCyclone DDS on loopback: latency, throughput, best "
                         "effort, RGB-D at 30 Hz");
  flags.Add("--json", &json, "OUT", "write the figures as JSON");
  flags.AddCallback(
      "--frames", "N", "frames of the paced phases",
      [&](const std::string& text) {
        frames = static_cast<uint32_t>(node::ParseNumberOption("--frames", text));
      },
      std::to_string(frames));
  flags.Add("--seconds", &seconds, "S", "length of the throughput phase");
  flags.AddCallback(
      "--domain-id", "D", "the DDS domain",
      [&](const std::string& text) { domain_id = parse::ParseInteger<int>("--domain-id", text); },
      "40 + pid % 100");
  if (!flags.Parse(argc, argv)) return 0;
  const std::string exe =
      (std::filesystem::read_symlink("/proc/self/exe").parent_path() / "dds_bridge").string();
  const std::string a = "ddsbench" + std::to_string(getpid()) + "a";
  const std::string b = "ddsbench" + std::to_string(getpid()) + "b";
  const size_t bytes = msgs::Image::MessageBytesFor(kWidth, kHeight, msgs::Encoding::kRgb8);

  auto phase = [&](const std::string& qos_rule, uint32_t count, double hz, double max_s) {
    std::vector<std::string> common = {"-p", "domain_id:=" + std::to_string(domain_id), "-p",
                                       "stats_period_s:=0"};
    if (!qos_rule.empty()) {
      common.push_back("-p");
      common.push_back("qos:=[\"" + qos_rule + "\"]");
    }
    setenv("PROBELESS_DOMAIN", b.c_str(), 1);
    bus::SubscriberOptions so;
    so.queue_depth = 64;
    so.node_name = "/dds_bench";
    bus::Subscriber sub("/camera/image", msgs::TopicTypeOf<msgs::Image>(), so);
    std::vector<std::string> args_b = {"--ros-args", "-r", "__node:=bridge_b", "-p",
                                       "from_dds:=[/camera/image]"};
    args_b.insert(args_b.end(), common.begin(), common.end());
    Child bridge_b(exe, args_b, b);
    setenv("PROBELESS_DOMAIN", a.c_str(), 1);
    bus::PublisherOptions po;
    po.max_message_bytes = bytes;
    po.slot_count = 16;
    po.node_name = "/dds_bench";
    bus::Publisher pub("/camera/image", msgs::TopicTypeOf<msgs::Image>(), po);
    std::vector<std::string> args_a = {"--ros-args", "-r", "__node:=bridge_a", "-p",
                                       "to_dds:=[/camera/image]"};
    args_a.insert(args_a.end(), common.begin(), common.end());
    Child bridge_a(exe, args_a, a);
    const uint32_t first = Warm(pub, sub, 0);
    return Measure(pub, sub, first, count, hz, max_s);
  };

  std::fprintf(stderr, "latency phase (reliable, 30 Hz, %u frames)...\n", frames);
  const Run lat = phase("/camera/.*=reliable,4,", frames, 30, 1e9);
  std::fprintf(stderr, "throughput phase (reliable, unpaced, %.0f s)...\n", seconds);
  const Run thr = phase("/camera/.*=reliable,4,", 1'000'000, 0, seconds);
  std::fprintf(stderr, "best-effort phase (default image QoS, 30 Hz, %u frames)...\n", frames);
  const Run be = phase("", frames, 30, 1e9);
  std::fprintf(stderr,
               "RGB-D phase (640x480 rgb8 + depth16, 30 Hz, default image QoS, %u frames)...\n",
               frames);
  // Two topics at once, regex routes, the default image QoS (best effort, depth 2).
  uint64_t rgbd_received[2] = {0, 0}, rgbd_published = 0, rgbd_dropped = 0;
  std::vector<double> rgbd_latency;
  {
    const std::string regex = "^/camera/(image|depth)$";
    const std::string out_a = "/tmp/dds_bench_" + std::to_string(getpid()) + "_a.out";
    const std::string out_b = "/tmp/dds_bench_" + std::to_string(getpid()) + "_b.out";
    setenv("PROBELESS_DOMAIN", b.c_str(), 1);
    bus::SubscriberOptions so;
    so.queue_depth = 64;
    so.node_name = "/dds_bench";
    bus::Subscriber subs[2] = {
        bus::Subscriber("/camera/image", msgs::TopicTypeOf<msgs::Image>(), so),
        bus::Subscriber("/camera/depth", msgs::TopicTypeOf<msgs::Image>(), so)};
    auto bridge_b = std::make_unique<Child>(
        exe,
        std::vector<std::string>{
            "--ros-args", "-r", "__node:=bridge_b", "-p", "from_dds_regex:=" + regex, "-p",
            "domain_id:=" + std::to_string(domain_id), "-p", "stats_period_s:=0"},
        b, out_b);
    setenv("PROBELESS_DOMAIN", a.c_str(), 1);
    bus::PublisherOptions po;
    po.slot_count = 16;
    po.node_name = "/dds_bench";
    po.max_message_bytes = msgs::Image::MessageBytesFor(640, 480, msgs::Encoding::kRgb8);
    bus::Publisher rgb("/camera/image", msgs::TopicTypeOf<msgs::Image>(), po);
    po.max_message_bytes = msgs::Image::MessageBytesFor(640, 480, msgs::Encoding::kDepth16);
    bus::Publisher depth("/camera/depth", msgs::TopicTypeOf<msgs::Image>(), po);
    auto bridge_a = std::make_unique<Child>(
        exe,
        std::vector<std::string>{
            "--ros-args", "-r", "__node:=bridge_a", "-p", "to_dds_regex:=" + regex, "-p",
            "domain_id:=" + std::to_string(domain_id), "-p", "stats_period_s:=0"},
        a, out_a);
    uint32_t next = 0;
    const auto deadline = Clock::now() + 20s;
    bool seen[2] = {false, false};
    while (!(seen[0] && seen[1]) && Clock::now() < deadline) {
      Publish(rgb, next, 640, 480, msgs::Encoding::kRgb8);
      Publish(depth, next, 640, 480, msgs::Encoding::kDepth16);
      ++next;
      std::this_thread::sleep_for(33ms);
      for (int k = 0; k < 2; ++k)
        while (subs[k].TryTake()) seen[k] = true;
    }
    if (!(seen[0] && seen[1])) throw std::runtime_error("RGB-D: no frames crossed within 20 s");
    std::this_thread::sleep_for(300ms);
    for (auto& sub : subs)
      while (sub.TryTake()) {
      }
    const uint32_t first = next;
    std::map<uint32_t, Clock::time_point> sent;
    auto drain = [&] {
      for (int k = 0; k < 2; ++k) {
        while (auto sm = subs[k].TryTake()) {
          const auto index = static_cast<uint32_t>(
              (sm->As<msgs::Image>()->header.stamp_ns - kBaseStamp) / 1'000'000);
          if (index < first) continue;
          ++rgbd_received[k];
          if (k == 0 && sent.count(index)) {
            rgbd_latency.push_back(
                std::chrono::duration<double, std::milli>(Clock::now() - sent[index]).count());
          }
        }
      }
    };
    auto t = Clock::now();
    for (uint32_t i = 0; i < frames; ++i) {
      sent[next] = Clock::now();
      Publish(rgb, next, 640, 480, msgs::Encoding::kRgb8);
      Publish(depth, next, 640, 480, msgs::Encoding::kDepth16);
      ++next;
      ++rgbd_published;
      t += std::chrono::microseconds(33'333);
      while (Clock::now() < t) {
        drain();
        std::this_thread::sleep_for(500us);
      }
    }
    const auto end = Clock::now() + 1500ms;
    while (Clock::now() < end) {
      drain();
      std::this_thread::sleep_for(1ms);
    }
    bridge_a.reset();
    bridge_b.reset();
    for (const std::string& path : {out_a, out_b}) {
      std::ifstream f(path);
      std::string line;
      while (std::getline(f, line)) {
        const size_t at = line.find("dropped=");
        if (at != std::string::npos) rgbd_dropped += std::stoull(line.substr(at + 8));
      }
      std::filesystem::remove(path);
    }
  }
  bus::CleanDeadSegments(a);
  bus::CleanDeadSegments(b);

  const double mb = static_cast<double>(bytes) / 1e6;
  char out[4096];
  std::snprintf(
      out, sizeof(out),
      "{\n  \"frame_bytes\": %zu,\n  \"frame\": \"%ux%u rgb8\",\n  \"transport\": \"Cyclone DDS "
      "0.10 loopback (127.0.0.1, unicast)\",\n"
      "  \"latency\": {\"qos\": \"reliable depth 4\", \"rate_hz\": 30, \"published\": %llu, "
      "\"received\": %llu,"
      " \"out_of_order\": %llu, \"p50_ms\": %.3f, \"p90_ms\": %.3f, \"p99_ms\": %.3f, \"max_ms\": "
      "%.3f},\n"
      "  \"throughput\": {\"qos\": \"reliable depth 4\", \"seconds\": %.2f, \"published\": %llu, "
      "\"received\": %llu,"
      " \"frames_per_s\": %.1f, \"mb_per_s\": %.1f, \"p50_ms\": %.3f},\n"
      "  \"best_effort\": {\"qos\": \"best_effort depth 2 (image default)\", \"rate_hz\": 30, "
      "\"published\": %llu,"
      " \"received\": %llu, \"delivered_fraction\": %.4f, \"p50_ms\": %.3f},\n"
      "  \"rgbd_30hz\": {\"topics\": [\"/camera/image 640x480 rgb8\", \"/camera/depth 640x480 "
      "depth16\"],"
      " \"qos\": \"best_effort depth 2 (image default)\", \"published_per_topic\": %llu,"
      " \"received_image\": %llu, \"received_depth\": %llu, \"bridge_drops\": %llu,"
      " \"image_p50_ms\": %.3f, \"image_p99_ms\": %.3f}\n}\n",
      bytes, kWidth, kHeight, static_cast<unsigned long long>(lat.published),
      static_cast<unsigned long long>(lat.received),
      static_cast<unsigned long long>(lat.out_of_order), Percentile(lat.latency_ms, 0.5),
      Percentile(lat.latency_ms, 0.9), Percentile(lat.latency_ms, 0.99),
      Percentile(lat.latency_ms, 1.0), thr.seconds, static_cast<unsigned long long>(thr.published),
      static_cast<unsigned long long>(thr.received), thr.received / thr.seconds,
      thr.received * mb / thr.seconds, Percentile(thr.latency_ms, 0.5),
      static_cast<unsigned long long>(be.published), static_cast<unsigned long long>(be.received),
      be.published ? static_cast<double>(be.received) / be.published : 0.0,
      Percentile(be.latency_ms, 0.5), static_cast<unsigned long long>(rgbd_published),
      static_cast<unsigned long long>(rgbd_received[0]),
      static_cast<unsigned long long>(rgbd_received[1]),
      static_cast<unsigned long long>(rgbd_dropped), Percentile(rgbd_latency, 0.5),
      Percentile(rgbd_latency, 0.99));
  std::fputs(out, stdout);
  if (!json.empty()) {
    std::ofstream f(json);
    f << out;
    if (!f) throw std::runtime_error("cannot write " + json);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return probeless::node::RunMain("dds_bench", [&] { return Main(argc, argv); });
}
