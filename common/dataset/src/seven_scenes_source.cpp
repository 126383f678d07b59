// Microsoft 7-Scenes sequence folders: frame-XXXXXX.color.jpg|png, frame-XXXXXX.depth.png (uint16
// millimetres, 0 and 65535 invalid), frame-XXXXXX.pose.txt (4x4 camera-to-world), optional
// camera-intrinsics.txt (3x3).
#include <algorithm>
#include <filesystem>
#include <map>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "camera_info_file.h"
#include "image_io.h"
#include "internal.h"
#include "probeless/msgs/pose.h"
#include "text_io.h"

namespace probeless::dataset::internal {

namespace {

constexpr std::string_view kColourExpectation = "an 8-bit colour JPEG or PNG";
constexpr std::string_view kDepthExpectation = "a 16-bit single-channel PNG (millimetres)";
constexpr std::string_view kPoseExpectation = "16 numbers (a 4x4 camera-to-world matrix)";

// The published intrinsics of the 7-Scenes (Kinect v1 depth) camera.
Intrinsics SevenScenesDefaultIntrinsics() {
  Intrinsics intrinsics;
  intrinsics.fx = 585;
  intrinsics.fy = 585;
  intrinsics.cx = 320;
  intrinsics.cy = 240;
  // No distortion, written as ROS writes an undistorted camera: plumb_bob with five zeros.
  intrinsics.model = msgs::DistortionModel::kPlumbBob;
  intrinsics.distortion.assign(5, 0.0);
  return intrinsics;
}

// The Kinect v1 colour camera as seen from its depth camera (nominal values; 7-Scenes ships no
// colour calibration): pinhole at 640 x 480 and the depth-to-colour translation along x, metres.
// Checked on the shared RedKitchen frames by the colour gradient at depth discontinuities
// (docs/dataset.md): these values are the best of a grid around them.
constexpr double kKinectColourFocal = 525;
constexpr double kKinectColourCx = 320;
constexpr double kKinectColourCy = 240;
constexpr double kKinectColourBaseline = -0.025;

// `colour` (any type) resampled onto the pixel grid of `depth_mm` (CV_16UC1, 0 = invalid) with
// `depth` intrinsics: pixel (u, v) at depth z is the 3D point ((u - cx) z / fx, (v - cy) z / fy, z)
// of the depth camera, seen by the Kinect colour camera above. Pixels without depth use the
// frame's median depth (the parallax term is small: 525 * 0.025 / z px). Bilinear; outside the
// colour image: black.
cv::Mat RegisterColourToDepth(const cv::Mat& colour, const cv::Mat& depth_mm,
                              const Intrinsics& depth) {
  std::vector<uint16_t> valid;
  valid.reserve(depth_mm.total() / 16);
  for (int v = 0; v < depth_mm.rows; v += 4) {
    for (int u = 0; u < depth_mm.cols; u += 4) {
      if (const uint16_t z = depth_mm.at<uint16_t>(v, u); z != 0) valid.push_back(z);
    }
  }
  double fill_m = 2.0;
  if (!valid.empty()) {
    std::nth_element(valid.begin(), valid.begin() + valid.size() / 2, valid.end());
    fill_m = valid[valid.size() / 2] * 0.001;
  }
  cv::Mat map_x(depth_mm.size(), CV_32FC1), map_y(depth_mm.size(), CV_32FC1);
  for (int v = 0; v < depth_mm.rows; ++v) {
    const uint16_t* z_row = depth_mm.ptr<uint16_t>(v);
    float* mx = map_x.ptr<float>(v);
    float* my = map_y.ptr<float>(v);
    const double y = (v - depth.cy) / depth.fy;
    for (int u = 0; u < depth_mm.cols; ++u) {
      const double z = z_row[u] != 0 ? z_row[u] * 0.001 : fill_m;
      const double x = (u - depth.cx) / depth.fx;
      mx[u] = static_cast<float>(kKinectColourFocal * (x + kKinectColourBaseline / z) +
                                 kKinectColourCx);
      my[u] = static_cast<float>(kKinectColourFocal * y + kKinectColourCy);
    }
  }
  cv::Mat out;
  cv::remap(colour, out, map_x, map_y, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar::all(0));
  return out;
}

// The frame number and part ("color.jpg", ...) of "frame-000012.color.jpg"; false otherwise.
bool ParseFrameName(const std::string& name, uint64_t& index, std::string& part) {
  if (!name.starts_with("frame-")) return false;
  size_t i = 6;
  uint64_t value = 0;
  while (i < name.size() && name[i] >= '0' && name[i] <= '9' && i < 6 + 12) {
    value = value * 10 + static_cast<uint64_t>(name[i] - '0');
    ++i;
  }
  if (i == 6 || i >= name.size() || name[i] != '.') return false;
  index = value;
  part = name.substr(i + 1);
  return true;
}

struct Frame {
  std::string colour;
  std::string depth;
  std::string pose;
};

class SevenScenesSource : public FrameSource {
 public:
  SevenScenesSource(const std::string& path, const DatasetOptions& options,
                    std::vector<Frame> frames, uint64_t frame_count, bool has_depth, bool has_pose,
                    Intrinsics intrinsics, cv::Size colour_size, cv::Size depth_size)
      : FrameSource("7scenes", path, frame_count),
        options_(options),
        frames_(std::move(frames)),
        intrinsics_(std::move(intrinsics)),
        colour_size_(colour_size),
        depth_size_(depth_size) {
    info_topic_ = AddTopic<msgs::CameraInfo>(TopicName(options.topic_prefix, "camera_info"),
                                             sizeof(msgs::CameraInfo), frame_count);
    image_topic_ = AddTopic<msgs::Image>(
        TopicName(options.topic_prefix, "image"),
        msgs::Image::MessageBytesFor(colour_size.width, colour_size.height, msgs::Encoding::kRgb8),
        frame_count);
    if (has_depth) {
      depth_topic_ =
          AddTopic<msgs::Image>(TopicName(options.topic_prefix, "depth"),
                                msgs::Image::MessageBytesFor(depth_size.width, depth_size.height,
                                                             msgs::Encoding::kDepth16),
                                frame_count);
    }
    if (has_pose) {
      pose_topic_ = AddTopic<msgs::Pose>(TopicName(options.ground_truth_prefix, "pose"),
                                         sizeof(msgs::Pose), frame_count);
    }
    time_range_ = std::make_pair(uint64_t{0}, FrameTimeNs(frame_count - 1, options.fps));
  }

 protected:
  bool ReadFrame(uint64_t index, std::vector<StreamMessage>& out) override {
    if (index >= frames_.size()) return false;
    const Frame& frame = frames_[index];
    const uint64_t time = FrameTimeNs(index, options_.fps);
    const auto stamp = static_cast<int64_t>(time);
    const uint64_t sequence = index + 1;
    const std::string& frame_id = options_.camera_frame_id;

    const cv::Mat colour_file = ReadImageFile(frame.colour, "colour image", kColourExpectation);
    if (colour_file.size() != colour_size_ || colour_file.depth() != CV_8U) {
      throw DatasetError("colour image '" + frame.colour + "' is " + DescribeMat(colour_file) +
                         ": expected 8-bit " + std::to_string(colour_size_.width) + "x" +
                         std::to_string(colour_size_.height) + " like the first frame");
    }
    cv::Mat colour = ConvertForEncoding(colour_file, msgs::Encoding::kRgb8, frame.colour);

    cv::Mat depth;
    if (depth_topic_) {
      depth = ReadImageFile(frame.depth, "depth image", kDepthExpectation);
      if (depth.type() != CV_16UC1 || depth.size() != depth_size_) {
        throw DatasetError("depth image '" + frame.depth + "' is " + DescribeMat(depth) +
                           ": expected a 16-bit single-channel " +
                           std::to_string(depth_size_.width) + "x" +
                           std::to_string(depth_size_.height) + " PNG like the first frame");
      }
      if (!depth.isContinuous()) depth = depth.clone();
      // 65535 marks an invalid measurement in 7-Scenes; probeless uses 0.
      for (auto it = depth.begin<uint16_t>(); it != depth.end<uint16_t>(); ++it) {
        if (*it == 65535) *it = 0;
      }
      if (options_.register_colour && colour_size_ == cv::Size(640, 480) &&
          depth_size_ == cv::Size(640, 480)) {
        colour = RegisterColourToDepth(colour, depth, intrinsics_);
      }
    }

    msgs::RigidTransform transform;
    if (pose_topic_) {
      transform = TransformFromMatrix(ReadNumberFile(frame.pose, 16, "pose file", kPoseExpectation),
                                      frame.pose);
    }

    out.push_back(CameraInfoMessage(info_topic_, time, intrinsics_, depth_topic_ ? 0.001 : 0, stamp,
                                    sequence, frame_id));
    out.push_back(
        ImageMessage(image_topic_, time, colour, msgs::Encoding::kRgb8, stamp, sequence, frame_id));
    if (depth_topic_) {
      out.push_back(ImageMessage(*depth_topic_, time, depth, msgs::Encoding::kDepth16, stamp,
                                 sequence, frame_id));
    }
    if (pose_topic_) {
      StreamMessage message = NewMessage(*pose_topic_, time, sizeof(msgs::Pose));
      msgs::WriteView<msgs::Pose> pose = msgs::WriteMessage<msgs::Pose>(message.message.bytes());
      FillHeader(pose->header, stamp, sequence, options_.world_frame_id);
      pose->SetParentFrameId(options_.world_frame_id);
      pose->SetChildFrameId(frame_id);
      pose->transform = transform;
      out.push_back(std::move(message));
    }
    return true;
  }

 private:
  DatasetOptions options_;
  std::vector<Frame> frames_;
  Intrinsics intrinsics_;
  cv::Size colour_size_;
  cv::Size depth_size_;
  size_t info_topic_ = 0;
  size_t image_topic_ = 0;
  std::optional<size_t> depth_topic_;
  std::optional<size_t> pose_topic_;
};

}  // namespace

std::unique_ptr<Source> OpenSevenScenes(const std::string& path, const DatasetOptions& options) {
  std::map<uint64_t, Frame> by_index;
  size_t depth_files = 0;
  size_t pose_files = 0;
  for (const std::string& name : ListFiles(path)) {
    uint64_t index = 0;
    std::string part;
    if (!ParseFrameName(name, index, part)) continue;
    Frame& frame = by_index[index];
    const std::string file = JoinPath(path, name);
    if (part == "color.jpg" || part == "color.png") {
      if (!frame.colour.empty()) {
        throw DatasetError("7-Scenes folder '" + path + "' has two colour images for frame " +
                           std::to_string(index) + ": '" + frame.colour + "' and '" + file + "'");
      }
      frame.colour = file;
    } else if (part == "depth.png") {
      frame.depth = file;
      ++depth_files;
    } else if (part == "pose.txt") {
      frame.pose = file;
      ++pose_files;
    }
  }
  std::vector<Frame> frames;
  for (auto& [index, frame] : by_index) {
    if (frame.colour.empty()) {
      // A depth or pose file without a colour image: the frame is incomplete.
      const std::string& other = frame.depth.empty() ? frame.pose : frame.depth;
      throw DatasetError("7-Scenes folder '" + path + "': '" + other +
                         "' has no colour image frame-XXXXXX.color.jpg|png beside it");
    }
    frames.push_back(frame);
  }
  if (frames.empty()) {
    throw DatasetError("7-Scenes folder '" + path + "' has no frame-XXXXXX.color.jpg|png files");
  }
  const bool has_depth = depth_files > 0;
  const bool has_pose = pose_files > 0;
  for (const Frame& frame : frames) {
    const std::string stem = frame.colour.substr(0, frame.colour.rfind(".color."));
    if (has_depth && frame.depth.empty()) {
      throw DatasetError("missing depth image '" + stem + ".depth.png' (the other frames of '" +
                         path + "' have one)");
    }
    if (has_pose && frame.pose.empty()) {
      throw DatasetError("missing pose file '" + stem + ".pose.txt' (the other frames of '" + path +
                         "' have one)");
    }
  }

  Intrinsics fallback = SevenScenesDefaultIntrinsics();
  const std::string intrinsics_file = JoinPath(path, "camera-intrinsics.txt");
  if (std::filesystem::exists(intrinsics_file)) {
    const std::vector<double> k =
        ReadNumberFile(intrinsics_file, 9, "camera intrinsics", "9 numbers (a 3x3 camera matrix)");
    if (!(k[0] > 0) || !(k[4] > 0) || k[6] != 0 || k[7] != 0 || k[8] != 1) {
      throw DatasetError("malformed camera intrinsics '" + intrinsics_file +
                         "': expected a camera matrix [fx 0 cx; 0 fy cy; 0 0 1] with fx, fy > 0");
    }
    fallback.fx = k[0];
    fallback.fy = k[4];
    fallback.cx = k[2];
    fallback.cy = k[5];
  }

  const cv::Mat first_colour =
      ReadImageFile(frames.front().colour, "colour image", kColourExpectation);
  if (first_colour.depth() != CV_8U) {
    throw DatasetError("colour image '" + frames.front().colour + "' is " +
                       DescribeMat(first_colour) + ": expected " + std::string(kColourExpectation));
  }
  cv::Size depth_size;
  if (has_depth) {
    const cv::Mat first_depth =
        ReadImageFile(frames.front().depth, "depth image", kDepthExpectation);
    if (first_depth.type() != CV_16UC1) {
      throw DatasetError("depth image '" + frames.front().depth + "' is " +
                         DescribeMat(first_depth) + ": expected " + std::string(kDepthExpectation));
    }
    depth_size = first_depth.size();
  }
  const Intrinsics intrinsics =
      ResolveIntrinsics(options, fallback, static_cast<uint32_t>(first_colour.cols),
                        static_cast<uint32_t>(first_colour.rows));
  const uint64_t frame_count = LimitFrames(frames.size(), options);
  frames.resize(frame_count);
  return std::make_unique<SevenScenesSource>(path, options, std::move(frames), frame_count,
                                             has_depth, has_pose, intrinsics, first_colour.size(),
                                             depth_size);
}

}  // namespace probeless::dataset::internal
