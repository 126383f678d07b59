// A video file decoded with OpenCV's VideoCapture, published as rgb8 frames.
#include <cmath>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "camera_info_file.h"
#include "image_io.h"
#include "internal.h"

namespace probeless::dataset::internal {

namespace {

cv::VideoCapture OpenCapture(const std::string& path) {
  cv::VideoCapture capture;
  // FFmpeg first (the same decoder on every machine), then whatever backend OpenCV has.
  for (const int backend : {cv::CAP_FFMPEG, cv::CAP_ANY}) {
    try {
      capture.open(path, backend);
    } catch (const cv::Exception&) {
      capture.release();
    }
    if (capture.isOpened()) break;
  }
  if (!capture.isOpened()) {
    throw DatasetError("cannot open video '" + path +
                       "': expected a video file OpenCV can decode (e.g. MJPG .avi, H.264 .mp4)");
  }
  return capture;
}

// The next frame as rgb8, or an empty matrix at the end.
cv::Mat ReadRgb(cv::VideoCapture& capture, const std::string& path) {
  cv::Mat frame;
  bool ok = false;
  try {
    ok = capture.read(frame);
  } catch (const cv::Exception&) {
    ok = false;
  }
  if (!ok || frame.empty()) return {};
  return ConvertForEncoding(frame, msgs::Encoding::kRgb8, path);
}

class VideoSource : public FrameSource {
 public:
  VideoSource(const std::string& path, const DatasetOptions& options, double fps,
              Intrinsics intrinsics, cv::Size size, uint64_t frame_limit)
      : FrameSource("video", path, frame_limit),
        options_(options),
        fps_(fps),
        intrinsics_(std::move(intrinsics)),
        size_(size) {
    // The container's frame count is an estimate for many formats: counts stay 0 (unknown).
    info_topic_ = AddTopic<msgs::CameraInfo>(TopicName(options.topic_prefix, "camera_info"),
                                             sizeof(msgs::CameraInfo), 0);
    image_topic_ = AddTopic<msgs::Image>(
        TopicName(options.topic_prefix, "image"),
        msgs::Image::MessageBytesFor(size.width, size.height, msgs::Encoding::kRgb8), 0);
  }

 protected:
  bool ReadFrame(uint64_t index, std::vector<StreamMessage>& out) override {
    if (!capture_.isOpened()) {
      capture_ = OpenCapture(path());
      position_ = 0;
    }
    cv::Mat rgb;
    while (position_ <= index) {
      rgb = ReadRgb(capture_, path());
      if (rgb.empty()) return false;
      ++position_;
    }
    if (rgb.size() != size_) {
      throw DatasetError("video '" + path() + "' frame " + std::to_string(index) + " is " +
                         DescribeMat(rgb) + ": expected " + std::to_string(size_.width) + "x" +
                         std::to_string(size_.height) + " like the first frame");
    }
    const uint64_t time = FrameTimeNs(index, fps_);
    const auto stamp = static_cast<int64_t>(time);
    out.push_back(CameraInfoMessage(info_topic_, time, intrinsics_, 0, stamp, index + 1,
                                    options_.camera_frame_id));
    out.push_back(ImageMessage(image_topic_, time, rgb, msgs::Encoding::kRgb8, stamp, index + 1,
                               options_.camera_frame_id));
    return true;
  }

  void OnRewind() override { capture_.release(); }

 private:
  DatasetOptions options_;
  double fps_;
  Intrinsics intrinsics_;
  cv::Size size_;
  cv::VideoCapture capture_;
  uint64_t position_ = 0;  // frames read from capture_
  size_t info_topic_ = 0;
  size_t image_topic_ = 0;
};

}  // namespace

std::unique_ptr<Source> OpenVideo(const std::string& path, const DatasetOptions& options) {
  cv::VideoCapture capture = OpenCapture(path);
  double fps = capture.get(cv::CAP_PROP_FPS);
  if (!std::isfinite(fps) || fps <= 0 || fps > 1000) fps = options.fps;
  const cv::Mat first = ReadRgb(capture, path);
  if (first.empty()) {
    throw DatasetError("video '" + path + "' has no decodable frame");
  }
  capture.release();
  const auto width = static_cast<uint32_t>(first.cols);
  const auto height = static_cast<uint32_t>(first.rows);
  const Intrinsics intrinsics =
      ResolveIntrinsics(options, calib::IntrinsicsFromFieldOfView(width, height), width, height);
  return std::make_unique<VideoSource>(path, options, fps, intrinsics, first.size(),
                                       options.max_frames);
}

}  // namespace probeless::dataset::internal
