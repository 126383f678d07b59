// capture_freenect: a Kinect v1 through libfreenect. Publishes `image` (rgb8 640x480), `depth`
// (depth16 mm, registered to the RGB camera by libfreenect by default) and `camera_info`.
//
// Params: device ("" = first; index or serial), depth_mode (registered | mm | raw), colour (true),
// depth (true), tilt_deg (unset = leave), led (-1 = leave; 0 off, 1 green, 2 red, 3 yellow,
// 4 blink green, 6 blink red/yellow), plus the common capture params (capture_node.h: frame_id,
// camera_info_url, retry, stall_timeout_s, max_frames, ...). Runs against fakenect too
// (LD_LIBRARY_PATH=/usr/lib/x86_64-linux-gnu/fakenect FAKENECT_PATH=dump). Exit: 0 on shutdown or
// max_frames, 1 on a device error, 2 on bad arguments.
#include <cmath>
#include <cstdio>
#include <string>

#include "probeless/capture/capture_node.h"
#include "probeless/parse/number.h"

int main(int argc, char** argv) {
  using namespace probeless;
  try {
    node::Node node(argc, argv, "capture_freenect");
    capture::FreenectOptions options;
    options.device = node.Param("device", "");
    // An all-digit device is libfreenect's int index: checked here so that a 20-digit one is bad
    // input (exit 2) before any USB access; OpenFreenect checks it again for other callers.
    if (!options.device.empty() &&
        options.device.find_first_not_of("0123456789") == std::string::npos) {
      parse::ParseInteger<int>("param device", options.device, 0);
    }
    options.depth_mode = node.Param("depth_mode", "registered");
    options.colour = node.Param("colour", true);
    options.depth = node.Param("depth", true);
    options.tilt_deg = node.Param("tilt_deg", std::nan(""));
    options.led = node.Param("led", -1);
    auto log = [&node](const std::string& line) { node.Warn() << line; };
    return capture::RunCaptureNode(node, [&] { return capture::OpenFreenect(options, log); });
  } catch (const node::NodeError& e) {
    std::fprintf(stderr, "[error] [capture_freenect] %s\n", e.what());
    return 2;
  } catch (const parse::NumberError& e) {
    std::fprintf(stderr, "[error] [capture_freenect] %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "[error] [capture_freenect] %s\n", e.what());
    return 1;
  }
}
