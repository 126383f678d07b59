// rectify: lens-distortion rectification of a camera stream, the role of ROS image_proc /
// depth_image_proc rectify (rectify::Rectifier; docs/rectify.md). Subscribes `image` (rgb8, bgr8,
// mono8, mono16, rgb32f), `depth` (depth16 or float32; a colour-only camera simply never
// publishes it) and `camera_info`. Publishes, with each input's header, `image_rect` and
// `depth_rect` (same size and encoding, written straight into the loaned bus slot: colour
// bilinear, depth nearest or edge-aware) and `camera_info_rect` (plumb_bob with five zeros, the
// new camera matrix; ROS's P = [K | 0] with the default alpha). Maps are computed once per
// calibration, again only when camera_info changes. A camera without distortion passes through
// (one copy into the slot, no resampling). Frames that arrive before the first camera_info wait
// (the latest of each stream) until it comes; after 30 frames without any, frames pass through
// unrectified (with a warning) so that a log without camera_info does not stall its consumers.
//
// Params: alpha (-1: keep the calibrated K; 0..1 OpenCV free scaling), depth_interpolation
// (nearest | edge_aware), depth_edge_tolerance (0.03, fraction of the depth), threads (1: OpenCV
// threads of the remap). Exit: 0 on SIGINT/SIGTERM, 2 on bad params, 1 otherwise. A malformed or
// inconsistent camera_info or image is rejected with one line naming the topic (node::Node::Spin).
#include "probeless/node/main.h"

#include <chrono>
#include <optional>
#include <string>

#include "probeless/msgs/msgs.h"
#include "probeless/node/growing_publisher.h"
#include "probeless/node/node.h"
#include "probeless/rectify/rectify.h"

namespace {

using namespace probeless;

// One rectified output stream: its publisher follows the image size (node::GrowingPublisher).
struct Output {
  node::GrowingPublisher<msgs::Image> publisher;
  uint64_t published = 0;
};

int Run(int argc, char** argv) {
  node::Node node(argc, argv, "rectify");
  rectify::RectifyOptions options;
  options.alpha = node.Param("alpha", options.alpha, {.max = 1.0});  // < 0 keeps K
  const std::string interpolation =
      node.Param("depth_interpolation", "nearest", {.choices = {"nearest", "edge_aware"}});
  options.depth_interpolation = interpolation == "nearest"
                                    ? rectify::DepthInterpolation::kNearest
                                    : rectify::DepthInterpolation::kEdgeAware;
  options.depth_edge_tolerance = node.Param("depth_edge_tolerance", options.depth_edge_tolerance,
                                            {.min = 0.0, .min_exclusive = true});
  const int threads = node.Param("threads", 1, {.min = 1.0});
  rectify::SetThreads(threads);

  const std::string info_topic = node.ResolveTopicName("camera_info");
  const std::string image_topic = node.ResolveTopicName("image");
  const std::string depth_topic = node.ResolveTopicName("depth");
  bus::Subscriber image_sub = node.CreateSubscriber<msgs::Image>("image", {.queue_depth = 4});
  bus::Subscriber depth_sub = node.CreateSubscriber<msgs::Image>("depth", {.queue_depth = 4});
  bus::Subscriber info_sub =
      node.CreateSubscriber<msgs::CameraInfo>("camera_info", {.queue_depth = 4});
  bus::Publisher info_pub = node.CreatePublisher<msgs::CameraInfo>("camera_info_rect");
  Output image_out{{node, "image_rect"}}, depth_out{{node, "depth_rect"}};

  std::optional<rectify::Rectifier> rectifier;
  std::optional<bus::Sample> waiting_image, waiting_depth;
  uint64_t map_builds = 0;
  double total_ms = 0;
  uint64_t timed = 0;

  // Publishes `sample` rectified, or copied unchanged when there is no calibration at all.
  auto rectify_frame = [&](bus::Sample& sample, const std::string& in_topic, Output& out) {
    const auto in = msgs::ReadMessage<msgs::Image>(sample.data());
    if (msgs::BytesPerPixel(in->encoding) == 0) {
      throw rectify::RectifyError(in_topic + ": invalid image encoding " +
                                  std::to_string(static_cast<uint32_t>(in->encoding)));
    }
    const size_t bytes = msgs::Image::MessageBytesFor(in->width, in->height, in->encoding);
    const auto t0 = std::chrono::steady_clock::now();
    bus::Loan loan = out.publisher.Borrow(bytes);
    msgs::WriteView<msgs::Image> view = msgs::WriteMessage<msgs::Image>(loan.data());
    if (rectifier) {
      rectifier->Rectify(*in, in.payload, *view, view.payload, in_topic);
    } else {
      rectify::CopyImage(*in, in.payload, *view, view.payload, in_topic);
    }
    out.publisher.Publish(std::move(loan));
    total_ms +=
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    ++timed;
    ++out.published;
  };

  auto on_info = [&](bus::Sample&& sample) {
    const msgs::CameraInfo info = *msgs::ReadMessage<msgs::CameraInfo>(sample.data());
    if (!rectifier || !rectifier->Matches(info)) {
      const auto t0 = std::chrono::steady_clock::now();
      rectifier.emplace(info, options, info_topic);
      ++map_builds;
      const double ms =
          std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
      if (rectifier->passthrough()) {
        node.Info() << info_topic << ": " << info.width << "x" << info.height
                    << ", no lens distortion: frames pass through";
      } else {
        node.Info() << info_topic << ": " << info.width << "x" << info.height << " "
                    << msgs::DistortionModelName(info.distortion_model) << ": maps in " << ms
                    << " ms, rectified fx " << rectifier->rectified_info().fx << " fy "
                    << rectifier->rectified_info().fy << " cx " << rectifier->rectified_info().cx
                    << " cy " << rectifier->rectified_info().cy;
      }
    }
    msgs::CameraInfo rectified = rectifier->rectified_info();
    rectified.header = info.header;
    info_pub.PublishCopy(std::as_bytes(std::span(&rectified, 1)));
    if (waiting_image) rectify_frame(*waiting_image, image_topic, image_out);
    if (waiting_depth) rectify_frame(*waiting_depth, depth_topic, depth_out);
    waiting_image.reset();
    waiting_depth.reset();
  };
  // A stream without any camera_info (a log recorded without it) must not stall its consumers:
  // after this many frames they are passed through unrectified (nothing to undistort with).
  constexpr uint64_t kFramesWithoutInfo = 30;
  uint64_t frames_without_info = 0;
  auto on_frame = [&](const std::string& topic, Output& out, std::optional<bus::Sample>& waiting) {
    return [&, topic](bus::Sample&& sample) {
      if (!rectifier && ++frames_without_info <= kFramesWithoutInfo) {
        if (!waiting) node.Info() << topic << ": waiting for " << info_topic;
        waiting = std::move(sample);  // the bus slot is held, not copied
        return;
      }
      if (!rectifier && frames_without_info == kFramesWithoutInfo + 1) {
        node.Warn() << "no " << info_topic << " after " << kFramesWithoutInfo
                    << " frames: passing frames through unrectified until one comes";
      }
      waiting.reset();
      rectify_frame(sample, topic, out);
    };
  };
  node.Spin({{&info_sub, on_info},
             {&image_sub, on_frame(image_topic, image_out, waiting_image)},
             {&depth_sub, on_frame(depth_topic, depth_out, waiting_depth)}});
  node.Info() << "rectified " << image_out.published << " images and " << depth_out.published
              << " depth images (" << (timed ? total_ms / static_cast<double>(timed) : 0.0)
              << " ms each on average), maps built " << map_builds << " time(s)";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return probeless::node::RunMain("rectify", [&] { return Run(argc, argv); });
}
