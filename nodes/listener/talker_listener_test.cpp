// Process test of the example nodes: bin/talker and bin/listener talk over the bus, honour their
// params and remaps, stop cleanly on SIGINT with a summary, and leave nothing in /dev/shm.
#include <gtest/gtest.h>
#include <signal.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "probeless/bus/bus.h"
#include "probeless/testing/testing.h"

namespace {

using namespace std::chrono_literals;

// Expectations below assume the default log level: ignore the developer's environment.
[[maybe_unused]] const bool kEnvironmentCleared = (unsetenv("PROBELESS_LOG_LEVEL"), true);

using probeless::testing::Process;

std::vector<std::string> Segments() {
  const std::string prefix =
      "probeless." + std::to_string(getuid()) + "." + probeless::bus::CurrentDomain() + ".";
  std::vector<std::string> names;
  for (const auto& entry : std::filesystem::directory_iterator("/dev/shm")) {
    const std::string name = entry.path().filename().string();
    if (name.starts_with(prefix)) names.push_back(name);
  }
  return names;
}

class TalkerListenerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    probeless::bus::CleanDeadSegments();
    ASSERT_TRUE(Segments().empty());
  }
  void TearDown() override { EXPECT_EQ(Segments(), std::vector<std::string>{}); }
};

TEST_F(TalkerListenerTest, CountedRunDeliversEverythingWithRemapsAndParams) {
  Process listener("listener", {"--ros-args", "-r", "__ns:=/demo", "-r", "chatter:=/cam/image",
                                "-p", "count:=5"});
  Process talker("talker",
                 {"--ros-args", "-r", "__ns:=/demo", "-r", "chatter:=/cam/image", "-p", "count:=5",
                  "-p", "rate_hz:=50", "-p", "width:=320", "-p", "height:=240", "-p",
                  "encoding:=depth16", "-p", "wait_for_subscribers:=1"});
  EXPECT_EQ(talker.Wait(), 0) << talker.Err();
  EXPECT_EQ(listener.Wait(), 0) << listener.Err();
  EXPECT_EQ(talker.Out(), "summary: published=5\n");
  EXPECT_EQ(listener.Out(), "summary: received=5 dropped=0 gaps=0 invalid=0 last=5\n");
  const std::string log = listener.Err();
  EXPECT_NE(log.find("[info] [/demo/listener] listening on /cam/image\n"), std::string::npos)
      << log;
  for (int i = 1; i <= 5; ++i) {
    EXPECT_NE(log.find("received #" + std::to_string(i) + " (320x240 depth16 (step 640)"),
              std::string::npos)
        << log;
  }
}

TEST_F(TalkerListenerTest, SigintStopsBothWithSummaries) {
  Process listener("listener", {});
  Process talker("talker", {"--ros-args", "-p", "rate_hz:=100.0", "-p", "width:=64", "-p",
                            "height:=48", "-p", "wait_for_subscribers:=1"});
  std::this_thread::sleep_for(500ms);
  const auto start = std::chrono::steady_clock::now();
  talker.Signal(SIGINT);
  listener.Signal(SIGINT);
  EXPECT_EQ(talker.Wait(), 0) << talker.Err();
  EXPECT_EQ(listener.Wait(), 0) << listener.Err();
  EXPECT_LT(std::chrono::steady_clock::now() - start, 1s);
  long long published = -1, received = -1;
  ASSERT_EQ(std::sscanf(talker.Out().c_str(), "summary: published=%lld", &published), 1)
      << talker.Out();
  ASSERT_EQ(std::sscanf(listener.Out().c_str(), "summary: received=%lld", &received), 1)
      << listener.Out();
  EXPECT_GT(published, 10);
  EXPECT_GT(received, 10);
  EXPECT_LE(received, published);
  EXPECT_NE(listener.Out().find(" invalid=0 "), std::string::npos) << listener.Out();
}

TEST_F(TalkerListenerTest, BadParamsFailWithOneLine) {
  Process talker("talker", {"--ros-args", "-p", "rate_hz:=fast"});
  EXPECT_EQ(talker.Wait(), 1);
  EXPECT_EQ(talker.Err(),
            "[error] [talker] node '/talker': parameter 'rate_hz' has type string (value "
            "\"fast\", from -p), expected double\n");
}

}  // namespace
