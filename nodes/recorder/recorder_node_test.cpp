// Process test of bin/recorder: records topics published from this test, SIGINT/SIGTERM close the
// file (footer written, not truncated), the drop report is printed, bad options exit 2 with one
// line.
#include <gtest/gtest.h>
#include <signal.h>
#include <stdlib.h>
#include <sys/resource.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <thread>
#include <vector>

#include "probeless/bus/bus.h"
#include "probeless/log/mcap_reader.h"
#include "probeless/log/ros2.h"
#include "probeless/msgs/image.h"
#include "probeless/testing/testing.h"

namespace {

using namespace std::chrono_literals;
namespace bus = probeless::bus;
namespace log = probeless::log;
namespace msgs = probeless::msgs;

[[maybe_unused]] const bool kEnvironmentCleared = (unsetenv("PROBELESS_LOG_LEVEL"), true);

constexpr uint32_t kWidth = 32;
constexpr uint32_t kHeight = 24;

using probeless::testing::Process;

bool WaitFor(const std::function<bool()>& done) {
  const auto deadline = std::chrono::steady_clock::now() + 20s;
  while (!done()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(2ms);
  }
  return true;
}

bus::Publisher ImagePublisher(const std::string& topic, msgs::Encoding encoding) {
  bus::PublisherOptions options;
  options.max_message_bytes = msgs::Image::MessageBytesFor(kWidth, kHeight, encoding);
  options.slot_count = 80;
  return bus::Publisher(topic, msgs::TopicTypeOf<msgs::Image>(), options);
}

void PublishImage(bus::Publisher& publisher, msgs::Encoding encoding, uint64_t index) {
  bus::Loan loan = publisher.Borrow(msgs::Image::MessageBytesFor(kWidth, kHeight, encoding));
  auto out = msgs::WriteMessage<msgs::Image>(loan.data());
  out->header.StampNow();
  out->header.sequence = index;
  out->Init(kWidth, kHeight, encoding);
  for (size_t j = 0; j < out->PayloadBytes(); ++j) {
    out.payload[j] = static_cast<std::byte>((j + index * 3) & 0xff);
  }
  publisher.Publish(std::move(loan));
}

// Checks that `path` is complete and holds images 1..count on `topic`, byte for byte, in order;
// returns the total CDR bytes.
uint64_t ExpectRecorded(const std::string& path, const std::string& topic, uint64_t count) {
  log::McapReader reader(path);
  EXPECT_FALSE(reader.truncated()) << reader.recovery().detail;
  log::ReadOptions select;
  select.topics = {topic};
  log::MessageCursor cursor = reader.Messages(select);
  log::MessageView m;
  uint64_t n = 0;
  uint64_t bytes = 0;
  const log::Ros2Converter& converter = log::Ros2ConverterFor<msgs::Image>();
  while (cursor.Next(m)) {
    ++n;
    bytes += m.data.size();
    EXPECT_EQ(m.sequence, n);
    log::MessageBuffer decoded = log::DecodeRos2(converter, m.data);
    auto in = msgs::ReadMessage<msgs::Image>(decoded.bytes());
    size_t mismatches = 0;
    for (size_t j = 0; j < in->PayloadBytes(); ++j) {
      mismatches += in.payload[j] != static_cast<std::byte>((j + n * 3) & 0xff);
    }
    EXPECT_EQ(mismatches, 0u) << topic << " message " << n;
  }
  EXPECT_EQ(n, count) << topic;
  return bytes;
}

class RecorderNodeTest : public ::testing::Test {
 protected:
  void SetUp() override {
    bus::CleanDeadSegments();
    char pattern[] = "/tmp/probeless_recorder_node_XXXXXX";
    ASSERT_NE(mkdtemp(pattern), nullptr);
    dir_ = pattern;
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string dir_;
};

TEST_F(RecorderNodeTest, CommandLineRecordingStopsCleanlyOnSigintWithReport) {
  bus::Publisher rgb = ImagePublisher("/rec/image", msgs::Encoding::kRgb8);
  bus::Publisher depth = ImagePublisher("/rec/depth", msgs::Encoding::kDepth16);
  bus::Publisher other = ImagePublisher("/other", msgs::Encoding::kMono8);
  const std::string file = dir_ + "/out.mcap";
  Process recorder("recorder", {"-o", file, "--compression", "lz4", "/rec/image", "/rec/depth"});
  ASSERT_TRUE(WaitFor([&] { return rgb.SubscriberCount() == 1 && depth.SubscriberCount() == 1; }))
      << recorder.Err();
  for (uint64_t i = 1; i <= 30; ++i) {
    PublishImage(rgb, msgs::Encoding::kRgb8, i);
    PublishImage(depth, msgs::Encoding::kDepth16, i);
    PublishImage(other, msgs::Encoding::kMono8, i);
  }
  recorder.Signal(SIGINT);  // what is still queued on the bus is recorded before closing
  ASSERT_EQ(recorder.Wait(20s), 0) << recorder.Err();
  EXPECT_EQ(other.SubscriberCount(), 0u);
  const uint64_t image_bytes = ExpectRecorded(file, "/rec/image", 30);
  const uint64_t depth_bytes = ExpectRecorded(file, "/rec/depth", 30);
  EXPECT_EQ(
      recorder.Out(),
      "/rec/depth: received=30 dropped=0 invalid=0 bytes=" + std::to_string(depth_bytes) +
          "\n/rec/image: received=30 dropped=0 invalid=0 bytes=" + std::to_string(image_bytes) +
          "\nfile: " + file + "\nsummary: topics=2 received=60 dropped=0 bytes=" +
          std::to_string(image_bytes + depth_bytes) + " files=1\n");
  const std::string err = recorder.Err();
  EXPECT_NE(err.find("[info] [/recorder] recording to " + file + "\n"), std::string::npos) << err;
  EXPECT_NE(err.find("[info] [/recorder] recording /rec/image (probeless_msgs/Image as "
                     "sensor_msgs/msg/Image cdr)\n"),
            std::string::npos)
      << err;
}

TEST_F(RecorderNodeTest, ParamsSplitBySizeAndSigterm) {
  bus::Publisher rgb = ImagePublisher("/p/image", msgs::Encoding::kRgb8);  // 2,304 B of pixels
  const std::string prefix = dir_ + "/run";
  Process recorder("recorder", {"--ros-args", "-p", "all:=true", "-p", "output:=" + prefix, "-p",
                                "split_size_mb:=0.02", "-p", "chunk_size_mb:=0.01", "-p",
                                "compression:=none", "-p", "queue_depth:=64"});
  ASSERT_TRUE(WaitFor([&] { return rgb.SubscriberCount() == 1; })) << recorder.Err();
  for (uint64_t i = 1; i <= 40; ++i) PublishImage(rgb, msgs::Encoding::kRgb8, i);
  recorder.Signal(SIGTERM);
  ASSERT_EQ(recorder.Wait(20s), 0) << recorder.Err();
  const std::string out = recorder.Out();
  EXPECT_EQ(out.rfind("/p/image: received=40 dropped=0 invalid=0 bytes=", 0), 0u) << out;
  // Every file is complete; their union is messages 1..40 in order.
  uint64_t next = 1;
  int files = 0;
  for (;; ++files) {
    const std::string path = prefix + "_" + std::to_string(files) + ".mcap";
    if (!std::filesystem::exists(path)) break;
    EXPECT_NE(out.find("file: " + path + "\n"), std::string::npos) << out;
    log::McapReader reader(path);
    EXPECT_FALSE(reader.truncated()) << path;
    log::MessageCursor cursor = reader.Messages();
    log::MessageView m;
    while (cursor.Next(m)) EXPECT_EQ(m.sequence, next++);
  }
  EXPECT_GE(files, 3);
  EXPECT_EQ(next, 41u);
  EXPECT_NE(out.find(" files=" + std::to_string(files) + "\n"), std::string::npos) << out;
}

// The disk filling up mid-recording: RLIMIT_FSIZE makes write() fail with EFBIG as a full disk
// fails it with ENOSPC (the child inherits the limit and the ignored SIGXFSZ, both restored here
// right after the spawn). The recorder stops by itself with one error line and exit 1, prints its
// report, and the file opens, recovering every complete chunk in order.
TEST_F(RecorderNodeTest, AFullDiskEndsWithOneErrorAndARecoverableFile) {
  bus::Publisher rgb = ImagePublisher("/full/image", msgs::Encoding::kRgb8);  // 2,304 B of pixels
  const std::string file = dir_ + "/full.mcap";
  rlimit saved{};
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &saved), 0);
  rlimit limit = saved;
  limit.rlim_cur = 64 * 1024;
  struct sigaction ignore {};
  struct sigaction previous {};
  ignore.sa_handler = SIG_IGN;
  ASSERT_EQ(sigaction(SIGXFSZ, &ignore, &previous), 0);
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &limit), 0);
  Process recorder(
      "recorder", {"-o", file, "--compression", "none", "--chunk-size-mb", "0.005", "/full/image"});
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &saved), 0);
  ASSERT_EQ(sigaction(SIGXFSZ, &previous, nullptr), 0);
  ASSERT_TRUE(WaitFor([&] { return rgb.SubscriberCount() == 1; })) << recorder.Err();
  for (uint64_t i = 1; i <= 100; ++i) {
    PublishImage(rgb, msgs::Encoding::kRgb8, i);
    std::this_thread::sleep_for(1ms);  // no bus drops: every message reaches the writer
  }
  ASSERT_EQ(recorder.Wait(20s), 1) << recorder.Err();
  const std::string err = recorder.Err();
  EXPECT_NE(err.find("[error] [/recorder] recording failed: " + file + ": offset "),
            std::string::npos)
      << err;
  EXPECT_NE(err.find(": write failed: File too large\n"), std::string::npos) << err;
  EXPECT_EQ(err.find("[error]"), err.rfind("[error]")) << "one error line:\n" << err;
  EXPECT_NE(recorder.Out().find("\nsummary: topics=1 "), std::string::npos) << recorder.Out();
  EXPECT_LE(std::filesystem::file_size(file), 64u * 1024u);
  log::McapReader reader(file);
  EXPECT_TRUE(reader.truncated());
  log::MessageCursor cursor = reader.Messages();
  log::MessageView m;
  uint64_t n = 0, last = 0;
  while (cursor.Next(m)) {
    EXPECT_GT(m.sequence, last);  // in order (a loaded machine may drop on the bus, not here)
    last = m.sequence;
    ++n;
  }
  EXPECT_GE(n, 10u) << "the complete chunks before the limit";
  EXPECT_LT(n, 100u);
}

// Runs the recorder with `args`; expects exit 2 and exactly `error` on stderr.
void ExpectUsageError(std::vector<std::string> args, const std::string& error) {
  Process recorder("recorder", std::move(args));
  EXPECT_EQ(recorder.Wait(20s), 2);
  EXPECT_EQ(recorder.Err(), "[error] [/recorder] " + error + "\n");
  EXPECT_EQ(recorder.Out(), "");
}

TEST_F(RecorderNodeTest, BadOptionsExitTwoWithOneLine) {
  const std::string out = dir_ + "/x";
  ExpectUsageError({"-o", out}, "no topics selected (expected topic names, a regex or all)");
  ExpectUsageError({"-o", out, "--all", "--compression", "brotli"},
                   "unknown compression 'brotli' (expected none, zstd or lz4)");
  ExpectUsageError({"-o", out, "--all", "--bogus"}, "unknown option '--bogus' (see --help)");
  ExpectUsageError({"-o", out, "--all", "--split-size-mb", "big"},
                   "--split-size-mb expects a number, got 'big'");
  ExpectUsageError({"-o", out, "--all", "--queue-depth"}, "--queue-depth needs a value N");
  ExpectUsageError({"-o", out, "--regex", "(a"},
                   "invalid include regex '(a': Mismatched '(' and ')' in regular expression");
  ExpectUsageError(
      {"-o", out, "/bad name"},
      "node '/recorder': invalid topic name '/bad name' (expected segments of letters, "
      "digits and '_' not starting with a digit, separated by single '/', optionally "
      "starting with '/' or '~/')");
  ExpectUsageError({"--all", "--ros-args", "-p", "queue_depth:=0", "-p", "output:=" + out},
                   "queue_depth 0 out of range (expected 1..64)");
  ExpectUsageError({"--all", "-o", dir_ + "/missing/out"},
                   dir_ + "/missing/out.mcap: cannot create: No such file or directory");
}

TEST_F(RecorderNodeTest, HelpPrintsUsage) {
  Process recorder("recorder", {"--help"});
  EXPECT_EQ(recorder.Wait(20s), 0);
  EXPECT_EQ(recorder.Out().rfind("usage: recorder ", 0), 0u) << recorder.Out();
}

}  // namespace
