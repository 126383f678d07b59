// Unit tests of the pure helpers behind `probeless topic` / `probeless clean`
// (tools/probeless/topic_format.h): argument parsing, formatting, the counter-based rate window,
// message descriptions and the clean plan.
#include "topic_format.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "probeless/msgs/msgs.h"
#include "probeless/testing/expect.h"

namespace probeless::tools {
namespace {

// --- Arguments ---------------------------------------------------------------------------------

constexpr OptionSpec kSpecs[] = {{"-n", true}, {"--window", true}, {"-v", false}};

TEST(ParseArgsTest, SplitsPositionalsAndOptionsInAnyOrder) {
  const std::vector<std::string> args = {"-v", "/a", "--window", "5", "/b", "-n=3", "--", "-x"};
  const ParsedArgs parsed = ParseArgs(args, kSpecs);
  EXPECT_EQ(parsed.positionals, (std::vector<std::string>{"/a", "/b", "-x"}));
  ASSERT_EQ(parsed.options.size(), 3u);
  EXPECT_EQ(parsed.options.at("--window"), "5");
  EXPECT_EQ(parsed.options.at("-n"), "3");
  EXPECT_TRUE(parsed.Has("-v"));
  EXPECT_EQ(parsed.options.at("-v"), "");
  EXPECT_FALSE(parsed.help);
  EXPECT_TRUE(ParseArgs(std::vector<std::string>{"/a", "--help"}, kSpecs).help);
  EXPECT_TRUE(ParseArgs(std::vector<std::string>{"-h"}, kSpecs).help);
  // A lone "-" is a positional, not an option.
  EXPECT_EQ(ParseArgs(std::vector<std::string>{"-"}, kSpecs).positionals.size(), 1u);
}

TEST(ParseArgsTest, RejectsWithPreciseMessages) {
  auto parse = [](std::vector<std::string> args) {
    return probeless::testing::ThrownMessage<UsageError>([&] { ParseArgs(args, kSpecs); });
  };
  EXPECT_EQ(parse({"/a", "--bogus"}), "unknown option '--bogus'");
  EXPECT_EQ(parse({"--bogus=1"}), "unknown option '--bogus'");
  EXPECT_EQ(parse({"/a", "--window"}), "--window expects a value");
  EXPECT_EQ(parse({"-v=yes"}), "-v takes no value");
}

TEST(ParseArgsTest, CountsAndSeconds) {
  EXPECT_EQ(ParseCount("-n", "3"), 3u);
  EXPECT_EQ(ParseCount("-n", "9223372036854775807"), 9223372036854775807u);
  EXPECT_EQ(ParseCount("-n", "+3"), 3u);  // parse::ParseInteger's rules, as every option
  for (const char* bad : {"0", "-1", "3x", "", "abc", "9223372036854775808", "1.5", " 3"}) {
    PROBELESS_EXPECT_THROWS_MESSAGE(
        ParseCount("-n", bad), UsageError,
        std::string("-n expects a positive integer, got '") + bad + "'");
  }
  EXPECT_DOUBLE_EQ(ParseSeconds("--duration", "2"), 2.0);
  EXPECT_DOUBLE_EQ(ParseSeconds("--duration", "0.25"), 0.25);
  EXPECT_DOUBLE_EQ(ParseSeconds("--duration", "0"), 0.0);
  EXPECT_DOUBLE_EQ(ParseSeconds("--duration", "1e3"), 1000.0);
  for (const char* bad : {"-1", "soon", "", "1s", "inf", "nan", "1e400", "0x10"}) {
    PROBELESS_EXPECT_THROWS_MESSAGE(
        ParseSeconds("--timeout", bad), UsageError,
        std::string("--timeout expects a non-negative number of seconds, got '") + bad + "'");
  }
}

// --- Formatting --------------------------------------------------------------------------------

TEST(FormatTest, BytesUseSiUnits) {
  EXPECT_EQ(FormatBytes(0), "0 B");
  EXPECT_EQ(FormatBytes(999), "999 B");
  EXPECT_EQ(FormatBytes(1000), "1.00 KB");
  EXPECT_EQ(FormatBytes(1'536'000), "1.54 MB");
  EXPECT_EQ(FormatBytes(2.5e9), "2.50 GB");
  EXPECT_EQ(FormatBytes(3e12), "3.00 TB");
  EXPECT_EQ(FormatBandwidth(300'000), "300.00 KB/s");
  EXPECT_EQ(FormatBandwidth(27'648'000), "27.65 MB/s");
  EXPECT_EQ(FormatByteCount(32), "32 B");
  EXPECT_EQ(FormatByteCount(1'536'000), "1536000 B (1.54 MB)");
}

TEST(FormatTest, WallTimeIsUtcWithNanoseconds) {
  EXPECT_EQ(FormatWallTime(0), "1970-01-01T00:00:00.000000000Z");
  EXPECT_EQ(FormatWallTime(1'700'000'000'123'456'789), "2023-11-14T22:13:20.123456789Z");
  EXPECT_EQ(FormatWallTime(-5), "-5 ns");
}

TEST(FormatTest, TableAlignsColumns) {
  EXPECT_EQ(FormatTable({{"TOPIC", "TYPE", "N"}, {"/camera/image", "Image", "1"}, {"/a", "B"}}),
            "TOPIC          TYPE   N\n"
            "/camera/image  Image  1\n"
            "/a             B\n");
  EXPECT_EQ(FormatTable({}), "");
}

TEST(FormatTest, HexDumpShowsOffsetsBytesAndAscii) {
  std::string text = "Hello, probeless!";
  text += std::string("\x00\xff\x7f", 3);
  const auto bytes = std::as_bytes(std::span(text.data(), text.size()));
  EXPECT_EQ(HexDump(bytes),
            "  0000  48 65 6c 6c 6f 2c 20 70  72 6f 62 65 6c 65 73 73  |Hello, probeless|\n"
            "  0010  21 00 ff 7f " +
                std::string(4 * 3 + 1 + 8 * 3, ' ') + " |!...|\n");
  EXPECT_EQ(HexDump(bytes, 3),
            "  0000  48 65 6c " + std::string(5 * 3 + 1 + 8 * 3, ' ') + " |Hel|\n");
  EXPECT_EQ(HexDump({}), "");
  // 64 of 100 bytes: four lines, the last at offset 0x30.
  const std::vector<std::byte> big(100, std::byte{0x41});
  const std::string dump = HexDump(big, 64);
  EXPECT_EQ(std::count(dump.begin(), dump.end(), '\n'), 4);
  EXPECT_NE(dump.find("  0030  41"), std::string::npos);
  EXPECT_EQ(dump.find("  0040"), std::string::npos);
}

bus::MessageInfo Info(uint64_t sequence, uint32_t size) {
  bus::MessageInfo info;
  info.sequence = sequence;
  info.publish_mono_ns = 1'234'000'000'456;
  info.publish_wall_ns = 1'700'000'000'123'456'789;
  info.size = size;
  info.publisher_pid = 4321;
  return info;
}

TEST(FormatTest, MessageOfUnknownTypeIsHexDumped) {
  const bus::TopicType blob{"test_msgs/Blob", 0x1234};
  const std::string text = "Hello, probeless!";
  const auto bytes = std::as_bytes(std::span(text.data(), text.size()));
  EXPECT_EQ(FormatMessage(blob, Info(12, 17), bytes),
            "sequence: 12\n"
            "publisher pid: 4321\n"
            "published: 2023-11-14T22:13:20.123456789Z (mono 1234.000000456 s)\n"
            "size: 17 B\n"
            "data (17 bytes):\n" +
                HexDump(bytes) + "---\n");
  const std::vector<std::byte> big(100, std::byte{0});
  const std::string long_text = FormatMessage(blob, Info(1, 100), big);
  EXPECT_NE(
      long_text.find("size: 100 B\ndata (first 64 of 100 bytes):\n" + HexDump(big, 64) + "---\n"),
      std::string::npos);
  EXPECT_NE(FormatMessage(blob, Info(1, 0), {}).find("size: 0 B\ndata: (empty)\n---\n"),
            std::string::npos);
}

// --- Message descriptions ----------------------------------------------------------------------

TEST(DescribeMessageTest, DecodesKnownTypes) {
  alignas(64) std::array<std::byte, sizeof(msgs::Image) + 24> buffer{};
  auto image = msgs::WriteMessage<msgs::Image>(buffer);
  image->header.stamp_ns = 1'700'000'000'123'456'789;
  image->header.stamp_mono_ns = 5'000'000'001;
  image->header.sequence = 7;
  image->header.SetFrameId("camera_optical");
  image->width = 4;
  image->height = 2;
  image->step = 12;
  image->encoding = msgs::Encoding::kRgb8;
  const std::string header =
      "header:\n  stamp: 2023-11-14T22:13:20.123456789Z (mono 5.000000001 s)\n  sequence: 7\n"
      "  frame_id: 'camera_optical'\n";
  const auto text = DescribeMessage(msgs::TopicTypeOf<msgs::Image>(), buffer);
  ASSERT_TRUE(text);
  EXPECT_EQ(*text, header + "image: 4x2 rgb8, step 12, payload 24 B\n");
  const std::string echoed =
      FormatMessage(msgs::TopicTypeOf<msgs::Image>(), Info(3, buffer.size()), buffer);
  EXPECT_NE(echoed.find("size: 152 B\ntype: probeless_msgs/Image\n" + header), std::string::npos)
      << echoed;
  EXPECT_EQ(echoed.find("data ("), std::string::npos);

  alignas(64) std::array<std::byte, sizeof(msgs::Pose)> pose_bytes{};
  auto pose = msgs::WriteMessage<msgs::Pose>(pose_bytes);
  pose->SetParentFrameId("world");
  pose->SetChildFrameId("camera");
  pose->transform.translation = {1, 2.5, -3};
  pose->transform.rotation = {1, 0, 0, 0};
  const auto pose_text = DescribeMessage(msgs::TopicTypeOf<msgs::Pose>(), pose_bytes);
  ASSERT_TRUE(pose_text);
  EXPECT_NE(pose_text->find("frame_id: 'world'\npose: parent 'world' child 'camera', translation "
                            "(1, 2.5, -3) m, rotation (w, x, y, z) (1, 0, 0, 0)\n"),
            std::string::npos)
      << *pose_text;
}

TEST(DescribeMessageTest, UnknownMismatchedShortOrMisalignedGivesNothing) {
  alignas(64) std::array<std::byte, sizeof(msgs::Image) + 64> buffer{};
  msgs::WriteMessage<msgs::Image>(buffer);
  const bus::TopicType image = msgs::TopicTypeOf<msgs::Image>();
  EXPECT_FALSE(DescribeMessage({"test_msgs/Blob", 1}, buffer));
  EXPECT_FALSE(DescribeMessage({image.name, image.layout_hash ^ 1}, buffer));
  EXPECT_FALSE(DescribeMessage(image, std::span(buffer).first(sizeof(msgs::Image) - 1)));
  EXPECT_FALSE(DescribeMessage(image, std::span(buffer).subspan(1)));
  EXPECT_TRUE(DescribeMessage(image, std::span(buffer).first(sizeof(msgs::Image))));
}

// --- Rate window -------------------------------------------------------------------------------

// The counters of one publisher whose messages went out at `times_ns` (sorted), read at `at_ns`.
CounterSample Reading(const std::vector<int64_t>& times_ns, int64_t at_ns, uint64_t message_bytes,
                      const std::string& key = "1:/cam:64:32;") {
  const auto published = static_cast<uint64_t>(
      std::upper_bound(times_ns.begin(), times_ns.end(), at_ns) - times_ns.begin());
  CounterSample sample;
  sample.published = published;
  sample.published_bytes = published * message_bytes;
  sample.last_publish_mono_ns = published == 0 ? 0 : times_ns[published - 1];
  sample.publishers_key = key;
  return sample;
}

constexpr int64_t kStart = 1'000'000'000;
constexpr int64_t kMs = 1'000'000;

// Message times with periods drawn uniformly from [min_ms, max_ms] (fixed seed).
std::vector<int64_t> JitteredTimes(size_t count, double min_ms, double max_ms) {
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> period(min_ms, max_ms);
  std::vector<int64_t> times = {kStart};
  while (times.size() < count) {
    times.push_back(times.back() + static_cast<int64_t>(period(rng) * kMs));
  }
  return times;
}

TEST(RateWindowTest, SteadyThirtyHertzIsExact) {
  const int64_t period = 33'333'333;
  std::vector<int64_t> times;
  for (int i = 0; i < 300; ++i) times.push_back(kStart + i * period);
  RateWindow window(10000);
  uint64_t accounted = 0;
  for (int64_t at = kStart + 5 * kMs; at < times.back() + 100 * kMs; at += 100 * kMs) {
    accounted += window.Add(Reading(times, at, 1000));
  }
  EXPECT_EQ(accounted, 299u);  // every message after the baseline reading (which saw 1)
  const auto stats = window.Compute();
  ASSERT_TRUE(stats);
  EXPECT_EQ(stats->messages, 299u);
  EXPECT_NEAR(stats->rate_hz, 1e9 / period, 1e-6);
  EXPECT_NEAR(stats->min_period_s, period * 1e-9, 1e-12);
  EXPECT_NEAR(stats->max_period_s, period * 1e-9, 1e-12);
  EXPECT_NEAR(stats->std_period_s, 0, 1e-9);
  EXPECT_NEAR(stats->bytes_per_second, 1000 * 1e9 / period, 1e-3);
  EXPECT_DOUBLE_EQ(stats->mean_message_bytes, 1000);
}

TEST(RateWindowTest, FastReadingsGivePerMessageStatistics) {
  // Readings every 1 ms, messages 20..47 ms apart: every window entry is exactly one message, so
  // min/max/std are those of the individual periods, as `ros2 topic hz` computes them.
  const std::vector<int64_t> times = JitteredTimes(200, 20, 47);
  RateWindow window(10000);
  for (int64_t at = kStart - 5 * kMs; at <= times.back() + kMs; at += kMs) {
    window.Add(Reading(times, at, 10));
  }
  // Baselines: the reading before the first message, then the one that saw message 1.
  std::vector<double> periods;
  for (size_t i = 1; i < times.size(); ++i) periods.push_back((times[i] - times[i - 1]) * 1e-9);
  double mean = 0;
  for (double p : periods) mean += p;
  mean /= static_cast<double>(periods.size());
  double variance = 0;
  for (double p : periods) variance += (p - mean) * (p - mean);
  variance /= static_cast<double>(periods.size());
  const auto stats = window.Compute();
  ASSERT_TRUE(stats);
  EXPECT_EQ(stats->messages, periods.size());
  EXPECT_NEAR(stats->rate_hz, 1.0 / mean, 1e-9);
  EXPECT_DOUBLE_EQ(stats->min_period_s, *std::min_element(periods.begin(), periods.end()));
  EXPECT_DOUBLE_EQ(stats->max_period_s, *std::max_element(periods.begin(), periods.end()));
  EXPECT_NEAR(stats->std_period_s, std::sqrt(variance), 1e-12);
  EXPECT_GT(stats->std_period_s, 0.005);  // the jitter is visible
}

TEST(RateWindowTest, SlowReadingsKeepTheExactMeanAndSmoothTheExtremes) {
  const std::vector<int64_t> times = JitteredTimes(300, 20, 47);
  RateWindow window(10000);
  const int64_t first_reading = kStart + 50 * kMs;
  int64_t last_reading = 0;
  for (int64_t at = first_reading; at <= times.back(); at += 100 * kMs) {
    window.Add(Reading(times, at, 10));
    last_reading = at;
  }
  const CounterSample base = Reading(times, first_reading, 10);
  const CounterSample last = Reading(times, last_reading, 10);
  const double expected_rate =
      static_cast<double>(last.published - base.published) * 1e9 /
      static_cast<double>(last.last_publish_mono_ns - base.last_publish_mono_ns);
  const auto stats = window.Compute();
  ASSERT_TRUE(stats);
  EXPECT_EQ(stats->messages, last.published - base.published);
  EXPECT_NEAR(stats->rate_hz, expected_rate, 1e-9);
  EXPECT_NEAR(stats->bytes_per_second, 10 * expected_rate, 1e-6);
  EXPECT_GE(stats->min_period_s, 0.020);
  EXPECT_LE(stats->max_period_s, 0.047);
  EXPECT_LT(stats->min_period_s, 1 / stats->rate_hz);
  EXPECT_GT(stats->max_period_s, 1 / stats->rate_hz);
}

TEST(RateWindowTest, WindowFollowsTheNewestMessages) {
  // 5 s at 10 Hz, then 5 s at 50 Hz.
  std::vector<int64_t> times;
  for (int i = 0; i < 50; ++i) times.push_back(kStart + i * 100 * kMs);
  for (int i = 1; i <= 250; ++i) times.push_back(kStart + 4900 * kMs + i * 20 * kMs);
  RateWindow recent(20);
  RateWindow all(10000);
  for (int64_t at = kStart + 5 * kMs; at <= times.back() + 100 * kMs; at += 100 * kMs) {
    recent.Add(Reading(times, at, 100));
    all.Add(Reading(times, at, 100));
  }
  const auto r = recent.Compute();
  ASSERT_TRUE(r);
  EXPECT_GE(r->messages, 20u);
  EXPECT_LT(r->messages, 26u);  // at most one 100 ms reading (5 messages) beyond the window
  EXPECT_NEAR(r->rate_hz, 50, 1e-6);
  EXPECT_NEAR(r->max_period_s, 0.020, 1e-9);
  const auto a = all.Compute();
  ASSERT_TRUE(a);
  EXPECT_EQ(a->messages, 299u);
  EXPECT_NEAR(a->min_period_s, 0.020, 1e-9);
  EXPECT_NEAR(a->max_period_s, 0.100, 1e-9);
  EXPECT_NEAR(a->rate_hz, 299 / 9.9, 1e-6);  // 299 periods from t=0 to t=9.9 s
}

TEST(RateWindowTest, RebaselinesOnPublisherChangesAndWaitsForNewMessages) {
  RateWindow window(100);
  EXPECT_FALSE(window.Compute());
  auto sample = [](uint64_t published, int64_t last_ms, const std::string& key) {
    CounterSample s;
    s.published = published;
    s.published_bytes = published * 8;
    s.last_publish_mono_ns = last_ms * kMs;
    s.publishers_key = key;
    return s;
  };
  EXPECT_EQ(window.Add(sample(0, 0, "a")), 0u);      // nothing published yet
  EXPECT_EQ(window.Add(sample(10, 1000, "a")), 0u);  // message 0 has no stamp: new baseline
  EXPECT_FALSE(window.Compute());
  EXPECT_EQ(window.Add(sample(10, 1000, "a")), 0u);  // nothing new
  EXPECT_EQ(window.Add(sample(13, 1300, "a")), 3u);
  // Another publisher set: counters are not comparable, so no entry.
  EXPECT_EQ(window.Add(sample(500, 9000, "b")), 0u);
  EXPECT_EQ(window.Add(sample(2, 9100, "b")), 0u);  // counters went backwards (restart)
  EXPECT_EQ(window.Add(sample(4, 9300, "b")), 2u);
  const auto stats = window.Compute();
  ASSERT_TRUE(stats);
  EXPECT_EQ(stats->messages, 5u);
  EXPECT_NEAR(stats->rate_hz, 5 / 0.5, 1e-9);  // 3 in 300 ms and 2 in 200 ms
  EXPECT_NEAR(stats->min_period_s, 0.1, 1e-12);
  EXPECT_NEAR(stats->max_period_s, 0.1, 1e-12);
  PROBELESS_EXPECT_THROWS_MESSAGE(RateWindow(0), UsageError,
                                  "the rate window must hold at least 1 message");
}

TEST(RateWindowTest, RateBetweenTwoReadings) {
  EXPECT_NEAR(*RateBetween(10, 1'000'000'000, 40, 2'000'000'000), 30.0, 1e-12);
  EXPECT_NEAR(*RateBetween(1, 0, 2, 250'000'000), 4.0, 1e-12);
  EXPECT_FALSE(RateBetween(0, 0, 40, 2'000'000'000));               // stamp of message 0 unknown
  EXPECT_FALSE(RateBetween(10, 1'000'000'000, 10, 1'000'000'000));  // nothing new
  EXPECT_FALSE(RateBetween(10, 1'000'000'000, 9, 2'000'000'000));
}

TEST(RateWindowTest, SumPublishersAddsCountersAndKeysTheSet) {
  EXPECT_EQ(SumPublishers(nullptr).published, 0u);
  EXPECT_EQ(SumPublishers(nullptr).publishers_key, "");
  bus::TopicSnapshot topic;
  bus::PublisherSnapshot a;
  a.pid = 10;
  a.node_name = "/cam";
  a.max_message_bytes = 64;
  a.slot_count = 4;
  a.published = 5;
  a.published_bytes = 50;
  a.last_publish_mono_ns = 700;
  bus::PublisherSnapshot b = a;
  b.pid = 11;
  b.published = 7;
  b.published_bytes = 70;
  b.last_publish_mono_ns = 900;
  topic.publishers = {a, b};
  const CounterSample sum = SumPublishers(&topic);
  EXPECT_EQ(sum.published, 12u);
  EXPECT_EQ(sum.published_bytes, 120u);
  EXPECT_EQ(sum.last_publish_mono_ns, 900);
  EXPECT_EQ(sum.publishers_key, "10:/cam:64:4;11:/cam:64:4;");
}

TEST(RateWindowTest, ReportsLookLikeRos2) {
  RateWindow::Stats stats;
  stats.messages = 30;
  stats.rate_hz = 30;
  stats.min_period_s = 0.0331;
  stats.max_period_s = 0.0336;
  stats.std_period_s = 0.00012;
  stats.bytes_per_second = 300'000;
  stats.mean_message_bytes = 10'000;
  EXPECT_EQ(FormatRateReport(stats),
            "average rate: 30.00 Hz\n"
            "    min: 0.0331 s  max: 0.0336 s  std dev: 0.00012 s  window: 30\n");
  EXPECT_EQ(FormatBandwidthReport(stats),
            "300.00 KB/s from 30 messages\n"
            "    message size mean: 10.00 KB\n");
}

// --- Clean plan --------------------------------------------------------------------------------

TEST(PlanCleanupTest, ChoosesDeadPoolsAndRegistriesWithoutLiveParticipants) {
  auto participant = [](int32_t pid, bool alive) {
    bus::PublisherSnapshot p;
    p.pid = pid;
    p.alive = alive;
    return p;
  };
  std::vector<bus::TopicSnapshot> topics(3);
  topics[0].topic = "/dead/topic";
  topics[0].publishers = {participant(100, false)};
  topics[1].topic = "/live";
  topics[1].publishers = {participant(100, false), participant(200, true)};
  topics[2].topic = "/only_sub";
  bus::SubscriberSnapshot dead_sub;
  dead_sub.pid = 300;
  dead_sub.alive = false;
  topics[2].subscribers = {dead_sub};
  const std::vector<std::string> names = {
      "t.dead.topic", "p.100.0.dead.topic",  "t.live",  "p.200.1.live", "p.100.2.live",
      "t.only_sub",   "t.never_initialised", "p.x.0.a", "p.12",         "unrelated"};
  const auto plan = PlanCleanup(names, topics, [](int32_t pid) { return pid == 200; });
  EXPECT_EQ(plan, (std::vector<std::string>{"p.100.0.dead.topic", "p.100.2.live", "t.dead.topic",
                                            "t.never_initialised", "t.only_sub"}));
  EXPECT_TRUE(
      PlanCleanup({"t.live", "p.200.1.live"}, topics, [](int32_t) { return true; }).empty());
}

}  // namespace
}  // namespace probeless::tools
