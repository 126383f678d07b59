// Recorder library tests: publish on the bus (from this process and from forked children), record,
// read the MCAP files back with log::McapReader and log::DecodeRos2.
#include "probeless/record/recorder.h"

#include <gtest/gtest.h>
#include <stdlib.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <functional>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "probeless/bus/bus.h"
#include "probeless/log/mcap_reader.h"
#include "probeless/log/ros2.h"
#include "probeless/msgs/image.h"

namespace {

using namespace std::chrono_literals;
namespace bus = probeless::bus;
namespace log = probeless::log;
namespace msgs = probeless::msgs;
namespace record = probeless::record;

constexpr uint32_t kWidth = 64;
constexpr uint32_t kHeight = 48;

// Payload byte j of message `index` on a topic with `salt`: deterministic, compressible.
std::byte PatternByte(uint64_t index, uint64_t salt, size_t j) {
  return static_cast<std::byte>((j / 7 + index * 13 + salt * 101) & 0xff);
}

bus::Publisher ImagePublisher(const std::string& topic, msgs::Encoding encoding) {
  bus::PublisherOptions options;
  options.max_message_bytes = msgs::Image::MessageBytesFor(kWidth, kHeight, encoding);
  options.slot_count = 80;  // more than a recorder queue holds: nothing is dropped to free slots
  return bus::Publisher(topic, msgs::TopicTypeOf<msgs::Image>(), options);
}

// Publishes image `index` (header.sequence = index) with the pattern of `salt`.
void PublishImage(bus::Publisher& publisher, msgs::Encoding encoding, uint64_t index,
                  uint64_t salt) {
  const size_t bytes = msgs::Image::MessageBytesFor(kWidth, kHeight, encoding);
  bus::Loan loan = publisher.Borrow(bytes);
  auto out = msgs::WriteMessage<msgs::Image>(loan.data());
  out->header.StampNow();
  out->header.sequence = index;
  out->header.SetFrameId("cam");
  out->Init(kWidth, kHeight, encoding);
  for (size_t j = 0; j < out->PayloadBytes(); ++j) out.payload[j] = PatternByte(index, salt, j);
  publisher.Publish(std::move(loan));
}

// One message read back.
struct Read {
  uint32_t sequence = 0;
  uint64_t log_time_ns = 0;
  uint64_t publish_time_ns = 0;
  std::vector<std::byte> data;
};

// Messages of every file, per topic, in file then log-time order; checks every file is complete.
std::map<std::string, std::vector<Read>> ReadFiles(const std::vector<std::string>& paths) {
  std::map<std::string, std::vector<Read>> out;
  for (const std::string& path : paths) {
    log::McapReader reader(path);
    EXPECT_FALSE(reader.truncated()) << path << ": " << reader.recovery().detail;
    log::MessageCursor cursor = reader.Messages();
    log::MessageView m;
    while (cursor.Next(m)) {
      out[m.channel->topic].push_back(
          {m.sequence, m.log_time_ns, m.publish_time_ns, {m.data.begin(), m.data.end()}});
    }
  }
  return out;
}

// Checks that `read` are exactly images 1..count of `salt`, byte for byte, in order.
void ExpectImages(const std::vector<Read>& read, msgs::Encoding encoding, uint64_t count,
                  uint64_t salt) {
  ASSERT_EQ(read.size(), count);
  const log::Ros2Converter& converter = log::Ros2ConverterFor<msgs::Image>();
  for (uint64_t i = 1; i <= count; ++i) {
    const Read& r = read[i - 1];
    EXPECT_EQ(r.sequence, i);
    EXPECT_GT(r.publish_time_ns, 0u);
    EXPECT_GE(r.log_time_ns, r.publish_time_ns);
    log::MessageBuffer decoded = log::DecodeRos2(converter, r.data);
    auto in = msgs::ReadMessage<msgs::Image>(decoded.bytes());
    ASSERT_EQ(in->width, kWidth);
    ASSERT_EQ(in->height, kHeight);
    ASSERT_EQ(in->encoding, encoding);
    EXPECT_STREQ(in->header.frame_id, "cam");
    ASSERT_EQ(in.payload.size(), in->PayloadBytes());
    size_t mismatches = 0;
    for (size_t j = 0; j < in->PayloadBytes(); ++j)
      mismatches += in.payload[j] != PatternByte(i, salt, j);
    EXPECT_EQ(mismatches, 0u) << "image " << i;
  }
}

// Waits (bounded, generous) until `done` holds; the tests then assert on contents, not timing.
bool WaitFor(const std::function<bool()>& done) {
  const auto deadline = std::chrono::steady_clock::now() + 20s;
  while (!done()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(2ms);
  }
  return true;
}

uint64_t Received(const record::Recorder& recorder, const std::string& topic) {
  for (const auto& t : recorder.Stats().topics) {
    if (t.topic == topic) return t.received;
  }
  return 0;
}

class RecorderTest : public ::testing::Test {
 protected:
  void SetUp() override {
    bus::CleanDeadSegments();
    char pattern[] = "/tmp/probeless_record_test_XXXXXX";
    ASSERT_NE(mkdtemp(pattern), nullptr);
    dir_ = pattern;
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  record::RecorderOptions Options(const std::string& name = "out") {
    record::RecorderOptions o;
    o.output = dir_ + "/" + name;
    o.discovery_period = 10ms;
    o.chunk_size = 64 * 1024;
    o.log = [this](std::string_view line) {
      std::lock_guard lock(log_mutex_);
      log_.emplace_back(line);
    };
    return o;
  }
  std::vector<std::string> LogLines() {
    std::lock_guard lock(log_mutex_);
    return log_;
  }

  std::string dir_;
  std::mutex log_mutex_;
  std::vector<std::string> log_;
};

TEST_F(RecorderTest, RecordsEveryImageByteExactInOrderPerTopic) {
  bus::Publisher rgb = ImagePublisher("/cam/image", msgs::Encoding::kRgb8);
  bus::Publisher depth = ImagePublisher("/cam/depth", msgs::Encoding::kDepth16);
  record::RecorderOptions o = Options();
  o.topics = {"/cam/image", "/cam/depth"};
  record::Recorder recorder(o);
  recorder.Start();
  EXPECT_EQ(rgb.SubscriberCount(), 1u);  // Start subscribes to existing topics at once
  EXPECT_EQ(depth.SubscriberCount(), 1u);
  for (uint64_t i = 1; i <= 60; ++i) {
    PublishImage(rgb, msgs::Encoding::kRgb8, i, 1);
    PublishImage(depth, msgs::Encoding::kDepth16, i, 2);
  }
  const record::RecorderStats stats = recorder.Stop();
  ASSERT_EQ(stats.files, std::vector<std::string>{dir_ + "/out.mcap"});
  ASSERT_EQ(stats.topics.size(), 2u);
  EXPECT_EQ(stats.topics[0].topic, "/cam/depth");
  EXPECT_EQ(stats.topics[1].topic, "/cam/image");
  uint64_t bytes = 0;
  for (const auto& t : stats.topics) {
    EXPECT_EQ(t.type, "probeless_msgs/Image");
    EXPECT_EQ(t.encoding, "cdr");
    EXPECT_EQ(t.received, 60u);
    EXPECT_EQ(t.dropped, 0u);
    EXPECT_EQ(t.invalid, 0u);
    EXPECT_EQ(t.written, 60u);
    bytes += t.bytes;
  }
  EXPECT_EQ(stats.written, 120u);
  EXPECT_EQ(stats.bytes, bytes);
  EXPECT_EQ(stats.file_bytes, std::filesystem::file_size(dir_ + "/out.mcap"));

  const auto read = ReadFiles(stats.files);
  ExpectImages(read.at("/cam/image"), msgs::Encoding::kRgb8, 60, 1);
  ExpectImages(read.at("/cam/depth"), msgs::Encoding::kDepth16, 60, 2);

  log::McapReader reader(stats.files[0]);
  EXPECT_EQ(reader.profile(), "ros2");
  EXPECT_EQ(reader.statistics().message_count, 120u);
  const log::Channel* channel = reader.FindChannelByTopic("/cam/image");
  ASSERT_NE(channel, nullptr);
  EXPECT_EQ(channel->message_encoding, "cdr");
  EXPECT_EQ(channel->metadata.at("probeless.type"), "probeless_msgs/Image");
  const log::Schema* schema = reader.FindSchema(channel->schema_id);
  ASSERT_NE(schema, nullptr);
  EXPECT_EQ(schema->name, "sensor_msgs/msg/Image");
  EXPECT_EQ(schema->encoding, "ros2msg");
  EXPECT_EQ(reader.schemas().size(), 1u);  // one schema shared by both channels
  uint64_t payload = 0;
  for (const auto& [topic, messages] : read) {
    for (const Read& r : messages) payload += r.data.size();
  }
  EXPECT_EQ(payload, stats.bytes);
}

TEST_F(RecorderTest, SelectsByListRegexAndExclude) {
  std::vector<bus::Publisher> publishers;
  for (const char* topic : {"/a/image", "/a/depth", "/b/image", "/c/x"}) {
    publishers.push_back(ImagePublisher(topic, msgs::Encoding::kMono8));
  }
  record::RecorderOptions o = Options();
  o.topics = {"/c/x"};
  o.regex = "^/a/";
  o.exclude = "depth$";
  record::Recorder recorder(o);
  recorder.Start();
  for (auto& p : publishers) {
    for (uint64_t i = 1; i <= 3; ++i) PublishImage(p, msgs::Encoding::kMono8, i, 0);
  }
  const record::RecorderStats stats = recorder.Stop();
  ASSERT_EQ(stats.topics.size(), 2u);
  EXPECT_EQ(stats.topics[0].topic, "/a/image");
  EXPECT_EQ(stats.topics[1].topic, "/c/x");
  const auto read = ReadFiles(stats.files);
  ASSERT_EQ(read.size(), 2u);
  ExpectImages(read.at("/a/image"), msgs::Encoding::kMono8, 3, 0);
  ExpectImages(read.at("/c/x"), msgs::Encoding::kMono8, 3, 0);
  EXPECT_EQ(publishers[1].SubscriberCount(), 0u);
  EXPECT_EQ(publishers[2].SubscriberCount(), 0u);
}

TEST_F(RecorderTest, AllWithExcludeRecordsEverythingElse) {
  std::vector<bus::Publisher> publishers;
  for (const char* topic : {"/x/one", "/x/two", "/debug/three"}) {
    publishers.push_back(ImagePublisher(topic, msgs::Encoding::kMono8));
  }
  record::RecorderOptions o = Options();
  o.all = true;
  o.exclude = "^/debug";
  record::Recorder recorder(o);
  recorder.Start();
  for (auto& p : publishers) PublishImage(p, msgs::Encoding::kMono8, 1, 0);
  const record::RecorderStats stats = recorder.Stop();
  ASSERT_EQ(stats.topics.size(), 2u);
  EXPECT_EQ(stats.topics[0].topic, "/x/one");
  EXPECT_EQ(stats.topics[1].topic, "/x/two");
  EXPECT_EQ(stats.written, 2u);
}

TEST_F(RecorderTest, PicksUpATopicThatAppearsAfterStart) {
  record::RecorderOptions o = Options();
  o.regex = "^/late/";
  record::Recorder recorder(o);
  recorder.Start();
  EXPECT_TRUE(recorder.Stats().topics.empty());
  bus::Publisher late = ImagePublisher("/late/image", msgs::Encoding::kRgb8);
  ASSERT_TRUE(WaitFor([&] { return late.SubscriberCount() == 1; }));
  for (uint64_t i = 1; i <= 5; ++i) PublishImage(late, msgs::Encoding::kRgb8, i, 3);
  const record::RecorderStats stats = recorder.Stop();
  ASSERT_EQ(stats.topics.size(), 1u);
  EXPECT_EQ(stats.topics[0].received, 5u);
  ExpectImages(ReadFiles(stats.files).at("/late/image"), msgs::Encoding::kRgb8, 5, 3);
  const auto lines = LogLines();
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_EQ(lines[0], "recording /late/image (probeless_msgs/Image as sensor_msgs/msg/Image cdr)");
}

TEST_F(RecorderTest, SplitBySizeGivesValidFilesWhoseUnionIsTheStream) {
  bus::Publisher rgb = ImagePublisher("/s/image", msgs::Encoding::kRgb8);  // 9,216 B of pixels
  record::RecorderOptions o = Options("split.mcap");
  o.topics = {"/s/image"};
  o.split_bytes = 200'000;
  o.chunk_size = 50'000;
  record::Recorder recorder(o);
  recorder.Start();
  for (uint64_t i = 1; i <= 60; ++i) {
    PublishImage(rgb, msgs::Encoding::kRgb8, i, 4);
    if (i % 20 == 0) {
      ASSERT_TRUE(WaitFor([&] { return Received(recorder, "/s/image") == i; }));
    }
  }
  const record::RecorderStats stats = recorder.Stop();
  ASSERT_GE(stats.files.size(), 3u);
  uint64_t total = 0;
  for (size_t i = 0; i < stats.files.size(); ++i) {
    EXPECT_EQ(stats.files[i], dir_ + "/split_" + std::to_string(i) + ".mcap");
    const uint64_t size = std::filesystem::file_size(stats.files[i]);
    EXPECT_LE(size, o.split_bytes + 4096) << stats.files[i];  // + summary and footer
    log::McapReader reader(stats.files[i]);
    EXPECT_FALSE(reader.truncated());
    EXPECT_GT(reader.statistics().message_count, 0u);
    ASSERT_NE(reader.FindChannelByTopic("/s/image"), nullptr);
    total += size;
  }
  EXPECT_EQ(total, stats.file_bytes);
  ExpectImages(ReadFiles(stats.files).at("/s/image"), msgs::Encoding::kRgb8, 60, 4);
}

TEST_F(RecorderTest, SplitByDurationStartsANewFileAfterTheSpan) {
  bus::Publisher rgb = ImagePublisher("/d/image", msgs::Encoding::kMono8);
  record::RecorderOptions o = Options("timed");
  o.topics = {"/d/image"};
  o.split_seconds = 0.2;
  record::Recorder recorder(o);
  recorder.Start();
  for (uint64_t i = 1; i <= 5; ++i) PublishImage(rgb, msgs::Encoding::kMono8, i, 5);
  ASSERT_TRUE(WaitFor([&] { return Received(recorder, "/d/image") == 5; }));
  std::this_thread::sleep_for(300ms);  // not a timing assertion: makes the next batch 0.3 s later
  for (uint64_t i = 6; i <= 10; ++i) PublishImage(rgb, msgs::Encoding::kMono8, i, 5);
  const record::RecorderStats stats = recorder.Stop();
  ASSERT_GE(stats.files.size(), 2u);
  EXPECT_EQ(stats.files[0], dir_ + "/timed_0.mcap");
  EXPECT_EQ(stats.files[1], dir_ + "/timed_1.mcap");
  ExpectImages(ReadFiles(stats.files).at("/d/image"), msgs::Encoding::kMono8, 10, 5);
}

class RecorderCompressionTest : public RecorderTest,
                                public ::testing::WithParamInterface<log::Compression> {};

TEST_P(RecorderCompressionTest, RoundTripsWithEachCompression) {
  bus::Publisher rgb = ImagePublisher("/z/image", msgs::Encoding::kRgb8);
  record::RecorderOptions o = Options();
  o.topics = {"/z/image"};
  o.compression = GetParam();
  record::Recorder recorder(o);
  recorder.Start();
  for (uint64_t i = 1; i <= 40; ++i) PublishImage(rgb, msgs::Encoding::kRgb8, i, 6);
  const record::RecorderStats stats = recorder.Stop();
  ExpectImages(ReadFiles(stats.files).at("/z/image"), msgs::Encoding::kRgb8, 40, 6);
  const uint64_t size = std::filesystem::file_size(stats.files[0]);
  if (GetParam() == log::Compression::kNone) {
    EXPECT_GT(size, stats.bytes);
  } else {
    EXPECT_LT(size, stats.bytes / 2);  // the pattern compresses well
  }
}

INSTANTIATE_TEST_SUITE_P(All, RecorderCompressionTest,
                         ::testing::Values(log::Compression::kNone, log::Compression::kLz4,
                                           log::Compression::kZstd),
                         [](const auto& info) {
                           return std::string(log::CompressionOptionName(info.param));
                         });

TEST_F(RecorderTest, RecordsPublishersInForkedChildren) {
  record::RecorderOptions o = Options();
  o.regex = "^/child";
  record::Recorder recorder(o);
  recorder.Start();
  std::vector<pid_t> children;
  std::vector<int> release_pipes;
  for (int c = 0; c < 2; ++c) {
    int fds[2];
    ASSERT_EQ(pipe(fds), 0);
    const pid_t pid = fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
      close(fds[1]);
      int status = 0;
      try {
        bus::Publisher p =
            ImagePublisher("/child" + std::to_string(c) + "/image", msgs::Encoding::kRgb8);
        while (p.SubscriberCount() == 0) std::this_thread::sleep_for(1ms);
        for (uint64_t i = 1; i <= 25; ++i) PublishImage(p, msgs::Encoding::kRgb8, i, 10 + c);
        char byte;
        // Stay alive until the parent saw every message (a dead publisher's queued messages are
        // reclaimed).
        if (read(fds[0], &byte, 1) != 1) status = 3;
      } catch (...) {
        status = 4;
      }
      _exit(status);
    }
    close(fds[0]);
    children.push_back(pid);
    release_pipes.push_back(fds[1]);
  }
  const bool all_received = WaitFor([&] {
    return Received(recorder, "/child0/image") == 25 && Received(recorder, "/child1/image") == 25;
  });
  for (int fd : release_pipes) {
    EXPECT_EQ(write(fd, "x", 1), 1);
    close(fd);
  }
  for (pid_t pid : children) {
    int status = 0;
    ASSERT_EQ(waitpid(pid, &status, 0), pid);
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << status;
  }
  ASSERT_TRUE(all_received);
  const record::RecorderStats stats = recorder.Stop();
  const auto read = ReadFiles(stats.files);
  ExpectImages(read.at("/child0/image"), msgs::Encoding::kRgb8, 25, 10);
  ExpectImages(read.at("/child1/image"), msgs::Encoding::kRgb8, 25, 11);
}

TEST_F(RecorderTest, TypesWithoutConverterAreRecordedRawOrSkipped) {
  const bus::TopicType blob{"test_msgs/Blob", 0x0123456789abcdefull};
  bus::PublisherOptions po;
  po.max_message_bytes = 256;
  po.slot_count = 80;
  bus::Publisher publisher("/raw/blob", blob, po);
  {
    record::RecorderOptions o = Options("skip");
    o.topics = {"/raw/blob"};
    o.record_raw = false;
    record::Recorder recorder(o);
    recorder.Start();
    EXPECT_TRUE(recorder.Stop().topics.empty());
    EXPECT_EQ(LogLines(), std::vector<std::string>{
                              "warning: skipping /raw/blob: type test_msgs/Blob has no ROS 2 "
                              "conversion"});
  }
  record::RecorderOptions o = Options("raw");
  o.topics = {"/raw/blob"};
  record::Recorder recorder(o);
  recorder.Start();
  std::vector<std::vector<std::byte>> sent;
  for (int i = 1; i <= 10; ++i) {
    std::vector<std::byte> bytes(static_cast<size_t>(i * 20));
    for (size_t j = 0; j < bytes.size(); ++j) bytes[j] = static_cast<std::byte>(i * 3 + j);
    publisher.PublishCopy(bytes);
    sent.push_back(bytes);
  }
  const record::RecorderStats stats = recorder.Stop();
  ASSERT_EQ(stats.topics.size(), 1u);
  EXPECT_EQ(stats.topics[0].encoding, "probeless");
  const auto read = ReadFiles(stats.files);
  ASSERT_EQ(read.at("/raw/blob").size(), 10u);
  for (size_t i = 0; i < 10; ++i) {
    EXPECT_EQ(read.at("/raw/blob")[i].data, sent[i]);
    EXPECT_EQ(read.at("/raw/blob")[i].sequence, i + 1);
  }
  log::McapReader reader(stats.files[0]);
  const log::Channel* channel = reader.FindChannelByTopic("/raw/blob");
  ASSERT_NE(channel, nullptr);
  EXPECT_EQ(channel->message_encoding, "probeless");
  EXPECT_EQ(channel->schema_id, 0);
  EXPECT_EQ(channel->metadata.at("probeless.type"), "test_msgs/Blob");
  EXPECT_EQ(channel->metadata.at("probeless.layout_hash"), "0x0123456789abcdef");
}

TEST_F(RecorderTest, InvalidMessagesAreCountedAndWarnedOnce) {
  bus::Publisher rgb = ImagePublisher("/bad/image", msgs::Encoding::kRgb8);
  record::RecorderOptions o = Options();
  o.topics = {"/bad/image"};
  record::Recorder recorder(o);
  recorder.Start();
  PublishImage(rgb, msgs::Encoding::kRgb8, 1, 7);
  for (int i = 0; i < 3; ++i) {
    bus::Loan loan = rgb.Borrow(sizeof(msgs::Image));  // no pixels for a 64x48 image
    auto out = msgs::WriteMessage<msgs::Image>(loan.data());
    out->header.StampNow();
    out->Init(kWidth, kHeight, msgs::Encoding::kRgb8);
    rgb.Publish(std::move(loan));
  }
  const record::RecorderStats stats = recorder.Stop();
  ASSERT_EQ(stats.topics.size(), 1u);
  EXPECT_EQ(stats.topics[0].received, 4u);
  EXPECT_EQ(stats.topics[0].invalid, 3u);
  EXPECT_EQ(stats.topics[0].written, 1u);
  ExpectImages(ReadFiles(stats.files).at("/bad/image"), msgs::Encoding::kRgb8, 1, 7);
  int warnings = 0;
  for (const std::string& line : LogLines()) {
    if (line.starts_with("warning: /bad/image: message 2 not recorded: ")) ++warnings;
  }
  EXPECT_EQ(warnings, 1);
}

TEST_F(RecorderTest, FileNames) {
  record::RecorderOptions o;
  o.output = "/data/run";
  EXPECT_EQ(record::RecordFileName(o, 0), "/data/run.mcap");
  o.output = "/data/run.mcap";
  EXPECT_EQ(record::RecordFileName(o, 0), "/data/run.mcap");
  o.split_bytes = 1000;
  EXPECT_EQ(record::RecordFileName(o, 0), "/data/run_0.mcap");
  EXPECT_EQ(record::RecordFileName(o, 12), "/data/run_12.mcap");
  o.split_bytes = 0;
  o.split_seconds = 1;
  o.output = "x";
  EXPECT_EQ(record::RecordFileName(o, 3), "x_3.mcap");
}

std::string OptionError(const std::function<void(record::RecorderOptions&)>& change) {
  record::RecorderOptions o;
  o.output = "/tmp/never";
  o.all = true;
  change(o);
  try {
    record::Recorder recorder(o);
  } catch (const record::RecordError& e) {
    return e.what();
  }
  return "no error";
}

TEST_F(RecorderTest, BadOptionsThrowOneLineMessages) {
  EXPECT_EQ(OptionError([](auto& o) { o.output.clear(); }),
            "no output given (expected a file name or prefix)");
  EXPECT_EQ(OptionError([](auto& o) { o.all = false; }),
            "no topics selected (expected topic names, a regex or all)");
  EXPECT_EQ(OptionError([](auto& o) { o.topics = {"camera"}; }),
            "invalid topic name 'camera': must start with '/' (expected e.g. /camera/image)");
  EXPECT_EQ(OptionError([](auto& o) { o.regex = "(a"; }).rfind("invalid include regex '(a': ", 0),
            0u);
  EXPECT_EQ(OptionError([](auto& o) { o.exclude = "[x"; }).rfind("invalid exclude regex '[x': ", 0),
            0u);
  EXPECT_EQ(OptionError([](auto& o) { o.queue_depth = 0; }),
            "queue_depth 0 out of range (expected 1..64)");
  EXPECT_EQ(OptionError([](auto& o) { o.queue_depth = 65; }),
            "queue_depth 65 out of range (expected 1..64)");
  EXPECT_EQ(OptionError([](auto& o) { o.chunk_size = 0; }),
            "chunk_size 0 out of range (expected > 0)");
  EXPECT_EQ(OptionError([](auto& o) { o.split_seconds = -1; }),
            "split_seconds -1.000000 out of range (expected >= 0)");
  EXPECT_EQ(OptionError([](auto& o) { o.buffer_bytes = 1000; }),
            "buffer_bytes 1000 out of range (expected >= 1048576)");
  EXPECT_EQ(OptionError([](auto& o) { o.discovery_period = 0s; }),
            "discovery_period out of range (expected > 0)");
  EXPECT_EQ(OptionError([](auto& o) { o.flush_period = -1s; }),
            "flush_period out of range (expected >= 0)");
}

TEST_F(RecorderTest, StartErrorsAndIdempotentStop) {
  record::RecorderOptions o = Options();
  o.output = dir_ + "/missing/dir/out";
  o.all = true;
  record::Recorder broken(o);
  try {
    broken.Start();
    FAIL() << "Start did not throw";
  } catch (const log::LogError& e) {
    EXPECT_EQ(std::string(e.what()).rfind(dir_ + "/missing/dir/out.mcap: ", 0), 0u) << e.what();
  }
  record::RecorderOptions ok = Options();
  ok.all = true;
  record::Recorder recorder(ok);
  recorder.Start();
  try {
    recorder.Start();
    FAIL() << "second Start did not throw";
  } catch (const record::RecordError& e) {
    EXPECT_STREQ(e.what(), "recorder already started");
  }
  EXPECT_FALSE(recorder.Failed());
  const auto first = recorder.Stop();
  const auto second = recorder.Stop();
  EXPECT_EQ(first.files, second.files);
  log::McapReader reader(first.files[0]);
  EXPECT_FALSE(reader.truncated());
  EXPECT_EQ(reader.statistics().message_count, 0u);
}

TEST(RecorderReportTest, OneLinePerTopicAndFileThenTheSums) {
  record::RecorderStats stats;
  record::TopicStats image;
  image.topic = "/camera/image";
  image.received = 40;
  image.dropped = 2;
  image.invalid = 1;
  image.bytes = 1000;
  record::TopicStats depth = image;
  depth.topic = "/camera/depth";
  depth.dropped = 0;
  stats.topics = {depth, image};
  stats.files = {"a_0.mcap", "a_1.mcap"};
  stats.bytes = 2000;
  EXPECT_EQ(record::RecorderReport(stats),
            "/camera/depth: received=40 dropped=0 invalid=1 bytes=1000\n"
            "/camera/image: received=40 dropped=2 invalid=1 bytes=1000\n"
            "file: a_0.mcap\nfile: a_1.mcap\n"
            "summary: topics=2 received=80 dropped=2 bytes=2000 files=2\n");
}

}  // namespace
