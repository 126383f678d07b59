// calibrate: checkerboard calibration of a camera from its image topic; writes a ROS camera_info
// YAML file that every capture node reads with param camera_info_url.
//
//   calibrate --size 9x6 --square 0.025 [--topic /camera/image] [--frames 20] [--out camera.yaml]
//             [--name webcam] [--min-interval 0.5]
//
// --size is the number of INNER corners (columns x rows); --square the square side in metres.
// Collects --frames views in which the whole board is found (at least --min-interval seconds
// apart; move the board between them: tilt it, cover the corners of the image), then runs
// cv::calibrateCamera (plumb_bob) and prints the RMS reprojection error. Exit: 0 written,
// 1 calibration failed, 2 bad options.
#include "probeless/node/main.h"

#include <chrono>
#include <cstdio>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "probeless/calib/calibration.h"
#include "probeless/msgs/image.h"
#include "probeless/node/flags.h"
#include "probeless/node/node.h"
#include "probeless/parse/number.h"

namespace {

using namespace probeless;

int Run(int argc, char** argv) {
  // Defaults, then the node's params (-p name:=value), then these flags.
  std::string topic = "/camera/image", out = "camera.yaml", name = "camera", size_text = "9x6";
  double square = 0.025;
  int frames = 20;
  double min_interval = 0.5;
  node::FlagParser flags("calibrate",
                         "checkerboard calibration of a camera from its image topic; writes a ROS "
                         "camera_info YAML file");
  flags.Add("--size", &size_text, "COLSxROWS", "INNER corners of the board");
  flags.Add("--square", &square, "M", "square side in metres");
  flags.Add("--topic", &topic, "TOPIC", "the camera's image topic");
  flags.Add("--frames", &frames, "N", "views with the whole board found", 3);
  flags.Add("--out", &out, "FILE.yaml", "the camera_info file to write");
  flags.Add("--name", &name, "NAME", "camera_name in the file");
  flags.Add("--min-interval", &min_interval, "S", "seconds between two views at least");
  node::Node node(argc, argv, "calibrate", flags.Usage());  // answers --help
  topic = node.Param("topic", topic);
  out = node.Param("out", out);
  name = node.Param("name", name);
  size_text = node.Param("size", size_text);
  square = node.Param("square", square);
  frames = node.Param("frames", frames);
  min_interval = node.Param("min_interval", min_interval);
  std::vector<const char*> args = {argv[0]};
  for (const std::string& arg : node.args()) args.push_back(arg.c_str());
  if (!flags.Parse(static_cast<int>(args.size()), args.data())) return 0;  // --help printed
  // Whole-text parse: sscanf took "9x6abc" and "9x6x2" as 9x6.
  const size_t x = size_text.find('x');
  const std::string_view size_view(size_text);
  const auto cols_parsed = parse::TryParseInteger<int>(size_view.substr(0, x), 2);
  const auto rows_parsed = x == std::string::npos
                               ? std::nullopt
                               : parse::TryParseInteger<int>(size_view.substr(x + 1), 2);
  const int cols = cols_parsed.value_or(0), rows = rows_parsed.value_or(0);
  if (!cols_parsed || !rows_parsed) {
    throw node::UsageError("--size must be COLSxROWS inner corners, e.g. 9x6, got '" + size_text +
                           "'");
  }
  if (!(square > 0) || frames < 3) throw node::UsageError("--square must be > 0 and --frames >= 3");
  const cv::Size pattern(cols, rows);
  std::vector<cv::Point3f> board;
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) board.emplace_back(c * square, r * square, 0.0f);
  }
  bus::Subscriber subscriber = node.CreateSubscriber<msgs::Image>(topic, {.queue_depth = 1});
  node.Info() << "waiting for a " << cols << "x" << rows << " board on " << topic << " (" << frames
              << " views)";
  std::vector<std::vector<cv::Point2f>> image_points;
  cv::Size image_size;
  auto last = std::chrono::steady_clock::now() - std::chrono::hours(1);
  while (node.ok() && static_cast<int>(image_points.size()) < frames) {
    std::optional<bus::Sample> sample = subscriber.Take(std::chrono::milliseconds(100));
    if (!sample) continue;
    msgs::ReadView<msgs::Image> im = msgs::ReadMessage<msgs::Image>(sample->data());
    cv::Mat grey;
    const int type = im->encoding == msgs::Encoding::kMono8 ? CV_8UC1 : CV_8UC3;
    if (im->encoding != msgs::Encoding::kMono8 && im->encoding != msgs::Encoding::kRgb8 &&
        im->encoding != msgs::Encoding::kBgr8) {
      throw node::UsageError(topic + " carries " + std::string(msgs::EncodingName(im->encoding)) +
                             " images: expected rgb8, bgr8 or mono8");
    }
    im->Validate(im.payload.size());
    cv::Mat view(static_cast<int>(im->height), static_cast<int>(im->width), type,
                 const_cast<std::byte*>(im.payload.data()), im->step);
    if (type == CV_8UC3) {
      cv::cvtColor(view, grey,
                   im->encoding == msgs::Encoding::kRgb8 ? cv::COLOR_RGB2GRAY : cv::COLOR_BGR2GRAY);
    } else {
      grey = view;
    }
    if (std::chrono::steady_clock::now() - last < std::chrono::duration<double>(min_interval)) {
      continue;
    }
    std::vector<cv::Point2f> corners;
    if (!cv::findChessboardCorners(grey, pattern, corners,
                                   cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE |
                                       cv::CALIB_CB_FAST_CHECK)) {
      continue;
    }
    cv::cornerSubPix(grey, corners, cv::Size(11, 11), cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 30, 0.01));
    image_points.push_back(corners);
    image_size = grey.size();
    last = std::chrono::steady_clock::now();
    node.Info() << "view " << image_points.size() << "/" << frames;
  }
  if (static_cast<int>(image_points.size()) < frames) return 0;  // interrupted
  std::vector<std::vector<cv::Point3f>> object_points(image_points.size(), board);
  cv::Mat k, d;
  std::vector<cv::Mat> rvecs, tvecs;
  const double rms =
      cv::calibrateCamera(object_points, image_points, image_size, k, d, rvecs, tvecs);
  calib::Intrinsics intrinsics;
  intrinsics.width = static_cast<uint32_t>(image_size.width);
  intrinsics.height = static_cast<uint32_t>(image_size.height);
  intrinsics.fx = k.at<double>(0, 0);
  intrinsics.fy = k.at<double>(1, 1);
  intrinsics.cx = k.at<double>(0, 2);
  intrinsics.cy = k.at<double>(1, 2);
  intrinsics.model = msgs::DistortionModel::kPlumbBob;
  for (int i = 0; i < 5; ++i) intrinsics.distortion.push_back(d.at<double>(0, i));
  calib::WriteCameraInfoYaml(out, intrinsics, name);
  std::printf(
      "calibrate: %zu views, RMS reprojection error %.3f px, fx %.2f fy %.2f cx %.2f cy %.2f -> "
      "%s\n",
      image_points.size(), rms, intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy,
      out.c_str());
  if (rms > 1.0) node.Warn() << "RMS error above 1 px: use more, sharper, more varied views";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return probeless::node::RunMain("calibrate", [&] { return Run(argc, argv); });
}
