// Process tests of `probeless topic list|info|hz|bw|echo` and `probeless clean`: the real
// build/bin/probeless binary against publishers and subscribers of this process (and of forked
// children), asserting counts, measured rates, echoed sequences, cleanup and the exact one-line
// errors.
#include <dirent.h>
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "probeless/bus/bus.h"

extern char** environ;

namespace {

using namespace std::chrono_literals;
using probeless::bus::ListTopics;
using probeless::bus::Publisher;
using probeless::bus::PublisherOptions;
using probeless::bus::Subscriber;
using probeless::bus::TopicType;

// Outside ctest (which sets it) run in a domain of our own, never in the user's default graph.
[[maybe_unused]] const bool kDomainSet = (setenv("PROBELESS_DOMAIN", "topic_cli_test", 0), true);

const TopicType kBlob{"test_msgs/Blob", 0x1234};
const TopicType kOther{"test_msgs/Other", 0x9999};

std::string Domain() { return probeless::bus::CurrentDomain(); }
std::string SegmentPrefix() {
  return "probeless." + std::to_string(getuid()) + "." + Domain() + ".";
}

// This user's and domain's segments in /dev/shm (full names), sorted.
std::set<std::string> Segments() {
  std::set<std::string> names;
  DIR* dir = opendir("/dev/shm");
  while (dirent* entry = readdir(dir)) {
    const std::string name = entry->d_name;
    if (name.rfind(SegmentPrefix(), 0) == 0) names.insert(name);
  }
  closedir(dir);
  return names;
}

std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

std::vector<std::string> Lines(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

std::vector<std::string> Words(const std::string& line) {
  std::istringstream in(line);
  std::vector<std::string> words;
  for (std::string w; in >> w;) words.push_back(w);
  return words;
}

// A running `probeless ...` whose stdout and stderr go to files.
class Probeless {
 public:
  explicit Probeless(std::vector<std::string> args, const std::string& domain = "") {
    static int counter = 0;
    const std::string base =
        "/tmp/probeless_topic_cli_" + std::to_string(getpid()) + "_" + std::to_string(counter++);
    out_path_ = base + ".out";
    err_path_ = base + ".err";
    args.insert(args.begin(), std::string(PROBELESS_BIN_DIR) + "/probeless");
    std::vector<char*> argv;
    for (std::string& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    std::vector<std::string> env_storage;
    for (char** e = environ; *e != nullptr; ++e) {
      if (domain.empty() || std::strncmp(*e, "PROBELESS_DOMAIN=", 17) != 0) {
        env_storage.emplace_back(*e);
      }
    }
    if (!domain.empty()) env_storage.push_back("PROBELESS_DOMAIN=" + domain);
    std::vector<char*> envp;
    for (std::string& e : env_storage) envp.push_back(e.data());
    envp.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, out_path_.c_str(),
                                     O_WRONLY | O_CREAT | O_TRUNC, 0600);
    posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, err_path_.c_str(),
                                     O_WRONLY | O_CREAT | O_TRUNC, 0600);
    const int rc = posix_spawn(&pid_, argv[0], &actions, nullptr, argv.data(), envp.data());
    posix_spawn_file_actions_destroy(&actions);
    EXPECT_EQ(rc, 0) << "cannot start " << argv[0];
    if (rc != 0) pid_ = -1;
  }
  ~Probeless() {
    if (pid_ > 0) {
      kill(pid_, SIGKILL);
      Wait(10s);
    }
    std::filesystem::remove(out_path_);
    std::filesystem::remove(err_path_);
  }
  Probeless(const Probeless&) = delete;
  Probeless& operator=(const Probeless&) = delete;

  pid_t pid() const { return pid_; }
  void Signal(int signal_number) const { kill(pid_, signal_number); }

  // Exit code; a signal death is 128 + signal; -1 after killing it when `timeout` passed.
  int Wait(std::chrono::milliseconds timeout = 15s) {
    if (pid_ <= 0) return -1;
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    int status = 0;
    for (;;) {
      const pid_t done = waitpid(pid_, &status, WNOHANG);
      if (done == pid_) break;
      if (std::chrono::steady_clock::now() > deadline) {
        kill(pid_, SIGKILL);
        waitpid(pid_, &status, 0);
        pid_ = -1;
        ADD_FAILURE() << "probeless did not finish in time; stdout:\n" << Stdout();
        return -1;
      }
      std::this_thread::sleep_for(5ms);
    }
    pid_ = -1;
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  }
  std::string Stdout() const { return ReadFile(out_path_); }
  std::string Stderr() const { return ReadFile(err_path_); }

 private:
  pid_t pid_ = -1;
  std::string out_path_;
  std::string err_path_;
};

struct Result {
  int code = -1;
  std::string out;
  std::string err;
};

Result RunProbeless(std::vector<std::string> args, const std::string& domain = "") {
  Probeless p(std::move(args), domain);
  Result r;
  r.code = p.Wait();
  r.out = p.Stdout();
  r.err = p.Stderr();
  return r;
}

PublisherOptions Options(size_t bytes, const std::string& node = "", uint32_t slots = 8,
                         uint32_t history = 0) {
  PublisherOptions o;
  o.max_message_bytes = bytes;
  o.slot_count = slots;
  o.history = history;
  o.node_name = node;
  return o;
}

// Publishes `bytes`-byte messages at `hz` on a thread (absolute schedule, so the mean rate is
// exact); each payload starts with its sequence number (uint64, host order).
class Ticker {
 public:
  Ticker(Publisher& publisher, double hz, size_t bytes) {
    thread_ = std::thread([this, &publisher, hz, bytes] {
      const auto period = std::chrono::duration_cast<std::chrono::steady_clock::duration>(
          std::chrono::duration<double>(1.0 / hz));
      auto next = std::chrono::steady_clock::now();
      for (uint64_t sequence = 1; !stop_.load(); ++sequence) {
        probeless::bus::Loan loan = publisher.Borrow(bytes);
        std::memset(loan.data().data(), 0xA5, bytes);
        std::memcpy(loan.data().data(), &sequence, sizeof(sequence));
        if (publisher.Publish(std::move(loan)) != sequence) mismatches_.fetch_add(1);
        published_.store(sequence);
        next += period;
        std::this_thread::sleep_until(next);
      }
    });
  }
  ~Ticker() { Stop(); }
  void Stop() {
    stop_.store(true);
    if (thread_.joinable()) thread_.join();
  }
  uint64_t published() const { return published_.load(); }
  uint64_t mismatches() const { return mismatches_.load(); }

 private:
  std::atomic<bool> stop_{false};
  std::atomic<uint64_t> published_{0};
  std::atomic<uint64_t> mismatches_{0};
  std::thread thread_;
};

// Runs `body` in a forked child; returns its pid. The child exits with body's return value.
template <typename F>
pid_t Spawn(F body) {
  const pid_t pid = fork();
  if (pid == 0) {
    int code = 0;
    try {
      code = body();
    } catch (const std::exception& e) {
      fprintf(stderr, "child failed: %s\n", e.what());
      code = 3;
    }
    _exit(code);
  }
  return pid;
}

int WaitExit(pid_t pid) {
  int status = 0;
  waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

// A forked child that publishes on `topic` and stays alive until Release() (or SIGKILL).
class ChildPublisher {
 public:
  ChildPublisher(const std::string& topic, const TopicType& type, const std::string& node) {
    int ready[2];
    EXPECT_EQ(pipe(ready), 0);
    EXPECT_EQ(pipe(hold_), 0);
    pid_ = Spawn([&] {
      close(ready[0]);
      close(hold_[1]);
      Publisher pub(topic, type, Options(64, node));
      const std::string text = "from the child";
      pub.PublishCopy(std::as_bytes(std::span(text.data(), text.size())));
      (void)!write(ready[1], "r", 1);
      char c;
      (void)!read(hold_[0], &c, 1);  // returns when the parent closes its end
      return 0;
    });
    close(ready[1]);
    close(hold_[0]);
    char c = 0;
    EXPECT_EQ(read(ready[0], &c, 1), 1) << "child publisher did not start";
    close(ready[0]);
  }
  ~ChildPublisher() {
    if (pid_ > 0) Release();
  }
  pid_t pid() const { return pid_; }
  int Release() {
    close(hold_[1]);
    const int code = WaitExit(pid_);
    pid_ = -1;
    return code;
  }
  int Kill() {
    kill(pid_, SIGKILL);
    close(hold_[1]);
    const int code = WaitExit(pid_);  // reaped: the pid is gone, not a zombie
    pid_ = -1;
    return code;
  }

 private:
  pid_t pid_ = -1;
  int hold_[2] = {-1, -1};
};

class TopicCliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    probeless::bus::CleanDeadSegments();
    ASSERT_TRUE(ListTopics().empty()) << "leftover topic " << ListTopics().front().topic;
  }
};

// The line of `text` starting with "<first> " (a table row), or "".
std::string RowOf(const std::string& text, const std::string& first) {
  for (const std::string& line : Lines(text)) {
    if (line.rfind(first + " ", 0) == 0) return line;
  }
  return "";
}

// --- topic list --------------------------------------------------------------------------------

TEST_F(TopicCliTest, ListShowsTopicsWithCountsAndParticipants) {
  Result empty = RunProbeless({"topic", "list"});
  EXPECT_EQ(empty.code, 0);
  EXPECT_EQ(empty.out, "no topics in domain '" + Domain() + "'\n");

  Publisher pub("/cli/list", kBlob, Options(64, "/cam"));
  Subscriber viewer("/cli/list", kBlob, {.queue_depth = 1, .node_name = "/viewer"});
  Subscriber logger("/cli/list", kBlob, {.queue_depth = 4, .node_name = "/logger"});
  ChildPublisher child("/cli/child", kOther, "/child_node");

  const Result list = RunProbeless({"topic", "list"});
  ASSERT_EQ(list.code, 0) << list.err;
  EXPECT_EQ(list.err, "");
  EXPECT_EQ(Words(Lines(list.out).at(0)),
            (std::vector<std::string>{"TOPIC", "TYPE", "PUBLISHERS", "SUBSCRIBERS"}));
  EXPECT_EQ(Words(RowOf(list.out, "/cli/list")),
            (std::vector<std::string>{"/cli/list", "test_msgs/Blob", "1", "2"}))
      << list.out;
  EXPECT_EQ(Words(RowOf(list.out, "/cli/child")),
            (std::vector<std::string>{"/cli/child", "test_msgs/Other", "1", "0"}))
      << list.out;
  EXPECT_EQ(Lines(list.out).size(), 3u);

  const Result verbose = RunProbeless({"topic", "list", "-v"});
  ASSERT_EQ(verbose.code, 0) << verbose.err;
  const std::string self = std::to_string(getpid());
  const std::string& out = verbose.out;
  const size_t child_row = out.find("/cli/child ");
  const size_t child_pub = out.find("    publisher   pid " + std::to_string(child.pid()) +
                                    "  node /child_node  alive\n");
  const size_t list_row = out.find("/cli/list ");
  const size_t cam = out.find("    publisher   pid " + self + "  node /cam  alive\n");
  ASSERT_NE(child_row, std::string::npos) << out;
  ASSERT_NE(child_pub, std::string::npos) << out;
  ASSERT_NE(list_row, std::string::npos) << out;
  ASSERT_NE(cam, std::string::npos) << out;
  EXPECT_LT(child_row, child_pub);  // each topic's participants follow its row
  EXPECT_LT(child_pub, list_row);
  EXPECT_LT(list_row, cam);
  EXPECT_NE(out.find("    subscriber  pid " + self + "  node /viewer  alive\n"), std::string::npos);
  EXPECT_NE(out.find("    subscriber  pid " + self + "  node /logger  alive\n"), std::string::npos);

  // A killed participant is shown as dead until someone reclaims it.
  EXPECT_EQ(child.Kill(), 128 + SIGKILL);
  const Result after_kill = RunProbeless({"topic", "list", "-v"});
  EXPECT_EQ(Words(RowOf(after_kill.out, "/cli/child")),
            (std::vector<std::string>{"/cli/child", "test_msgs/Other", "0", "(+1", "dead)", "0"}))
      << after_kill.out;
  EXPECT_NE(after_kill.out.find("node /child_node  dead\n"), std::string::npos);
  probeless::bus::CleanDeadSegments();
}

// --- topic info --------------------------------------------------------------------------------

TEST_F(TopicCliTest, InfoShowsTypeParticipantsAndCounters) {
  Publisher pub("/cli/info", kBlob, Options(16, "/cam", 8, 2));
  Subscriber sub("/cli/info", kBlob,
                 {.queue_depth = 1, .receive_history = false, .node_name = "/viewer"});
  const std::string text = "sixteen bytes!!!";
  for (int i = 0; i < 5; ++i) pub.PublishCopy(std::as_bytes(std::span(text.data(), 16)));

  const Result info = RunProbeless({"topic", "info", "/cli/info"});
  ASSERT_EQ(info.code, 0) << info.err;
  EXPECT_EQ(info.err, "");
  const std::string self = std::to_string(getpid());
  std::string stable;  // everything but the wall-clock dependent "last message" line
  int last_message_lines = 0;
  for (const std::string& line : Lines(info.out)) {
    if (line.rfind("    last message: ", 0) == 0) {
      ++last_message_lines;
      EXPECT_TRUE(std::regex_match(line, std::regex("    last message: [0-9]+\\.[0-9]{3} s ago")))
          << line;
      continue;
    }
    stable += line + "\n";
  }
  EXPECT_EQ(last_message_lines, 1);
  EXPECT_EQ(stable,
            "topic: /cli/info\n"
            "type: test_msgs/Blob\n"
            "layout hash: 0x0000000000001234\n"
            "publishers: 1\n"
            "  - node: /cam\n"
            "    pid: " +
                self +
                "\n"
                "    alive: yes\n"
                "    capacity: 16 B\n"
                "    slots: 8\n"
                "    history: 2\n"
                "    published: 5 messages, 80 B\n"
                "    rate: 0 Hz (no message in 0.5 s)\n"
                "subscribers: 1\n"
                "  - node: /viewer\n"
                "    pid: " +
                self +
                "\n"
                "    alive: yes\n"
                "    queue depth: 1\n"
                "    queued: 1\n"
                "    received: 5\n"
                "    dropped: 4\n");
}

TEST_F(TopicCliTest, InfoMeasuresEachPublishersRate) {
  Publisher pub("/cli/info_rate", kBlob, Options(32, "/fast"));
  Ticker ticker(pub, 30, 32);
  std::this_thread::sleep_for(100ms);
  const Result info = RunProbeless({"topic", "info", "/cli/info_rate"});
  ASSERT_EQ(info.code, 0) << info.err;
  std::smatch match;
  ASSERT_TRUE(std::regex_search(info.out, match, std::regex("\n    rate: ([0-9.]+) Hz\n")))
      << info.out;
  EXPECT_NEAR(std::stod(match[1]), 30.0, 3.0) << info.out;
  EXPECT_EQ(info.out.find("subscribers: 0\n") != std::string::npos, true) << info.out;
}

// --- topic hz / bw -----------------------------------------------------------------------------

// Unit of FormatBytes output in bytes.
double UnitBytes(const std::string& unit) {
  if (unit == "B") return 1;
  if (unit == "KB") return 1e3;
  if (unit == "MB") return 1e6;
  if (unit == "GB") return 1e9;
  ADD_FAILURE() << "unknown unit " << unit;
  return 0;
}

TEST_F(TopicCliTest, HzAndBwMeasureWithoutSubscribing) {
  constexpr size_t kBytes = 10'000;
  Publisher pub("/cli/rate", kBlob, Options(kBytes, "/camera"));
  Subscriber own("/cli/rate", kBlob, {.queue_depth = 1, .node_name = "/own"});
  Ticker ticker(pub, 30, kBytes);
  std::this_thread::sleep_for(100ms);
  ASSERT_EQ(pub.SubscriberCount(), 1u);

  Probeless hz({"topic", "hz", "/cli/rate", "--window", "30"});  // until SIGINT
  Probeless bw({"topic", "bw", "/cli/rate", "--window", "30", "--duration", "2.5"});
  // While both run, the topic keeps exactly its one subscriber.
  uint32_t min_count = 1000;
  uint32_t max_count = 0;
  size_t max_listed = 0;
  const auto until = std::chrono::steady_clock::now() + 2700ms;
  while (std::chrono::steady_clock::now() < until) {
    const uint32_t count = pub.SubscriberCount();
    min_count = std::min(min_count, count);
    max_count = std::max(max_count, count);
    for (const auto& t : ListTopics()) max_listed = std::max(max_listed, t.subscribers.size());
    std::this_thread::sleep_for(10ms);
  }
  hz.Signal(SIGINT);
  EXPECT_EQ(hz.Wait(), 0) << hz.Stderr();
  EXPECT_EQ(bw.Wait(), 0) << bw.Stderr();
  EXPECT_EQ(min_count, 1u);
  EXPECT_EQ(max_count, 1u);
  EXPECT_EQ(max_listed, 1u);
  EXPECT_EQ(hz.Stderr(), "");
  EXPECT_EQ(bw.Stderr(), "");

  // hz: one report a second (and one at SIGINT), the last over a full window.
  const std::vector<std::string> hz_lines = Lines(hz.Stdout());
  std::vector<double> rates;
  for (size_t i = 0; i < hz_lines.size(); ++i) {
    std::smatch m;
    if (std::regex_match(hz_lines[i], m, std::regex("average rate: ([0-9.]+) Hz"))) {
      rates.push_back(std::stod(m[1]));
      ASSERT_LT(i + 1, hz_lines.size());
      EXPECT_TRUE(std::regex_match(hz_lines[i + 1],
                                   std::regex("    min: 0\\.0[0-9]{3} s  max: 0\\.0[0-9]{3} s  std "
                                              "dev: [0-9.]+ s  window: [0-9]+")))
          << hz_lines[i + 1];
    }
  }
  ASSERT_GE(rates.size(), 2u) << hz.Stdout();
  EXPECT_NEAR(rates.back(), 30.0, 3.0) << hz.Stdout();

  // bw: 30 Hz x 10 kB = 300 kB/s.
  const std::vector<std::string> bw_lines = Lines(bw.Stdout());
  ASSERT_GE(bw_lines.size(), 2u) << bw.Stdout();
  std::smatch m;
  const std::string& rate_line = bw_lines[bw_lines.size() - 2];
  ASSERT_TRUE(
      std::regex_match(rate_line, m, std::regex("([0-9.]+) (B|KB|MB|GB)/s from ([0-9]+) messages")))
      << bw.Stdout();
  EXPECT_NEAR(std::stod(m[1]) * UnitBytes(m[2]), 30.0 * kBytes, 3.0 * kBytes) << rate_line;
  EXPECT_GE(std::stoul(m[3]), 30u);
  EXPECT_EQ(bw_lines.back(), "    message size mean: 10.00 KB");
  EXPECT_EQ(ticker.mismatches(), 0u);
}

TEST_F(TopicCliTest, HzReportsTopicsWithoutMessages) {
  Publisher idle("/cli/idle", kBlob, Options(8, "/idle"));
  const Result hz = RunProbeless({"topic", "hz", "/cli/idle", "--duration", "0.3"});
  EXPECT_EQ(hz.code, 0) << hz.err;
  EXPECT_EQ(hz.out, "no new messages\n");
}

// --- topic echo --------------------------------------------------------------------------------

TEST_F(TopicCliTest, EchoPrintsCountMessagesWithTheirSequences) {
  Publisher pub("/cli/echo", kBlob, Options(24, "/talker"));
  Ticker ticker(pub, 30, 24);
  const Result echo = RunProbeless({"topic", "echo", "/cli/echo", "-n", "3"});
  ticker.Stop();
  ASSERT_EQ(echo.code, 0) << echo.err;
  EXPECT_EQ(echo.err, "");
  std::vector<std::string> blocks;
  std::string block;
  for (const std::string& line : Lines(echo.out)) {
    if (line == "---") {
      blocks.push_back(block);
      block.clear();
    } else {
      block += line + "\n";
    }
  }
  EXPECT_EQ(block, "");
  ASSERT_EQ(blocks.size(), 3u) << echo.out;
  uint64_t previous = 0;
  for (const std::string& b : blocks) {
    std::smatch m;
    ASSERT_TRUE(std::regex_search(b, m, std::regex("^sequence: ([0-9]+)\n"))) << b;
    const uint64_t sequence = std::stoull(m[1]);
    EXPECT_GT(sequence, previous);
    EXPECT_LE(sequence, ticker.published());
    previous = sequence;
    // The payload starts with the sequence the publisher wrote (little-endian uint64).
    std::string hex;
    char byte[4];
    for (int i = 0; i < 8; ++i) {
      std::snprintf(byte, sizeof(byte), "%02x ",
                    static_cast<unsigned>((sequence >> (8 * i)) & 0xff));
      hex += byte;
    }
    EXPECT_NE(b.find("publisher pid: " + std::to_string(getpid()) + "\n"), std::string::npos) << b;
    EXPECT_NE(b.find("size: 24 B\ndata (24 bytes):\n  0000  " + hex + " a5 a5 a5"),
              std::string::npos)
        << b;
    EXPECT_TRUE(std::regex_search(
        b,
        std::regex("\npublished: 20[0-9]{2}-[0-9]{2}-[0-9]{2}T[0-9:.]+Z \\(mono [0-9.]+ s\\)\n")))
        << b;
  }
  EXPECT_EQ(ticker.mismatches(), 0u);
}

TEST_F(TopicCliTest, EchoWaitsForTheTopicAndSubscribesWithQueueDepthOne) {
  Probeless echo({"topic", "echo", "/cli/late", "-n", "1", "--timeout", "10"});
  std::this_thread::sleep_for(300ms);
  EXPECT_TRUE(ListTopics().empty()) << "waiting must not create the topic";
  // Any type can be echoed: the type comes from the topic's registry.
  Publisher pub("/cli/late", {"custom_msgs/Anything", 0xfeed}, Options(8, "/late"));
  bool subscribed = false;
  for (int i = 0; i < 500 && !subscribed; ++i) {
    for (const auto& t : ListTopics()) {
      for (const auto& s : t.subscribers) {
        if (s.node_name == "probeless_echo") {
          subscribed = true;
          EXPECT_EQ(s.queue_depth, 1u);
          EXPECT_EQ(s.pid, echo.pid());
        }
      }
    }
    if (!subscribed) std::this_thread::sleep_for(10ms);
  }
  ASSERT_TRUE(subscribed);
  EXPECT_EQ(pub.SubscriberCount(), 1u);
  const std::string text = "12345678";
  pub.PublishCopy(std::as_bytes(std::span(text.data(), text.size())));
  EXPECT_EQ(echo.Wait(), 0) << echo.Stderr();
  const std::string out = echo.Stdout();
  EXPECT_EQ(out.rfind("sequence: 1\n", 0), 0u) << out;
  EXPECT_NE(out.find("size: 8 B\ndata (8 bytes):\n  0000  31 32 33 34 35 36 37 38 "),
            std::string::npos)
      << out;
  EXPECT_EQ(pub.SubscriberCount(), 0u);  // echo left the topic
}

TEST_F(TopicCliTest, EchoOfAMissingTopicFailsAfterTheTimeout) {
  const auto start = std::chrono::steady_clock::now();
  const Result echo = RunProbeless({"topic", "echo", "/cli/none", "--timeout", "0.3"});
  const auto elapsed = std::chrono::steady_clock::now() - start;
  EXPECT_EQ(echo.code, 1);
  EXPECT_EQ(echo.out, "");
  EXPECT_EQ(echo.err, "probeless topic echo: no topic '/cli/none' in domain '" + Domain() +
                          "' after waiting 0.3 s\n");
  EXPECT_GE(elapsed, 300ms);
  EXPECT_LT(elapsed, 5s);
}

// --- clean -------------------------------------------------------------------------------------

std::set<std::string> Listed(const std::string& out, const std::string& verb) {
  std::set<std::string> names;
  for (const std::string& line : Lines(out)) {
    EXPECT_EQ(line.rfind(verb + " ", 0), 0u) << line;
    names.insert(line.substr(verb.size() + 1));
  }
  return names;
}

TEST_F(TopicCliTest, CleanRemovesTheSegmentsOfAKilledPublisherOnly) {
  Publisher live("/cli/live", kBlob, Options(16, "/alive"));
  Subscriber live_sub("/cli/live", kBlob, {.queue_depth = 4, .node_name = "/live_sub"});
  ChildPublisher child("/cli/dead", kBlob, "/doomed");
  const pid_t dead_pid = child.pid();
  EXPECT_EQ(child.Kill(), 128 + SIGKILL);

  const std::string prefix = SegmentPrefix();
  const std::set<std::string> before = Segments();
  std::set<std::string> expected = {prefix + "t.cli.dead"};
  for (const std::string& name : before) {
    if (name.rfind(prefix + "p." + std::to_string(dead_pid) + ".", 0) == 0) expected.insert(name);
  }
  ASSERT_EQ(expected.size(), 2u) << "registry and pool of the killed child";
  ASSERT_TRUE(before.count(prefix + "t.cli.live"));

  const Result dry = RunProbeless({"clean", "--dry-run"});
  ASSERT_EQ(dry.code, 0) << dry.err;
  EXPECT_EQ(Listed(dry.out, "would remove"), expected) << dry.out;
  EXPECT_EQ(Segments(), before) << "--dry-run removed something";

  const Result clean = RunProbeless({"clean"});
  ASSERT_EQ(clean.code, 0) << clean.err;
  EXPECT_EQ(clean.err, "");
  EXPECT_EQ(Listed(clean.out, "removed"), expected) << clean.out;
  std::set<std::string> remaining = before;
  for (const std::string& name : expected) remaining.erase(name);
  EXPECT_EQ(Segments(), remaining);

  // The live topic still works.
  const std::string text = "still alive";
  live.PublishCopy(std::as_bytes(std::span(text.data(), text.size())));
  auto sample = live_sub.TryTake();
  ASSERT_TRUE(sample);
  EXPECT_EQ(sample->info().size, text.size());

  const Result again = RunProbeless({"clean"});
  EXPECT_EQ(again.code, 0);
  EXPECT_EQ(again.out, "nothing to clean\n");
  const Result dry_again = RunProbeless({"clean", "--dry-run"});
  EXPECT_EQ(dry_again.out, "nothing to clean\n");
}

// --- errors ------------------------------------------------------------------------------------

TEST_F(TopicCliTest, BadInputGivesExactOneLineErrorsAndExitCodes) {
  const std::string domain = Domain();
  struct Case {
    std::vector<std::string> args;
    int code;
    std::string error;
  };
  const std::vector<Case> cases = {
      {{"topic"}, 2, "probeless topic: missing subcommand (expected list, info, hz, bw or echo)"},
      {{"topic", "frob"},
       2,
       "probeless topic: unknown subcommand 'frob' (expected list, info, hz, bw or echo)"},
      {{"topic", "info"},
       2,
       "probeless topic info: missing TOPIC (usage: probeless topic info TOPIC)"},
      {{"topic", "info", "camera"},
       2,
       "probeless topic info: invalid topic name 'camera': must start with '/' (expected e.g. "
       "/camera/image)"},
      {{"topic", "info", "/a", "/b"}, 2, "probeless topic info: unexpected argument '/b'"},
      {{"topic", "info", "/cli/none"},
       1,
       "probeless topic info: no topic '/cli/none' in domain '" + domain +
           "' (see 'probeless topic list')"},
      {{"topic", "hz", "/a", "--window", "0"},
       2,
       "probeless topic hz: --window expects a positive integer, got '0'"},
      {{"topic", "hz", "/a", "--window"}, 2, "probeless topic hz: --window expects a value"},
      {{"topic", "hz"},
       2,
       "probeless topic hz: missing TOPIC (usage: probeless topic hz TOPIC [--window N] "
       "[--duration S] [--timeout S])"},
      {{"topic", "bw", "/a", "--duration", "soon"},
       2,
       "probeless topic bw: --duration expects a non-negative number of seconds, got 'soon'"},
      {{"topic", "hz", "/cli/none", "--timeout", "0"},
       1,
       "probeless topic hz: no topic '/cli/none' in domain '" + domain + "' after waiting 0 s"},
      {{"topic", "echo", "/a", "-n", "abc"},
       2,
       "probeless topic echo: -n expects a positive integer, got 'abc'"},
      {{"topic", "echo", "/a", "--timeout=-1"},
       2,
       "probeless topic echo: --timeout expects a non-negative number of seconds, got '-1'"},
      {{"topic", "echo", "/a//b"},
       2,
       "probeless topic echo: invalid topic name '/a//b': contains '//'"},
      {{"topic", "list", "--bogus"}, 2, "probeless topic list: unknown option '--bogus'"},
      {{"topic", "list", "-v=1"}, 2, "probeless topic list: -v takes no value"},
      {{"topic", "list", "/extra"}, 2, "probeless topic list: unexpected argument '/extra'"},
      {{"clean", "extra"}, 2, "probeless clean: unexpected argument 'extra'"},
      {{"clean", "--force"}, 2, "probeless clean: unknown option '--force'"},
  };
  for (const Case& c : cases) {
    const Result r = RunProbeless(c.args);
    std::string joined;
    for (const auto& a : c.args) joined += a + " ";
    EXPECT_EQ(r.code, c.code) << joined;
    EXPECT_EQ(r.err, c.error + "\n") << joined;
    EXPECT_EQ(r.out, "") << joined;
  }
  const Result bad_domain = RunProbeless({"topic", "list"}, "bad-domain");
  EXPECT_EQ(bad_domain.code, 2);
  EXPECT_EQ(bad_domain.err,
            "probeless topic list: PROBELESS_DOMAIN 'bad-domain' may contain only letters, digits "
            "and '_' (expected e.g. 0 or lab_2)\n");
  // Help goes to stdout with exit 0.
  for (const std::vector<std::string>& args : {std::vector<std::string>{"topic", "--help"},
                                               {"topic", "echo", "--help"},
                                               {"clean", "-h"}}) {
    const Result help = RunProbeless(args);
    EXPECT_EQ(help.code, 0);
    EXPECT_EQ(help.err, "");
    EXPECT_NE(help.out.find("usage: probeless "), std::string::npos) << help.out;
  }
}

}  // namespace
