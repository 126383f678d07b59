// probeless node runtime: the small shared part of every node process.
//
// - Command line: ROS 2's convention. Everything up to "--ros-args" is the node's own arguments;
//   after it (until an optional "--", after which own arguments resume; "--ros-args" may appear
//   again) come
//     -r/--remap [node:]from:=to      topic remap, or __node:=NAME / __ns:=/NAMESPACE
//     -p/--param [node:]name:=value   parameter override, value in YAML syntax ("[1, 2]", "'7'")
//     --params-file FILE              ROS 2 params file (see below)
//     --log-level LEVEL | NAME:=LEVEL debug, info, warn or error
//   A "node:" prefix limits a rule to the node of that name (its default name for __node/__ns).
// - Params files (ROS 2 format): top-level keys are node names ("talker", "/ns/talker", nested
//   namespace keys, or wildcards "/**", "/ns/*", "/**/talker"), each holding a `ros__parameters:`
//   mapping; nested mappings below it are flattened with '.' ("camera: {width: 640}" gives
//   "camera.width").
// - Parameter precedence: -p over params files over the default given in code; a later params
//   file over an earlier one; within one file an exact node name over a wildcard entry.
// - Topic names: "image" -> "<namespace>/image"; "/image" unchanged; "~" / "~/image" -> the node's
//   private "<namespace>/<node>[/image]"; "{node}" and "{ns}" substitutions; then the first
//   matching remap rule (whose sides are expanded the same way) replaces the whole name.
// - Logging: "[level] [<fully qualified node name>] message" on stderr, one write per line,
//   thread-safe. Level: param log_level (-p or file), else --log-level, else $PROBELESS_LOG_LEVEL,
//   else info.
// - Shutdown: the first SIGINT/SIGTERM makes ok() false and wakes WaitForShutdown/Spin/Rate at
//   once (Spin polls the WaitSet at most kShutdownPollPeriod apart); a second one exits the process
//   immediately with status 128 + signal (130 for SIGINT).
// - Run statistics (for tools/graph_bench): with $PROBELESS_NODE_STATS set to a directory,
// Node::Spin
//   times every handler call and, when it returns, writes <dir>/<fqn without the leading '/',
//   '/' -> '.'>.json: pid, wall and CPU seconds (getrusage: all threads) since the Node was made,
//   per input topic the samples handled, the bus's received/dropped counters, the samples
//   rejected as bad input (Spin below) and the handler time
//   (p50/p99/max ms, total s), per output topic the messages published (this process's
//   publishers, read from the bus registry), and every handler call as [start CLOCK_MONOTONIC ns,
//   duration ns, input index] (the first 100000). Unset (the default): nothing is timed or written.
//
// Errors: bad arguments, params files, parameter types, values outside a parameter's declared
// range or choices, unknown parameter overrides (CheckParamOverrides) and bad topic names throw
// NodeError with one line naming the node (once known) and the problem.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

#include "probeless/bus/bus.h"
#include "probeless/error/error.h"
#include "probeless/msgs/layout.h"

namespace probeless::node {

class NodeError : public InputError {
 public:
  using InputError::InputError;
};

enum class LogLevel : int { kDebug = 0, kInfo = 1, kWarn = 2, kError = 3 };

// "debug", "info", "warn", "error".
std::string_view LogLevelName(LogLevel level);
// Parses "debug", "info", "warn"/"warning", "error" (any case). Throws NodeError otherwise.
LogLevel ParseLogLevel(std::string_view text);

// Rejections per input topic that Node::Spin logs one by one; after them it logs every
// kRejectionLogPeriod-th only.
inline constexpr uint64_t kLoggedRejections = 10;
inline constexpr uint64_t kRejectionLogPeriod = 100;

// Longest time Spin() waits on its WaitSet before re-checking ok().
inline constexpr std::chrono::milliseconds kShutdownPollPeriod{20};

// --- Process-wide shutdown state -----------------------------------------------------------------

// Installs the SIGINT/SIGTERM handlers (idempotent; every Node constructor calls it).
void InstallSignalHandlers();
// False once SIGINT/SIGTERM arrived or RequestShutdown() was called.
bool ok();
// Makes ok() false and wakes every waiter (async-signal-safe).
void RequestShutdown();
// Blocks until shutdown is requested or `timeout` passes; returns !ok(). Wakes within
// microseconds of the signal (futex), not by polling.
bool WaitForShutdown(std::chrono::nanoseconds timeout);
// Calls on_ready(index) for every ready subscriber of `wait_set` (indices as returned by
// WaitSet::Add) until shutdown; returns within kShutdownPollPeriod (plus the callback's run time)
// of the request.
void Spin(bus::WaitSet& wait_set, const std::function<void(size_t)>& on_ready);

// A subscriber and what to do with each of its samples.
struct Handler {
  bus::Subscriber* subscriber = nullptr;
  std::function<void(bus::Sample&&)> on_sample;
};
// Waits on all handlers' subscribers at once and passes every received sample to its handler, in
// arrival order per subscriber, until shutdown (same promptness as Spin above). When several
// subscribers are ready at one wake-up they are served in the order of `handlers` (put a topic
// that triggers work after the topics whose latest state that work reads).
void Spin(const std::vector<Handler>& handlers);

// Paces a loop at a fixed rate: `while (rate.Sleep()) {...}`. Deadlines are start + k / hz; if the
// loop falls more than one period behind, the schedule restarts from now instead of bursting.
class Rate {
 public:
  // Throws NodeError unless hz is finite and > 0.
  explicit Rate(double hz);
  // Sleeps until the next deadline or shutdown; returns ok().
  bool Sleep();
  std::chrono::nanoseconds period() const { return period_; }

 private:
  std::chrono::nanoseconds period_;
  std::chrono::steady_clock::time_point next_;
};

// --- Node --------------------------------------------------------------------------------------

// Supported parameter types. `int` is a range-checked view of an integer parameter.
template <class T>
concept ParamType = std::is_same_v<T, bool> || std::is_same_v<T, int64_t> ||
    std::is_same_v<T, int> || std::is_same_v<T, double> || std::is_same_v<T, std::string> ||
    std::is_same_v<T, std::vector<double>> || std::is_same_v<T, std::vector<int64_t>> ||
    std::is_same_v<T, std::vector<std::string>>;

// What a parameter means and which values it may take (ROS 2's ParameterDescriptor). The
// effective value (the override, else the default) is checked when the parameter is read: a
// number, or each element of a number array, against [min, max] (min exclusive with
// `min_exclusive`); a string, or each element of a string array, against `choices`. A range on a
// non-number or choices on a non-string parameter is a bug (PROBELESS_DEMAND).
struct ParamDescriptor {
  std::string description;           // one line, e.g. "spherical-harmonic bands of the estimate"
  std::string unit;                  // e.g. "m", "ms", "Hz", "deg"; empty: unitless
  std::optional<double> min;         // no lower bound when empty
  std::optional<double> max;         // no upper bound when empty
  bool min_exclusive = false;        // value > min instead of value >= min
  std::vector<std::string> choices;  // empty: any string
};

// A declared parameter, for introspection.
struct ParamInfo {
  std::string name;
  std::string type;         // "bool", "integer", "double", "string", "double_array", ...
  std::string value;        // e.g. "30", "0.5", "rgb8", "[1, 2]", "[\"a\", \"b\"]"
  std::string source;       // "default", "-p" or "params file '<path>'"
  std::string description;  // ParamDescriptor::description; empty when declared without one
  std::string unit;         // ParamDescriptor::unit
  std::string constraint;   // e.g. "[1, 8]", "(0, inf)", "one of gbuffer|depth"; empty: any value
};

class Node;

// A log line being built: `node.Info() << "x = " << x;` emits on destruction if the level is
// enabled (operands are not formatted otherwise).
class LogStream {
 public:
  LogStream(const Node& node, LogLevel level);
  ~LogStream();
  LogStream(LogStream&&) = delete;
  template <class T>
  LogStream& operator<<(const T& value) {
    if (stream_) *stream_ << value;
    return *this;
  }

 private:
  const Node& node_;
  LogLevel level_;
  std::unique_ptr<std::ostringstream> stream_;
};

class Node {
 public:
  // Parses argv (argv[0] is the program) as described at the top of this file and reads every
  // params file. `default_name` is used unless remapped by __node. Installs the signal handlers.
  // Throws NodeError on any malformed argument or file.
  // -h or --help among the node's own arguments (before --ros-args) prints `usage` (a node's own
  // options; empty: "usage: <default_name> [--ros-args ...]") and the --ros-args syntax to stdout
  // and exits 0 before anything else happens, so every node answers --help.
  Node(int argc, char** argv, std::string_view default_name, std::string_view usage = {});
  // Same with the arguments as strings (argv[0] first).
  Node(const std::vector<std::string>& argv, std::string_view default_name,
       std::string_view usage = {});
  ~Node();
  Node(const Node&) = delete;
  Node& operator=(const Node&) = delete;

  // Node name, e.g. "talker".
  const std::string& name() const;
  // Namespace, "/" or e.g. "/robot1/camera".
  const std::string& namespace_() const;
  // "/talker" or "/robot1/camera/talker".
  const std::string& fully_qualified_name() const;
  // argv[0].
  const std::string& program() const;
  // The node's own arguments (not the ROS ones), without argv[0], in order.
  const std::vector<std::string>& args() const;

  // Value of parameter `name`: its override (-p or params file) if any, else `default_value`.
  // Declares it (see DeclaredParams). Throws NodeError if the override has another type (an
  // integer is accepted for double, integers for double arrays, an empty list for any array) or
  // the parameter was declared before with another type.
  template <ParamType T>
  T Param(std::string_view name, T default_value) {
    return Param<T>(name, std::move(default_value), ParamDescriptor{});
  }
  std::string Param(std::string_view name, const char* default_value) {
    return Param<std::string>(name, std::string(default_value), ParamDescriptor{});
  }
  // Like Param, and checks the effective value against `descriptor` (see ParamDescriptor): throws
  // NodeError "parameter 'bands' = 12 (from -p) is out of range: expected a value in [1, 8]" or
  // "... is not one of gbuffer|depth". The descriptor is kept for DeclaredParams.
  template <ParamType T>
  T Param(std::string_view name, T default_value, const ParamDescriptor& descriptor);
  std::string Param(std::string_view name, const char* default_value,
                    const ParamDescriptor& descriptor) {
    return Param<std::string>(name, std::string(default_value), descriptor);
  }
  // Like Param, but throws NodeError if the parameter has no override.
  template <ParamType T>
  T RequireParam(std::string_view name, const ParamDescriptor& descriptor = {});
  // Whether `name` has an override (-p or params file).
  bool HasParamOverride(std::string_view name) const;
  // Parameters declared so far, in declaration order.
  std::vector<ParamInfo> DeclaredParams() const;
  // Overrides that no Param/RequireParam call has read yet (typos in launch files), sorted.
  std::vector<std::string> UnusedParamOverrides() const;
  // Throws NodeError for the first (sorted) override that no Param/RequireParam call has read,
  // naming its source and the nearest declared name: "unknown parameter 'bandz' (from -p); did
  // you mean 'bands'?". Overrides that came only from wildcard params-file entries ("/**",
  // "/ns/*") are shared by many nodes and are not checked. Spin calls it before it starts, so a
  // node declares all of its parameters before spinning; a node without Spin calls it once its
  // parameters are read.
  void CheckParamOverrides() const;

  // Fully qualified, remapped topic name for `name` (see top of file). Throws NodeError if the
  // name or the result is invalid (the result is also checked by bus::ValidateTopicName).
  std::string ResolveTopicName(std::string_view name) const;

  // A bus publisher of M on the resolved `topic`, with type msgs::TopicTypeOf<M>() and
  // options.node_name = fully_qualified_name(). For types without payload a zero
  // options.max_message_bytes becomes sizeof(M); types with a payload must set it (e.g.
  // Image::MessageBytesFor(...)), or NodeError is thrown.
  template <msgs::Message M>
  bus::Publisher CreatePublisher(std::string_view topic, bus::PublisherOptions options = {}) {
    if (options.max_message_bytes == 0) {
      if constexpr (M::kHasPayload) {
        ThrowMissingCapacity(topic, M::kTypeName);
      } else {
        options.max_message_bytes = sizeof(M);
      }
    }
    options.node_name = fully_qualified_name();
    const std::string resolved = ResolveTopicName(topic);
    LogCreation("publisher", resolved, M::kTypeName);
    return bus::Publisher(resolved, msgs::TopicTypeOf<M>(), options);
  }
  // A bus subscriber of M on the resolved `topic`, with options.node_name filled in.
  template <msgs::Message M>
  bus::Subscriber CreateSubscriber(std::string_view topic, bus::SubscriberOptions options = {}) {
    options.node_name = fully_qualified_name();
    const std::string resolved = ResolveTopicName(topic);
    LogCreation("subscriber", resolved, M::kTypeName);
    return bus::Subscriber(resolved, msgs::TopicTypeOf<M>(), options);
  }

  LogLevel log_level() const;
  void set_log_level(LogLevel level);
  bool LogEnabled(LogLevel level) const { return level >= log_level(); }
  // Writes "[level] [fqn] message\n" to stderr if `level` is enabled.
  void Log(LogLevel level, std::string_view message) const;
  LogStream Debug() const { return LogStream(*this, LogLevel::kDebug); }
  LogStream Info() const { return LogStream(*this, LogLevel::kInfo); }
  LogStream Warn() const { return LogStream(*this, LogLevel::kWarn); }
  LogStream Error() const { return LogStream(*this, LogLevel::kError); }

  // --- Lock-step replay ---
  // "<fully qualified name>/ack": where this node acknowledges processed inputs.
  std::string AckTopic() const;
  // Publishes a msgs::Ack for `input` (a sample taken from `from`) on AckTopic(), so a player in
  // lock-step mode knows this node has finished with it (docs/replay.md). Spin below calls it after
  // every handler; a node that finishes its inputs elsewhere (e.g. on a worker thread) calls it
  // itself. Thread-safe; the publisher is created on first use.
  void Ack(const bus::Subscriber& from, const bus::MessageInfo& input);
  // node::Spin(handlers), acknowledging every sample once its handler has returned; with
  // $PROBELESS_NODE_STATS set, also timing each handler and writing the run statistics when it
  // returns (top of file). Calls CheckParamOverrides first.
  // One rule for bad input in every C++ node: a handler that throws InputError for a sample (a
  // malformed message, a frame its library refuses) rejects that sample only: RejectSample below,
  // the sample acknowledged, and Spin goes on; when it returns it logs "<topic>: rejected N of M
  // samples" per topic that rejected any. NodeError and UsageError (configuration), bus::BusError
  // (the bus itself) and every other exception end Spin as before, so a handler throws NodeError
  // for a problem that no later sample can fix (an output file that cannot be written).
  void Spin(const std::vector<Handler>& handlers);
  // Counts one rejected sample of `topic` (resolved) and logs "rejected a sample of <topic>:
  // <what>" (a leading "<topic>: " of `what` dropped, control bytes escaped) for the first
  // kLoggedRejections of the topic, then for every kRejectionLogPeriod-th with the count so far.
  // Spin calls it; a handler that takes samples of another subscriber itself (TryTake) calls it for
  // those. Thread-safe.
  void RejectSample(const std::string& topic, std::string_view what);
  // Samples rejected so far (RejectSample), per resolved input topic (topics without rejections
  // are absent).
  std::map<std::string, uint64_t> RejectedSamples() const;

  // Shortcuts for the process-wide functions above.
  bool ok() const { return node::ok(); }
  bool WaitForShutdown(std::chrono::nanoseconds timeout) const {
    return node::WaitForShutdown(timeout);
  }

 private:
  struct Impl;
  [[noreturn]] void ThrowMissingCapacity(std::string_view topic, std::string_view type) const;
  void LogCreation(std::string_view what, const std::string& topic, std::string_view type) const;
  std::unique_ptr<Impl> impl_;
};

extern template bool Node::Param<bool>(std::string_view, bool, const ParamDescriptor&);
extern template int64_t Node::Param<int64_t>(std::string_view, int64_t, const ParamDescriptor&);
extern template int Node::Param<int>(std::string_view, int, const ParamDescriptor&);
extern template double Node::Param<double>(std::string_view, double, const ParamDescriptor&);
extern template std::string Node::Param<std::string>(std::string_view, std::string,
                                                     const ParamDescriptor&);
extern template std::vector<double> Node::Param<std::vector<double>>(std::string_view,
                                                                     std::vector<double>,
                                                                     const ParamDescriptor&);
extern template std::vector<int64_t> Node::Param<std::vector<int64_t>>(std::string_view,
                                                                       std::vector<int64_t>,
                                                                       const ParamDescriptor&);
extern template std::vector<std::string> Node::Param<std::vector<std::string>>(
    std::string_view, std::vector<std::string>, const ParamDescriptor&);
extern template bool Node::RequireParam<bool>(std::string_view, const ParamDescriptor&);
extern template int64_t Node::RequireParam<int64_t>(std::string_view, const ParamDescriptor&);
extern template int Node::RequireParam<int>(std::string_view, const ParamDescriptor&);
extern template double Node::RequireParam<double>(std::string_view, const ParamDescriptor&);
extern template std::string Node::RequireParam<std::string>(std::string_view,
                                                            const ParamDescriptor&);
extern template std::vector<double> Node::RequireParam<std::vector<double>>(std::string_view,
                                                                            const ParamDescriptor&);
extern template std::vector<int64_t> Node::RequireParam<std::vector<int64_t>>(
    std::string_view, const ParamDescriptor&);
extern template std::vector<std::string> Node::RequireParam<std::vector<std::string>>(
    std::string_view, const ParamDescriptor&);

}  // namespace probeless::node
