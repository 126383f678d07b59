// Pure helpers of `probeless topic` and `probeless clean`: argument parsing, number and table
// formatting, hex dumps, message descriptions and the counter-based rate/bandwidth window used by
// `topic hz` / `topic bw` (which never subscribe). Nothing here touches shared memory, so all of it
// is unit-testable (tests/topic_cli/topic_format_test.cpp).
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "probeless/bus/bus.h"
#include "probeless/error/error.h"

namespace probeless::tools {

// Bad command-line input (exit code 2). what() is one line naming the argument and what was
// expected, without the "probeless topic <sub>: " prefix (the command adds it).
class UsageError : public InputError {
 public:
  using InputError::InputError;
};

// --- Arguments ---------------------------------------------------------------------------------

// One option of a subcommand: its spelling ("-n", "--window") and whether it takes a value.
struct OptionSpec {
  std::string_view name;
  bool takes_value = false;
};

// Arguments split into positionals (in order) and options (spelling -> value; "" for flags).
struct ParsedArgs {
  std::vector<std::string> positionals;
  std::map<std::string, std::string, std::less<>> options;
  bool help = false;  // -h or --help was given

  bool Has(std::string_view option) const { return options.find(option) != options.end(); }
};

// Parses `args` (the arguments after the subcommand name) against `specs`. A value is given as the
// next argument or as "--name=value". Options and positionals may be interleaved; "--" ends the
// options. Throws UsageError for an unknown option ("unknown option '--x'"), a missing value
// ("--window expects a value") or a value given to a flag ("-v takes no value").
ParsedArgs ParseArgs(std::span<const std::string> args, std::span<const OptionSpec> specs);

// `text` as a positive integer (1 .. 2^63). Throws UsageError
// "<option> expects a positive integer, got '<text>'".
uint64_t ParseCount(std::string_view option, std::string_view text);

// `text` as a finite, non-negative number of seconds ("2", "0.5"). Throws UsageError
// "<option> expects a non-negative number of seconds, got '<text>'".
double ParseSeconds(std::string_view option, std::string_view text);

// --- Formatting --------------------------------------------------------------------------------

// A byte count with decimal (SI) units: "512 B", "1.50 KB", "27.65 MB", "1.20 GB" (1 KB = 1000 B,
// two decimals above 1000 B).
std::string FormatBytes(double bytes);

// An exact byte count, with the SI form added from 1000 B on: "32 B", "1536000 B (1.54 MB)".
std::string FormatByteCount(uint64_t bytes);

// A bandwidth in bytes per second: FormatBytes(bytes_per_second) + "/s".
std::string FormatBandwidth(double bytes_per_second);

// `value` with `decimals` digits after the point ("%.<decimals>f").
std::string FormatFixed(double value, int decimals);

// A CLOCK_REALTIME instant (ns since the Unix epoch) as UTC ISO 8601 with nanoseconds:
// "2026-11-23T13:03:56.000000123Z". Negative values are printed as raw nanoseconds.
std::string FormatWallTime(int64_t wall_ns);

// Left-aligned columns separated by two spaces; every row ends with '\n' and trailing spaces are
// trimmed. Rows may have fewer cells than others.
std::string FormatTable(const std::vector<std::vector<std::string>>& rows);

// Hex dump of the first `max_bytes` of `bytes`, 16 per line: two spaces, the offset as 4 hex
// digits, two spaces, the bytes as lower-case hex pairs (an extra space after the 8th), then
// "  |ascii|" with '.' for non-printable bytes. Empty input gives "".
std::string HexDump(std::span<const std::byte> bytes, size_t max_bytes = 64);

// Decoded lines for a message of a known probeless_msgs type (name and layout hash both match):
// the header (stamp, sequence, frame id) and the type's main fields, each line ending with '\n'.
// nullopt for any other type (also a known name with another layout hash), for bytes too short for
// the type or not 64-byte aligned, and when this build has no probeless_msgs headers.
std::optional<std::string> DescribeMessage(const bus::TopicType& type,
                                           std::span<const std::byte> bytes);

// One message as `probeless topic echo` prints it, every line ending with '\n':
//   sequence: 12
//   publisher pid: 4321
//   published: 2026-11-23T13:03:56.000000123Z (mono 1234.000000456 s)
//   size: 128 B
// then "type: <name>" and DescribeMessage(type, bytes) when that decodes the message, else
// "data (first 64 of 128 bytes):" (or "data (16 bytes):", "data: (empty)") and HexDump(bytes),
// and finally a "---" line.
std::string FormatMessage(const bus::TopicType& type, const bus::MessageInfo& info,
                          std::span<const std::byte> bytes);

// --- Non-intrusive rate and bandwidth ----------------------------------------------------------

// The publisher counters of one topic at one instant, summed over its publishers.
struct CounterSample {
  uint64_t published = 0;            // messages published since the publishers joined
  uint64_t published_bytes = 0;      // payload bytes published since the publishers joined
  int64_t last_publish_mono_ns = 0;  // CLOCK_MONOTONIC ns of the newest Publish(); 0 = never
  // Identity of the publisher set (pids, nodes, capacities); a change makes RateWindow start a new
  // baseline instead of mixing counters of different publishers.
  std::string publishers_key;
};

// Sums the publishers of `topic` (nullptr: the topic does not exist, i.e. no publishers).
CounterSample SumPublishers(const bus::TopicSnapshot* topic);

// Mean publish rate in Hz of one publisher between two readings of its counters: exact, because
// the last-publish stamps belong to messages `published0` and `published1`. nullopt if no message
// was published in between, if `published0` is 0 (its stamp is unknown) or the stamps do not
// advance.
std::optional<double> RateBetween(uint64_t published0, int64_t last_mono_ns0, uint64_t published1,
                                  int64_t last_mono_ns1);

// Rate and bandwidth of the last N messages computed from periodic counter readings (the way
// `probeless topic hz/bw` measures without subscribing). Between two readings that saw k new
// messages, the messages' mean period is exactly (t1 - t0) / k; each such interval is one entry of
// the window. min/max/std of the period are over those entries (weighted by k), so they equal
// `ros2 topic hz`'s per-message values only when the readings are faster than the messages
// (k = 1) and are smoothed otherwise.
class RateWindow {
 public:
  struct Stats {
    uint64_t messages = 0;          // messages in the window
    double rate_hz = 0;             // messages / seconds spanned
    double min_period_s = 0;        // shortest entry period
    double max_period_s = 0;        // longest entry period
    double std_period_s = 0;        // standard deviation of the period (weighted by messages)
    double bytes_per_second = 0;    // payload bytes / seconds spanned
    double mean_message_bytes = 0;  // payload bytes / messages
  };

  // `window_messages` >= 1: the window keeps the newest entries totalling at least that many
  // messages (dropping older entries whenever the rest still reach it).
  explicit RateWindow(uint64_t window_messages);

  // Adds a reading. Returns the number of new messages accounted (0 for the first reading, after a
  // change of the publisher set, a counter going backwards or a reading with nothing new).
  uint64_t Add(const CounterSample& sample);

  // Statistics over the window; nullopt while it is empty.
  std::optional<Stats> Compute() const;

 private:
  struct Entry {
    uint64_t messages = 0;
    uint64_t bytes = 0;
    int64_t span_ns = 0;
  };
  uint64_t window_messages_;
  std::optional<CounterSample> last_;
  std::deque<Entry> entries_;
  uint64_t total_messages_ = 0;
};

// --- Cleanup -----------------------------------------------------------------------------------

// What `probeless clean` would remove (for --dry-run), estimated without touching anything.
// `segment_names` are this user's and domain's names in /dev/shm with the
// "probeless.<uid>.<domain>." prefix removed: "t.<topic>" registries and "p.<pid>.<n>.<topic>"
// publisher pools. A pool goes if !pid_alive(pid); a registry goes if `topics` (ListTopics) does
// not show it (never initialised) or shows it with no live participant. Returns the chosen names,
// sorted. The real cleanup also reclaims dead participants of live topics and keeps pools still
// referenced by live subscribers, so this is an estimate (exact for the usual cases).
std::vector<std::string> PlanCleanup(const std::vector<std::string>& segment_names,
                                     const std::vector<bus::TopicSnapshot>& topics,
                                     const std::function<bool(int32_t)>& pid_alive);

// `ros2 topic hz`-style report of `stats`:
// "average rate: 30.00 Hz\n    min: 0.0331 s  max: 0.0336 s  std dev: 0.00012 s  window: 30\n".
std::string FormatRateReport(const RateWindow::Stats& stats);

// `ros2 topic bw`-style report of `stats`:
// "300.00 KB/s from 30 messages\n    message size mean: 10.00 KB\n".
std::string FormatBandwidthReport(const RateWindow::Stats& stats);

}  // namespace probeless::tools
