// capture_v4l2 through its real streaming code, without a camera: the node binary runs with the
// V4L2 stand-in (v4l2_standin.cpp, LD_PRELOAD) serving recordings this test writes with OpenCV
// from fixed seeds. The stand-in's event log (CLOCK_MONOTONIC) and the node's bus output are
// compared: frames arrive intact (YUYV exactly as the library converts the recorded bytes, MJPEG
// exactly as it decodes the recorded JPEG, both within a small tolerance of OpenCV), stamps are
// the buffers' timestamps, exposure / white balance / gain are locked after 2 s of auto, unplug
// is detected within 1 s and the node reopens on replug, a busy device is retried without leaks,
// corrupt MJPEG frames and buffers the driver flags as erroneous are dropped with a warning while
// the stream goes on, and a stream of nothing but corrupt frames ends the node.
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <mutex>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <set>
#include <sstream>
#include <thread>

#include "probeless/bus/bus.h"
#include "probeless/capture/convert.h"
#include "probeless/msgs/msgs.h"
#include "probeless/testing/testing.h"

extern char** environ;

namespace {

namespace fs = std::filesystem;
using namespace probeless;
using namespace std::chrono_literals;
using probeless::testing::ReadText;

const std::string kBin = PROBELESS_BIN_DIR;
const std::string kStandin = PROBELESS_V4L2_STANDIN_LIBRARY;
constexpr int kWidth = 640;
constexpr int kHeight = 480;
constexpr int kRecordedFrames = 5;
// The node's frame period at 30 fps and its stamp for a start-of-exposure buffer timestamp
// without exposure_time_us: + half an exposure taken as half a period (docs/capture.md).
constexpr int64_t kPeriodNs = 1'000'000'000 / 30;
constexpr int64_t kHalfExposureNs = kPeriodNs / 4;

// CLOCK_MONOTONIC now, ns (the clock of the stand-in's log and of the node's stamps).
int64_t NowNs() {
  timespec t{};
  clock_gettime(CLOCK_MONOTONIC, &t);
  return static_cast<int64_t>(t.tv_sec) * 1'000'000'000 + t.tv_nsec;
}

// One line of the stand-in's event log: "<ns> <name> key=value ...".
struct Event {
  int64_t t_ns = 0;
  std::string name;
  std::map<std::string, std::string> fields;
  // Field `key` as an integer (-1 if absent).
  int64_t Int(const std::string& key) const {
    const auto it = fields.find(key);
    return it == fields.end() ? -1 : std::stoll(it->second);
  }
  // Field `key` ("" if absent).
  std::string Str(const std::string& key) const {
    const auto it = fields.find(key);
    return it == fields.end() ? std::string() : it->second;
  }
};

// The events logged so far.
std::vector<Event> ReadEvents(const fs::path& log) {
  std::vector<Event> events;
  std::istringstream lines(ReadText(log));
  for (std::string line; std::getline(lines, line);) {
    std::istringstream words(line);
    Event e;
    words >> e.t_ns >> e.name;
    for (std::string w; words >> w;) {
      const size_t eq = w.find('=');
      if (eq != std::string::npos) e.fields[w.substr(0, eq)] = w.substr(eq + 1);
    }
    events.push_back(std::move(e));
  }
  return events;
}

// The events named `name` (of descriptor `handle`, if >= 0).
std::vector<Event> Named(const std::vector<Event>& events, const std::string& name,
                         int handle = -1) {
  std::vector<Event> out;
  for (const Event& e : events) {
    if (e.name == name && (handle < 0 || e.Int("handle") == handle)) out.push_back(e);
  }
  return out;
}

// Polls `done` every 5 ms for at most `timeout`; whether it became true.
bool WaitFor(const std::function<bool()>& done, std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!done()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(5ms);
  }
  return true;
}

// Occurrences of `needle` in `text`.
size_t CountOf(const std::string& text, const std::string& needle) {
  size_t n = 0;
  for (size_t p = text.find(needle); p != std::string::npos; p = text.find(needle, p + 1)) ++n;
  return n;
}

// An image the node published, copied out of the bus at arrival.
struct Frame {
  int64_t arrival_ns = 0;
  int64_t stamp_mono_ns = 0;
  int64_t stamp_ns = 0;
  uint64_t sequence = 0;
  std::string frame_id;
  uint32_t width = 0;
  uint32_t height = 0;
  uint32_t step = 0;
  msgs::Encoding encoding = msgs::Encoding::kInvalid;
  std::vector<uint8_t> pixels;
};

// Takes the images of one subscriber on a thread while the node runs (the node's publisher has 8
// slots: samples are copied and released at once).
class FrameCollector {
 public:
  explicit FrameCollector(bus::Subscriber& subscriber) : subscriber_(subscriber) {
    thread_ = std::thread([this] {
      while (!stop_) {
        std::optional<bus::Sample> s = subscriber_.TryTake();
        if (!s) {
          std::this_thread::sleep_for(1ms);
          continue;
        }
        msgs::ReadView<msgs::Image> im = msgs::ReadMessage<msgs::Image>(s->data());
        Frame f;
        f.arrival_ns = NowNs();
        f.stamp_mono_ns = im->header.stamp_mono_ns;
        f.stamp_ns = im->header.stamp_ns;
        f.sequence = im->header.sequence;
        f.frame_id = std::string(im->header.FrameId());
        f.width = im->width;
        f.height = im->height;
        f.step = im->step;
        f.encoding = im->encoding;
        const auto* p = reinterpret_cast<const uint8_t*>(im.payload.data());
        f.pixels.assign(p, p + im.payload.size());
        std::lock_guard lock(mutex_);
        frames_.push_back(std::move(f));
      }
    });
  }
  ~FrameCollector() {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
  }
  // Images taken so far that arrived after `t_ns`.
  size_t CountAfter(int64_t t_ns) {
    std::lock_guard lock(mutex_);
    return std::count_if(frames_.begin(), frames_.end(),
                         [&](const Frame& f) { return f.arrival_ns > t_ns; });
  }
  // Stops (after taking what is queued) and returns the images in arrival order.
  std::vector<Frame> Finish() {
    std::this_thread::sleep_for(100ms);
    stop_ = true;
    thread_.join();
    return std::move(frames_);
  }

 private:
  bus::Subscriber& subscriber_;
  std::mutex mutex_;
  std::vector<Frame> frames_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

// The recorded YUYV frame `i`: uniformly random bytes from a fixed seed (every Y, U and V value
// occurs, so clamping is exercised and any misplaced byte changes the image).
std::vector<uint8_t> YuyvFrame(int i) {
  cv::Mat m(kHeight, kWidth, CV_8UC2);
  cv::RNG rng(0x5eed0 + i);
  rng.fill(m, cv::RNG::UNIFORM, 0, 256);
  return std::vector<uint8_t>(m.data, m.data + m.total() * m.elemSize());
}

// The scene of recorded MJPEG frame `i` (BGR): gradients and filled rectangles from a fixed seed,
// distinct per frame.
cv::Mat SceneFrame(int i) {
  cv::Mat m(kHeight, kWidth, CV_8UC3);
  for (int y = 0; y < kHeight; ++y) {
    for (int x = 0; x < kWidth; ++x) {
      m.at<cv::Vec3b>(y, x) = cv::Vec3b(static_cast<uint8_t>(x * 255 / (kWidth - 1)),
                                        static_cast<uint8_t>(y * 255 / (kHeight - 1)),
                                        static_cast<uint8_t>((x + y + 50 * i) & 255));
    }
  }
  cv::RNG rng(0xc0ffee + i);
  for (int r = 0; r < 24; ++r) {
    const cv::Point a(rng.uniform(0, kWidth), rng.uniform(0, kHeight));
    const cv::Point b(rng.uniform(0, kWidth), rng.uniform(0, kHeight));
    cv::rectangle(m, a, b,
                  cv::Scalar(rng.uniform(0, 256), rng.uniform(0, 256), rng.uniform(0, 256)),
                  cv::FILLED);
  }
  cv::putText(m, "frame " + std::to_string(i), {40, 240}, cv::FONT_HERSHEY_SIMPLEX, 3,
              cv::Scalar(255, 255, 255), 6);
  return m;
}

// `image` (RGB, packed) as the node publishes it: a vector of width * height * 3 bytes.
using Rgb = std::vector<uint8_t>;

// The largest difference of two images of the same size.
int MaxDifference(const Rgb& a, const Rgb& b) {
  int m = 0;
  for (size_t i = 0; i < a.size(); ++i) m = std::max(m, std::abs(int(a[i]) - int(b[i])));
  return m;
}

// Peak signal-to-noise ratio of `a` against `b`, dB.
double Psnr(const Rgb& a, const Rgb& b) {
  double sum = 0;
  for (size_t i = 0; i < a.size(); ++i) sum += (double(a[i]) - b[i]) * (double(a[i]) - b[i]);
  return 10 * std::log10(255.0 * 255.0 / std::max(sum / a.size(), 1e-12));
}

// An RGB cv::Mat (from OpenCV) as a packed vector.
Rgb ToVector(const cv::Mat& rgb) { return Rgb(rgb.data, rgb.data + rgb.total() * rgb.elemSize()); }

// capture_v4l2 started with the stand-in preloaded; stdout/stderr in files of `dir`.
class NodeRun {
 public:
  // Starts build/bin/capture_v4l2 --ros-args -p <params> with this process' environment plus
  // LD_PRELOAD and `env` ("NAME=value").
  NodeRun(const fs::path& dir, const std::vector<std::string>& env,
          const std::vector<std::string>& params)
      : err_path_(dir / "node.err") {
    std::vector<std::string> args = {kBin + "/capture_v4l2", "--ros-args"};
    for (const std::string& p : params) {
      args.push_back("-p");
      args.push_back(p);
    }
    std::vector<std::string> environment = {"LD_PRELOAD=" + kStandin};
    for (char** e = environ; *e != nullptr; ++e) {
      if (!std::string_view(*e).starts_with("LD_PRELOAD=")) environment.emplace_back(*e);
    }
    environment.insert(environment.end(), env.begin(), env.end());
    std::vector<char*> argv, envp;
    for (std::string& a : args) argv.push_back(a.data());
    for (std::string& e : environment) envp.push_back(e.data());
    argv.push_back(nullptr);
    envp.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
    posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, (dir / "node.out").c_str(),
                                     O_WRONLY | O_CREAT | O_TRUNC, 0600);
    posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, err_path_.c_str(),
                                     O_WRONLY | O_CREAT | O_TRUNC, 0600);
    const int rc = posix_spawn(&pid_, argv[0], &actions, nullptr, argv.data(), envp.data());
    posix_spawn_file_actions_destroy(&actions);
    EXPECT_EQ(rc, 0) << "cannot start " << argv[0];
  }
  ~NodeRun() {
    if (pid_ > 0) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
  }
  NodeRun(const NodeRun&) = delete;
  NodeRun& operator=(const NodeRun&) = delete;

  // SIGTERM: the node stops and releases the device.
  void Terminate() const { kill(pid_, SIGTERM); }
  // Waits at most `timeout` for the exit; its code (-1 if killed or still running).
  int Wait(std::chrono::milliseconds timeout = 10s) {
    int status = 0;
    const bool exited = WaitFor([&] { return waitpid(pid_, &status, WNOHANG) == pid_; }, timeout);
    if (!exited) return -1;
    pid_ = -1;
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  }
  // What the node printed on stderr so far.
  std::string Err() const { return ReadText(err_path_); }

 private:
  fs::path err_path_;
  pid_t pid_ = -1;
};

class V4l2StandinTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("probeless_v4l2_standin_" + std::to_string(getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    device_ = (dir_ / "video0").string();  // never created: the stand-in answers for it
  }
  void TearDown() override { fs::remove_all(dir_); }

  // Writes the YUYV recording (kRecordedFrames frames back to back) and returns the RGB the
  // library's conversion makes of each frame.
  std::vector<Rgb> WriteYuyvRecording() {
    std::ofstream out(dir_ / "frames.yuyv", std::ios::binary);
    std::vector<Rgb> expected;
    for (int i = 0; i < kRecordedFrames; ++i) {
      const std::vector<uint8_t> yuyv = YuyvFrame(i);
      out.write(reinterpret_cast<const char*>(yuyv.data()),
                static_cast<std::streamsize>(yuyv.size()));
      Rgb rgb(kWidth * kHeight * 3);
      capture::YuyvToRgb(yuyv.data(), kWidth * 2, kWidth, kHeight, rgb.data(), kWidth * 3);
      expected.push_back(std::move(rgb));
    }
    return expected;
  }

  // Writes the MJPEG recording (OpenCV JPEGs, quality 90, back to back) and returns the JPEGs.
  std::vector<std::vector<uint8_t>> WriteMjpegRecording() {
    std::ofstream out(dir_ / "frames.mjpeg", std::ios::binary);
    std::vector<std::vector<uint8_t>> jpegs;
    for (int i = 0; i < kRecordedFrames; ++i) {
      std::vector<uint8_t> jpeg;
      EXPECT_TRUE(cv::imencode(".jpg", SceneFrame(i), jpeg, {cv::IMWRITE_JPEG_QUALITY, 90}));
      out.write(reinterpret_cast<const char*>(jpeg.data()),
                static_cast<std::streamsize>(jpeg.size()));
      jpegs.push_back(std::move(jpeg));
    }
    return jpegs;
  }

  // What the library decodes from each of `jpegs` (the images the node must publish for them).
  static std::vector<Rgb> Decoded(const std::vector<std::vector<uint8_t>>& jpegs) {
    std::vector<Rgb> expected;
    for (const std::vector<uint8_t>& jpeg : jpegs) {
      Rgb rgb(kWidth * kHeight * 3);
      capture::DecodeMjpegToRgb(jpeg, kWidth, kHeight, rgb.data(), kWidth * 3);
      expected.push_back(std::move(rgb));
    }
    return expected;
  }

  // The stand-in's environment: the device, the log, the state file, and `recordings`.
  std::vector<std::string> StandinEnv(const std::vector<std::string>& recordings) const {
    std::vector<std::string> env = {"PROBELESS_V4L2_STANDIN_DEVICE=" + device_,
                                    "PROBELESS_V4L2_STANDIN_LOG=" + Log().string(),
                                    "PROBELESS_V4L2_STANDIN_STATE=" + State().string()};
    env.insert(env.end(), recordings.begin(), recordings.end());
    return env;
  }
  std::string YuyvEnv() const {
    return "PROBELESS_V4L2_STANDIN_YUYV=" + (dir_ / "frames.yuyv").string();
  }
  std::string MjpegEnv() const {
    return "PROBELESS_V4L2_STANDIN_MJPEG=" + (dir_ / "frames.mjpeg").string();
  }
  fs::path Log() const { return dir_ / "standin.log"; }
  fs::path State() const { return dir_ / "state"; }
  // Sets the device's state as a test would by pulling the cable ("" = plugged in).
  void SetState(const std::string& word) const {
    if (word.empty()) {
      fs::remove(State());
      return;
    }
    probeless::testing::WriteText(dir_ / "state.tmp", word);
    fs::rename(dir_ / "state.tmp", State());  // atomic: the stand-in never reads half a word
  }
  // The node's description of the device once open.
  std::string Description() const {
    return "V4L2 device '" + device_ + "' (probeless V4L2 stand-in)";
  }

  // Every frame was served by the stand-in (matched by its buffer timestamp: stamp_mono_ns is
  // it + kHalfExposureNs) and equals the expected image of the recorded frame it carried; frames
  // are in the order served; of each descriptor's frames up to the last one received, none was
  // lost between the stand-in and the bus except those the bus reports dropped. Returns the
  // descriptors (handles) the frames came from.
  std::set<int64_t> ExpectFramesIntact(const std::vector<Frame>& frames,
                                       const std::vector<Event>& events,
                                       const std::vector<Rgb>& expected, uint64_t bus_dropped) {
    std::map<int64_t, Event> served;                    // by buffer timestamp
    std::map<int64_t, std::vector<int64_t>> by_handle;  // timestamps served, in order
    for (const Event& e : Named(events, "frame")) {
      served[e.Int("ts_ns")] = e;
      by_handle[e.Int("handle")].push_back(e.Int("ts_ns"));
    }
    std::map<int64_t, int64_t> last_position;  // per handle
    int64_t last_ts = -1;
    for (size_t i = 0; i < frames.size(); ++i) {
      const Frame& f = frames[i];
      EXPECT_EQ(f.encoding, msgs::Encoding::kRgb8);
      EXPECT_EQ(f.width, uint32_t(kWidth));
      EXPECT_EQ(f.height, uint32_t(kHeight));
      EXPECT_EQ(f.step, uint32_t(kWidth * 3));
      EXPECT_EQ(f.frame_id, "camera");
      EXPECT_GT(f.stamp_ns, 1'600'000'000'000'000'000);
      EXPECT_LE(f.stamp_mono_ns, f.arrival_ns) << "frame " << i << " stamped after it arrived";
      const int64_t ts = f.stamp_mono_ns - kHalfExposureNs;
      const auto it = served.find(ts);
      if (it == served.end()) {
        ADD_FAILURE() << "frame " << i << " (stamp " << f.stamp_mono_ns
                      << ") matches no buffer the stand-in served";
        continue;
      }
      EXPECT_GT(ts, last_ts) << "frame " << i << " out of order";
      last_ts = ts;
      const int64_t handle = it->second.Int("handle");
      const std::vector<int64_t>& order = by_handle[handle];
      last_position[handle] = std::lower_bound(order.begin(), order.end(), ts) - order.begin();
      const int64_t source = it->second.Int("source");
      EXPECT_TRUE(f.pixels == expected[source])
          << "frame " << i << " (recorded frame " << source << ") differs by up to "
          << MaxDifference(f.pixels, expected[source]);
    }
    uint64_t served_until_last = 0;
    std::set<int64_t> handles;
    for (const auto& [handle, position] : last_position) {
      served_until_last += static_cast<uint64_t>(position + 1);
      handles.insert(handle);
    }
    EXPECT_EQ(served_until_last, frames.size() + bus_dropped)
        << "frames lost between the stand-in's buffers and the bus";
    return handles;
  }

  fs::path dir_;
  std::string device_;
};

TEST_F(V4l2StandinTest, YuyvFramesArriveIntactAndAutoControlsLockAfterTwoSeconds) {
  const std::vector<Rgb> expected = WriteYuyvRecording();
  bus::Subscriber image("/camera/image", msgs::TopicTypeOf<msgs::Image>(), {.queue_depth = 64});
  FrameCollector collector(image);
  NodeRun node(dir_, StandinEnv({YuyvEnv()}), {"device:=" + device_});
  // The default lock: 2 s of auto, then the auto modes off; run on for 0.6 s of locked frames.
  ASSERT_TRUE(WaitFor([&] { return Named(ReadEvents(Log()), "g_ctrl").size() >= 3; }, 8s))
      << node.Err();
  std::this_thread::sleep_for(600ms);
  node.Terminate();
  EXPECT_EQ(node.Wait(), 0) << node.Err();
  const std::vector<Frame> frames = collector.Finish();
  const std::vector<Event> events = ReadEvents(Log());
  const std::string err = node.Err();

  // The node's path through the device: one open, YUYV 640x480 @ 30, 4 mmap buffers.
  ASSERT_EQ(Named(events, "open").size(), 1u) << err;
  ASSERT_EQ(Named(events, "s_fmt").size(), 1u);
  EXPECT_EQ(Named(events, "s_fmt")[0].Str("fourcc"), "YUYV");
  EXPECT_EQ(Named(events, "s_fmt")[0].Str("size"), "640x480");
  EXPECT_EQ(Named(events, "s_parm")[0].Int("fps"), 30);
  EXPECT_EQ(Named(events, "reqbufs")[0].Int("count"), 4);
  ASSERT_EQ(Named(events, "streamon").size(), 1u);
  EXPECT_EQ(Named(events, "streamon")[0].Int("queued"), 4);
  EXPECT_NE(err.find("streaming from " + Description() + ": image 640x480 yuyv"), std::string::npos)
      << err;

  // Locked after 2 s of auto: no control write before, then the auto modes off in this order.
  const std::vector<Event> writes = Named(events, "s_ctrl");
  ASSERT_EQ(writes.size(), 4u) << err;
  const std::vector<std::pair<std::string, int>> lock = {{"exposure_auto", 1},
                                                         {"exposure_auto_priority", 0},
                                                         {"auto_white_balance", 0},
                                                         {"autogain", 0}};
  for (size_t i = 0; i < lock.size(); ++i) {
    EXPECT_EQ(writes[i].Str("name"), lock[i].first);
    EXPECT_EQ(writes[i].Int("value"), lock[i].second);
    EXPECT_EQ(writes[i].Str("result"), "ok") << writes[i].Str("name");
  }
  const double lock_s = (writes[0].t_ns - Named(events, "streamon")[0].t_ns) / 1e9;
  EXPECT_GE(lock_s, 2.0);
  EXPECT_LT(lock_s, 2.5);
  // While auto, the stand-in's values followed its changing scene; from each auto mode's switch-off
  // on, its value stays what it was then, and the node logged exactly those values read back.
  std::set<int64_t> exposures, gains, balances;
  for (const Event& e : Named(events, "frame")) {
    if (e.t_ns < writes[0].t_ns) {
      exposures.insert(e.Int("exposure"));
      gains.insert(e.Int("gain"));
      balances.insert(e.Int("wb"));
    }
  }
  EXPECT_GT(exposures.size(), 10u);
  EXPECT_GT(gains.size(), 10u);
  EXPECT_GT(balances.size(), 10u);
  const int64_t exposure = writes[0].Int("exposure");
  const int64_t balance = writes[2].Int("wb");
  const int64_t gain = writes[3].Int("gain");
  size_t locked_frames = 0;
  for (const Event& e : Named(events, "frame")) {
    if (e.t_ns < writes[3].t_ns) continue;
    ++locked_frames;
    EXPECT_EQ(e.Int("exposure"), exposure);
    EXPECT_EQ(e.Int("gain"), gain);
    EXPECT_EQ(e.Int("wb"), balance);
  }
  EXPECT_GE(locked_frames, 12u);
  const std::vector<Event> close = Named(events, "close");
  ASSERT_EQ(close.size(), 1u);
  EXPECT_EQ(close[0].Int("exposure"), exposure);
  EXPECT_EQ(close[0].Int("gain"), gain);
  EXPECT_EQ(close[0].Int("wb"), balance);
  EXPECT_NE(err.find(Description() +
                     ": locked auto exposure / white balance / gain (exposure_time_us/100 " +
                     std::to_string(exposure) + ", gain " + std::to_string(gain) +
                     ", white_balance_temperature_k " + std::to_string(balance) + ")"),
            std::string::npos)
      << err;

  // Frames: every one served, intact, in order, stamped from its buffer.
  ASSERT_GE(frames.size(), 60u);
  EXPECT_EQ(ExpectFramesIntact(frames, events, expected, image.dropped()), std::set<int64_t>{1});
  // The library's BT.601 conversion against OpenCV's (an independent implementation): within a
  // level wherever Y >= 16; in the footroom below, outside the limited range, OpenCV clamps Y to
  // 16 and the library does not.
  for (int i = 0; i < kRecordedFrames; ++i) {
    std::vector<uint8_t> yuyv = YuyvFrame(i);
    cv::Mat rgb;
    cv::cvtColor(cv::Mat(kHeight, kWidth, CV_8UC2, yuyv.data()), rgb, cv::COLOR_YUV2RGB_YUYV);
    int worst = 0;
    for (size_t p = 0; p < size_t(kWidth) * kHeight; ++p) {
      if (yuyv[2 * p] < 16) continue;
      for (size_t c = 3 * p; c < 3 * p + 3; ++c) {
        worst = std::max(worst, std::abs(int(expected[i][c]) - int(rgb.data[c])));
      }
    }
    EXPECT_LE(worst, 1) << "recorded frame " << i;
  }
  const std::vector<Event> exit = Named(events, "exit");
  ASSERT_EQ(exit.size(), 1u);
  EXPECT_EQ(exit[0].Int("open"), 0);
  EXPECT_EQ(exit[0].Int("mappings"), 0);
}

TEST_F(V4l2StandinTest, MjpegFramesDecodeToTheRecordedJpegs) {
  WriteYuyvRecording();
  const std::vector<std::vector<uint8_t>> jpegs = WriteMjpegRecording();
  const std::vector<Rgb> expected = Decoded(jpegs);
  bus::Subscriber image("/camera/image", msgs::TopicTypeOf<msgs::Image>(), {.queue_depth = 64});
  FrameCollector collector(image);
  NodeRun node(dir_, StandinEnv({YuyvEnv(), MjpegEnv()}),
               {"device:=" + device_, "pixel_format:=mjpeg", "lock_auto:=false", "max_frames:=12"});
  EXPECT_EQ(node.Wait(), 0) << node.Err();
  const std::vector<Frame> frames = collector.Finish();
  const std::vector<Event> events = ReadEvents(Log());
  ASSERT_EQ(Named(events, "s_fmt").size(), 1u) << node.Err();
  EXPECT_EQ(Named(events, "s_fmt")[0].Str("fourcc"), "MJPG");
  EXPECT_TRUE(Named(events, "s_ctrl").empty()) << "lock_auto: false writes no control";
  EXPECT_NE(node.Err().find("image 640x480 mjpeg"), std::string::npos) << node.Err();
  ASSERT_EQ(frames.size() + image.dropped(), 12u);
  // Exact equality with the same decoder: the JPEG bytes crossed the mmap buffers unchanged
  // (bytesused included); decoder correctness itself is capture_test's.
  ExpectFramesIntact(frames, events, expected, image.dropped());
  for (int i = 0; i < kRecordedFrames; ++i) {
    // OpenCV decodes the same JPEG to within a level (another libjpeg caller), and each decoded
    // frame is the scene it was encoded from within JPEG quality 90's loss (> 27 dB: sharp edges
    // and text), far from the other scenes (< 20 dB).
    cv::Mat bgr = cv::imdecode(jpegs[i], cv::IMREAD_COLOR), rgb;
    cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
    EXPECT_LE(MaxDifference(expected[i], ToVector(rgb)), 1) << "recorded frame " << i;
    for (int j = 0; j < kRecordedFrames; ++j) {
      cv::Mat scene;
      cv::cvtColor(SceneFrame(j), scene, cv::COLOR_BGR2RGB);
      const double psnr = Psnr(expected[i], ToVector(scene));
      if (i == j) {
        EXPECT_GT(psnr, 27) << "recorded frame " << i;
      } else {
        EXPECT_LT(psnr, 20) << "recorded frame " << i << " against scene " << j;
      }
    }
  }
  const std::vector<Event> exit = Named(events, "exit");
  ASSERT_EQ(exit.size(), 1u);
  EXPECT_EQ(exit[0].Int("open"), 0);
  EXPECT_EQ(exit[0].Int("mappings"), 0);
}

TEST_F(V4l2StandinTest, CorruptAndErrorFlaggedFramesAreDroppedAndStreamingGoesOn) {
  const std::vector<std::vector<uint8_t>> jpegs = WriteMjpegRecording();
  const std::vector<Rgb> expected = Decoded(jpegs);
  bus::Subscriber image("/camera/image", msgs::TopicTypeOf<msgs::Image>(), {.queue_depth = 64});
  FrameCollector collector(image);
  // Served frames 3 and 4 are truncated JPEGs; 6 is flagged by the driver with its data intact,
  // so only the flag can make the node drop it.
  NodeRun node(dir_,
               StandinEnv({MjpegEnv(), "PROBELESS_V4L2_STANDIN_CORRUPT=3,4",
                           "PROBELESS_V4L2_STANDIN_ERROR_FLAG=6"}),
               {"device:=" + device_, "pixel_format:=mjpeg", "lock_auto:=false", "max_frames:=20"});
  EXPECT_EQ(node.Wait(), 0) << node.Err();
  const std::vector<Frame> frames = collector.Finish();
  const std::vector<Event> events = ReadEvents(Log());
  const std::string err = node.Err();

  // The stand-in served the damage asked for, on the one stream.
  ASSERT_EQ(Named(events, "streamon").size(), 1u) << err;
  const std::vector<Event> corrupt = Named(events, "corrupt");
  const std::vector<Event> flagged = Named(events, "flagged");
  ASSERT_EQ(corrupt.size(), 2u) << err;
  EXPECT_EQ(corrupt[0].Int("served"), 3);
  EXPECT_EQ(corrupt[1].Int("served"), 4);
  for (const Event& e : corrupt) EXPECT_EQ(e.Int("bytes"), 16);
  ASSERT_EQ(flagged.size(), 1u) << err;
  EXPECT_EQ(flagged[0].Int("served"), 6);
  EXPECT_EQ(flagged[0].Int("bytes"), int64_t(jpegs.at(flagged[0].Int("source")).size()));

  // Exactly those three are missing on the bus: none of their stamps arrived, and every other
  // frame served up to the 20th published one arrived intact, in order (ExpectFramesIntact only
  // counts the stand-in's intact "frame" events).
  std::set<int64_t> damaged = {flagged[0].Int("ts_ns")};
  for (const Event& e : corrupt) damaged.insert(e.Int("ts_ns"));
  for (const Frame& f : frames) {
    EXPECT_FALSE(damaged.contains(f.stamp_mono_ns - kHalfExposureNs))
        << "a damaged frame was published (stamp " << f.stamp_mono_ns << ")";
  }
  ASSERT_EQ(frames.size() + image.dropped(), 20u) << err;
  EXPECT_EQ(ExpectFramesIntact(frames, events, expected, image.dropped()), std::set<int64_t>{1});
  // Sequence numbers and the node's count are of published images: the drops leave no gap.
  for (size_t i = 1; i < frames.size(); ++i) EXPECT_GT(frames[i].sequence, frames[i - 1].sequence);
  EXPECT_EQ(frames.back().sequence, 20u);
  EXPECT_NE(err.find("published 20 images and 0 depth images (max_frames reached)"),
            std::string::npos)
      << err;

  // One warning per corrupt frame, naming the decoder's problem; the driver's flag once.
  const std::string warning = "[warn] [/capture_v4l2] dropped a frame that cannot be converted (";
  EXPECT_EQ(CountOf(err, "dropped a frame that cannot be converted"), 2u) << err;
  EXPECT_NE(err.find(warning + "1 so far): MJPEG frame (16 bytes) is corrupt: "), std::string::npos)
      << err;
  EXPECT_NE(err.find(warning + "2 so far): MJPEG frame (16 bytes) is corrupt: "), std::string::npos)
      << err;
  EXPECT_EQ(CountOf(err, "flagged as erroneous"), 1u) << err;
  EXPECT_NE(
      err.find(Description() + ": dropped a buffer the driver flagged as erroneous (1 so far)\n"),
      std::string::npos)
      << err;
  EXPECT_EQ(CountOf(err, "[error]"), 0u) << err;
  const std::vector<Event> exit = Named(events, "exit");
  ASSERT_EQ(exit.size(), 1u);
  EXPECT_EQ(exit[0].Int("open"), 0);
  EXPECT_EQ(exit[0].Int("mappings"), 0);
}

TEST_F(V4l2StandinTest, NothingButCorruptFramesEndsTheNodeAfterThirtyEvenWithRetry) {
  WriteMjpegRecording();
  bus::Subscriber image("/camera/image", msgs::TopicTypeOf<msgs::Image>(), {.queue_depth = 64});
  FrameCollector collector(image);
  // retry: true must not help: bad input is not a device that went away.
  NodeRun node(dir_, StandinEnv({MjpegEnv(), "PROBELESS_V4L2_STANDIN_CORRUPT=all"}),
               {"device:=" + device_, "pixel_format:=mjpeg", "lock_auto:=false", "retry:=true",
                "retry_period_s:=0.1"});
  // 30 frames at 30 fps take 1 s; 5 s leaves room for a loaded machine.
  EXPECT_EQ(node.Wait(5s), 1) << node.Err();
  const std::vector<Frame> frames = collector.Finish();
  const std::vector<Event> events = ReadEvents(Log());
  const std::string err = node.Err();

  // Every served frame was corrupt; the node gave up at the 30th in a row, at once.
  EXPECT_TRUE(frames.empty());
  EXPECT_TRUE(Named(events, "frame").empty());
  const std::vector<Event> corrupt = Named(events, "corrupt");
  ASSERT_GE(corrupt.size(), 30u) << err;
  ASSERT_EQ(Named(events, "close").size(), 1u) << err;
  const int64_t stop_ns = Named(events, "close")[0].t_ns;
  EXPECT_LT(stop_ns - corrupt[29].t_ns, 500'000'000) << "stopped long after the 30th";
  EXPECT_LT(stop_ns - Named(events, "streamon").at(0).t_ns, 2'000'000'000);

  // The first 10 drops warned (of 29), then one error line, the decoder's, last; not retried.
  EXPECT_EQ(CountOf(err, "dropped a frame that cannot be converted"), 10u) << err;
  EXPECT_NE(err.find("dropped a frame that cannot be converted (10 so far): "), std::string::npos)
      << err;
  EXPECT_NE(err.find("published 0 images and 0 depth images\n"), std::string::npos) << err;
  EXPECT_EQ(CountOf(err, "[error]"), 1u) << err;
  const std::string last_line = err.substr(err.rfind('\n', err.size() - 2) + 1);
  // One line naming the device, the count, the decoder's reason and what to check.
  EXPECT_TRUE(last_line.starts_with("[error] [/capture_v4l2] V4L2 device '" + device_ + "'"))
      << err;
  EXPECT_NE(last_line.find(": 30 frames in a row cannot be converted (MJPEG frame (16 bytes) is "
                           "corrupt: "),
            std::string::npos)
      << err;
  EXPECT_TRUE(last_line.ends_with("): check pixel_format, or the camera and its cable\n")) << err;
  EXPECT_EQ(CountOf(err, "retrying"), 0u) << err;
  EXPECT_EQ(CountOf(err, "waiting for it"), 0u) << err;
  EXPECT_EQ(Named(events, "open").size(), 1u);
  const std::vector<Event> exit = Named(events, "exit");
  ASSERT_EQ(exit.size(), 1u);
  EXPECT_EQ(exit[0].Int("open"), 0);
  EXPECT_EQ(exit[0].Int("mappings"), 0);
}

TEST_F(V4l2StandinTest, UnplugDetectedWithinASecondAndReopenedOnReplug) {
  const std::vector<Rgb> expected = WriteYuyvRecording();
  bus::Subscriber image("/camera/image", msgs::TopicTypeOf<msgs::Image>(), {.queue_depth = 64});
  FrameCollector collector(image);
  NodeRun node(dir_, StandinEnv({YuyvEnv()}),
               {"device:=" + device_, "retry:=true", "retry_period_s:=0.2", "lock_after_s:=0.3",
                "gain:=64"});
  ASSERT_TRUE(WaitFor([&] { return collector.CountAfter(0) >= 10; }, 5s)) << node.Err();
  const int64_t unplug_ns = NowNs();
  SetState("unplugged");
  ASSERT_TRUE(WaitFor([&] { return !Named(ReadEvents(Log()), "close", 1).empty(); }, 3s))
      << node.Err();
  ASSERT_TRUE(WaitFor([&] { return node.Err().find("does not exist") != std::string::npos; }, 3s))
      << node.Err();
  std::this_thread::sleep_for(300ms);  // unplugged for a while: the node keeps waiting
  const int64_t replug_ns = NowNs();
  SetState("");
  ASSERT_TRUE(WaitFor([&] { return collector.CountAfter(replug_ns) >= 10; }, 5s)) << node.Err();
  ASSERT_TRUE(WaitFor([&] { return CountOf(node.Err(), "locked auto exposure") >= 2; }, 3s))
      << node.Err();
  node.Terminate();
  EXPECT_EQ(node.Wait(), 0) << node.Err();
  const std::vector<Frame> frames = collector.Finish();
  const std::vector<Event> events = ReadEvents(Log());
  const std::string err = node.Err();

  // Detected within 1 s of the unplug (the stand-in sees the state file within 5 ms): the node
  // closed the dead descriptor, tried to reopen (ENOENT while unplugged) and said so once.
  const std::vector<Event> unplug = Named(events, "unplug");
  ASSERT_EQ(unplug.size(), 1u);
  const Event closed = Named(events, "close", 1).at(0);
  EXPECT_LT(closed.t_ns - unplug_ns, 1'000'000'000);
  EXPECT_GT(closed.t_ns, unplug[0].t_ns);
  EXPECT_NE(err.find("[warn] [/capture_v4l2] " + Description() +
                     " went away (unplugged?): plug it back in (waiting for it to come back)"),
            std::string::npos)
      << err;
  EXPECT_EQ(CountOf(err, "[warn] [/capture_v4l2] V4L2 device '" + device_ +
                             "' does not exist: plug the camera in or pick another with param "
                             "device (ls /dev/v4l/by-id) (retrying every 0.2 s)\n"),
            1u)
      << err;
  EXPECT_FALSE(Named(events, "open-failed").empty());
  // Reopened after the replug within a retry period (plus scheduling), streaming again.
  ASSERT_EQ(Named(events, "replug").size(), 1u);
  const std::vector<Event> opens = Named(events, "open");
  ASSERT_EQ(opens.size(), 2u) << err;
  const std::vector<Event> streamon = Named(events, "streamon", 2);
  ASSERT_EQ(streamon.size(), 1u);
  EXPECT_GT(streamon[0].t_ns, replug_ns);
  EXPECT_LT(streamon[0].t_ns - replug_ns, 700'000'000);
  EXPECT_EQ(CountOf(err, "streaming from " + Description()), 2u) << err;

  // Both times: the explicit gain (its auto mode off first), the lock 0.3 s after streaming of
  // what was left automatic; the replugged camera had its defaults back, so all is applied again.
  for (int handle : {1, 2}) {
    std::vector<std::string> writes;
    for (const Event& e : Named(events, "s_ctrl", handle)) {
      writes.push_back(e.Str("name") + "=" + e.Str("value") + " " + e.Str("result"));
    }
    EXPECT_EQ(writes,
              (std::vector<std::string>{"autogain=0 ok", "gain=64 ok", "exposure_auto=1 ok",
                                        "exposure_auto_priority=0 ok", "auto_white_balance=0 ok"}))
        << "handle " << handle;
  }
  EXPECT_EQ(CountOf(err, ", gain 64, "), 2u) << err;

  // The same subscriber received frames before and after (publishers stay), all intact.
  EXPECT_EQ(ExpectFramesIntact(frames, events, expected, image.dropped()),
            (std::set<int64_t>{1, 2}));
  const std::vector<Event> exit = Named(events, "exit");
  ASSERT_EQ(exit.size(), 1u);
  EXPECT_EQ(exit[0].Int("open"), 0);
  EXPECT_EQ(exit[0].Int("mappings"), 0);
}

TEST_F(V4l2StandinTest, BusyDeviceIsRetriedWithoutLeakingDescriptors) {
  WriteYuyvRecording();
  SetState("busy");
  bus::Subscriber image("/camera/image", msgs::TopicTypeOf<msgs::Image>(), {.queue_depth = 64});
  FrameCollector collector(image);
  NodeRun node(dir_, StandinEnv({YuyvEnv()}),
               {"device:=" + device_, "retry:=true", "retry_period_s:=0.1"});
  ASSERT_TRUE(WaitFor([&] { return Named(ReadEvents(Log()), "open").size() >= 3; }, 5s))
      << node.Err();
  SetState("");
  ASSERT_TRUE(WaitFor([&] { return collector.CountAfter(0) >= 5; }, 5s)) << node.Err();
  node.Terminate();
  EXPECT_EQ(node.Wait(), 0) << node.Err();
  collector.Finish();
  const std::vector<Event> events = ReadEvents(Log());
  EXPECT_EQ(CountOf(node.Err(), "[warn] [/capture_v4l2] " + Description() +
                                    " is busy: another process streams from it (fuser " + device_ +
                                    ") (retrying every 0.1 s)\n"),
            1u)
      << node.Err();
  // Each busy attempt released its descriptor before the next one (a leaked one would hold a
  // real device's queue, and a descriptor per retry).
  const std::vector<Event> opens = Named(events, "open");
  ASSERT_GE(opens.size(), 4u);
  for (size_t i = 0; i + 1 < opens.size(); ++i) {
    const std::vector<Event> close = Named(events, "close", opens[i].Int("handle"));
    ASSERT_EQ(close.size(), 1u) << "descriptor of attempt " << i + 1 << " leaked";
    EXPECT_LT(close[0].t_ns, opens[i + 1].t_ns);
  }
  const std::vector<Event> exit = Named(events, "exit");
  ASSERT_EQ(exit.size(), 1u);
  EXPECT_EQ(exit[0].Int("open"), 0);
  EXPECT_EQ(exit[0].Int("mappings"), 0);
}

TEST_F(V4l2StandinTest, BadStandinSettingsFailTheOpenWithOneLine) {
  probeless::testing::WriteText(dir_ / "short.yuyv", std::string(1000, 'x'));
  probeless::testing::WriteText(dir_ / "not.mjpeg", "not a JPEG");
  const std::string node_line = "[error] [/capture_v4l2] V4L2 device '" + device_ +
                                "' is not a V4L2 video device: cannot be opened (Invalid "
                                "argument)\n";
  const std::string yuyv = "PROBELESS_V4L2_STANDIN_YUYV=" + (dir_ / "short.yuyv").string();
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"PROBELESS_V4L2_STANDIN_SIZE=640 " + yuyv,
       "PROBELESS_V4L2_STANDIN_SIZE '640' is not WIDTHxHEIGHT with an even width up to 8192 (e.g. "
       "640x480)"},
      {yuyv, "PROBELESS_V4L2_STANDIN_YUYV '" + (dir_ / "short.yuyv").string() +
                 "': 1000 bytes is not a whole number of 640x480 YUYV frames (614400 bytes each)"},
      {"PROBELESS_V4L2_STANDIN_MJPEG=" + (dir_ / "not.mjpeg").string(),
       "PROBELESS_V4L2_STANDIN_MJPEG: frame 0 has no SOI marker at byte 0 (expected JPEG images "
       "back to back)"},
      {"PROBELESS_V4L2_STANDIN_YUYV=" + (dir_ / "absent.yuyv").string(),
       "PROBELESS_V4L2_STANDIN_YUYV '" + (dir_ / "absent.yuyv").string() +
           "' cannot be read (No such file or directory)"},
      {"", "set PROBELESS_V4L2_STANDIN_YUYV and/or PROBELESS_V4L2_STANDIN_MJPEG to a recording"},
      {"PROBELESS_V4L2_STANDIN_CORRUPT=3,x",
       "PROBELESS_V4L2_STANDIN_CORRUPT '3,x' is not a comma-separated list of served-frame indices "
       "(e.g. 3,4) or all"},
      {"PROBELESS_V4L2_STANDIN_ERROR_FLAG=6, " + yuyv,
       "PROBELESS_V4L2_STANDIN_ERROR_FLAG '6,' is not a comma-separated list of served-frame "
       "indices (e.g. 3,4) or all"},
      {"PROBELESS_V4L2_STANDIN_CORRUPT=3 " + yuyv,
       "PROBELESS_V4L2_STANDIN_CORRUPT needs PROBELESS_V4L2_STANDIN_MJPEG (only MJPEG frames are "
       "served corrupt)"},
  };
  for (const auto& [env, line] : cases) {
    // retry: true does not help: bad settings are not a missing device.
    probeless::testing::CommandResult r = probeless::testing::RunCommand(
        "env LD_PRELOAD=" + kStandin + " PROBELESS_V4L2_STANDIN_DEVICE=" + device_ + " " + env +
            " " + kBin + "/capture_v4l2 --ros-args -p device:=" + device_ + " -p retry:=true",
        dir_);
    EXPECT_EQ(r.code, 1) << env;
    EXPECT_EQ(r.err, "[error] [v4l2_standin] " + line + "\n" + node_line) << env;
  }
}

}  // namespace
