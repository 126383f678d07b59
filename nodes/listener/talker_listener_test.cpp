// Process test of the example nodes: bin/talker and bin/listener talk over the bus, honour their
// params and remaps, stop cleanly on SIGINT with a summary, and leave nothing in /dev/shm.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "probeless/bus/bus.h"

extern char** environ;

namespace {

using namespace std::chrono_literals;

// Expectations below assume the default log level: ignore the developer's environment.
[[maybe_unused]] const bool kEnvironmentCleared = (unsetenv("PROBELESS_LOG_LEVEL"), true);

// A child process whose stdout and stderr go to files.
class Process {
 public:
  Process(const std::string& exe, std::vector<std::string> args) {
    static int counter = 0;
    const std::string base =
        "/tmp/probeless_tl_" + std::to_string(getpid()) + "_" + std::to_string(counter++);
    out_path_ = base + ".out";
    err_path_ = base + ".err";
    args.insert(args.begin(), std::string(PROBELESS_BIN_DIR) + "/" + exe);
    std::vector<char*> argv;
    for (std::string& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, out_path_.c_str(),
                                     O_WRONLY | O_CREAT | O_TRUNC, 0600);
    posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, err_path_.c_str(),
                                     O_WRONLY | O_CREAT | O_TRUNC, 0600);
    const int rc = posix_spawn(&pid_, argv[0], &actions, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    EXPECT_EQ(rc, 0) << "cannot start " << argv[0];
  }
  ~Process() {
    if (pid_ > 0) {
      kill(pid_, SIGKILL);
      Wait();
    }
    std::filesystem::remove(out_path_);
    std::filesystem::remove(err_path_);
  }
  void Signal(int signal_number) const { kill(pid_, signal_number); }
  // Waits for the exit (at most `timeout`, then SIGKILL) and returns the exit code (-1 if killed).
  int Wait(std::chrono::milliseconds timeout = 10s) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    int status = 0;
    while (waitpid(pid_, &status, WNOHANG) == 0) {
      if (std::chrono::steady_clock::now() > deadline) {
        kill(pid_, SIGKILL);
        waitpid(pid_, &status, 0);
        break;
      }
      std::this_thread::sleep_for(5ms);
    }
    pid_ = -1;
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  }
  std::string Out() const { return Read(out_path_); }
  std::string Err() const { return Read(err_path_); }

 private:
  static std::string Read(const std::string& path) {
    std::ifstream in(path);
    std::stringstream text;
    text << in.rdbuf();
    return text.str();
  }
  pid_t pid_ = -1;
  std::string out_path_;
  std::string err_path_;
};

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
