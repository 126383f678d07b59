#include "probeless/node/node.h"

#include <sys/resource.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <climits>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <mutex>
#include <optional>
#include <sstream>

#include "arguments.h"
#include "names.h"
#include "params.h"
#include "probeless/msgs/replay.h"
#include "probeless/node/main.h"
#include "text.h"

namespace probeless::node {

using internal::ParamValue;

namespace {

std::mutex& LogMutex() {
  static std::mutex mutex;
  return mutex;
}

void WriteAll(int fd, std::string_view text) {
  while (!text.empty()) {
    const ssize_t n = ::write(fd, text.data(), text.size());
    if (n < 0) {
      if (errno == EINTR) continue;
      return;  // stderr is gone: nothing sensible left to report to
    }
    text.remove_prefix(static_cast<size_t>(n));
  }
}

template <class T>
constexpr std::string_view ExpectedTypeName() {
  if constexpr (std::is_same_v<T, bool>) return "bool";
  if constexpr (std::is_same_v<T, int64_t> || std::is_same_v<T, int>) return "integer";
  if constexpr (std::is_same_v<T, double>) return "double";
  if constexpr (std::is_same_v<T, std::string>) return "string";
  if constexpr (std::is_same_v<T, std::vector<double>>) return "double_array";
  if constexpr (std::is_same_v<T, std::vector<int64_t>>) return "integer_array";
  if constexpr (std::is_same_v<T, std::vector<std::string>>) return "string_array";
}

template <class T>
ParamValue ToParamValue(const T& value) {
  if constexpr (std::is_same_v<T, int>) {
    return static_cast<int64_t>(value);
  } else {
    return value;
  }
}

// Converts `value` to T; false if the types are incompatible.
template <class T>
bool ConvertParam(const ParamValue& value, T& out) {
  if constexpr (std::is_same_v<T, double>) {
    if (const int64_t* i = std::get_if<int64_t>(&value)) {
      out = static_cast<double>(*i);
      return true;
    }
  } else if constexpr (std::is_same_v<T, int>) {
    if (const int64_t* i = std::get_if<int64_t>(&value)) {
      if (*i < INT_MIN || *i > INT_MAX) return false;
      out = static_cast<int>(*i);
      return true;
    }
    return false;
  } else if constexpr (std::is_same_v<T, std::vector<double>>) {
    if (const auto* ints = std::get_if<std::vector<int64_t>>(&value)) {
      out.assign(ints->begin(), ints->end());
      return true;
    }
  }
  if constexpr (std::is_same_v<T, std::vector<double>> || std::is_same_v<T, std::vector<int64_t>> ||
                std::is_same_v<T, std::vector<std::string>>) {
    if (std::holds_alternative<internal::EmptyArray>(value)) {
      out.clear();
      return true;
    }
  }
  if constexpr (!std::is_same_v<T, int>) {
    if (const T* exact = std::get_if<T>(&value)) {
      out = *exact;
      return true;
    }
  }
  return false;
}

int64_t MonotonicNs() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return int64_t{ts.tv_sec} * 1'000'000'000 + ts.tv_nsec;
}

// Handler timing of one Spin input (only with $PROBELESS_NODE_STATS).
struct InputTiming {
  const bus::Subscriber* subscriber = nullptr;
  std::vector<int64_t> durations_ns;
};
struct HandlerCall {
  int64_t start_ns = 0;
  int64_t duration_ns = 0;
  size_t input = 0;
};
constexpr size_t kMaxRecordedCalls = 100000;

double Quantile(std::vector<int64_t> values, double q) {
  if (values.empty()) return 0.0;
  std::sort(values.begin(), values.end());
  const size_t index = std::min(values.size() - 1, static_cast<size_t>(q * values.size()));
  return static_cast<double>(values[index]) * 1e-6;
}

std::string StatsFileName(std::string fqn) {
  if (fqn.starts_with('/')) fqn.erase(0, 1);
  std::replace(fqn.begin(), fqn.end(), '/', '.');
  return (fqn.empty() ? std::string("root") : fqn) + ".json";
}

// "[1, 8]", "(0, inf)", "[-inf, 3]".
std::string RangeText(const ParamDescriptor& d) {
  return std::string(d.min && !d.min_exclusive ? "[" : "(") +
         (d.min ? internal::FormatReal(*d.min) : "-inf") + ", " +
         (d.max ? internal::FormatReal(*d.max) : "inf") + (d.max ? "]" : ")");
}

// ParamInfo::constraint of a descriptor.
std::string ConstraintText(const ParamDescriptor& d) {
  if (d.min || d.max) return RangeText(d);
  if (!d.choices.empty()) return "one of " + internal::Join(d.choices, "|");
  return {};
}

const ParamDescriptor kLogLevelDescriptor{.description = "lowest level of the lines logged"};

// Levenshtein distance, for "did you mean" on unknown parameters.
size_t EditDistance(std::string_view a, std::string_view b) {
  std::vector<size_t> row(b.size() + 1);
  for (size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (size_t i = 1; i <= a.size(); ++i) {
    size_t diagonal = row[0];
    row[0] = i;
    for (size_t j = 1; j <= b.size(); ++j) {
      const size_t up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diagonal = up;
    }
  }
  return row[b.size()];
}

}  // namespace

std::string_view LogLevelName(LogLevel level) {
  switch (level) {
    case LogLevel::kDebug:
      return "debug";
    case LogLevel::kInfo:
      return "info";
    case LogLevel::kWarn:
      return "warn";
    case LogLevel::kError:
      return "error";
  }
  return "info";
}

LogLevel ParseLogLevel(std::string_view text) {
  std::string lower(text);
  std::transform(lower.begin(), lower.end(), lower.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (lower == "debug") return LogLevel::kDebug;
  if (lower == "info") return LogLevel::kInfo;
  if (lower == "warn" || lower == "warning") return LogLevel::kWarn;
  if (lower == "error") return LogLevel::kError;
  throw NodeError("invalid log level '" + std::string(text) +
                  "' (expected debug, info, warn or error)");
}

struct Node::Impl {
  struct Override {
    ParamValue value;
    std::string source;
    bool used = false;
    bool wildcard = false;  // set only by wildcard params-file entries: not checked when unused
  };
  struct Remap {
    std::string from;  // fully qualified
    std::string to;    // fully qualified
  };

  std::string program;
  std::string name;
  std::string ns = "/";
  std::string fqn;
  std::vector<std::string> own_args;
  std::vector<Remap> remaps;
  std::map<std::string, Override, std::less<>> overrides;
  std::vector<ParamInfo> declared;
  std::map<std::string, uint64_t> rejected;  // Spin's rejected samples per resolved topic
  mutable std::mutex mutex;                  // guards overrides, declared and rejected
  std::mutex ack_mutex;                      // guards ack_publisher and acks
  std::optional<bus::Publisher> ack_publisher;
  uint64_t acks = 0;
  int64_t created_mono_ns = MonotonicNs();
  std::atomic<int> log_level{static_cast<int>(LogLevel::kInfo)};

  std::string Prefix() const { return "node '" + (fqn.empty() ? name : fqn) + "': "; }
  [[noreturn]] void Fail(const std::string& message) const { throw NodeError(Prefix() + message); }

  void Init(const std::vector<std::string>& argv, std::string_view default_name) {
    name = std::string(default_name);
    if (!internal::IsValidNodeName(name)) {
      throw NodeError("invalid default node name '" + name +
                      "' (letters, digits and '_', not starting with a digit)");
    }
    internal::ParsedArguments args;
    try {
      args = internal::ParseArguments(argv);
    } catch (const NodeError& e) {
      Fail(e.what());
    }
    program = args.program;
    own_args = args.own_args;

    // Name and namespace: the first matching rule of each kind wins.
    bool name_set = false, ns_set = false;
    for (const internal::RemapRule& rule : args.remaps) {
      if (!rule.node.empty() && rule.node != default_name) continue;
      if (rule.from == "__node" && !name_set) {
        name = rule.to;
        name_set = true;
      } else if (rule.from == "__ns" && !ns_set) {
        ns = rule.to;
        ns_set = true;
      }
    }
    fqn = internal::FullyQualifiedName(ns, name);

    for (const internal::RemapRule& rule : args.remaps) {
      if (rule.from == "__node" || rule.from == "__ns") continue;
      if (!rule.node.empty() && rule.node != name) continue;
      try {
        remaps.push_back({internal::ExpandTopicName(rule.from, name, ns),
                          internal::ExpandTopicName(rule.to, name, ns)});
      } catch (const NodeError& e) {
        Fail("remap rule '" + rule.text + "': " + e.what());
      }
    }

    // Params files in order (within a file wildcard entries first), then -p rules.
    for (const std::string& path : args.params_files) {
      std::vector<internal::ParamsFileEntry> entries;
      try {
        entries = internal::ReadParamsFile(path);
      } catch (const NodeError& e) {
        Fail(e.what());
      }
      for (bool wildcard_pass : {true, false}) {
        for (const internal::ParamsFileEntry& entry : entries) {
          if (entry.wildcard != wildcard_pass) continue;
          if (!internal::MatchNodePattern(entry.pattern, fqn)) continue;
          for (const auto& [param, value] : entry.params) {
            // An exact entry keeps the override checked even if a later file's wildcard sets it.
            auto it = overrides.find(param);
            const bool only_wildcards =
                entry.wildcard && (it == overrides.end() || it->second.wildcard);
            overrides[param] = {value, "params file '" + path + "'", false, only_wildcards};
          }
        }
      }
    }
    for (const internal::ParamRule& rule : args.params) {
      if (!rule.node.empty() && rule.node != name) continue;
      overrides[rule.name] = {rule.value, "-p"};
    }

    // Log level: param log_level, else --log-level, else $PROBELESS_LOG_LEVEL, else info.
    std::string level = "info";
    std::string level_source = "default";
    if (const char* env = std::getenv("PROBELESS_LOG_LEVEL"); env != nullptr && *env != '\0') {
      level = env;
      level_source = "PROBELESS_LOG_LEVEL";
    }
    for (const internal::LogLevelRule& rule : args.log_levels) {
      if (rule.logger.empty() || rule.logger == name || rule.logger == fqn) {
        level = rule.level;
        level_source = "--log-level";
      }
    }
    if (auto it = overrides.find("log_level"); it != overrides.end()) {
      // A non-string override is reported by the log_level declaration in the constructor.
      if (const std::string* text = std::get_if<std::string>(&it->second.value)) {
        level = *text;
        level_source = it->second.source;
      }
    }
    try {
      log_level = static_cast<int>(ParseLogLevel(level));
    } catch (const NodeError& e) {
      Fail(std::string(e.what()) + " from " + level_source);
    }
  }

  void Declare(std::string_view param, std::string_view type, std::string value, std::string source,
               const ParamDescriptor& descriptor) {
    for (ParamInfo& info : declared) {
      if (info.name != param) continue;
      if (info.type != type) {
        Fail("parameter '" + std::string(param) + "' declared as " + info.type +
             ", now requested as " + std::string(type));
      }
      info.value = std::move(value);
      info.source = std::move(source);
      if (!descriptor.description.empty()) info.description = descriptor.description;
      if (!descriptor.unit.empty()) info.unit = descriptor.unit;
      if (const std::string c = ConstraintText(descriptor); !c.empty()) info.constraint = c;
      return;
    }
    declared.push_back({std::string(param), std::string(type), std::move(value), std::move(source),
                        descriptor.description, descriptor.unit, ConstraintText(descriptor)});
  }

  // Checks `value` (from `source`) of `param` against `descriptor`; throws NodeError if outside.
  template <class T>
  void CheckDescriptor(std::string_view param, const T& value, const std::string& source,
                       const ParamDescriptor& descriptor) const {
    const bool ranged = descriptor.min.has_value() || descriptor.max.has_value();
    constexpr bool kNumber =
        std::is_same_v<T, int> || std::is_same_v<T, int64_t> || std::is_same_v<T, double>;
    constexpr bool kNumbers =
        std::is_same_v<T, std::vector<double>> || std::is_same_v<T, std::vector<int64_t>>;
    constexpr bool kString = std::is_same_v<T, std::string>;
    constexpr bool kStrings = std::is_same_v<T, std::vector<std::string>>;
    PROBELESS_DEMAND(!ranged || kNumber || kNumbers, "a parameter range is for numbers only");
    PROBELESS_DEMAND(descriptor.choices.empty() || kString || kStrings,
                     "parameter choices are for strings only");
    const auto shown = [&] {
      const std::string text = internal::FormatValue(ToParamValue(value));
      return "parameter '" + std::string(param) + "' = " + (kString ? "\"" + text + "\"" : text) +
             " (from " + source + ")";
    };
    if constexpr (kNumber || kNumbers) {
      if (!ranged) return;
      const auto inside = [&](double v) {
        if (std::isnan(v)) return false;
        if (descriptor.min) {
          if (descriptor.min_exclusive ? !(v > *descriptor.min) : !(v >= *descriptor.min)) {
            return false;
          }
        }
        return !descriptor.max || v <= *descriptor.max;
      };
      bool ok = true;
      if constexpr (kNumber) {
        ok = inside(static_cast<double>(value));
      } else {
        for (const auto v : value) ok = ok && inside(static_cast<double>(v));
      }
      if (!ok) {
        Fail(shown() + " is out of range: expected " + (kNumbers ? "every element " : "a value ") +
             "in " + RangeText(descriptor) +
             (descriptor.unit.empty() ? std::string() : " " + descriptor.unit));
      }
    }
    if constexpr (kString || kStrings) {
      if (descriptor.choices.empty()) return;
      const auto allowed = [&](const std::string& v) {
        return std::find(descriptor.choices.begin(), descriptor.choices.end(), v) !=
               descriptor.choices.end();
      };
      bool ok = true;
      if constexpr (kString) {
        ok = allowed(value);
      } else {
        for (const std::string& v : value) ok = ok && allowed(v);
      }
      if (!ok) {
        Fail(shown() + (kStrings ? " has an element that is" : " is") + " not one of " +
             internal::Join(descriptor.choices, "|"));
      }
    }
  }

  template <class T>
  bool Lookup(std::string_view param, T& out, std::string& source) {
    auto it = overrides.find(param);
    if (it == overrides.end()) return false;
    it->second.used = true;
    source = it->second.source;
    if (!ConvertParam(it->second.value, out)) {
      const ParamValue& value = it->second.value;
      if constexpr (std::is_same_v<T, int>) {
        if (std::holds_alternative<int64_t>(value)) {
          Fail("parameter '" + std::string(param) + "' value " + internal::FormatValue(value) +
               " (from " + source + ") is out of range for int32");
        }
      }
      const std::string shown = std::holds_alternative<std::string>(value)
                                    ? "\"" + internal::FormatValue(value) + "\""
                                    : internal::FormatValue(value);
      Fail("parameter '" + std::string(param) + "' has type " +
           std::string(internal::TypeName(value)) + " (value " + shown + ", from " + source +
           "), expected " + std::string(ExpectedTypeName<T>()));
    }
    return true;
  }
};

Node::Node(int argc, char** argv, std::string_view default_name, std::string_view usage)
    : Node(std::vector<std::string>(argv, argv + argc), default_name, usage) {}

namespace {

// --help before --ros-args: the usage and the ROS-style arguments every node takes, then exit 0.
void HandleHelp(const std::vector<std::string>& argv, std::string_view name,
                std::string_view usage) {
  for (size_t i = 1; i < argv.size() && argv[i] != "--ros-args"; ++i) {
    if (argv[i] != "-h" && argv[i] != "--help") continue;
    if (usage.empty()) {
      std::printf("usage: %.*s [--ros-args ...]\n", static_cast<int>(name.size()), name.data());
    } else {
      std::printf("%.*s", static_cast<int>(usage.size()), usage.data());
      if (usage.back() != '\n') std::printf("\n");
    }
    std::printf(
        "node arguments (after --ros-args): -r/--remap FROM:=TO (topics; __node:=NAME, "
        "__ns:=/NS), -p/--param NAME:=VALUE, --params-file FILE, --log-level [LOGGER:=]LEVEL\n"
        "parameters and topics of this node: the comment at the top of its main.cpp and docs/\n");
    std::fflush(stdout);
    std::exit(0);
  }
}

}  // namespace

Node::Node(const std::vector<std::string>& argv, std::string_view default_name,
           std::string_view usage)
    : impl_(std::make_unique<Impl>()) {
  HandleHelp(argv, default_name, usage);
  impl_->Init(argv, default_name);
  InstallSignalHandlers();
  // Declare log_level so it shows in introspection (its value was applied in Init).
  std::lock_guard lock(impl_->mutex);
  auto it = impl_->overrides.find("log_level");
  if (it != impl_->overrides.end()) {
    std::string ignored;
    std::string value;
    impl_->Lookup(std::string_view("log_level"), value, ignored);
    impl_->Declare("log_level", "string", value, it->second.source, kLogLevelDescriptor);
  } else {
    impl_->Declare("log_level", "string", std::string(LogLevelName(log_level())), "default",
                   kLogLevelDescriptor);
  }
}

Node::~Node() = default;

std::string Node::AckTopic() const { return impl_->fqn == "/" ? "/ack" : impl_->fqn + "/ack"; }

void Node::Ack(const bus::Subscriber& from, const bus::MessageInfo& input) {
  std::lock_guard<std::mutex> lock(impl_->ack_mutex);
  if (!impl_->ack_publisher) {
    bus::PublisherOptions options;
    options.max_message_bytes = sizeof(msgs::Ack);
    options.slot_count = 16;
    options.node_name = fully_qualified_name();
    impl_->ack_publisher.emplace(AckTopic(), msgs::TopicTypeOf<msgs::Ack>(), options);
  }
  bus::Loan loan = impl_->ack_publisher->Borrow(sizeof(msgs::Ack));
  auto ack = msgs::WriteMessage<msgs::Ack>(loan.data());
  ack->header.StampNow();
  ack->header.sequence = ++impl_->acks;
  ack->SetTopic(from.topic());
  ack->publisher_pid = input.publisher_pid;
  ack->publish_sequence = input.sequence;
  impl_->ack_publisher->Publish(std::move(loan));
}

namespace {

// The run statistics of Node::Spin (top of node.h) into <dir>/<node>.json.
void WriteRunStats(const Node& node, int64_t created_mono_ns, const char* dir,
                   const std::vector<InputTiming>& inputs, const std::vector<HandlerCall>& calls) {
  const std::map<std::string, uint64_t> rejected = node.RejectedSamples();
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  auto seconds = [](const timeval& t) { return static_cast<double>(t.tv_sec) + t.tv_usec * 1e-6; };
  const int pid = static_cast<int>(getpid());
  // This process's participants in the registry: received/dropped of the inputs, published.
  std::map<std::string, std::pair<uint64_t, uint64_t>> received_dropped;
  std::map<std::string, uint64_t> published;
  for (const bus::TopicSnapshot& topic : bus::ListTopics()) {
    for (const bus::SubscriberSnapshot& s : topic.subscribers) {
      if (s.pid != pid) continue;
      auto& [received, dropped] = received_dropped[topic.topic];
      received += s.received;
      dropped += s.dropped;
    }
    for (const bus::PublisherSnapshot& p : topic.publishers) {
      if (p.pid == pid) published[topic.topic] += p.published;
    }
  }
  std::ostringstream out;
  out.precision(9);
  out << "{\"node\": \"" << node.fully_qualified_name() << "\", \"pid\": " << pid
      << ", \"wall_s\": " << (MonotonicNs() - created_mono_ns) * 1e-9
      << ", \"cpu_user_s\": " << seconds(usage.ru_utime)
      << ", \"cpu_system_s\": " << seconds(usage.ru_stime) << ",\n \"inputs\": [";
  for (size_t i = 0; i < inputs.size(); ++i) {
    const InputTiming& input = inputs[i];
    const std::string& topic = input.subscriber->topic();
    int64_t total = 0;
    for (int64_t d : input.durations_ns) total += d;
    const auto counters = received_dropped.find(topic);
    out << (i ? ",\n  " : "\n  ") << "{\"topic\": \"" << topic
        << "\", \"handled\": " << input.durations_ns.size()
        << ", \"received\": " << (counters == received_dropped.end() ? 0 : counters->second.first)
        << ", \"dropped\": " << input.subscriber->dropped()
        << ", \"rejected\": " << (rejected.count(topic) ? rejected.at(topic) : 0)
        << ", \"handler_ms\": {\"p50\": " << Quantile(input.durations_ns, 0.5)
        << ", \"p99\": " << Quantile(input.durations_ns, 0.99)
        << ", \"max\": " << Quantile(input.durations_ns, 1.0)
        << "}, \"handler_total_s\": " << total * 1e-9 << "}";
  }
  out << "],\n \"outputs\": [";
  bool first = true;
  for (const auto& [topic, count] : published) {
    out << (first ? "\n  " : ",\n  ") << "{\"topic\": \"" << topic << "\", \"published\": " << count
        << "}";
    first = false;
  }
  out << "],\n \"calls\": [";
  for (size_t c = 0; c < calls.size(); ++c) {
    out << (c ? (c % 8 == 0 ? ",\n  " : ", ") : "\n  ") << "[" << calls[c].start_ns << ", "
        << calls[c].duration_ns << ", " << calls[c].input << "]";
  }
  out << "]}\n";
  const std::string path = std::string(dir) + "/" + StatsFileName(node.fully_qualified_name());
  std::ofstream file(path);
  file << out.str();
  if (!file) node.Warn() << "cannot write the run statistics to " << path;
}

}  // namespace

void Node::Spin(const std::vector<Handler>& handlers) {
  CheckParamOverrides();
  const char* stats_dir = std::getenv("PROBELESS_NODE_STATS");
  const bool timed = stats_dir != nullptr && *stats_dir != '\0';
  std::vector<InputTiming> inputs(handlers.size());
  std::vector<HandlerCall> calls;
  std::vector<Handler> acking;
  acking.reserve(handlers.size());
  std::vector<uint64_t> handled(handlers.size(), 0);
  for (size_t i = 0; i < handlers.size(); ++i) {
    bus::Subscriber* subscriber = handlers[i].subscriber;
    // The bad-input rule (node.h): an InputError of the sample rejects that sample only.
    auto on_sample = [this, subscriber, inner = handlers[i].on_sample,
                      count = &handled[i]](bus::Sample&& sample) {
      ++*count;
      try {
        inner(std::move(sample));
      } catch (const NodeError&) {
        throw;  // configuration, not this sample
      } catch (const UsageError&) {
        throw;  // configuration, not this sample
      } catch (const bus::BusError&) {
        throw;  // the bus itself, not this sample
      } catch (const InputError& e) {
        RejectSample(subscriber->topic(), e.what());
      }
    };
    inputs[i].subscriber = subscriber;
    if (!timed) {
      acking.push_back({subscriber, [this, subscriber, on_sample](bus::Sample&& sample) {
                          const bus::MessageInfo info = sample.info();
                          on_sample(std::move(sample));
                          Ack(*subscriber, info);
                        }});
      continue;
    }
    InputTiming* timing = &inputs[i];
    acking.push_back(
        {subscriber, [this, subscriber, on_sample, timing, &calls, i](bus::Sample&& sample) {
           const bus::MessageInfo info = sample.info();
           const int64_t start = MonotonicNs();
           on_sample(std::move(sample));
           const int64_t duration = MonotonicNs() - start;
           timing->durations_ns.push_back(duration);
           if (calls.size() < kMaxRecordedCalls) calls.push_back({start, duration, i});
           Ack(*subscriber, info);
         }});
  }
  node::Spin(acking);
  // Per topic (two handlers may share one): rejected of handled.
  std::map<std::string, uint64_t> handled_per_topic;
  for (size_t i = 0; i < handlers.size(); ++i) {
    handled_per_topic[handlers[i].subscriber->topic()] += handled[i];
  }
  for (const auto& [topic, count] : RejectedSamples()) {
    auto it = handled_per_topic.find(topic);
    Warn() << topic << ": rejected " << count << " of "
           << (it == handled_per_topic.end() ? count : it->second) << " samples";
  }
  if (timed) WriteRunStats(*this, impl_->created_mono_ns, stats_dir, inputs, calls);
}

void Node::RejectSample(const std::string& topic, std::string_view what) {
  uint64_t count = 0;
  {
    std::lock_guard lock(impl_->mutex);
    count = ++impl_->rejected[topic];
  }
  if (count > kLoggedRejections && count % kRejectionLogPeriod != 0) return;
  if (what.starts_with(topic) && what.substr(topic.size()).starts_with(": ")) {
    what.remove_prefix(topic.size() + 2);  // the line names the topic already
  }
  if (count <= kLoggedRejections) {
    Error() << "rejected a sample of " << topic << ": " << msgs::PrintableText(what);
  } else {
    Error() << "rejected a sample of " << topic << ": " << msgs::PrintableText(what) << " ("
            << count << " rejected so far; only every " << kRejectionLogPeriod << "th is logged)";
  }
}

const std::string& Node::name() const { return impl_->name; }
const std::string& Node::namespace_() const { return impl_->ns; }
const std::string& Node::fully_qualified_name() const { return impl_->fqn; }
const std::string& Node::program() const { return impl_->program; }
const std::vector<std::string>& Node::args() const { return impl_->own_args; }

template <ParamType T>
T Node::Param(std::string_view name, T default_value, const ParamDescriptor& descriptor) {
  std::lock_guard lock(impl_->mutex);
  T value{};
  std::string source;
  if (!impl_->Lookup(name, value, source)) {
    value = std::move(default_value);
    source = "default";
  }
  impl_->CheckDescriptor(name, value, source, descriptor);
  impl_->Declare(name, ExpectedTypeName<T>(), internal::FormatValue(ToParamValue(value)), source,
                 descriptor);
  return value;
}

template <ParamType T>
T Node::RequireParam(std::string_view name, const ParamDescriptor& descriptor) {
  std::lock_guard lock(impl_->mutex);
  T value{};
  std::string source;
  if (!impl_->Lookup(name, value, source)) {
    impl_->Fail("required parameter '" + std::string(name) + "' (" +
                std::string(ExpectedTypeName<T>()) +
                ") is not set (give it with -p or a params file)");
  }
  impl_->CheckDescriptor(name, value, source, descriptor);
  impl_->Declare(name, ExpectedTypeName<T>(), internal::FormatValue(ToParamValue(value)), source,
                 descriptor);
  return value;
}

#define PROBELESS_NODE_INSTANTIATE(T)                                     \
  template T Node::Param<T>(std::string_view, T, const ParamDescriptor&); \
  template T Node::RequireParam<T>(std::string_view, const ParamDescriptor&);
PROBELESS_NODE_INSTANTIATE(bool)
PROBELESS_NODE_INSTANTIATE(int64_t)
PROBELESS_NODE_INSTANTIATE(int)
PROBELESS_NODE_INSTANTIATE(double)
PROBELESS_NODE_INSTANTIATE(std::string)
PROBELESS_NODE_INSTANTIATE(std::vector<double>)
PROBELESS_NODE_INSTANTIATE(std::vector<int64_t>)
PROBELESS_NODE_INSTANTIATE(std::vector<std::string>)
#undef PROBELESS_NODE_INSTANTIATE

bool Node::HasParamOverride(std::string_view name) const {
  std::lock_guard lock(impl_->mutex);
  return impl_->overrides.find(name) != impl_->overrides.end();
}

std::vector<ParamInfo> Node::DeclaredParams() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->declared;
}

std::vector<std::string> Node::UnusedParamOverrides() const {
  std::lock_guard lock(impl_->mutex);
  std::vector<std::string> unused;
  for (const auto& [name, entry] : impl_->overrides) {
    if (!entry.used) unused.push_back(name);
  }
  return unused;
}

void Node::CheckParamOverrides() const {
  std::lock_guard lock(impl_->mutex);
  for (const auto& [param, entry] : impl_->overrides) {
    if (entry.used || entry.wildcard) continue;
    // The nearest declared name within a third of its length: a typo, not another parameter.
    std::string nearest;
    size_t best = param.size() / 3 + 1;
    for (const ParamInfo& info : impl_->declared) {
      const size_t d = EditDistance(param, info.name);
      if (d < best) {
        best = d;
        nearest = info.name;
      }
    }
    impl_->Fail("unknown parameter '" + param + "' (from " + entry.source + ")" +
                (nearest.empty() ? std::string("; this node declares no parameter of that name")
                                 : "; did you mean '" + nearest + "'?"));
  }
}

std::map<std::string, uint64_t> Node::RejectedSamples() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->rejected;
}

std::string Node::ResolveTopicName(std::string_view name) const {
  std::string resolved;
  try {
    resolved = internal::ExpandTopicName(name, impl_->name, impl_->ns);
  } catch (const NodeError& e) {
    impl_->Fail(e.what());
  }
  for (const Impl::Remap& remap : impl_->remaps) {
    if (remap.from == resolved) {
      resolved = remap.to;
      break;
    }
  }
  try {
    bus::ValidateTopicName(resolved);
  } catch (const bus::BusError& e) {
    impl_->Fail(e.what());
  }
  return resolved;
}

void Node::ThrowMissingCapacity(std::string_view topic, std::string_view type) const {
  impl_->Fail("publisher of " + std::string(type) + " on '" + std::string(topic) +
              "' needs options.max_message_bytes (the type has a variable payload)");
}

void Node::LogCreation(std::string_view what, const std::string& topic,
                       std::string_view type) const {
  if (LogEnabled(LogLevel::kDebug)) {
    Log(LogLevel::kDebug, std::string(what) + " on " + topic + " [" + std::string(type) + "]");
  }
}

LogLevel Node::log_level() const { return static_cast<LogLevel>(impl_->log_level.load()); }
void Node::set_log_level(LogLevel level) { impl_->log_level = static_cast<int>(level); }

void Node::Log(LogLevel level, std::string_view message) const {
  if (!LogEnabled(level)) return;
  std::string line;
  line.reserve(message.size() + impl_->fqn.size() + 16);
  line += '[';
  line += LogLevelName(level);
  line += "] [";
  line += impl_->fqn;
  line += "] ";
  line += message;
  line += '\n';
  std::lock_guard lock(LogMutex());
  WriteAll(STDERR_FILENO, line);
}

LogStream::LogStream(const Node& node, LogLevel level) : node_(node), level_(level) {
  if (node.LogEnabled(level)) stream_ = std::make_unique<std::ostringstream>();
}

LogStream::~LogStream() {
  if (stream_) node_.Log(level_, stream_->str());
}

}  // namespace probeless::node
