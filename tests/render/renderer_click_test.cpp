// Click-to-place in the renderer's viewer window (issue #19 item 7), end to end: the renderer in
// scene mode with a GLFW window on its own Xvfb server, a reconstructed wall 1 m in front of the
// camera with a hole (no depth) on its left, and real mouse clicks injected with xdotool. A click
// on the wall moves the virtual sphere onto the wall at that pixel (the log line's centre and the
// composite); after a resize (letterbox bars) a second click moves it again; a click on the hole
// logs "no reconstructed surface" and the sphere stays. Skipped only when no X server can be
// started.
#include <gtest/gtest.h>
#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <optional>
#include <regex>
#include <string>
#include <thread>

#include "probeless/bus/bus.h"
#include "probeless/msgs/msgs.h"
#include "probeless/testing/testing.h"

namespace probeless {
namespace {

using namespace std::chrono_literals;

constexpr uint32_t kW = 160, kH = 120;
constexpr double kF = 150, kCx = 79.5, kCy = 59.5;
constexpr int kHoleColumns = 40;   // u < 40: no depth (no reconstructed surface)
constexpr double kWallZ = 1.0;     // metres, facing the camera
constexpr double kRadius = 0.066;  // the nose (0.022 m) at object_scale 3
constexpr float kCameraX = 0.5f;   // camera -> world: 0.5 m along x
constexpr int kScale = 4;          // the 640 x 480 window shows the 160 x 120 image 4x

// Runs `command` through the shell; its stdout, trailing newline removed.
std::string Output(const std::string& command, int* code = nullptr) {
  FILE* pipe = popen(command.c_str(), "r");
  std::string out;
  char buffer[512];
  size_t n;
  while ((n = fread(buffer, 1, sizeof(buffer), pipe)) > 0) out.append(buffer, n);
  const int status = pclose(pipe);
  if (code != nullptr) *code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  while (!out.empty() && (out.back() == '\n' || out.back() == '\r')) out.pop_back();
  return out;
}

// An Xvfb server on a free display (Xvfb -displayfd picks it); stopped when destroyed.
class XServer {
 public:
  explicit XServer(const std::string& dir) {
    if (std::system("command -v Xvfb > /dev/null 2>&1") != 0) {
      why_ = "Xvfb is missing (apt-get install xvfb)";
      return;
    }
    const std::string display_file = dir + "/display", pid_file = dir + "/xvfb.pid";
    const std::string command = "Xvfb -displayfd 3 -screen 0 1024x768x24 -nolisten tcp 3> " +
                                display_file + " > " + dir + "/xvfb.log 2>&1 & echo $! > " +
                                pid_file;
    if (std::system(command.c_str()) != 0) {
      why_ = "cannot run Xvfb";
      return;
    }
    for (int i = 0; i < 200 && display_.empty(); ++i) {
      std::this_thread::sleep_for(50ms);
      const std::string text = testing::ReadText(display_file);
      if (!text.empty() && text.back() == '\n') display_ = ":" + text.substr(0, text.size() - 1);
    }
    pid_ = std::atoi(testing::ReadText(pid_file).c_str());
    if (display_.empty()) why_ = "Xvfb did not start: " + testing::ReadText(dir + "/xvfb.log");
  }
  ~XServer() {
    if (pid_ > 0) ::kill(pid_, SIGTERM);
  }
  const std::string& display() const { return display_; }
  const std::string& why_not() const { return why_; }

 private:
  std::string display_, why_;
  pid_t pid_ = -1;
};

template <class T>
bus::Publisher LatchedPublisher(const std::string& topic, size_t bytes) {
  bus::PublisherOptions options;
  options.max_message_bytes = bytes;
  options.history = 1;  // the node subscribes later
  return bus::Publisher(topic, msgs::TopicTypeOf<T>(), options);
}

// The first "viewer click at pixel [u, v]: ..." line of `err` for that pixel, "" if none yet.
std::string ClickLine(const std::string& err, int u, int v) {
  const std::string key =
      "viewer click at pixel [" + std::to_string(u) + ", " + std::to_string(v) + "]";
  const size_t at = err.find(key);
  if (at == std::string::npos) return "";
  return err.substr(at, err.find('\n', at) - at);
}

// The world position the sphere's centre must get for a click on the wall at pixel (u, v): the
// wall point there, pushed the radius towards the camera (the wall's normal).
std::array<double, 3> ExpectedCentre(int u, int v) {
  return {(u - kCx) / kF * kWallZ + kCameraX, (v - kCy) / kF * kWallZ, kWallZ - kRadius};
}

// The centroid (u, v) of the red pixels (the clown-nose sphere) of a composite; nullopt if none.
std::optional<std::array<double, 2>> RedCentroid(bus::Subscriber& composites) {
  std::optional<bus::Sample> last;
  // The newest composite: drain what is queued, then wait for one drawn after the click.
  while (auto s = composites.TryTake()) last = std::move(s);
  last = composites.Take(10s);
  if (!last) return std::nullopt;
  const auto m = msgs::ReadMessage<msgs::Image>(last->data());
  const auto* rgb = reinterpret_cast<const uint8_t*>(m.payload.data());
  double su = 0, sv = 0;
  int n = 0;
  for (uint32_t y = 0; y < m->height; ++y) {
    for (uint32_t x = 0; x < m->width; ++x) {
      const uint8_t* p = rgb + (static_cast<size_t>(y) * m->width + x) * 3;
      if (p[0] > 120 && p[0] > 2 * p[1] && p[0] > 2 * p[2]) su += x, sv += y, ++n;
    }
  }
  if (n < 20) return std::nullopt;
  return std::array<double, 2>{su / n, sv / n};
}

// Where the sphere centred at world point c projects (camera = world shifted by kCameraX).
std::array<double, 2> Project(const std::array<double, 3>& c) {
  return {kCx + kF * (c[0] - kCameraX) / c[2], kCy + kF * c[1] / c[2]};
}

TEST(RendererClick, AClickPlacesTheObjectsOnTheSurfaceAtThatPixel) {
  testing::TempDir dir("renderer_click");
  XServer x(dir.path());
  if (x.display().empty()) GTEST_SKIP() << "no X server could be started (" << x.why_not() << ")";
  ASSERT_EQ(std::system("command -v xdotool > /dev/null 2>&1"), 0)
      << "xdotool is missing: tools/setup installs it (apt-get install xdotool)";
  ::setenv("DISPLAY", x.display().c_str(), 1);

  bus::Publisher image_pub = LatchedPublisher<msgs::Image>(
      "/camera/image", msgs::Image::MessageBytesFor(kW, kH, msgs::Encoding::kRgb8));
  bus::Publisher info_pub =
      LatchedPublisher<msgs::CameraInfo>("/camera/camera_info", sizeof(msgs::CameraInfo));
  bus::Publisher pose_pub = LatchedPublisher<msgs::Pose>("/scene/pose", sizeof(msgs::Pose));
  bus::Publisher gbuffer_pub = LatchedPublisher<msgs::GeometryBuffer>(
      "/scene/gbuffer", msgs::GeometryBuffer::MessageBytesFor(kW, kH));
  bus::Publisher light_pub("/light", msgs::TopicTypeOf<msgs::ShLight>(),
                           {.max_message_bytes = sizeof(msgs::ShLight)});
  bus::Subscriber composites("/render/composite", msgs::TopicTypeOf<msgs::Image>(),
                             {.queue_depth = 4});
  {
    bus::Loan loan = image_pub.Borrow(msgs::Image::MessageBytesFor(kW, kH, msgs::Encoding::kRgb8));
    auto m = msgs::WriteMessage<msgs::Image>(loan.data());
    m->Init(kW, kH, msgs::Encoding::kRgb8);
    std::memset(m.payload.data(), 110, m->PayloadBytes());  // a grey wall
    image_pub.Publish(std::move(loan));
  }
  {
    bus::Loan loan = info_pub.Borrow(sizeof(msgs::CameraInfo));
    auto m = msgs::WriteMessage<msgs::CameraInfo>(loan.data());
    m->width = kW;
    m->height = kH;
    m->fx = m->fy = kF;
    m->cx = kCx;
    m->cy = kCy;
    info_pub.Publish(std::move(loan));
  }
  {
    bus::Loan loan = pose_pub.Borrow(sizeof(msgs::Pose));
    auto m = msgs::WriteMessage<msgs::Pose>(loan.data());
    m->transform.rotation.w = 1;
    m->transform.translation.x = kCameraX;
    pose_pub.Publish(std::move(loan));
  }
  {
    bus::Loan loan = gbuffer_pub.Borrow(msgs::GeometryBuffer::MessageBytesFor(kW, kH));
    auto m = msgs::WriteMessage<msgs::GeometryBuffer>(loan.data());
    m->Init(kW, kH);
    const std::span<float> depth = msgs::DepthPlane(*m, m.payload);
    const std::span<float> normals = msgs::NormalsPlane(*m, m.payload);
    for (uint32_t p = 0; p < kW * kH; ++p) {
      const bool hole = p % kW < kHoleColumns;
      depth[p] = hole ? 0.0f : static_cast<float>(kWallZ);
      normals[3 * p] = normals[3 * p + 1] = 0;
      normals[3 * p + 2] = hole ? 0.0f : -1.0f;
    }
    for (uint8_t& c : msgs::ColourPlane(*m, m.payload)) c = 110;
    gbuffer_pub.Publish(std::move(loan));
  }

  testing::Process renderer(
      "renderer",
      {"--ros-args", "-p", "mode:=scene", "-p", "backend:=window", "-p", "objects:=[nose]", "-p",
       "object_scale:=3.0", "-p", "samples:=16", "-p", "tone:=clamp", "-p", "ssdo_directions:=8"});
  for (int i = 0; i < 1500 && light_pub.SubscriberCount() == 0; ++i)
    std::this_thread::sleep_for(20ms);
  ASSERT_GT(light_pub.SubscriberCount(), 0u) << renderer.Err();
  // Lights at 10 Hz: each draws and presents a frame, which polls the window's events.
  std::atomic<bool> lighting{true};
  std::thread lights([&] {
    msgs::ShLight light;
    light.bands = 3;
    light.coefficients[0][0] = light.coefficients[0][1] = light.coefficients[0][2] = 3.0f;
    light.units = msgs::ShLightUnits::kLinear;
    while (lighting) {
      light.header.StampNow();
      light_pub.PublishCopy(std::as_bytes(std::span(&light, 1)));
      std::this_thread::sleep_for(100ms);
    }
  });
  struct StopLights {
    std::atomic<bool>& flag;
    std::thread& thread;
    ~StopLights() {
      flag = false;
      thread.join();
    }
  } stop_lights{lighting, lights};

  ASSERT_TRUE(composites.Take(30s)) << renderer.Err();
  int code = 0;
  const std::string window =
      Output("timeout 20 xdotool search --sync --onlyvisible --name 'probeless renderer' | head -1",
             &code);
  ASSERT_FALSE(window.empty()) << "xdotool found no renderer window; " << renderer.Err();
  auto click = [&](int x, int y) {
    const std::string command = "xdotool mousemove --window " + window + " " + std::to_string(x) +
                                " " + std::to_string(y) + " click 1";
    ASSERT_EQ(std::system(command.c_str()), 0) << command;
  };
  auto wait_line = [&](int u, int v) {
    std::string line;
    for (int i = 0; i < 300 && (line = ClickLine(renderer.Err(), u, v)).empty(); ++i) {
      std::this_thread::sleep_for(50ms);
    }
    return line;
  };
  const std::regex centre_re(
      R"(centre at \(([-0-9.e]+), ([-0-9.e]+), ([-0-9.e]+)\) m, world frame)");
  auto expect_placed = [&](int u, int v) {
    const std::string line = wait_line(u, v);
    ASSERT_FALSE(line.empty()) << "no click line for [" << u << ", " << v
                               << "]: " << renderer.Err();
    std::smatch m;
    ASSERT_TRUE(std::regex_search(line, m, centre_re)) << line;
    const auto want = ExpectedCentre(u, v);
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(std::stod(m[k + 1].str()), want[k], 0.003) << line;
    const auto red = RedCentroid(composites);
    ASSERT_TRUE(red) << "no sphere in the composite after the click at [" << u << ", " << v << "]";
    const auto at = Project(want);
    EXPECT_NEAR((*red)[0], at[0], 1.5) << line;
    EXPECT_NEAR((*red)[1], at[1], 1.5) << line;
  };

  // The 640 x 480 window shows the image 4x: window pixel 4u + 2 is image pixel u.
  click(kScale * 100 + 2, kScale * 60 + 2);
  expect_placed(100, 60);

  // Wider window: 80-pixel bars left and right; a second click moves the sphere again.
  ASSERT_EQ(std::system(("xdotool windowsize " + window + " 800 480").c_str()), 0);
  std::this_thread::sleep_for(500ms);
  click(80 + kScale * 60 + 2, kScale * 80 + 2);
  expect_placed(60, 80);

  // The hole: one clear line, the sphere stays where the second click put it.
  click(80 + kScale * 20 + 2, kScale * 60 + 2);
  const std::string line = wait_line(20, 60);
  EXPECT_EQ(line,
            "viewer click at pixel [20, 60]: no reconstructed surface there; the objects stay "
            "where they were")
      << renderer.Err();
  const auto red = RedCentroid(composites);
  ASSERT_TRUE(red);
  const auto at = Project(ExpectedCentre(60, 80));
  EXPECT_NEAR((*red)[0], at[0], 1.5);
  EXPECT_NEAR((*red)[1], at[1], 1.5);

  // The renderer's click lines, for the test log.
  const std::string err = renderer.Err();
  for (size_t at = err.find("viewer click"); at != std::string::npos;
       at = err.find("viewer click", at + 1)) {
    std::printf("renderer: %s\n", err.substr(at, err.find('\n', at) - at).c_str());
  }
  renderer.Signal(SIGINT);
  EXPECT_EQ(renderer.Wait(20s), 0) << renderer.Err();
}

}  // namespace
}  // namespace probeless
