// capture_libcamera: a camera through libcamera (Raspberry Pi camera modules, other CSI sensors,
// UVC via libcamera's uvcvideo pipeline). Publishes `image` (rgb8/bgr8/mono8) and `camera_info`.
//
// Params: camera_id ("" = first; an id from `cam --list` or part of it), width (640), height (480),
// pixel_format (auto | rgb24 | bgr24 | yuyv | mjpeg | grey), buffers (4); controls where the camera
// supports them (unset = leave): auto_exposure (AeEnable), exposure_time_us (ExposureTime),
// analogue_gain (AnalogueGain), auto_white_balance (AwbEnable; false locks it), plus the common
// capture params (capture_node.h). Exit: 0 on shutdown or max_frames, 1 on a device error, 2 on
// bad arguments.
#include <cstdio>

#include "probeless/capture/capture_node.h"
#include "probeless/capture/v4l2.h"

int main(int argc, char** argv) {
  using namespace probeless;
  try {
    node::Node node(argc, argv, "capture_libcamera");
    capture::LibcameraOptions o;
    o.camera_id = node.Param("camera_id", "");
    o.width = static_cast<uint32_t>(node.Param("width", 640));
    o.height = static_cast<uint32_t>(node.Param("height", 480));
    o.pixel_format = node.Param("pixel_format", "auto");
    o.buffers = static_cast<uint32_t>(node.Param("buffers", 4));
    if (node.HasParamOverride("auto_exposure")) o.auto_exposure = node.Param("auto_exposure", true);
    if (node.HasParamOverride("exposure_time_us")) {
      o.exposure_time_us = node.Param("exposure_time_us", 10000.0);
    }
    if (node.HasParamOverride("analogue_gain")) o.analogue_gain = node.Param("analogue_gain", 1.0);
    if (node.HasParamOverride("auto_white_balance")) {
      o.auto_white_balance = node.Param("auto_white_balance", true);
    }
    auto log = [&node](const std::string& line) { node.Info() << line; };
    return capture::RunCaptureNode(node, [&] { return capture::OpenLibcamera(o, log); });
  } catch (const node::NodeError& e) {
    std::fprintf(stderr, "[error] [capture_libcamera] %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "[error] [capture_libcamera] %s\n", e.what());
    return 1;
  }
}
