// capture_openni2: an OpenNI2 device (PrimeSense Carmine, Asus Xtion, Orbbec Astra with its
// driver, ...) or an .oni recording. Publishes `image` (rgb8), `depth` (depth16 mm, registered to
// colour: in hardware when the device supports it, else in software) and `camera_info`.
//
// Params: uri ("" = first device; a path ending in .oni = a recording), width (640), height (480),
// fps (30), colour (true), depth (true), registration (auto | hardware | software | off),
// depth_to_colour_translation_m ([-0.025, 0, 0], for software registration), loop (false, .oni),
// plus the common capture params (capture_node.h). Exit: 0 on shutdown or max_frames, 1 on a device
// error (or the end of a recording), 2 on bad arguments.
#include <cstdio>

#include "probeless/capture/capture_node.h"

int main(int argc, char** argv) {
  using namespace probeless;
  try {
    node::Node node(argc, argv, "capture_openni2");
    capture::OpenNi2Options options;
    options.uri = node.Param("uri", "");
    options.width = static_cast<uint32_t>(node.Param("width", 640));
    options.height = static_cast<uint32_t>(node.Param("height", 480));
    options.fps = node.Param("fps", 30.0);
    options.colour = node.Param("colour", true);
    options.depth = node.Param("depth", true);
    options.registration = node.Param("registration", "auto");
    const std::vector<double> t =
        node.Param("depth_to_colour_translation_m", std::vector<double>{-0.025, 0, 0});
    if (t.size() != 3) {
      throw node::NodeError("param depth_to_colour_translation_m needs 3 values (x, y, z metres)");
    }
    options.depth_to_colour.translation_m = {t[0], t[1], t[2]};
    options.loop_recording = node.Param("loop", false);
    auto log = [&node](const std::string& line) { node.Info() << line; };
    return capture::RunCaptureNode(node, [&] { return capture::OpenOpenNi2(options, log); });
  } catch (const node::NodeError& e) {
    std::fprintf(stderr, "[error] [capture_openni2] %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "[error] [capture_openni2] %s\n", e.what());
    return 1;
  }
}
