// Record-and-replay through the real binaries: `probeless bag convert|info|play` on a dataset
// folder written by the test (and on the shared 7-Scenes frames), a log cut short, clear errors
// for bad input, and a recorded-stream source driving a slow node under test in lock-step inside a
// launch file — every frame, in order, identical across runs.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "probeless/bus/bus.h"
#include "probeless/launch/proc_stat.h"
#include "probeless/msgs/msgs.h"
#include "probeless/testing/testing.h"

namespace {

namespace fs = std::filesystem;
using namespace probeless;
using ::testing::HasSubstr;
using namespace std::chrono_literals;

const std::string kBin = PROBELESS_BIN_DIR;
const std::string kProbe = PROBELESS_TEST_BIN_DIR "/replay_probe";
const std::string kLaunchFile = PROBELESS_SOURCE_DIR "/tests/replay/lockstep.launch.yaml";

using Result = probeless::testing::CommandResult;
using probeless::testing::ReadText;

std::string FirstLine(const std::string& text) { return text.substr(0, text.find('\n')); }

class ReplayIntegrationTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("probeless_replay_it_" + std::to_string(getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  // Runs a shell command line (no stdin), capturing stdout and stderr.
  Result Run(const std::string& command) { return probeless::testing::RunCommand(command, dir_); }

  // A folder of `count` 16x8 8-bit PGM images; image i is filled with the value 10 * i.
  fs::path WriteImageFolder(int count) {
    const fs::path folder = dir_ / "images";
    fs::create_directories(folder);
    for (int i = 0; i < count; ++i) {
      char name[32];
      std::snprintf(name, sizeof(name), "img_%03d.pgm", i);
      std::ofstream f(folder / name, std::ios::binary);
      f << "P5\n16 8\n255\n" << std::string(16 * 8, static_cast<char>(10 * i));
    }
    return folder;
  }

  // Records `topics` with `probeless bag record` (the recorder node) while `probeless bag play`
  // publishes `source`; stops the recorder with SIGINT and returns `probeless bag info` of the log.
  Result RecordWhilePlaying(const std::string& source, const std::string& play_args,
                            const std::vector<std::string>& topics) {
    const fs::path recorded = dir_ / "recorded.mcap";
    const pid_t recorder = fork();
    if (recorder == 0) {
      const std::string probeless = kBin + "/probeless";
      std::vector<std::string> words = {probeless, "bag", "record", "-o", recorded.string()};
      words.insert(words.end(), topics.begin(), topics.end());
      std::vector<char*> argv;
      for (auto& w : words) argv.push_back(w.data());
      argv.push_back(nullptr);
      execv(probeless.c_str(), argv.data());
      _exit(127);
    }
    struct Reaper {  // the recorder never outlives the test, whatever fails
      pid_t pid;
      ~Reaper() {
        if (pid > 0 && kill(pid, SIGKILL) == 0) waitpid(pid, nullptr, 0);
      }
    } reaper{recorder};
    // While it waits for its topics to appear, an idle recorder uses (almost) no CPU.
    std::this_thread::sleep_for(1s);
    auto cpu_seconds = [](pid_t pid) {
      const std::optional<probeless::launch::ProcStat> stat = probeless::launch::ReadProcStat(pid);
      EXPECT_TRUE(stat.has_value()) << "the recorder (pid " << pid << ") is gone";
      return stat ? stat->CpuSeconds() : 0.0;
    };
    const double idle_cpu = cpu_seconds(recorder);
    std::this_thread::sleep_for(1s);
    EXPECT_LT(cpu_seconds(recorder) - idle_cpu, 0.2) << "the idle recorder spins";
    // The player creates its publishers, then waits 1 s: the recorder discovers the topics (every
    // 250 ms) and subscribes before the first image.
    Result r = Run(kBin + "/probeless bag play " + source + " --rate 5 --delay 1 --no-keyboard " +
                   play_args);
    if (r.code != 0) {
      ADD_FAILURE() << "bag play failed: " << r.err;
      return r;
    }
    std::this_thread::sleep_for(300ms);
    kill(recorder, SIGINT);
    int status = 0;
    waitpid(recorder, &status, 0);
    reaper.pid = 0;
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "recorder status " << status;
    return Run(kBin + "/probeless bag info " + recorded.string());
  }

  fs::path dir_;
};

TEST_F(ReplayIntegrationTest, ConvertInfoAndPlayAFolder) {
  const fs::path folder = WriteImageFolder(12);
  const fs::path log = dir_ / "images.mcap";
  Result r = Run(kBin + "/probeless bag convert " + folder.string() + " " + log.string() +
                 " --fps 20 --chunk-size 512");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("24 messages"));  // 12 images + 12 camera infos
  // The reference Python reader (PyPI mcap, mcap-ros2-support; tools/setup installs them) decodes
  // every message.
  r = Run("python3 " PROBELESS_SOURCE_DIR "/tests/replay/read_mcap.py " + log.string());
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(r.out,
            "/camera/camera_info 12 sensor_msgs/msg/CameraInfo\n"
            "/camera/image 12 sensor_msgs/msg/Image\n");

  r = Run(kBin + "/probeless bag info " + log.string());
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("state:     complete"));
  EXPECT_THAT(r.out, HasSubstr("messages:  24"));
  EXPECT_THAT(r.out, HasSubstr("duration:  0.550 s"));
  EXPECT_THAT(r.out,
              ::testing::ContainsRegex("/camera/image +12 msgs +20.00 Hz +sensor_msgs/msg/Image"));
  EXPECT_THAT(r.out, HasSubstr("sensor_msgs/msg/CameraInfo"));

  // A log whose writer died: cut it in the middle of the data.
  const fs::path cut = dir_ / "cut.mcap";
  {
    const std::string bytes = ReadText(log);
    std::ofstream(cut, std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  }
  r = Run(kBin + "/probeless bag info " + cut.string());
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("TRUNCATED"));
  EXPECT_THAT(r.out,
              ::testing::ContainsRegex("recovered [0-9]+ messages in [0-9]+ complete chunks"));

  // Play it back into a subscriber of this process that drains it on a thread (a subscriber that
  // does not take would lose frames once the player's 8 slots are all queued).
  bus::Subscriber images("/replayed/image", msgs::TopicTypeOf<msgs::Image>(), {.queue_depth = 64});
  std::vector<int> values;
  std::atomic<bool> stop{false};
  std::thread drain([&] {
    while (!stop) {
      if (auto sample = images.Take(10ms)) {
        const auto image = msgs::ReadMessage<msgs::Image>(sample->data());
        EXPECT_EQ(image->width, 16u);
        EXPECT_EQ(image->encoding, msgs::Encoding::kMono8);
        values.push_back(static_cast<int>(image.payload[5]));
      }
    }
  });
  r = Run(kBin + "/probeless bag play " + log.string() +
          " --rate 4 --delay 0.3 --no-keyboard --remap /camera/image:=/replayed/image");
  std::this_thread::sleep_for(100ms);
  stop = true;
  drain.join();
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("player: published 24 messages"));
  std::vector<int> expected;
  for (int i = 0; i < 12; ++i) expected.push_back(10 * i);
  EXPECT_EQ(values, expected);
}

// `probeless bag record` records what `probeless bag play` publishes, from a folder and from a
// simulator scenario (the synthetic world's stream through the bus and the recorder).
TEST_F(ReplayIntegrationTest, RecordWhatIsPlayed) {
  const Result r = RecordWhilePlaying(WriteImageFolder(10).string(), "",
                                      {"/camera/image", "/camera/camera_info"});
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("state:     complete"));
  EXPECT_THAT(r.out, ::testing::ContainsRegex("/camera/image +10 msgs"));
  EXPECT_THAT(r.out, ::testing::ContainsRegex("/camera/camera_info +10 msgs"));
}

TEST_F(ReplayIntegrationTest, RecordWhatTheSimulatorPublishes) {
  const Result r = RecordWhilePlaying(
      PROBELESS_SOURCE_DIR "/data/scenarios/face_orbit.yaml", "--max-frames 6",
      {"/camera/image", "/camera/depth", "/groundtruth/light", "/groundtruth/pose"});
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("state:     complete"));
  for (const char* topic : {"/camera/image", "/camera/depth", "/groundtruth/pose"}) {
    EXPECT_THAT(r.out, ::testing::ContainsRegex(std::string(topic) + " +6 msgs")) << r.out;
  }
  EXPECT_THAT(r.out, ::testing::ContainsRegex("/groundtruth/light +[1-6] msgs")) << r.out;
}

TEST_F(ReplayIntegrationTest, BadInputGivesOneLineErrorsAndExitCode2) {
  Result r = Run(kBin + "/probeless bag info /nonexistent/x.mcap");
  EXPECT_EQ(r.code, 2);
  EXPECT_THAT(r.err, HasSubstr("/nonexistent/x.mcap"));
  r = Run(kBin + "/probeless bag play /nonexistent/folder --no-keyboard");
  EXPECT_EQ(r.code, 2);
  EXPECT_THAT(r.err, HasSubstr("[error] [player]"));
  EXPECT_THAT(r.err, HasSubstr("/nonexistent/folder"));
  r = Run(kBin + "/probeless bag play " + WriteImageFolder(2).string() + " --rate fast");
  EXPECT_EQ(r.code, 2);
  EXPECT_THAT(r.err, HasSubstr("--rate expects a number, got 'fast'"));
  r = Run(kBin + "/probeless bag convert only_one_argument");
  EXPECT_EQ(r.code, 2);
  EXPECT_THAT(r.err, HasSubstr("convert takes SOURCE and OUT.mcap"));
  // Numbers are parsed whole and range-checked (parse::ParseInteger): issue #22's three cases.
  const std::string folder = WriteImageFolder(2).string();
  const std::string out = (dir_ / "bad.mcap").string();
  r = Run(kBin + "/probeless bag convert " + folder + " " + out +
          " --chunk-size 99999999999999999999");
  EXPECT_EQ(r.code, 2);
  EXPECT_EQ(FirstLine(r.err),
            "probeless bag: convert: --chunk-size expects a positive integer up to "
            "18446744073709551615, got '99999999999999999999'");
  r = Run(kBin + "/probeless bag convert " + folder + " " + out + " --chunk-size -1");
  EXPECT_EQ(r.code, 2);
  EXPECT_EQ(FirstLine(r.err),
            "probeless bag: convert: --chunk-size expects a positive integer, got '-1'");
  r = Run(kBin + "/probeless bag convert " + folder + " " + out + " --max-frames 12abc");
  EXPECT_EQ(r.code, 2);
  EXPECT_EQ(FirstLine(r.err),
            "probeless bag: convert: --max-frames expects a non-negative integer, got '12abc'");
  r = Run(kBin + "/probeless bag convert " + folder + " " + out + " --fps 0");
  EXPECT_EQ(r.code, 2);
  EXPECT_EQ(FirstLine(r.err), "probeless bag: convert: --fps expects a positive number, got '0'");
  r = Run(kBin + "/probeless bag convert " + folder + " " + out + " --fps");
  EXPECT_EQ(r.code, 2);
  EXPECT_EQ(FirstLine(r.err), "probeless bag: convert: --fps needs a value");
  EXPECT_FALSE(fs::exists(out));
  r = Run(kBin + "/probeless bag frobnicate");
  EXPECT_EQ(r.code, 2);
  EXPECT_THAT(r.err, HasSubstr("unknown command 'frobnicate'"));
}

// Runs the lock-step launch file on `source`; returns the probe's lines.
std::vector<std::string> RunLockstep(ReplayIntegrationTest* test, const fs::path& dir,
                                     const std::string& source, const std::string& name,
                                     Result* result) {
  const fs::path output = dir / (name + ".txt");
  fs::remove(output);
  const std::string cmd = kBin + "/probeless launch " + kLaunchFile + " source:=" + source +
                          " probe:=" + kProbe + " output:=" + output.string() + " delay_ms:=5";
  const fs::path out = dir / (name + ".log");
  const int status = std::system((cmd + " < /dev/null > " + out.string() + " 2>&1").c_str());
  result->code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  result->out = ReadText(out);
  std::vector<std::string> lines;
  std::ifstream in(output);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

// `frames` lines with increasing sequence numbers (images from an MCAP log carry none: ROS 2
// images have no sequence field, so they read 0 and only the count is checked).
void ExpectEveryFrameInOrder(const std::vector<std::string>& lines, size_t frames,
                             bool sequenced = true) {
  ASSERT_EQ(lines.size(), frames);
  if (!sequenced) return;
  uint64_t previous = 0;
  for (const auto& line : lines) {
    const uint64_t sequence = std::stoull(line.substr(0, line.find(' ')));
    EXPECT_GT(sequence, previous) << line;
    previous = sequence;
  }
}

TEST_F(ReplayIntegrationTest, LockStepThroughASlowNodeInALaunchFileIsCompleteAndDeterministic) {
  const fs::path folder = WriteImageFolder(60);
  Result first;
  Result second;
  const auto a = RunLockstep(this, dir_, folder.string(), "first", &first);
  ASSERT_EQ(first.code, 0) << first.out;
  ExpectEveryFrameInOrder(a, 60);
  const auto b = RunLockstep(this, dir_, folder.string(), "second", &second);
  ASSERT_EQ(second.code, 0) << second.out;
  EXPECT_EQ(a, b);
}

TEST_F(ReplayIntegrationTest, SevenScenesConvertsAndReplaysInLockStep) {
  const char* env = std::getenv("PROBELESS_DATA");
  const fs::path data = fs::path(env != nullptr ? env : PROBELESS_DATA_DIR) / "7scenes-redkitchen";
  if (!fs::exists(data / "camera-intrinsics.txt")) {
    GTEST_SKIP() << "shared 7-Scenes frames not found at " << data
                 << " (set PROBELESS_DATA to the shared data folder)";
  }
  const fs::path log = dir_ / "redkitchen.mcap";
  Result r = Run(kBin + "/probeless bag convert " + data.string() + " " + log.string() +
                 " --compression lz4");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("1200 messages"));  // image, depth, camera info, pose x 300
  r = Run(kBin + "/probeless bag info " + log.string());
  EXPECT_THAT(r.out, ::testing::ContainsRegex("/camera/depth +300 msgs"));
  EXPECT_THAT(r.out, ::testing::ContainsRegex("/groundtruth/pose +300 msgs"));

  // The folder and its log, each replayed twice through the slow node: all 300 frames, in order,
  // and the same pixels every time.
  Result run;
  const auto from_folder = RunLockstep(this, dir_, data.string(), "folder1", &run);
  ASSERT_EQ(run.code, 0) << run.out;
  ExpectEveryFrameInOrder(from_folder, 300);
  EXPECT_EQ(RunLockstep(this, dir_, data.string(), "folder2", &run), from_folder);
  const auto from_log = RunLockstep(this, dir_, log.string(), "log1", &run);
  ASSERT_EQ(run.code, 0) << run.out;
  ExpectEveryFrameInOrder(from_log, 300, /*sequenced=*/false);
  EXPECT_EQ(RunLockstep(this, dir_, log.string(), "log2", &run), from_log);
  // The log keeps the pixels: the same hashes in the same order as from the folder.
  ASSERT_EQ(from_log.size(), from_folder.size());
  for (size_t i = 0; i < from_log.size(); ++i) {
    EXPECT_EQ(from_log[i].substr(from_log[i].find(' ')),
              from_folder[i].substr(from_folder[i].find(' ')))
        << "frame " << i;
  }
}

}  // namespace
