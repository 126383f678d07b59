// Tests of probeless_replay: MCAP round trips through ConvertToMcap/OpenMcapSource, and the Player
// (timing, rate, filters, remaps, loop, start/duration, pause/step/rate by control topic, lock-step
// with a slow node in another process).
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <thread>

#include "probeless/bus/bus.h"
#include "probeless/msgs/msgs.h"
#include "probeless/node/node.h"
#include "probeless/replay/player.h"
#include "probeless/replay/sources.h"

namespace probeless::replay {
namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;

// An in-memory source: `count` frames every `period_ns`, each an 8x4 mono8 image on /cam/image
// (pixels = frame index) followed by a Pose on /gt/pose (x = frame index).
class VectorSource final : public dataset::Source {
 public:
  VectorSource(int count, uint64_t period_ns) : count_(count), period_ns_(period_ns) {
    topics_ = {
        {"/cam/image", std::string(msgs::Image::kTypeName), msgs::Image::kLayoutHash,
         msgs::Image::MessageBytesFor(8, 4, msgs::Encoding::kMono8), static_cast<uint64_t>(count)},
        {"/gt/pose", std::string(msgs::Pose::kTypeName), msgs::Pose::kLayoutHash,
         sizeof(msgs::Pose), static_cast<uint64_t>(count)}};
  }
  std::string_view kind() const override { return "vector"; }
  const std::string& path() const override { return path_; }
  const std::vector<dataset::TopicInfo>& topics() const override { return topics_; }
  void Rewind() override { next_ = 0; }
  std::optional<dataset::StreamMessage> Next() override {
    if (next_ >= 2 * count_) return std::nullopt;
    const int frame = next_ / 2;
    const bool image = next_ % 2 == 0;
    ++next_;
    dataset::StreamMessage m;
    m.topic_index = image ? 0 : 1;
    m.log_time_ns = 1'000'000'000 + static_cast<uint64_t>(frame) * period_ns_;
    const int64_t stamp = 1'700'000'000'000'000'000 + static_cast<int64_t>(m.log_time_ns);
    if (image) {
      m.message = log::MessageBuffer(topics_[0].max_message_bytes);
      auto img = msgs::WriteMessage<msgs::Image>(m.message.bytes());
      img->header.stamp_ns = stamp;
      img->header.SetFrameId("cam");
      img->width = 8;
      img->height = 4;
      img->step = 8;
      img->encoding = msgs::Encoding::kMono8;
      std::memset(img.payload.data(), frame & 0xFF, img.payload.size());
    } else {
      m.message = log::MessageBuffer(sizeof(msgs::Pose));
      auto pose = msgs::WriteMessage<msgs::Pose>(m.message.bytes());
      pose->header.stamp_ns = stamp;
      pose->header.SetFrameId("world");
      std::strcpy(pose->parent_frame_id, "world");
      std::strcpy(pose->child_frame_id, "cam");
      pose->transform.translation.x = frame;
      pose->transform.rotation.w = 1;
    }
    return m;
  }

 private:
  int count_;
  uint64_t period_ns_;
  int next_ = 0;
  std::string path_ = "vector";
  std::vector<dataset::TopicInfo> topics_;
};

fs::path TempDir() {
  const fs::path dir =
      fs::temp_directory_path() / ("probeless_replay_test_" + std::to_string(getpid()));
  fs::create_directories(dir);
  return dir;
}

// Receives every message of `topic` on a thread until stopped.
struct Recorder {
  Recorder(const std::string& topic, const bus::TopicType& type, uint32_t depth = 64)
      : sub(topic, type, {.queue_depth = depth}), thread([this] {
          while (!stop) {
            if (auto s = sub.Take(10ms)) {
              std::lock_guard<std::mutex> lock(mutex);
              mono.push_back(s->info().publish_mono_ns);
              log::MessageBuffer copy(s->data().size());  // 64-byte aligned, as ReadMessage needs
              std::memcpy(copy.bytes().data(), s->data().data(), s->data().size());
              bytes.push_back(std::move(copy));
            }
          }
        }) {}
  ~Recorder() { Stop(); }
  void Stop() {
    stop = true;
    if (thread.joinable()) thread.join();
  }
  bus::Subscriber sub;
  std::atomic<bool> stop{false};
  std::mutex mutex;
  std::vector<int64_t> mono;
  std::vector<log::MessageBuffer> bytes;
  std::thread thread;
};

PlayerOptions Quiet(PlayerOptions o = {}) {
  o.log = [](const std::string&) {};
  return o;
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
}

TEST(McapSourceTest, ConvertThenReplayGivesTheSameMessages) {
  const fs::path file = TempDir() / "roundtrip.mcap";
  VectorSource source(10, 33'000'000);
  for (auto compression :
       {log::Compression::kNone, log::Compression::kLz4, log::Compression::kZstd}) {
    log::WriterOptions wo;
    wo.compression = compression;
    uint64_t last_progress = 0;
    const ConvertStats stats =
        ConvertToMcap(source, file.string(), wo, [&](uint64_t done, uint64_t total) {
          EXPECT_EQ(total, 20u);
          last_progress = done;
        });
    EXPECT_EQ(stats.messages, 20u);
    EXPECT_EQ(last_progress, 20u);
    EXPECT_EQ(stats.per_topic, (std::vector<uint64_t>{10, 10}));

    auto replayed = OpenSource(file.string());
    EXPECT_EQ(replayed->kind(), "mcap");
    ASSERT_EQ(replayed->topics().size(), 2u);
    EXPECT_EQ(replayed->topics()[0].topic, "/cam/image");
    EXPECT_EQ(replayed->topics()[0].type_name, msgs::Image::kTypeName);
    EXPECT_EQ(replayed->topics()[0].max_message_bytes,
              msgs::Image::MessageBytesFor(8, 4, msgs::Encoding::kMono8));
    EXPECT_EQ(replayed->topics()[1].message_count, 10u);
    EXPECT_EQ(replayed->message_count(), 20u);
    ASSERT_TRUE(replayed->time_range());
    EXPECT_EQ(replayed->time_range()->second - replayed->time_range()->first, 9 * 33'000'000u);
    for (int pass = 0; pass < 2; ++pass) {
      source.Rewind();
      replayed->Rewind();
      int n = 0;
      while (auto expected = source.Next()) {
        auto got = replayed->Next();
        ASSERT_TRUE(got) << "message " << n;
        EXPECT_EQ(got->topic_index, expected->topic_index);
        EXPECT_EQ(got->log_time_ns, expected->log_time_ns);
        const auto a = expected->message.bytes();
        const auto b = got->message.bytes();
        ASSERT_EQ(a.size(), b.size());
        EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size()), 0) << "message " << n;
        ++n;
      }
      EXPECT_FALSE(replayed->Next());
      EXPECT_EQ(n, 20);
    }
  }
}

TEST(McapSourceTest, UnreadableFilesGiveOneLineErrorsNamingThem) {
  const fs::path bad = TempDir() / "not_a_log.mcap";
  std::ofstream(bad) << "hello";
  try {
    OpenSource(bad.string());
    FAIL() << "no exception";
  } catch (const dataset::DatasetError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("cannot read MCAP log"), std::string::npos) << what;
    EXPECT_NE(what.find(bad.string()), std::string::npos) << what;
  }
  try {
    OpenSource("mcap:/nonexistent/x.mcap");
    FAIL() << "no exception";
  } catch (const dataset::DatasetError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/x.mcap"), std::string::npos) << e.what();
  }
}

// The median lateness of a bare absolute-sleep loop on this machine right now: what no player can
// beat (on a quiet machine ~0.1 ms; under heavy load the scheduler adds milliseconds).
double PeerLatenessMs(int n, int64_t period_ns) {
  std::vector<double> late;
  timespec now{};
  clock_gettime(CLOCK_MONOTONIC, &now);
  int64_t t = int64_t{now.tv_sec} * 1'000'000'000 + now.tv_nsec;
  for (int i = 0; i < n; ++i) {
    t += period_ns;
    const timespec due{static_cast<time_t>(t / 1'000'000'000),
                       static_cast<long>(t % 1'000'000'000)};
    clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &due, nullptr);
    clock_gettime(CLOCK_MONOTONIC, &now);
    late.push_back(static_cast<double>(int64_t{now.tv_sec} * 1'000'000'000 + now.tv_nsec - t) /
                   1e6);
  }
  return Median(late);
}

// Rate 1.0 within 2 ms median jitter (the bound), or within 0.5 ms of a bare sleep loop
// measured in the same run when the machine itself is that late (machines here are shared).
TEST(PlayerTest, RateOneKeepsTheRecordedTimingWithin2MsMedian) {
  const double peer_ms = PeerLatenessMs(30, 20'000'000);
  const double bound_ms = std::max(2.0, peer_ms + 0.5);
  VectorSource source(30, 20'000'000);  // 30 frames at 50 Hz, 0.58 s
  Recorder images("/cam/image", msgs::TopicTypeOf<msgs::Image>());
  Player player(source, Quiet());
  const auto start = std::chrono::steady_clock::now();
  const PlayerStats stats = player.Run([] { return true; });
  const double elapsed =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::this_thread::sleep_for(50ms);
  images.Stop();
  EXPECT_EQ(stats.published, 60u);
  EXPECT_EQ(stats.passes, 1u);
  ASSERT_EQ(images.mono.size(), 30u);
  // Publish times against the schedule: intervals of 20 ms.
  std::vector<double> errors_ms;
  for (size_t i = 1; i < images.mono.size(); ++i) {
    const double expected = static_cast<double>(i) * 20.0;
    errors_ms.push_back(std::abs((images.mono[i] - images.mono[0]) / 1e6 - expected));
  }
  EXPECT_LE(Median(errors_ms), bound_ms) << "bare sleep loop: " << peer_ms << " ms";
  EXPECT_LE(Median(stats.lateness_us), bound_ms * 1000.0)
      << "bare sleep loop: " << peer_ms << " ms";
  EXPECT_GE(elapsed, 0.57);
}

TEST(PlayerTest, RateAndAsFastAsPossibleScaleTheDuration) {
  VectorSource source(21, 20'000'000);  // 0.4 s of log time
  {
    PlayerOptions o = Quiet();
    o.rate = 4.0;
    Player player(source, o);
    const auto start = std::chrono::steady_clock::now();
    player.Run([] { return true; });
    const double s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    EXPECT_GE(s, 0.095);
    EXPECT_LE(s, 0.3);
  }
  {
    PlayerOptions o = Quiet();
    o.as_fast_as_possible = true;
    Player player(source, o);
    const auto start = std::chrono::steady_clock::now();
    EXPECT_EQ(player.Run([] { return true; }).published, 42u);
    const double s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    EXPECT_LE(s, 0.25);
  }
}

TEST(PlayerTest, FiltersRemapsStartDurationAndLoop) {
  VectorSource source(10, 10'000'000);
  PlayerOptions o = Quiet();  // timed (rate 1): a pool of 8 slots never overflows
  o.include = {"/cam/.*"};
  o.remaps = {{"/cam/image", "/replayed/image"}};
  o.start_s = 0.02;     // skip frames 0, 1
  o.duration_s = 0.05;  // frames 2..6
  o.loop = true;
  Recorder images("/replayed/image", msgs::TopicTypeOf<msgs::Image>());
  Recorder clock("/clock", msgs::TopicTypeOf<msgs::Header>());
  Player player(source, o);
  EXPECT_EQ(player.published_topics(), (std::vector<std::string>{"/replayed/image", ""}));
  std::atomic<int> calls{0};
  const PlayerStats stats = player.Run([&] {
    std::lock_guard<std::mutex> lock(images.mutex);
    return images.bytes.size() < 15;  // three passes
  });
  std::this_thread::sleep_for(50ms);
  images.Stop();
  clock.Stop();
  EXPECT_GE(stats.passes, 2u);
  EXPECT_EQ(stats.per_topic[1], 0u);
  ASSERT_GE(images.bytes.size(), 15u);
  for (size_t i = 0; i < 15; ++i) {
    const auto img = msgs::ReadMessage<msgs::Image>(images.bytes[i].bytes());
    EXPECT_EQ(static_cast<int>(img.payload[0]), 2 + static_cast<int>(i % 5)) << i;
  }
  // The clock runs on across passes: strictly increasing log times.
  ASSERT_GE(clock.bytes.size(), 15u);
  int64_t previous = 0;
  for (const auto& b : clock.bytes) {
    const auto h = msgs::ReadMessage<msgs::Header>(b.bytes());
    EXPECT_GT(h->stamp_ns, previous);
    previous = h->stamp_ns;
  }
}

TEST(PlayerTest, ControlTopicPausesStepsResumesAndChangesRate) {
  VectorSource source(6, 10'000'000);
  PlayerOptions o = Quiet();
  o.start_paused = true;
  o.include = {"/cam/image"};
  Recorder images("/cam/image", msgs::TopicTypeOf<msgs::Image>());
  Player player(source, o);
  bus::Publisher control("/player/control", msgs::TopicTypeOf<msgs::PlayerControl>(),
                         {.max_message_bytes = sizeof(msgs::PlayerControl)});
  auto send = [&](msgs::PlayerCommand command, double rate = 0) {
    bus::Loan loan = control.Borrow(sizeof(msgs::PlayerControl));
    auto c = msgs::WriteMessage<msgs::PlayerControl>(loan.data());
    c->command = command;
    c->rate = rate;
    control.Publish(std::move(loan));
  };
  std::thread driver([&] {
    auto received = [&] {
      std::lock_guard<std::mutex> lock(images.mutex);
      return images.bytes.size();
    };
    std::this_thread::sleep_for(150ms);
    const size_t while_paused = received();
    send(msgs::PlayerCommand::kStep);
    std::this_thread::sleep_for(150ms);
    const size_t after_step = received();
    send(msgs::PlayerCommand::kSetRate, 2.0);
    send(msgs::PlayerCommand::kResume);
    EXPECT_EQ(while_paused, 0u);
    EXPECT_EQ(after_step, 1u);
  });
  const PlayerStats stats = player.Run([] { return true; });
  driver.join();
  std::this_thread::sleep_for(30ms);
  images.Stop();
  EXPECT_EQ(stats.published, 6u);
  EXPECT_EQ(images.bytes.size(), 6u);
  EXPECT_DOUBLE_EQ(player.rate(), 2.0);
  EXPECT_FALSE(player.paused());
}

TEST(PlayerTest, BadOptionsAreRejectedWithOneLine) {
  VectorSource source(2, 1);
  auto message = [&](PlayerOptions o) -> std::string {
    try {
      Player p(source, Quiet(o));
    } catch (const InputError& e) {
      return e.what();
    }
    return "";
  };
  PlayerOptions bad_rate;
  bad_rate.rate = 0;
  EXPECT_EQ(message(bad_rate), "player: rate must be > 0, got 0.000000");
  PlayerOptions bad_regex;
  bad_regex.include = {"(unclosed"};
  EXPECT_NE(message(bad_regex).find("player: invalid topic regex '(unclosed'"), std::string::npos);
  PlayerOptions bad_node;
  bad_node.lockstep_nodes = {"fusion"};
  EXPECT_EQ(message(bad_node),
            "player: lock-step node 'fusion' must be a fully qualified node name such as /fusion");
  PlayerOptions bad_remap;
  bad_remap.remaps = {{"/cam/image", "no spaces allowed"}};
  EXPECT_NE(message(bad_remap).find("player: invalid topic name 'no spaces allowed'"),
            std::string::npos);
}

// A node in a child process that takes 3 ms per image with a queue of 1: free-running it drops
// frames; in lock-step it sees every frame in order.
int SlowNodeChild(int expected, const std::string& result_file) {
  node::Node node(std::vector<std::string>{"slow", "--ros-args", "-r", "__node:=slow"}, "slow");
  bus::Subscriber sub = node.CreateSubscriber<msgs::Image>("/cam/image", {.queue_depth = 1});
  std::vector<int> seen;
  node.Spin({{&sub, [&](bus::Sample&& s) {
                const auto img = msgs::ReadMessage<msgs::Image>(s.data());
                seen.push_back(static_cast<int>(img.payload[0]));
                std::this_thread::sleep_for(3ms);
                if (static_cast<int>(seen.size()) >= expected) node::RequestShutdown();
              }}});
  std::ofstream out(result_file);
  for (int v : seen) out << v << "\n";
  return 0;
}

std::vector<int> RunThroughSlowNode(bool lockstep, int frames) {
  const fs::path result = TempDir() / (lockstep ? "lockstep.txt" : "free.txt");
  fs::remove(result);
  const pid_t child = fork();
  if (child == 0) _exit(SlowNodeChild(frames, result.string()));
  VectorSource source(frames, 1'000'000);
  PlayerOptions o = Quiet();
  o.as_fast_as_possible = true;
  o.include = {"/cam/image"};
  if (lockstep) {
    o.lockstep_nodes = {"/slow"};
  } else {
    // Free-running: wait until the child subscribes, then blast.
    bus::Subscriber probe("/cam/image", msgs::TopicTypeOf<msgs::Image>());
    for (int i = 0; i < 200; ++i) {
      bool found = false;
      for (const auto& t : bus::ListTopics()) {
        if (t.topic != "/cam/image") continue;
        for (const auto& s : t.subscribers) found |= s.node_name == "/slow";
      }
      if (found) break;
      std::this_thread::sleep_for(10ms);
    }
  }
  Player player(source, o);
  const auto deadline = std::chrono::steady_clock::now() + 20s;
  player.Run([&] { return std::chrono::steady_clock::now() < deadline; });
  if (!lockstep) {
    std::this_thread::sleep_for(200ms);
    kill(child, SIGINT);
  }
  int status = 0;
  waitpid(child, &status, 0);
  std::vector<int> seen;
  std::ifstream in(result);
  for (int v; in >> v;) seen.push_back(v);
  return seen;
}

TEST(PlayerTest, LockStepDeliversEveryFrameInOrderThroughASlowNode) {
  constexpr int kFrames = 120;
  const std::vector<int> free_running = RunThroughSlowNode(false, kFrames);
  EXPECT_LT(free_running.size(), static_cast<size_t>(kFrames))
      << "the free-running control run should drop frames at a queue depth of 1";
  for (int run = 0; run < 2; ++run) {
    const std::vector<int> seen = RunThroughSlowNode(true, kFrames);
    ASSERT_EQ(seen.size(), static_cast<size_t>(kFrames)) << "run " << run;
    for (int i = 0; i < kFrames; ++i) EXPECT_EQ(seen[i], i) << "run " << run;
  }
}

// A chain: /relay takes /cam/image and republishes it on /mid/image after 2 ms; /sink (queue of 1,
// 3 ms per image) only subscribes /mid/image — no played topic. Lock-step with both waits for the
// whole chain, so the sink sees every frame in order.
TEST(PlayerTest, LockStepCoversNodesDownstreamOfThePlayedTopics) {
  constexpr int kFrames = 60;
  const fs::path result = TempDir() / "chain.txt";
  fs::remove(result);
  const pid_t relay = fork();
  if (relay == 0) {
    {  // the bus objects leave the bus (and /dev/shm) before _exit
      node::Node node(std::vector<std::string>{"relay"}, "relay");
      bus::Subscriber in = node.CreateSubscriber<msgs::Image>("/cam/image", {.queue_depth = 1});
      bus::Publisher out = node.CreatePublisher<msgs::Image>(
          "/mid/image",
          {.max_message_bytes = msgs::Image::MessageBytesFor(8, 4, msgs::Encoding::kMono8)});
      node.Spin({{&in, [&](bus::Sample&& s) {
                    std::this_thread::sleep_for(2ms);
                    out.PublishCopy(s.data());
                  }}});
    }
    _exit(0);
  }
  const pid_t sink = fork();
  if (sink == 0) {
    {  // the bus objects leave the bus (and /dev/shm) and the file is flushed before _exit
      node::Node node(std::vector<std::string>{"sink"}, "sink");
      bus::Subscriber in = node.CreateSubscriber<msgs::Image>("/mid/image", {.queue_depth = 1});
      std::vector<int> seen;
      node.Spin({{&in, [&](bus::Sample&& s) {
                    seen.push_back(
                        static_cast<int>(msgs::ReadMessage<msgs::Image>(s.data()).payload[0]));
                    std::this_thread::sleep_for(3ms);
                    if (static_cast<int>(seen.size()) >= kFrames) node::RequestShutdown();
                  }}});
      std::ofstream out(result);
      for (int v : seen) out << v << "\n";
    }
    _exit(0);
  }
  VectorSource source(kFrames, 1'000'000);
  PlayerOptions o = Quiet();
  o.as_fast_as_possible = true;
  o.include = {"/cam/image"};
  o.lockstep_nodes = {"/relay", "/sink"};
  Player player(source, o);
  const auto deadline = std::chrono::steady_clock::now() + 20s;
  const PlayerStats stats = player.Run([&] { return std::chrono::steady_clock::now() < deadline; });
  EXPECT_EQ(stats.published, static_cast<uint64_t>(kFrames));
  int status = 0;
  waitpid(sink, &status, 0);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "sink status " << status;
  kill(relay, SIGINT);
  waitpid(relay, &status, 0);
  std::vector<int> seen;
  std::ifstream in(result);
  for (int v; in >> v;) seen.push_back(v);
  ASSERT_EQ(seen.size(), static_cast<size_t>(kFrames));
  for (int i = 0; i < kFrames; ++i) EXPECT_EQ(seen[i], i);
}

// Lock-step at rate 1 through a node that is quicker than the frame period keeps the recorded
// intervals (each wait re-anchors the schedule at the message just published, not at the next
// one, which would play as fast as possible).
TEST(PlayerTest, LockStepAtRateOneKeepsTheRecordedIntervals) {
  constexpr int kFrames = 20;
  const pid_t quick = fork();
  if (quick == 0) {
    {  // the bus objects leave the bus (and /dev/shm) before _exit
      node::Node node(std::vector<std::string>{"quick"}, "quick");
      bus::Subscriber in = node.CreateSubscriber<msgs::Image>("/cam/image", {.queue_depth = 1});
      int frames = 0;
      node.Spin({{&in, [&](bus::Sample&&) {
                    if (++frames == kFrames) node::RequestShutdown();
                  }}});
    }
    _exit(0);
  }
  Recorder recorder("/cam/image", msgs::TopicTypeOf<msgs::Image>());
  VectorSource source(kFrames, 20'000'000);
  PlayerOptions o = Quiet();
  o.include = {"/cam/image"};
  o.lockstep_nodes = {"/quick"};
  Player player(source, o);
  const auto deadline = std::chrono::steady_clock::now() + 20s;
  player.Run([&] { return std::chrono::steady_clock::now() < deadline; });
  int status = 0;
  waitpid(quick, &status, 0);
  std::this_thread::sleep_for(50ms);
  recorder.Stop();
  ASSERT_EQ(recorder.mono.size(), static_cast<size_t>(kFrames));
  std::vector<double> intervals_ms;
  for (size_t i = 1; i < recorder.mono.size(); ++i) {
    intervals_ms.push_back(static_cast<double>(recorder.mono[i] - recorder.mono[i - 1]) / 1e6);
  }
  EXPECT_NEAR(Median(intervals_ms), 20.0, 2.0);
  EXPECT_GE(*std::min_element(intervals_ms.begin(), intervals_ms.end()), 18.0);
}

// A lock-step node that dies mid-frame (SIGKILL inside its handler, before acknowledging) does not
// stall the player: it stops waiting for the node while it is gone and waits for it again once a
// new instance (a respawn) is on the bus. The new instance takes 30 ms per frame against a 20 ms
// frame period with a queue of 1, so it sees every frame from its first to the last only because
// the player waits for it again.
TEST(PlayerTest, LockStepSkipsANodeThatDiedAndWaitsForItsRespawn) {
  constexpr int kFrames = 60;
  constexpr int kDieAt = 10;
  const fs::path result = TempDir() / "respawned.txt";
  fs::remove(result);
  auto node_main = [&](bool dies) {
    node::Node node(std::vector<std::string>{"victim"}, "victim");
    bus::Subscriber in = node.CreateSubscriber<msgs::Image>("/cam/image", {.queue_depth = 1});
    std::vector<int> seen;
    node.Spin({{&in, [&](bus::Sample&& s) {
                  const int frame =
                      static_cast<int>(msgs::ReadMessage<msgs::Image>(s.data()).payload[0]);
                  if (dies && frame == kDieAt) raise(SIGKILL);
                  seen.push_back(frame);
                  std::this_thread::sleep_for(dies ? 1ms : 30ms);
                  if (frame == kFrames - 1) node::RequestShutdown();
                }}});
    std::ofstream out(result);
    for (int v : seen) out << v << "\n";
  };
  const pid_t first = fork();
  if (first == 0) {
    node_main(true);
    _exit(0);
  }
  int go[2];
  ASSERT_EQ(pipe(go), 0);
  const pid_t second = fork();  // the "respawn": started once the first one is dead
  if (second == 0) {
    close(go[1]);
    char c = 0;
    if (read(go[0], &c, 1) != 1) _exit(1);
    node_main(false);
    _exit(0);
  }
  close(go[0]);
  std::thread respawner([&] {
    int status = 0;
    waitpid(first, &status, 0);
    std::this_thread::sleep_for(100ms);  // a respawn delay: some frames are played without it
    const char c = 1;
    EXPECT_EQ(write(go[1], &c, 1), 1);
    close(go[1]);
  });
  VectorSource source(kFrames, 20'000'000);
  std::mutex log_mutex;
  std::vector<std::string> log;
  PlayerOptions o;
  o.log = [&](const std::string& line) {
    std::lock_guard<std::mutex> lock(log_mutex);
    log.push_back(line);
  };
  o.include = {"/cam/image"};
  o.lockstep_nodes = {"/victim"};
  Player player(source, o);
  const auto deadline = std::chrono::steady_clock::now() + 30s;
  const PlayerStats stats = player.Run([&] { return std::chrono::steady_clock::now() < deadline; });
  respawner.join();
  EXPECT_LT(std::chrono::steady_clock::now(), deadline) << "the player stalled";
  EXPECT_EQ(stats.published, static_cast<uint64_t>(kFrames));
  int status = 0;
  const auto node_deadline = std::chrono::steady_clock::now() + 10s;
  while (waitpid(second, &status, WNOHANG) == 0) {  // it ends after the last frame
    if (std::chrono::steady_clock::now() > node_deadline) {
      kill(second, SIGKILL);
      waitpid(second, &status, 0);
      ADD_FAILURE() << "the respawned node did not get the last frame";
      break;
    }
    std::this_thread::sleep_for(5ms);
  }
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "respawned node status " << status;
  std::vector<int> seen;
  std::ifstream in(result);
  for (int v; in >> v;) seen.push_back(v);
  ASSERT_FALSE(seen.empty()) << "the respawned node saw nothing";
  EXPECT_GT(seen.front(), kDieAt) << "the respawn joined before the first instance died";
  for (size_t i = 0; i < seen.size(); ++i) {
    ASSERT_EQ(seen[i], seen.front() + static_cast<int>(i)) << "a frame was dropped";
  }
  EXPECT_EQ(seen.back(), kFrames - 1);
  std::string all;
  for (const auto& line : log) all += line + "\n";
  EXPECT_NE(all.find("lock-step: /victim has left the bus; not waiting for it"), std::string::npos)
      << all;
  EXPECT_NE(all.find("lock-step: /victim is back on the bus"), std::string::npos) << all;
}

TEST(PlaybackSummaryTest, NamesPublishedTopicsAndOnlyTheFiguresThatApply) {
  PlayerStats stats;
  stats.published = 7;
  stats.passes = 1;
  stats.per_topic = {4, 2, 1};
  EXPECT_EQ(PlaybackSummary(stats, {"/camera/image", "", "/camera/depth"}, 0.5, false),
            "player: published 7 messages in 0.5 s, 1 pass(es); /camera/image 4; /camera/depth 1");
  for (int i = 100; i >= 1; --i) stats.lateness_us.push_back(i);  // unsorted on purpose
  stats.lockstep_wait_s = 0.25;
  EXPECT_EQ(PlaybackSummary(stats, {"/a", "/b", "/c"}, 2, true),
            "player: published 7 messages in 2 s, 1 pass(es); /a 4; /b 2; /c 1; lateness median "
            "51 us, p99 100 us; lock-step wait 0.25 s");
}

}  // namespace
}  // namespace probeless::replay
