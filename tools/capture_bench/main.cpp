// capture_bench: single-core time of the capture conversions on a 640x480 frame, written straight
// into a bus-slot-sized buffer: YUYV -> rgb8, MJPEG (quality 90, libjpeg-turbo) -> rgb8, Kinect
// 11-bit -> depth16 mm, and software depth registration. Prints JSON (median and p90 ms per frame,
// and frames per second) on stdout, and to --json FILE. Budget: <= 3 ms per frame.
//
//   capture_bench [--json OUT] [--iterations N]
#include "probeless/node/main.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <functional>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "probeless/capture/convert.h"
#include "probeless/capture/registration.h"
#include "probeless/node/flags.h"

namespace {

using namespace probeless;
using namespace probeless::capture;

struct Figure {
  std::string name;
  double median_ms;
  double p90_ms;
};

Figure Time(const std::string& name, int iterations, const std::function<void()>& body) {
  body();  // warm-up
  std::vector<double> ms;
  for (int i = 0; i < iterations; ++i) {
    const auto t0 = std::chrono::steady_clock::now();
    body();
    ms.push_back(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  std::sort(ms.begin(), ms.end());
  return {name, ms[ms.size() / 2], ms[ms.size() * 9 / 10]};
}

}  // namespace

int Run(int argc, char** argv) {
  std::string json_path;
  int iterations = 200;
  probeless::node::FlagParser flags(
      "capture_bench",
      "single-core time of the capture conversions on a 640x480 frame into a\n"
      "bus-slot-sized buffer (YUYV, MJPEG, Kinect 11-bit depth, depth registration); prints JSON");
  flags.Add("--json", &json_path, "OUT", "also write the JSON to OUT");
  flags.Add("--iterations", &iterations, "N", "timed frames per conversion", 1);
  if (!flags.Parse(argc, argv)) return 0;
  const uint32_t w = 640, h = 480;
  // A natural-ish test pattern (gradients plus texture) so JPEG has real work to do.
  cv::Mat bgr(h, w, CV_8UC3);
  for (uint32_t y = 0; y < h; ++y) {
    for (uint32_t x = 0; x < w; ++x) {
      bgr.at<cv::Vec3b>(y, x) =
          cv::Vec3b(static_cast<uint8_t>(x * 255 / w), static_cast<uint8_t>((x * y) % 251),
                    static_cast<uint8_t>(y * 255 / h));
    }
  }
  std::vector<uint8_t> jpeg;
  cv::imencode(".jpg", bgr, jpeg, {cv::IMWRITE_JPEG_QUALITY, 90});
  std::vector<uint8_t> yuyv(w * h * 2);
  for (size_t i = 0; i < yuyv.size(); ++i) yuyv[i] = static_cast<uint8_t>((i * 7) % 256);
  std::vector<uint16_t> raw(w * h);
  for (size_t i = 0; i < raw.size(); ++i) raw[i] = static_cast<uint16_t>(500 + (i % 500));
  std::vector<std::byte> slot(msgs::Image::PackedPayloadBytes(w, h, msgs::Encoding::kRgb8));
  msgs::Image image;

  std::vector<Figure> figures;
  RawFrame f{PixelFormat::kYuyv, w, h, 0, yuyv};
  figures.push_back(Time("yuyv_to_rgb8", iterations, [&] { ConvertFrame(f, image, slot); }));
  RawFrame j{PixelFormat::kMjpeg, w, h, 0, jpeg};
  figures.push_back(Time("mjpeg_to_rgb8", iterations, [&] { ConvertFrame(j, image, slot); }));
  RawFrame k{PixelFormat::kKinectRaw11,
             w,
             h,
             0,
             {reinterpret_cast<const uint8_t*>(raw.data()), raw.size() * 2}};
  figures.push_back(
      Time("kinect11_to_depth16_mm", iterations, [&] { ConvertFrame(k, image, slot); }));
  std::vector<uint16_t> depth(w * h, 1500), registered(w * h);
  const Intrinsics dk = calib::IntrinsicsFromFieldOfView(w, h, 58);
  const Intrinsics ck = calib::IntrinsicsFromFieldOfView(w, h, 62);
  DepthToColour extrinsics;
  extrinsics.translation_m = {-0.025, 0, 0};
  figures.push_back(Time("software_registration_depth16", iterations / 4 + 1, [&] {
    RegisterDepthToColour(depth.data(), w * 2, dk, ck, extrinsics, registered.data(), w * 2);
  }));

  std::ostringstream json;
  json << "{\n  \"frame\": \"640x480\",\n  \"iterations\": " << iterations
       << ",\n  \"mjpeg_bytes\": " << jpeg.size() << ",\n  \"budget_ms\": 3.0,\n  \"results\": [\n";
  for (size_t i = 0; i < figures.size(); ++i) {
    char line[256];
    std::snprintf(
        line, sizeof(line),
        "    {\"name\": \"%s\", \"median_ms\": %.3f, \"p90_ms\": %.3f, \"fps\": %.0f}%s\n",
        figures[i].name.c_str(), figures[i].median_ms, figures[i].p90_ms,
        1000.0 / figures[i].median_ms, i + 1 < figures.size() ? "," : "");
    json << line;
  }
  json << "  ]\n}\n";
  std::fputs(json.str().c_str(), stdout);
  if (!json_path.empty()) std::ofstream(json_path) << json.str();
  return 0;
}

int main(int argc, char** argv) {
  return probeless::node::RunMain("capture_bench", [&] { return Run(argc, argv); });
}
