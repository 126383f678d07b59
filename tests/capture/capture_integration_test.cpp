// Capture nodes through the real device libraries, without hardware:
// - capture_freenect on Debian's fakenect (the libfreenect API replaying a dump) fed with the
// shared
//   7-Scenes frames by tools/fakenect_dump, from a launch file: RGB identical, depth back in mm
//   within the Kinect model's quantisation step;
// - capture_openni2 through libOpenNI2 on our virtual-device driver plugin, from a launch file:
//   hardware registration, software registration, a stalled device detected within ~1 s;
// - every node without its device: one line naming it and what to do, exit 1; retry waits and
//   stops promptly on SIGTERM.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include "probeless/bus/bus.h"
#include "probeless/capture/convert.h"
#include "probeless/dataset/datasets.h"
#include "probeless/log/ros2.h"
#include "probeless/msgs/msgs.h"
#include "probeless/testing/testing.h"

namespace {

namespace fs = std::filesystem;
using namespace probeless;
using namespace std::chrono_literals;

const std::string kBin = PROBELESS_BIN_DIR;
const std::string kLaunch = PROBELESS_SOURCE_DIR "/launch/capture";
const std::string kOpenNi2Dir = PROBELESS_TEST_BIN_DIR "/openni2";
const std::string kSevenScenes = PROBELESS_DATA_DIR "/7scenes-redkitchen";

using Result = probeless::testing::CommandResult;
using probeless::testing::ReadText;

class CaptureIntegrationTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("probeless_capture_it_" + std::to_string(getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  // Runs a shell command line (no stdin), capturing stdout, stderr and the time it took.
  Result Run(const std::string& command) { return probeless::testing::RunCommand(command, dir_); }

  fs::path dir_;
};

bus::Subscriber ImageSubscriber(const std::string& topic) {
  return bus::Subscriber(topic, msgs::TopicTypeOf<msgs::Image>(), {.queue_depth = 64});
}

// Takes samples from several subscribers on a thread while a node runs (publishers keep 8 slots:
// a subscriber must take as the node publishes).
class Collector {
 public:
  explicit Collector(std::vector<bus::Subscriber*> subscribers)
      : subscribers_(std::move(subscribers)), samples_(subscribers_.size()) {
    thread_ = std::thread([this] {
      while (!stop_) {
        bool any = false;
        for (size_t i = 0; i < subscribers_.size(); ++i) {
          if (std::optional<bus::Sample> s = subscribers_[i]->TryTake()) {
            // Copied (64-byte aligned) and released at once: held samples would pin the slots.
            log::MessageBuffer copy(s->data().size());
            std::memcpy(copy.bytes().data(), s->data().data(), s->data().size());
            samples_[i].push_back(std::move(copy));
            any = true;
          }
        }
        if (!any) std::this_thread::sleep_for(1ms);
      }
    });
  }
  // Stops collecting (after draining what is queued) and returns the samples per subscriber.
  std::vector<std::vector<log::MessageBuffer>> Finish() {
    std::this_thread::sleep_for(100ms);
    stop_ = true;
    thread_.join();
    return std::move(samples_);
  }

 private:
  std::vector<bus::Subscriber*> subscribers_;
  std::vector<std::vector<log::MessageBuffer>> samples_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

// Takes up to `count` samples (waiting at most `timeout` for each).
std::vector<bus::Sample> TakeAll(bus::Subscriber& s, size_t count, std::chrono::seconds timeout) {
  std::vector<bus::Sample> samples;
  while (samples.size() < count) {
    std::optional<bus::Sample> sample = s.Take(timeout);
    if (!sample) break;
    samples.push_back(std::move(*sample));
  }
  return samples;
}

TEST_F(CaptureIntegrationTest, FreenectOnFakenectDumpOf7ScenesFromLaunchFile) {
  if (!fs::exists(kSevenScenes)) GTEST_SKIP() << "shared data absent: " << kSevenScenes;
  const fs::path dump = dir_ / "dump";
  Result r =
      Run(kBin + "/fakenect_dump " + kSevenScenes + " " + dump.string() + " --max-frames 12");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(r.out, "fakenect_dump: wrote 12 RGB and 12 depth frames to " + dump.string() + "\n");
  // The same frames from the dataset, as the reference.
  bus::Subscriber image = ImageSubscriber("/camera/image");
  bus::Subscriber depth = ImageSubscriber("/camera/depth");
  bus::Subscriber info("/camera/camera_info", msgs::TopicTypeOf<msgs::CameraInfo>(),
                       {.queue_depth = 64});
  Collector collector({&image, &depth, &info});
  r = Run(kBin + "/probeless launch " + kLaunch +
          "/freenect_fakenect.launch.yaml dump:=" + dump.string());
  std::vector<std::vector<log::MessageBuffer>> all = collector.Finish();
  // The node ends at the end of the dump with its clear error line; the graph shuts down.
  EXPECT_NE(r.err.find("Kinect v1 #0 stopped: libfreenect reports error -1 (unplugged, or the end "
                       "of a fakenect recording)"),
            std::string::npos)
      << r.err;
  std::vector<log::MessageBuffer>& images = all[0];
  std::vector<log::MessageBuffer>& depths = all[1];
  std::vector<log::MessageBuffer>& infos = all[2];
  ASSERT_EQ(images.size(), 12u);
  ASSERT_EQ(depths.size(), 12u);
  ASSERT_EQ(infos.size(), 12u);
  // The dump's files are what fakenect serves: RGB must arrive unchanged, depth as the model's mm.
  std::ifstream index(dump / "INDEX.txt");
  std::vector<std::string> colour_files, depth_files;
  for (std::string line; std::getline(index, line);) {
    (line[0] == 'r' ? colour_files : depth_files).push_back(line);
  }
  const capture::KinectDepthModel& model = capture::KinectDepthModel::Default();
  for (size_t i = 0; i < 12; ++i) {
    msgs::ReadView<msgs::Image> im = msgs::ReadMessage<msgs::Image>(images[i].bytes());
    ASSERT_EQ(im->encoding, msgs::Encoding::kRgb8);
    ASSERT_EQ(im->width, 640u);
    EXPECT_EQ(im->header.FrameId(), "kinect_rgb_optical");
    EXPECT_EQ(im->header.sequence, i + 1);
    EXPECT_GT(im->header.stamp_ns, 1'600'000'000'000'000'000);
    const std::string ppm = ReadText(dump / colour_files[i]);
    const std::string pixels = ppm.substr(ppm.find('\n') + 1);
    ASSERT_EQ(pixels.size(), 640u * 480 * 3);
    EXPECT_EQ(std::memcmp(pixels.data(), im.payload.data(), pixels.size()), 0) << "frame " << i;

    msgs::ReadView<msgs::Image> d = msgs::ReadMessage<msgs::Image>(depths[i].bytes());
    ASSERT_EQ(d->encoding, msgs::Encoding::kDepth16);
    const std::string pgm = ReadText(dump / depth_files[i]);
    const auto* raw = reinterpret_cast<const uint16_t*>(pgm.data() + pgm.find('\n') + 1);
    const auto* mm = reinterpret_cast<const uint16_t*>(d.payload.data());
    for (size_t p = 0; p < 640 * 480; ++p) {
      ASSERT_EQ(mm[p], model.ToMm(raw[p])) << "frame " << i << " pixel " << p;
    }
  }
  // Depth against the source frames (the dataset's depth PNGs, mm): within the model's
  // quantisation step wherever the Kinect could measure the depth, 0 elsewhere.
  dataset::DatasetOptions options;
  options.max_frames = 12;
  std::unique_ptr<dataset::Source> source = dataset::OpenDataset(kSevenScenes, options);
  size_t frame = 0, compared = 0;
  while (std::optional<dataset::StreamMessage> m = source->Next()) {
    if (source->topics()[m->topic_index].topic != "/camera/depth") continue;
    msgs::ReadView<msgs::Image> src = msgs::ReadMessage<msgs::Image>(m->message.bytes());
    msgs::ReadView<msgs::Image> out = msgs::ReadMessage<msgs::Image>(depths[frame].bytes());
    const auto* a = reinterpret_cast<const uint16_t*>(src.payload.data());
    const auto* b = reinterpret_cast<const uint16_t*>(out.payload.data());
    for (size_t p = 0; p < 640 * 480; ++p) {
      if (model.ToRaw(a[p]) == capture::KinectDepthModel::kNoData) {
        ASSERT_EQ(b[p], 0) << "frame " << frame << " pixel " << p << " source " << a[p];
        continue;
      }
      ASSERT_LE(std::abs(static_cast<int>(b[p]) - static_cast<int>(a[p])),
                model.QuantisationErrorMm(a[p]))
          << "frame " << frame << " pixel " << p;
      ++compared;
    }
    ++frame;
  }
  EXPECT_EQ(frame, 12u);
  EXPECT_GT(compared, 12u * 640 * 480 / 2);
  msgs::ReadView<msgs::CameraInfo> k = msgs::ReadMessage<msgs::CameraInfo>(infos[0].bytes());
  EXPECT_EQ(k->fx, 525.0);
  EXPECT_EQ(k->depth_scale, 0.001);
}

TEST_F(CaptureIntegrationTest, OpenNi2VirtualDeviceHardwareRegistrationFromLaunchFile) {
  bus::Subscriber image = ImageSubscriber("/camera/image");
  bus::Subscriber depth = ImageSubscriber("/camera/depth");
  Collector collector({&image, &depth});
  Result r = Run("LD_LIBRARY_PATH=" + kOpenNi2Dir + " " + kBin + "/probeless launch " + kLaunch +
                 "/openni2.launch.yaml uri:=probeless://virtual retry:=false max_frames:=20");
  std::vector<std::vector<log::MessageBuffer>> all = collector.Finish();
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.err.find("hardware depth-to-colour registration on"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("OpenNI2 device 'probeless://virtual' (probeless Virtual RGB-D)"),
            std::string::npos)
      << r.err;
  std::vector<log::MessageBuffer>& images = all[0];
  std::vector<log::MessageBuffer>& depths = all[1];
  ASSERT_GE(images.size(), 5u);
  ASSERT_GE(depths.size(), 5u);
  EXPECT_EQ(images.size() + depths.size(), 20u);
  for (const log::MessageBuffer& s : depths) {
    msgs::ReadView<msgs::Image> d = msgs::ReadMessage<msgs::Image>(s.bytes());
    ASSERT_EQ(d->encoding, msgs::Encoding::kDepth16);
    ASSERT_EQ(d->width, 640u);
    const auto* mm = reinterpret_cast<const uint16_t*>(d.payload.data());
    const int n = mm[8] - 816;  // frame number of the virtual device
    ASSERT_GE(n, 0);
    for (int y = 0; y < 480; y += 13) {
      for (int x = 0; x < 640; x += 7) {
        const int expected = (x < 8 && y < 8) ? 0 : 800 + 2 * x + y + n;
        ASSERT_EQ(mm[y * 640 + x], expected) << x << "," << y;  // not mirrored, not altered
      }
    }
  }
  for (const log::MessageBuffer& s : images) {
    msgs::ReadView<msgs::Image> im = msgs::ReadMessage<msgs::Image>(s.bytes());
    ASSERT_EQ(im->encoding, msgs::Encoding::kRgb8);
    const auto* p = reinterpret_cast<const uint8_t*>(im.payload.data());
    EXPECT_EQ(p[(10 * 640 + 300) * 3 + 0], 300 & 255);
    EXPECT_EQ(p[(10 * 640 + 300) * 3 + 1], 10);
  }
  // Stamps: monotonic mid-exposure estimates, increasing, ~33 ms per device frame (a frame the
  // device skipped under load spans several periods: divide by the frame numbers' difference).
  msgs::ReadView<msgs::Image> a = msgs::ReadMessage<msgs::Image>(depths.front().bytes());
  msgs::ReadView<msgs::Image> b = msgs::ReadMessage<msgs::Image>(depths.back().bytes());
  const auto frame_of = [](const msgs::ReadView<msgs::Image>& d) {
    return reinterpret_cast<const uint16_t*>(d.payload.data())[8] - 816;
  };
  const int frames = frame_of(b) - frame_of(a);
  ASSERT_GT(frames, 0);
  EXPECT_GT(b->header.stamp_mono_ns, a->header.stamp_mono_ns);
  EXPECT_NEAR((b->header.stamp_mono_ns - a->header.stamp_mono_ns) / 1e6 / frames, 33.3, 8);
}

TEST_F(CaptureIntegrationTest, OpenNi2SoftwareRegistrationAndStall) {
  bus::Subscriber depth = ImageSubscriber("/camera/depth");
  Result r = Run("PROBELESS_VIRTUAL_NO_REGISTRATION=1 LD_LIBRARY_PATH=" + kOpenNi2Dir + " " + kBin +
                 "/capture_openni2 --ros-args -p uri:=probeless://virtual -p max_frames:=10");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.err.find("software depth-to-colour registration"), std::string::npos) << r.err;
  std::vector<bus::Sample> depths = TakeAll(depth, 64, 1s);
  ASSERT_GE(depths.size(), 3u);
  msgs::ReadView<msgs::Image> d = msgs::ReadMessage<msgs::Image>(depths.back().data());
  const auto* mm = reinterpret_cast<const uint16_t*>(d.payload.data());
  size_t valid = 0;
  for (size_t p = 0; p < 640 * 480; ++p) {
    if (mm[p] == 0) continue;
    ++valid;
    ASSERT_GE(mm[p], 800);
    ASSERT_LE(mm[p], 3000);
  }
  EXPECT_GT(valid, 640u * 480 * 9 / 10);

  // A device that stops delivering: detected and reported within about a second.
  r = Run("PROBELESS_VIRTUAL_FRAMES=5 LD_LIBRARY_PATH=" + kOpenNi2Dir + " " + kBin +
          "/capture_openni2 --ros-args -p uri:=probeless://virtual");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("[error] [/capture_openni2] OpenNI2 device 'probeless://virtual' (probeless "
                       "Virtual RGB-D) delivered no frame for 1.00 s: check the cable and USB "
                       "bandwidth, or replug it (set param retry: true to wait for it)"),
            std::string::npos)
      << r.err;
  EXPECT_LT(r.seconds, 5.0);
}

TEST_F(CaptureIntegrationTest, NodesWithoutTheirDeviceFailWithOneLine) {
  Result r = Run(kBin + "/capture_v4l2 --ros-args -p device:=/dev/video_probeless_missing");
  EXPECT_EQ(r.code, 1);
  EXPECT_EQ(r.err,
            "[error] [/capture_v4l2] V4L2 device '/dev/video_probeless_missing' does not exist: "
            "plug the camera in or pick another with param device (ls /dev/v4l/by-id) (set param "
            "retry: true to wait for it)\n");
  r = Run(kBin + "/capture_v4l2 --ros-args -p device:=/dev/null");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(
      r.err.find("[error] [/capture_v4l2] V4L2 device '/dev/null' is not a V4L2 video device"),
      std::string::npos)
      << r.err;
  r = Run(kBin + "/capture_openni2 --ros-args -p uri:=/nonexistent/session.oni");
  EXPECT_EQ(r.code, 1);
  EXPECT_EQ(r.err,
            "[error] [/capture_openni2] OpenNI2 recording '/nonexistent/session.oni' does not "
            "exist: give the path of an .oni file\n");
  r = Run(kBin + "/capture_openni2 --ros-args -p uri:=usb://1/2");  // system drivers, no device
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("OpenNI2 device 'usb://1/2' is not connected"), std::string::npos) << r.err;
  // A driver that leaves a thread running at shutdown, as Debian's PS1080 does when its udev
  // thread is late on a loaded machine: unloading it would crash after the error (exit 139).
  for (int i = 0; i < 3; ++i) {
    r = Run("PROBELESS_VIRTUAL_STRAY_THREAD=1 LD_LIBRARY_PATH=" + kOpenNi2Dir + " " + kBin +
            "/capture_openni2 --ros-args -p uri:=usb://1/2");
    EXPECT_EQ(r.code, 1) << r.err;
    EXPECT_NE(
        r.err.find("OpenNI2 device 'usb://1/2' is not connected (found: probeless://virtual)"),
        std::string::npos)
        << r.err;
  }
  r = Run(kBin + "/capture_freenect");  // the real libfreenect, no Kinect here
  EXPECT_EQ(r.code, 1);
  EXPECT_TRUE(r.err.find("libfreenect finds no Kinect v1") != std::string::npos ||
              r.err.find("libfreenect could not initialise libusb") != std::string::npos)
      << r.err;
  // A device index beyond int (issue #22: was an uncaught std::out_of_range from stoi): bad input.
  r = Run(kBin + "/capture_freenect --ros-args -p \"device:='99999999999999999999'\"");
  EXPECT_EQ(r.code, 2);
  EXPECT_EQ(r.err,
            "[error] [capture_freenect] param device expects a non-negative integer up to "
            "2147483647, got '99999999999999999999'\n");
  r = Run(kBin + "/capture_libcamera --ros-args -p camera_id:=imx219");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("[error] [/capture_libcamera] libcamera camera 'imx219' not found"),
            std::string::npos)
      << r.err;
  r = Run(kBin + "/capture_v4l2 --ros-args -p device:=/dev/video0 -p width:=-5");
  EXPECT_EQ(r.code, 2) << r.err;
}

TEST_F(CaptureIntegrationTest, RetryWaitsForTheDeviceAndStopsPromptly) {
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    const std::string bin = kBin + "/capture_v4l2";
    freopen((dir_ / "retry.err").c_str(), "w", stderr);
    execl(bin.c_str(), bin.c_str(), "--ros-args", "-p", "device:=/dev/video_probeless_missing",
          "-p", "retry:=true", "-p", "retry_period_s:=0.2", nullptr);
    _exit(127);
  }
  std::this_thread::sleep_for(1s);
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, WNOHANG), 0) << "the node gave up instead of waiting";
  const auto start = std::chrono::steady_clock::now();
  kill(pid, SIGTERM);
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  EXPECT_LT(std::chrono::steady_clock::now() - start, 1s);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
  const std::string err = ReadText(dir_ / "retry.err");
  EXPECT_EQ(
      err,
      "[warn] [/capture_v4l2] V4L2 device '/dev/video_probeless_missing' does not exist: plug "
      "the camera in or pick another with param device (ls /dev/v4l/by-id) (retrying every "
      "0.2 s)\n");
}

}  // namespace
