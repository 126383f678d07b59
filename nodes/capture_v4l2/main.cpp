// capture_v4l2: a V4L2 camera (UVC webcam, capture card) through libv4l2, mmap streaming. Publishes
// `image` (rgb8 from MJPEG/YUYV/RGB, bgr8, mono8) and `camera_info`.
//
// Params: device ("/dev/video0", or part of a /dev/v4l/by-id name or serial), width (640), height
// (480), fps (30), pixel_format (auto | mjpeg | yuyv | rgb24 | bgr24 | grey), buffers (4); controls
// (unset = leave): auto_exposure, exposure_time_us, auto_white_balance,
// white_balance_temperature_k, auto_gain, gain, auto_focus, focus_absolute, brightness, contrast,
// saturation, power_line_frequency; lock_auto (true: after lock_after_s (2.0) seconds, switch the
// auto exposure / white balance / gain that were not set explicitly to manual), plus the common
// capture params (capture_node.h). Exit: 0 on shutdown or max_frames, 1 on a device error, 2 on bad
// arguments.
#include <cstdio>

#include "probeless/capture/capture_node.h"
#include "probeless/capture/v4l2.h"

namespace {

using namespace probeless;

template <class T>
std::optional<T> Optional(node::Node& node, const char* name, T fallback) {
  if (!node.HasParamOverride(name)) return std::nullopt;
  return node.Param<T>(name, fallback);
}

}  // namespace

int main(int argc, char** argv) {
  try {
    node::Node node(argc, argv, "capture_v4l2");
    capture::V4l2Options o;
    o.device = node.Param("device", "/dev/video0");
    o.width = static_cast<uint32_t>(node.Param("width", 640));
    o.height = static_cast<uint32_t>(node.Param("height", 480));
    o.fps = node.Param("fps", 30.0);
    o.pixel_format = node.Param("pixel_format", "auto");
    if (node.Param("width", 640) <= 0 || node.Param("height", 480) <= 0 || !(o.fps > 0)) {
      throw node::NodeError("params width, height and fps must be > 0");
    }
    o.buffers = static_cast<uint32_t>(node.Param("buffers", 4));
    capture::V4l2Controls& c = o.controls;
    c.auto_exposure = Optional<bool>(node, "auto_exposure", false);
    c.exposure_time_us = Optional<double>(node, "exposure_time_us", 0.0);
    c.auto_white_balance = Optional<bool>(node, "auto_white_balance", false);
    c.white_balance_temperature_k = Optional<int64_t>(node, "white_balance_temperature_k", 0);
    c.auto_gain = Optional<bool>(node, "auto_gain", false);
    c.gain = Optional<int64_t>(node, "gain", 0);
    c.auto_focus = Optional<bool>(node, "auto_focus", false);
    c.focus_absolute = Optional<int64_t>(node, "focus_absolute", 0);
    c.brightness = Optional<int64_t>(node, "brightness", 0);
    c.contrast = Optional<int64_t>(node, "contrast", 0);
    c.saturation = Optional<int64_t>(node, "saturation", 0);
    c.power_line_frequency = Optional<int64_t>(node, "power_line_frequency", 0);
    c.lock_auto = node.Param("lock_auto", true);
    c.lock_after_s = node.Param("lock_after_s", 2.0);
    auto log = [&node](const std::string& line) { node.Info() << line; };
    return capture::RunCaptureNode(node, [&] { return capture::OpenV4l2(o, log); });
  } catch (const node::NodeError& e) {
    std::fprintf(stderr, "[error] [capture_v4l2] %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "[error] [capture_v4l2] %s\n", e.what());
    return 1;
  }
}
