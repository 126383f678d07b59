// Pure helpers of `probeless topic` / `probeless clean` (see topic_format.h).
#include "topic_format.h"

#include <time.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <limits>

#include "probeless/msgs/msgs.h"
#include "probeless/parse/number.h"

namespace probeless::tools {

// --- Arguments ---------------------------------------------------------------------------------

ParsedArgs ParseArgs(std::span<const std::string> args, std::span<const OptionSpec> specs) {
  ParsedArgs parsed;
  bool options_ended = false;
  for (size_t i = 0; i < args.size(); ++i) {
    const std::string& arg = args[i];
    if (options_ended || arg.size() < 2 || arg[0] != '-') {
      parsed.positionals.push_back(arg);
      continue;
    }
    if (arg == "--") {
      options_ended = true;
      continue;
    }
    if (arg == "-h" || arg == "--help") {
      parsed.help = true;
      continue;
    }
    const size_t equals = arg.find('=');
    const std::string name = arg.substr(0, equals);
    const auto spec = std::find_if(specs.begin(), specs.end(),
                                   [&](const OptionSpec& s) { return s.name == name; });
    if (spec == specs.end()) throw UsageError("unknown option '" + name + "'");
    std::string value;
    if (!spec->takes_value) {
      if (equals != std::string::npos) throw UsageError(name + " takes no value");
    } else if (equals != std::string::npos) {
      value = arg.substr(equals + 1);
    } else if (i + 1 < args.size()) {
      value = args[++i];
    } else {
      throw UsageError(name + " expects a value");
    }
    parsed.options[name] = value;
  }
  return parsed;
}

uint64_t ParseCount(std::string_view option, std::string_view text) {
  // Up to int64's maximum: the counts are compared with the bus's signed counters.
  const auto value = parse::TryParseInteger<int64_t>(text, 1);
  if (!value) {
    throw UsageError(std::string(option) + " expects a positive integer, got '" +
                     std::string(text) + "'");
  }
  return static_cast<uint64_t>(*value);
}

double ParseSeconds(std::string_view option, std::string_view text) {
  const auto value = parse::TryParseDouble(text, 0);
  if (!value) {
    throw UsageError(std::string(option) + " expects a non-negative number of seconds, got '" +
                     std::string(text) + "'");
  }
  return *value;
}

// --- Formatting --------------------------------------------------------------------------------

std::string FormatFixed(double value, int decimals) {
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), "%.*f", decimals, value);
  return buffer;
}

std::string FormatBytes(double bytes) {
  if (std::fabs(bytes) < 1000) return FormatFixed(bytes, 0) + " B";
  static constexpr const char* kUnits[] = {"KB", "MB", "GB", "TB", "PB"};
  double scaled = bytes / 1000;
  size_t unit = 0;
  while (std::fabs(scaled) >= 1000 && unit + 1 < std::size(kUnits)) {
    scaled /= 1000;
    ++unit;
  }
  return FormatFixed(scaled, 2) + " " + kUnits[unit];
}

std::string FormatByteCount(uint64_t bytes) {
  std::string text = std::to_string(bytes) + " B";
  if (bytes >= 1000) text += " (" + FormatBytes(static_cast<double>(bytes)) + ")";
  return text;
}

std::string FormatBandwidth(double bytes_per_second) {
  return FormatBytes(bytes_per_second) + "/s";
}

std::string FormatWallTime(int64_t wall_ns) {
  if (wall_ns < 0) return std::to_string(wall_ns) + " ns";
  const time_t seconds = static_cast<time_t>(wall_ns / 1'000'000'000);
  const int64_t nanos = wall_ns % 1'000'000'000;
  tm utc{};
  gmtime_r(&seconds, &utc);
  char buffer[80];
  std::snprintf(buffer, sizeof(buffer), "%04d-%02d-%02dT%02d:%02d:%02d.%09lldZ", utc.tm_year + 1900,
                utc.tm_mon + 1, utc.tm_mday, utc.tm_hour, utc.tm_min, utc.tm_sec,
                static_cast<long long>(nanos));
  return buffer;
}

std::string FormatTable(const std::vector<std::vector<std::string>>& rows) {
  std::vector<size_t> widths;
  for (const auto& row : rows) {
    if (widths.size() < row.size()) widths.resize(row.size(), 0);
    for (size_t c = 0; c < row.size(); ++c) widths[c] = std::max(widths[c], row[c].size());
  }
  std::string out;
  for (const auto& row : rows) {
    std::string line;
    for (size_t c = 0; c < row.size(); ++c) {
      line += row[c];
      if (c + 1 < row.size()) line += std::string(widths[c] - row[c].size() + 2, ' ');
    }
    while (!line.empty() && line.back() == ' ') line.pop_back();
    out += line;
    out += '\n';
  }
  return out;
}

std::string HexDump(std::span<const std::byte> bytes, size_t max_bytes) {
  const size_t n = std::min(bytes.size(), max_bytes);
  std::string out;
  char buffer[32];
  for (size_t line = 0; line < n; line += 16) {
    std::snprintf(buffer, sizeof(buffer), "  %04zx  ", line);
    out += buffer;
    std::string ascii;
    for (size_t i = line; i < line + 16; ++i) {
      if (i == line + 8) out += ' ';
      if (i < n) {
        const auto b = static_cast<unsigned char>(bytes[i]);
        std::snprintf(buffer, sizeof(buffer), "%02x ", b);
        out += buffer;
        ascii += (b >= 0x20 && b < 0x7f) ? static_cast<char>(b) : '.';
      } else {
        out += "   ";
      }
    }
    out += " |" + ascii + "|\n";
  }
  return out;
}

// --- Message descriptions ----------------------------------------------------------------------

namespace {

// A number with up to 6 significant digits ("%g").
std::string Number(double value) {
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), "%g", value);
  return buffer;
}

template <class M>
bool IsType(const bus::TopicType& type) {
  return type.name == M::kTypeName && type.layout_hash == M::kLayoutHash;
}

template <class M>
bool Fits(std::span<const std::byte> bytes) {
  return bytes.size() >= sizeof(M) &&
         reinterpret_cast<uintptr_t>(bytes.data()) % msgs::kPayloadAlignment == 0;
}

std::string Triple(double x, double y, double z) {
  std::string text = "(";
  text += Number(x) + ", " + Number(y) + ", " + Number(z) + ")";
  return text;
}

std::string DescribeHeader(const msgs::Header& h) {
  return "header:\n  stamp: " + FormatWallTime(h.stamp_ns) + " (mono " +
         FormatFixed(static_cast<double>(h.stamp_mono_ns) * 1e-9, 9) +
         " s)\n  sequence: " + std::to_string(h.sequence) + "\n  frame_id: '" +
         std::string(h.FrameId()) + "'\n";
}

std::string DescribeTransform(const msgs::RigidTransform& t) {
  return "translation " + Triple(t.translation.x, t.translation.y, t.translation.z) +
         " m, rotation (w, x, y, z) (" + Number(t.rotation.w) + ", " + Number(t.rotation.x) + ", " +
         Number(t.rotation.y) + ", " + Number(t.rotation.z) + ")";
}

std::string PayloadText(std::span<const std::byte> bytes, size_t fixed) {
  return "payload " + FormatByteCount(bytes.size() - fixed);
}

// Decodes `bytes` as M with `describe(const M&)` if the type matches; nullopt otherwise.
template <class M, class F>
std::optional<std::string> Try(const bus::TopicType& type, std::span<const std::byte> bytes,
                               F describe, bool* matched) {
  if (*matched || !IsType<M>(type)) return std::nullopt;
  *matched = true;
  if (!Fits<M>(bytes)) return std::nullopt;
  return describe(*msgs::ReadMessage<M>(bytes));
}

}  // namespace

std::optional<std::string> DescribeMessage(const bus::TopicType& type,
                                           std::span<const std::byte> bytes) {
  using namespace msgs;
  bool matched = false;
  std::optional<std::string> text;
  auto attempt = [&](std::optional<std::string> result) {
    if (result) text = std::move(result);
  };
  attempt(Try<Header>(
      type, bytes, [](const Header& h) { return DescribeHeader(h); }, &matched));
  attempt(Try<Image>(
      type, bytes,
      [&](const Image& m) {
        return DescribeHeader(m.header) + "image: " + std::to_string(m.width) + "x" +
               std::to_string(m.height) + " " + std::string(EncodingName(m.encoding)) + ", step " +
               std::to_string(m.step) + ", " + PayloadText(bytes, sizeof(Image)) + "\n";
      },
      &matched));
  attempt(Try<CameraInfo>(
      type, bytes,
      [](const CameraInfo& m) {
        return DescribeHeader(m.header) + "camera_info: " + std::to_string(m.width) + "x" +
               std::to_string(m.height) + ", fx " + Number(m.fx) + " fy " + Number(m.fy) + " cx " +
               Number(m.cx) + " cy " + Number(m.cy) + ", distortion " +
               std::string(DistortionModelName(m.distortion_model)) + " (" +
               std::to_string(m.distortion_count) + " coefficients), depth_scale " +
               Number(m.depth_scale) + "\n";
      },
      &matched));
  attempt(Try<FaceObservation>(
      type, bytes,
      [](const FaceObservation& m) {
        return DescribeHeader(m.header) + "face: detected " +
               (m.face_detected != 0 ? "yes" : "no") + ", landmarks " +
               std::to_string(m.landmark_count) + ", samples " + std::to_string(m.sample_count) +
               ", quality " + Number(m.quality) + ", head " + DescribeTransform(m.head_pose) + "\n";
      },
      &matched));
  attempt(Try<GeometryBuffer>(
      type, bytes,
      [&](const GeometryBuffer& m) {
        return DescribeHeader(m.header) + "geometry_buffer: " + std::to_string(m.width) + "x" +
               std::to_string(m.height) + ", " + PayloadText(bytes, sizeof(GeometryBuffer)) + "\n";
      },
      &matched));
  attempt(Try<Pose>(
      type, bytes,
      [](const Pose& m) {
        return DescribeHeader(m.header) + "pose: parent '" + std::string(m.ParentFrameId()) +
               "' child '" + std::string(m.ChildFrameId()) + "', " +
               DescribeTransform(m.transform) + "\n";
      },
      &matched));
  attempt(Try<ShLight>(
      type, bytes,
      [](const ShLight& m) {
        const std::string_view units = ShLightUnitsName(m.units);
        return DescribeHeader(m.header) + "sh_light: bands " + std::to_string(m.bands) +
               ", units " +
               (units.empty() ? std::to_string(static_cast<uint32_t>(m.units))
                              : std::string(units)) +
               ", dominant direction " +
               Triple(m.dominant_direction[0], m.dominant_direction[1], m.dominant_direction[2]) +
               ", intensity " + Number(m.intensity) + ", confidence " + Number(m.confidence) + "\n";
      },
      &matched));
  attempt(Try<TransferBuffer>(
      type, bytes,
      [&](const TransferBuffer& m) {
        return DescribeHeader(m.header) + "transfer_buffer: " + std::to_string(m.width) + "x" +
               std::to_string(m.height) + ", " + std::to_string(m.coefficient_count) +
               " coefficients, " + PayloadText(bytes, sizeof(TransferBuffer)) + "\n";
      },
      &matched));
  attempt(Try<Vector3>(
      type, bytes, [](const Vector3& m) { return "vector3: " + Triple(m.x, m.y, m.z) + "\n"; },
      &matched));
  attempt(Try<Quaternion>(
      type, bytes,
      [](const Quaternion& m) {
        return "quaternion (w, x, y, z): (" + Number(m.w) + ", " + Number(m.x) + ", " +
               Number(m.y) + ", " + Number(m.z) + ")\n";
      },
      &matched));
  attempt(Try<RigidTransform>(
      type, bytes,
      [](const RigidTransform& m) { return "transform: " + DescribeTransform(m) + "\n"; },
      &matched));
  return text;
}

std::string FormatMessage(const bus::TopicType& type, const bus::MessageInfo& info,
                          std::span<const std::byte> bytes) {
  constexpr size_t kDumpBytes = 64;
  std::string out = "sequence: " + std::to_string(info.sequence) +
                    "\npublisher pid: " + std::to_string(info.publisher_pid) +
                    "\npublished: " + FormatWallTime(info.publish_wall_ns) + " (mono " +
                    FormatFixed(static_cast<double>(info.publish_mono_ns) * 1e-9, 9) +
                    " s)\nsize: " + FormatByteCount(bytes.size()) + "\n";
  if (auto decoded = DescribeMessage(type, bytes)) {
    out += "type: " + type.name + "\n" + *decoded;
  } else if (bytes.empty()) {
    out += "data: (empty)\n";
  } else {
    if (bytes.size() > kDumpBytes) {
      out += "data (first " + std::to_string(kDumpBytes) + " of " + std::to_string(bytes.size()) +
             " bytes):\n";
    } else {
      out += "data (" + std::to_string(bytes.size()) + " bytes):\n";
    }
    out += HexDump(bytes, kDumpBytes);
  }
  out += "---\n";
  return out;
}

// --- Non-intrusive rate and bandwidth ----------------------------------------------------------

CounterSample SumPublishers(const bus::TopicSnapshot* topic) {
  CounterSample sum;
  if (topic == nullptr) return sum;
  for (const bus::PublisherSnapshot& p : topic->publishers) {
    sum.published += p.published;
    sum.published_bytes += p.published_bytes;
    sum.last_publish_mono_ns = std::max(sum.last_publish_mono_ns, p.last_publish_mono_ns);
    sum.publishers_key += std::to_string(p.pid) + ":" + p.node_name + ":" +
                          std::to_string(p.max_message_bytes) + ":" + std::to_string(p.slot_count) +
                          ";";
  }
  return sum;
}

std::optional<double> RateBetween(uint64_t published0, int64_t last_mono_ns0, uint64_t published1,
                                  int64_t last_mono_ns1) {
  if (published0 == 0 || published1 <= published0 || last_mono_ns1 <= last_mono_ns0) {
    return std::nullopt;
  }
  return static_cast<double>(published1 - published0) * 1e9 /
         static_cast<double>(last_mono_ns1 - last_mono_ns0);
}

RateWindow::RateWindow(uint64_t window_messages) : window_messages_(window_messages) {
  if (window_messages_ == 0) throw UsageError("the rate window must hold at least 1 message");
}

uint64_t RateWindow::Add(const CounterSample& sample) {
  const bool rebase = !last_ || last_->publishers_key != sample.publishers_key ||
                      sample.published < last_->published ||
                      sample.published_bytes < last_->published_bytes;
  if (rebase) {
    last_ = sample;
    return 0;
  }
  if (sample.published == last_->published) return 0;  // keep the stamp of that message
  if (last_->published == 0 || sample.last_publish_mono_ns <= last_->last_publish_mono_ns) {
    last_ = sample;  // the previous stamp is unknown (nothing published before): new baseline
    return 0;
  }
  Entry entry;
  entry.messages = sample.published - last_->published;
  entry.bytes = sample.published_bytes - last_->published_bytes;
  entry.span_ns = sample.last_publish_mono_ns - last_->last_publish_mono_ns;
  entries_.push_back(entry);
  total_messages_ += entry.messages;
  while (entries_.size() > 1 && total_messages_ - entries_.front().messages >= window_messages_) {
    total_messages_ -= entries_.front().messages;
    entries_.pop_front();
  }
  last_ = sample;
  return entry.messages;
}

std::optional<RateWindow::Stats> RateWindow::Compute() const {
  if (entries_.empty()) return std::nullopt;
  Stats stats;
  double span_s = 0;
  double bytes = 0;
  stats.min_period_s = std::numeric_limits<double>::infinity();
  for (const Entry& e : entries_) {
    const double period = static_cast<double>(e.span_ns) * 1e-9 / static_cast<double>(e.messages);
    stats.min_period_s = std::min(stats.min_period_s, period);
    stats.max_period_s = std::max(stats.max_period_s, period);
    stats.messages += e.messages;
    span_s += static_cast<double>(e.span_ns) * 1e-9;
    bytes += static_cast<double>(e.bytes);
  }
  const double messages = static_cast<double>(stats.messages);
  const double mean_period = span_s / messages;
  double variance = 0;
  for (const Entry& e : entries_) {
    const double period = static_cast<double>(e.span_ns) * 1e-9 / static_cast<double>(e.messages);
    variance += static_cast<double>(e.messages) * (period - mean_period) * (period - mean_period);
  }
  stats.std_period_s = std::sqrt(variance / messages);
  stats.rate_hz = messages / span_s;
  stats.bytes_per_second = bytes / span_s;
  stats.mean_message_bytes = bytes / messages;
  return stats;
}

std::string FormatRateReport(const RateWindow::Stats& stats) {
  return "average rate: " + FormatFixed(stats.rate_hz, 2) +
         " Hz\n    min: " + FormatFixed(stats.min_period_s, 4) +
         " s  max: " + FormatFixed(stats.max_period_s, 4) +
         " s  std dev: " + FormatFixed(stats.std_period_s, 5) +
         " s  window: " + std::to_string(stats.messages) + "\n";
}

std::string FormatBandwidthReport(const RateWindow::Stats& stats) {
  return FormatBandwidth(stats.bytes_per_second) + " from " + std::to_string(stats.messages) +
         " messages\n    message size mean: " + FormatBytes(stats.mean_message_bytes) + "\n";
}

// --- Cleanup -----------------------------------------------------------------------------------

std::vector<std::string> PlanCleanup(const std::vector<std::string>& segment_names,
                                     const std::vector<bus::TopicSnapshot>& topics,
                                     const std::function<bool(int32_t)>& pid_alive) {
  std::vector<std::string> plan;
  for (const std::string& name : segment_names) {
    if (name.rfind("p.", 0) == 0) {
      int32_t pid = 0;
      const char* begin = name.data() + 2;
      const char* end = name.data() + name.size();
      const auto [ptr, ec] = std::from_chars(begin, end, pid);
      if (ec != std::errc() || ptr == end || *ptr != '.') continue;  // not a pool name
      if (!pid_alive(pid)) plan.push_back(name);
    } else if (name.rfind("t.", 0) == 0) {
      std::string topic = "/";
      topic += std::string_view(name).substr(2);
      std::replace(topic.begin(), topic.end(), '.', '/');
      const auto it = std::find_if(topics.begin(), topics.end(),
                                   [&](const bus::TopicSnapshot& t) { return t.topic == topic; });
      bool live = false;
      if (it != topics.end()) {
        for (const auto& p : it->publishers) live = live || p.alive;
        for (const auto& s : it->subscribers) live = live || s.alive;
      }
      if (!live) plan.push_back(name);
    }
  }
  std::sort(plan.begin(), plan.end());
  return plan;
}

}  // namespace probeless::tools
