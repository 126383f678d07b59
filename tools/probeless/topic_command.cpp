// `probeless topic list|info|hz|bw|echo` and `probeless clean`: look at a running graph without
// disturbing it. list/info/hz/bw only read the registries (bus::ListTopics); echo is the one
// command that joins a topic, as a single subscriber of queue depth 1. Reference: docs/cli.md.
#include <dirent.h>
#include <signal.h>
#include <time.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <functional>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "commands.h"
#include "probeless/bus/bus.h"
#include "topic_format.h"

namespace probeless::tools {
namespace {

using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;

// A failure at run time (exit code 1); what() is one line without the command prefix.
class RuntimeFailure : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

constexpr const char* kSubcommands = "list, info, hz, bw or echo";
constexpr const char* kListUsage = "probeless topic list [-v]";
constexpr const char* kInfoUsage = "probeless topic info TOPIC";
constexpr const char* kHzUsage =
    "probeless topic hz TOPIC [--window N] [--duration S] [--timeout S]";
constexpr const char* kBwUsage =
    "probeless topic bw TOPIC [--window N] [--duration S] [--timeout S]";
constexpr const char* kEchoUsage = "probeless topic echo TOPIC [-n COUNT] [--timeout S]";
constexpr const char* kCleanUsage = "probeless clean [--dry-run]";

constexpr uint64_t kDefaultWindow = 10000;    // messages, as `ros2 topic hz`
constexpr double kDefaultTopicTimeout = 5.0;  // seconds to wait for a topic to appear
constexpr auto kPollPeriod = 100ms;           // hz/bw: registry reads
constexpr auto kReportPeriod = 1s;            // hz/bw: printed reports
constexpr auto kInfoRateWindow = 500ms;       // info: time between the two counter readings

// Set by SIGINT/SIGTERM: loops finish their current step and the command exits 0.
std::atomic<bool> g_stop{false};
static_assert(std::atomic<bool>::is_always_lock_free);

void OnStopSignal(int) { g_stop.store(true); }

void InstallStopHandlers() {
  struct sigaction action {};
  action.sa_handler = OnStopSignal;
  sigemptyset(&action.sa_mask);
  action.sa_flags = 0;  // no SA_RESTART: blocking calls return early
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
}

// Sleeps until `deadline`; returns false as soon as a stop signal arrives instead.
bool SleepUntil(Clock::time_point deadline) {
  while (!g_stop.load()) {
    const auto now = Clock::now();
    if (now >= deadline) return true;
    std::this_thread::sleep_for(std::min<Clock::duration>(deadline - now, 20ms));
  }
  return false;
}

Clock::duration ToDuration(double seconds) {
  return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds));
}

// Seconds as typed by a user: "5", "0.3".
std::string SecondsText(double seconds) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%g", seconds);
  return buffer;
}

int64_t MonotonicNowNs() {
  timespec now{};
  clock_gettime(CLOCK_MONOTONIC, &now);
  return static_cast<int64_t>(now.tv_sec) * 1'000'000'000 + now.tv_nsec;
}

// Runs `body`, turning exceptions into one line "<prefix>: <message>" on stderr and the exit
// code: 2 for usage errors, 1 for everything else.
int Guarded(const std::string& prefix, const std::function<int()>& body) {
  try {
    return body();
  } catch (const UsageError& e) {
    std::fprintf(stderr, "%s: %s\n", prefix.c_str(), e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: %s\n", prefix.c_str(), e.what());
    return 1;
  }
}

// The domain of this process; an invalid PROBELESS_DOMAIN is a usage error.
std::string Domain() {
  try {
    return bus::CurrentDomain();
  } catch (const bus::BusError& e) {
    throw UsageError(e.what());
  }
}

std::vector<std::string> Arguments(int argc, char** argv, int first) {
  std::vector<std::string> args;
  for (int i = first; i < argc; ++i) args.emplace_back(argv[i]);
  return args;
}

void RejectPositionals(const ParsedArgs& args) {
  if (!args.positionals.empty()) {
    throw UsageError("unexpected argument '" + args.positionals.front() + "'");
  }
}

// The single TOPIC positional, validated.
std::string RequireTopic(const ParsedArgs& args, const char* usage) {
  if (args.positionals.empty()) {
    throw UsageError(std::string("missing TOPIC (usage: ") + usage + ")");
  }
  if (args.positionals.size() > 1) {
    throw UsageError("unexpected argument '" + args.positionals[1] + "'");
  }
  const std::string& topic = args.positionals.front();
  try {
    bus::ValidateTopicName(topic);
  } catch (const bus::BusError& e) {
    throw UsageError(e.what());
  }
  return topic;
}

std::string NoSuchTopic(const std::string& topic, const std::string& domain) {
  return "no topic '" + topic + "' in domain '" + domain + "'";
}

std::optional<bus::TopicSnapshot> FindTopic(const std::string& domain, const std::string& topic) {
  for (bus::TopicSnapshot& t : bus::ListTopics(domain)) {
    if (t.topic == topic) return std::move(t);
  }
  return std::nullopt;
}

// Waits up to `timeout_s` for `topic` to exist. nullopt if a stop signal came first; throws
// RuntimeFailure when the time is up.
std::optional<bus::TopicSnapshot> WaitForTopic(const std::string& domain, const std::string& topic,
                                               double timeout_s) {
  const auto deadline = Clock::now() + ToDuration(timeout_s);
  for (;;) {
    if (auto found = FindTopic(domain, topic)) return found;
    if (Clock::now() >= deadline) {
      throw RuntimeFailure(NoSuchTopic(topic, domain) + " after waiting " + SecondsText(timeout_s) +
                           " s");
    }
    if (!SleepUntil(std::min(deadline, Clock::now() + 50ms))) return std::nullopt;
  }
}

double TimeoutOption(const ParsedArgs& args) {
  return args.Has("--timeout") ? ParseSeconds("--timeout", args.options.find("--timeout")->second)
                               : kDefaultTopicTimeout;
}

std::string NodeText(const std::string& node) { return node.empty() ? "(none)" : node; }

// "2", or "2 (+1 dead)" when some participants are dead but not yet reclaimed.
template <class Participants>
std::string CountText(const Participants& participants) {
  size_t alive = 0;
  for (const auto& p : participants) alive += p.alive ? 1 : 0;
  std::string text = std::to_string(alive);
  if (alive != participants.size()) {
    text += " (+" + std::to_string(participants.size() - alive) + " dead)";
  }
  return text;
}

// --- topic list --------------------------------------------------------------------------------

int List(const std::vector<std::string>& argv) {
  static constexpr OptionSpec kSpecs[] = {{"-v", false}, {"--verbose", false}};
  const ParsedArgs args = ParseArgs(argv, kSpecs);
  if (args.help) {
    std::printf(
        "usage: %s\nTopics of this user and domain with type, publisher and subscriber "
        "counts (-v: every participant).\n",
        kListUsage);
    return 0;
  }
  RejectPositionals(args);
  const bool verbose = args.Has("-v") || args.Has("--verbose");
  const std::string domain = Domain();
  const std::vector<bus::TopicSnapshot> topics = bus::ListTopics(domain);
  if (topics.empty()) {
    std::printf("no topics in domain '%s'\n", domain.c_str());
    return 0;
  }
  std::vector<std::vector<std::string>> rows = {{"TOPIC", "TYPE", "PUBLISHERS", "SUBSCRIBERS"}};
  for (const auto& t : topics) {
    rows.push_back({t.topic, t.type.name, CountText(t.publishers), CountText(t.subscribers)});
  }
  const std::string table = FormatTable(rows);
  size_t begin = 0;
  for (size_t row = 0; row < rows.size(); ++row) {
    const size_t end = table.find('\n', begin) + 1;
    std::fputs(table.substr(begin, end - begin).c_str(), stdout);
    begin = end;
    if (!verbose || row == 0) continue;
    const bus::TopicSnapshot& t = topics[row - 1];
    for (const auto& p : t.publishers) {
      std::printf("    publisher   pid %d  node %s  %s\n", p.pid, NodeText(p.node_name).c_str(),
                  p.alive ? "alive" : "dead");
    }
    for (const auto& s : t.subscribers) {
      std::printf("    subscriber  pid %d  node %s  %s\n", s.pid, NodeText(s.node_name).c_str(),
                  s.alive ? "alive" : "dead");
    }
  }
  return 0;
}

// --- topic info --------------------------------------------------------------------------------

bool SamePublisher(const bus::PublisherSnapshot& a, const bus::PublisherSnapshot& b) {
  return a.pid == b.pid && a.node_name == b.node_name &&
         a.max_message_bytes == b.max_message_bytes && a.slot_count == b.slot_count;
}

int Info(const std::vector<std::string>& argv) {
  const ParsedArgs args = ParseArgs(argv, {});
  if (args.help) {
    std::printf(
        "usage: %s\nType, layout hash, publishers and subscribers of TOPIC with their "
        "counters and each publisher's rate.\n",
        kInfoUsage);
    return 0;
  }
  const std::string topic = RequireTopic(args, kInfoUsage);
  const std::string domain = Domain();
  InstallStopHandlers();
  const auto first = FindTopic(domain, topic);
  if (!first) throw RuntimeFailure(NoSuchTopic(topic, domain) + " (see 'probeless topic list')");
  // Rates come from two readings of the publish counters.
  SleepUntil(Clock::now() + kInfoRateWindow);
  const auto second = FindTopic(domain, topic);
  if (!second) throw RuntimeFailure("topic '" + topic + "' disappeared while being inspected");
  const int64_t now_ns = MonotonicNowNs();
  char hash[32];
  std::snprintf(hash, sizeof(hash), "0x%016llx",
                static_cast<unsigned long long>(second->type.layout_hash));
  std::printf("topic: %s\ntype: %s\nlayout hash: %s\n", topic.c_str(), second->type.name.c_str(),
              hash);
  std::printf("publishers: %zu\n", second->publishers.size());
  for (size_t i = 0; i < second->publishers.size(); ++i) {
    const bus::PublisherSnapshot& p = second->publishers[i];
    std::string rate;
    if (p.published == 0) {
      rate = "- (nothing published yet)";
    } else if (i < first->publishers.size() && SamePublisher(first->publishers[i], p)) {
      const auto& before = first->publishers[i];
      const auto hz = RateBetween(before.published, before.last_publish_mono_ns, p.published,
                                  p.last_publish_mono_ns);
      rate = hz ? FormatFixed(*hz, 2) + " Hz"
                : "0 Hz (no message in " +
                      SecondsText(std::chrono::duration<double>(kInfoRateWindow).count()) + " s)";
    } else {
      rate = "- (publisher joined while measuring)";
    }
    std::printf("  - node: %s\n    pid: %d\n    alive: %s\n", NodeText(p.node_name).c_str(), p.pid,
                p.alive ? "yes" : "no");
    std::printf("    capacity: %s\n    slots: %u\n    history: %u\n",
                FormatByteCount(p.max_message_bytes).c_str(), p.slot_count, p.history);
    std::printf("    published: %llu messages, %s\n    rate: %s\n",
                static_cast<unsigned long long>(p.published),
                FormatByteCount(p.published_bytes).c_str(), rate.c_str());
    if (p.published > 0) {
      std::printf(
          "    last message: %s s ago\n",
          FormatFixed(static_cast<double>(now_ns - p.last_publish_mono_ns) * 1e-9, 3).c_str());
    }
  }
  std::printf("subscribers: %zu\n", second->subscribers.size());
  for (const bus::SubscriberSnapshot& s : second->subscribers) {
    std::printf("  - node: %s\n    pid: %d\n    alive: %s\n", NodeText(s.node_name).c_str(), s.pid,
                s.alive ? "yes" : "no");
    std::printf("    queue depth: %u\n    queued: %u\n    received: %llu\n    dropped: %llu\n",
                s.queue_depth, s.queued, static_cast<unsigned long long>(s.received),
                static_cast<unsigned long long>(s.dropped));
  }
  return 0;
}

// --- topic hz / topic bw -----------------------------------------------------------------------

// Polls the topic's publisher counters every kPollPeriod and reports every kReportPeriod; never
// joins the topic.
int Measure(bool bandwidth, const std::vector<std::string>& argv) {
  static constexpr OptionSpec kSpecs[] = {
      {"--window", true}, {"--duration", true}, {"--timeout", true}};
  const char* usage = bandwidth ? kBwUsage : kHzUsage;
  const ParsedArgs args = ParseArgs(argv, kSpecs);
  if (args.help) {
    std::printf(
        "usage: %s\n%s of TOPIC over the last N messages (default %llu), read from the "
        "publishers' counters without subscribing. Runs for S seconds or until Ctrl-C.\n",
        usage, bandwidth ? "Bandwidth" : "Publish rate",
        static_cast<unsigned long long>(kDefaultWindow));
    return 0;
  }
  const std::string topic = RequireTopic(args, usage);
  const uint64_t window_messages =
      args.Has("--window") ? ParseCount("--window", args.options.find("--window")->second)
                           : kDefaultWindow;
  std::optional<double> duration_s;
  if (args.Has("--duration")) {
    duration_s = ParseSeconds("--duration", args.options.find("--duration")->second);
  }
  const double timeout_s = TimeoutOption(args);
  const std::string domain = Domain();
  InstallStopHandlers();
  if (!WaitForTopic(domain, topic, timeout_s)) return 0;

  RateWindow window(window_messages);
  const auto start = Clock::now();
  const auto deadline = duration_s ? start + ToDuration(*duration_s) : Clock::time_point::max();
  auto next_poll = start;
  auto next_report = start + kReportPeriod;
  uint64_t new_since_report = 0;
  bool reported = false;
  auto report = [&] {
    const auto stats = window.Compute();
    if (new_since_report == 0 || !stats) {
      std::fputs("no new messages\n", stdout);
    } else {
      std::fputs((bandwidth ? FormatBandwidthReport(*stats) : FormatRateReport(*stats)).c_str(),
                 stdout);
    }
    std::fflush(stdout);
    new_since_report = 0;
    reported = true;
  };
  for (;;) {
    const auto topic_now = FindTopic(domain, topic);
    new_since_report += window.Add(SumPublishers(topic_now ? &*topic_now : nullptr));
    const auto now = Clock::now();
    if (g_stop.load() || now >= deadline) break;
    if (now >= next_report) {
      report();
      next_report = std::max(next_report + kReportPeriod, now);
    }
    next_poll += kPollPeriod;
    if (next_poll < now) next_poll = now;
    if (!SleepUntil(std::min(next_poll, deadline))) break;
  }
  if (new_since_report > 0 || !reported) report();
  return 0;
}

// --- topic echo --------------------------------------------------------------------------------

int Echo(const std::vector<std::string>& argv) {
  static constexpr OptionSpec kSpecs[] = {{"-n", true}, {"--timeout", true}};
  const ParsedArgs args = ParseArgs(argv, kSpecs);
  if (args.help) {
    std::printf(
        "usage: %s\nPrints COUNT messages of TOPIC (default: until Ctrl-C), subscribing "
        "with queue depth 1; waits up to S seconds (default 5) for the topic.\n",
        kEchoUsage);
    return 0;
  }
  const std::string topic = RequireTopic(args, kEchoUsage);
  const uint64_t count = args.Has("-n") ? ParseCount("-n", args.options.find("-n")->second) : 0;
  const double timeout_s = TimeoutOption(args);
  const std::string domain = Domain();
  InstallStopHandlers();
  const auto found = WaitForTopic(domain, topic, timeout_s);
  if (!found) return 0;
  bus::SubscriberOptions options;
  options.queue_depth = 1;
  options.receive_history = true;
  options.node_name = "probeless_echo";
  bus::Subscriber subscriber(topic, found->type, options);
  uint64_t printed = 0;
  while (!g_stop.load() && (count == 0 || printed < count)) {
    std::optional<bus::Sample> sample = subscriber.Take(100ms);
    if (!sample) continue;
    const std::string text = FormatMessage(found->type, sample->info(), sample->data());
    sample->Release();
    std::fputs(text.c_str(), stdout);
    std::fflush(stdout);
    ++printed;
  }
  return 0;
}

// --- clean -------------------------------------------------------------------------------------

bool PidAlive(int32_t pid) { return pid > 0 && !(::kill(pid, 0) != 0 && errno == ESRCH); }

// This user's and domain's segment names in /dev/shm, without the prefix.
std::vector<std::string> DomainSegments(const std::string& prefix) {
  std::vector<std::string> names;
  DIR* dir = ::opendir("/dev/shm");
  if (dir == nullptr) throw RuntimeFailure("cannot read /dev/shm: " + std::string(strerror(errno)));
  while (const dirent* entry = ::readdir(dir)) {
    const std::string name = entry->d_name;
    if (name.rfind(prefix, 0) == 0) names.push_back(name.substr(prefix.size()));
  }
  ::closedir(dir);
  return names;
}

int Clean(const std::vector<std::string>& argv) {
  static constexpr OptionSpec kSpecs[] = {{"--dry-run", false}};
  const ParsedArgs args = ParseArgs(argv, kSpecs);
  if (args.help) {
    std::printf(
        "usage: %s\nRemoves this user's and domain's shared-memory segments that belong "
        "only to dead processes (--dry-run: list them, remove nothing).\n",
        kCleanUsage);
    return 0;
  }
  RejectPositionals(args);
  const std::string domain = Domain();
  std::vector<std::string> names;
  const char* verb = "removed";
  if (args.Has("--dry-run")) {
    verb = "would remove";
    const std::string prefix = "probeless." + std::to_string(::getuid()) + "." + domain + ".";
    for (const std::string& name :
         PlanCleanup(DomainSegments(prefix), bus::ListTopics(domain), PidAlive)) {
      names.push_back(prefix + name);
    }
  } else {
    names = bus::CleanDeadSegments(domain);
  }
  if (names.empty()) std::puts("nothing to clean");
  for (const std::string& name : names) std::printf("%s %s\n", verb, name.c_str());
  return 0;
}

void PrintTopicHelp(std::FILE* out) {
  std::fprintf(out,
               "usage: probeless topic <subcommand> [arguments]\n\n"
               "  %s\n  %s\n  %s\n  %s\n  %s\n\n"
               "Topics are those of this user and domain ($PROBELESS_DOMAIN, default 0).\n",
               kListUsage, kInfoUsage, kHzUsage, kBwUsage, kEchoUsage);
}

}  // namespace

int RunTopicCommand(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "probeless topic: missing subcommand (expected %s)\n", kSubcommands);
    return 2;
  }
  const std::string sub = argv[1];
  if (sub == "-h" || sub == "--help" || sub == "help") {
    PrintTopicHelp(stdout);
    return 0;
  }
  const std::vector<std::string> args = Arguments(argc, argv, 2);
  const std::string prefix = "probeless topic " + sub;
  if (sub == "list") return Guarded(prefix, [&] { return List(args); });
  if (sub == "info") return Guarded(prefix, [&] { return Info(args); });
  if (sub == "hz") return Guarded(prefix, [&] { return Measure(false, args); });
  if (sub == "bw") return Guarded(prefix, [&] { return Measure(true, args); });
  if (sub == "echo") return Guarded(prefix, [&] { return Echo(args); });
  std::fprintf(stderr, "probeless topic: unknown subcommand '%s' (expected %s)\n", sub.c_str(),
               kSubcommands);
  return 2;
}

int RunCleanCommand(int argc, char** argv) {
  const std::vector<std::string> args = Arguments(argc, argv, 1);
  return Guarded("probeless clean", [&] { return Clean(args); });
}

}  // namespace probeless::tools
