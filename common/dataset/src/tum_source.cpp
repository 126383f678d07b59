// TUM RGB-D sequence folders: rgb.txt and depth.txt ("timestamp filename" lines, '#' comments),
// optional groundtruth.txt ("timestamp tx ty tz qx qy qz qw"), 16-bit depth PNGs at 5000 units
// per metre.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <opencv2/core.hpp>

#include "camera_info_file.h"
#include "image_io.h"
#include "internal.h"
#include "probeless/msgs/pose.h"
#include "text_io.h"

namespace probeless::dataset::internal {

namespace {

constexpr int64_t kMaxAssociationNs = 20'000'000;        // associate.py --max_difference 0.02
constexpr int64_t kMaxInterpolationGapNs = 100'000'000;  // ground truth bracketing gap
constexpr std::string_view kRgbExpectation = "an 8-bit colour PNG";
constexpr std::string_view kDepthExpectation = "a 16-bit single-channel PNG (5000 per metre)";

struct Entry {
  uint64_t stamp_ns = 0;
  std::string file;  // full path
  size_t line = 0;   // 1-based line in the list file
};

struct GroundTruth {
  uint64_t stamp_ns = 0;
  msgs::RigidTransform transform;
};

bool IsCommentOrBlank(std::string_view line) {
  const std::vector<std::string_view> tokens = SplitWhitespace(line);
  return tokens.empty() || tokens.front().starts_with("#");
}

std::vector<std::string_view> Lines(std::string_view text) {
  std::vector<std::string_view> lines;
  size_t start = 0;
  while (start <= text.size()) {
    size_t end = text.find('\n', start);
    if (end == std::string_view::npos) end = text.size();
    lines.push_back(text.substr(start, end - start));
    start = end + 1;
  }
  return lines;
}

uint64_t ParseStamp(std::string_view token, const std::string& list, size_t line) {
  uint64_t ns = 0;
  if (!ParseSecondsToNs(token, ns)) {
    throw DatasetError("malformed line " + std::to_string(line) + " of '" + list + "': '" +
                       std::string(token) + "' is not a timestamp in seconds");
  }
  return ns;
}

// "timestamp filename" lines, sorted by timestamp (stable).
std::vector<Entry> ReadImageList(const std::string& folder, const std::string& name) {
  const std::string list = JoinPath(folder, name);
  const std::string text = ReadTextFile(list, "TUM list");
  std::vector<Entry> entries;
  const std::vector<std::string_view> lines = Lines(text);
  for (size_t i = 0; i < lines.size(); ++i) {
    if (IsCommentOrBlank(lines[i])) continue;
    const std::vector<std::string_view> tokens = SplitWhitespace(lines[i]);
    if (tokens.size() != 2) {
      throw DatasetError("malformed line " + std::to_string(i + 1) + " of '" + list +
                         "': expected 'timestamp filename'");
    }
    entries.push_back(
        {ParseStamp(tokens[0], list, i + 1), JoinPath(folder, std::string(tokens[1])), i + 1});
  }
  std::stable_sort(entries.begin(), entries.end(),
                   [](const Entry& a, const Entry& b) { return a.stamp_ns < b.stamp_ns; });
  return entries;
}

std::vector<GroundTruth> ReadGroundTruth(const std::string& list) {
  const std::string text = ReadTextFile(list, "TUM ground truth");
  std::vector<GroundTruth> poses;
  const std::vector<std::string_view> lines = Lines(text);
  for (size_t i = 0; i < lines.size(); ++i) {
    if (IsCommentOrBlank(lines[i])) continue;
    const std::vector<std::string_view> tokens = SplitWhitespace(lines[i]);
    const std::string where = "malformed line " + std::to_string(i + 1) + " of '" + list + "'";
    if (tokens.size() != 8) {
      throw DatasetError(where + ": expected 'timestamp tx ty tz qx qy qz qw'");
    }
    double v[7] = {};
    for (size_t k = 0; k < 7; ++k) {
      if (!ParseDouble(tokens[k + 1], v[k])) {
        throw DatasetError(where + ": '" + std::string(tokens[k + 1]) + "' is not a number");
      }
    }
    const double norm = std::sqrt(v[3] * v[3] + v[4] * v[4] + v[5] * v[5] + v[6] * v[6]);
    if (std::abs(norm - 1) > 1e-2) {
      throw DatasetError(where + ": qx qy qz qw is not a unit quaternion");
    }
    GroundTruth pose;
    pose.stamp_ns = ParseStamp(tokens[0], list, i + 1);
    pose.transform.translation = {v[0], v[1], v[2]};
    const double sign = v[6] < 0 ? -1.0 : 1.0;
    pose.transform.rotation = {v[6] * sign / norm, v[3] * sign / norm, v[4] * sign / norm,
                               v[5] * sign / norm};
    poses.push_back(pose);
  }
  std::stable_sort(poses.begin(), poses.end(), [](const GroundTruth& a, const GroundTruth& b) {
    return a.stamp_ns < b.stamp_ns;
  });
  return poses;
}

int64_t Diff(uint64_t a, uint64_t b) { return static_cast<int64_t>(a - b); }
uint64_t AbsDiff(uint64_t a, uint64_t b) { return a > b ? a - b : b - a; }

// For each rgb entry the index of its depth entry or -1, by TUM's associate.py: every pair closer
// than 20 ms is a candidate; candidates are accepted in order of increasing time difference
// (ties: earlier rgb, then earlier depth) unless either side is already taken.
std::vector<int64_t> Associate(const std::vector<Entry>& rgb, const std::vector<Entry>& depth) {
  struct Candidate {
    uint64_t diff;
    size_t rgb;
    size_t depth;
  };
  std::vector<Candidate> candidates;
  size_t low = 0;
  for (size_t r = 0; r < rgb.size(); ++r) {
    while (low < depth.size() && Diff(rgb[r].stamp_ns, depth[low].stamp_ns) >= kMaxAssociationNs) {
      ++low;
    }
    for (size_t d = low;
         d < depth.size() && Diff(depth[d].stamp_ns, rgb[r].stamp_ns) < kMaxAssociationNs; ++d) {
      candidates.push_back({AbsDiff(rgb[r].stamp_ns, depth[d].stamp_ns), r, d});
    }
  }
  std::sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& b) {
    if (a.diff != b.diff) return a.diff < b.diff;
    if (a.rgb != b.rgb) return a.rgb < b.rgb;
    return a.depth < b.depth;
  });
  std::vector<int64_t> match(rgb.size(), -1);
  std::vector<bool> depth_taken(depth.size(), false);
  for (const Candidate& c : candidates) {
    if (match[c.rgb] >= 0 || depth_taken[c.depth]) continue;
    match[c.rgb] = static_cast<int64_t>(c.depth);
    depth_taken[c.depth] = true;
  }
  return match;
}

// The ground-truth pose at `t`: interpolated (linear translation, slerp rotation) between the
// samples around t when they are at most 100 ms apart, else the nearest sample closer than 20 ms,
// else none.
std::optional<msgs::RigidTransform> PoseAt(const std::vector<GroundTruth>& poses, uint64_t t) {
  const auto next = std::lower_bound(
      poses.begin(), poses.end(), t,
      [](const GroundTruth& pose, uint64_t value) { return pose.stamp_ns < value; });
  if (next != poses.end() && next->stamp_ns == t) return next->transform;
  const bool has_next = next != poses.end();
  const bool has_prev = next != poses.begin();
  if (has_next && has_prev) {
    const GroundTruth& a = *(next - 1);
    const GroundTruth& b = *next;
    if (Diff(b.stamp_ns, a.stamp_ns) <= kMaxInterpolationGapNs) {
      const double alpha = static_cast<double>(Diff(t, a.stamp_ns)) /
                           static_cast<double>(Diff(b.stamp_ns, a.stamp_ns));
      msgs::RigidTransform out;
      out.translation = {
          a.transform.translation.x * (1 - alpha) + b.transform.translation.x * alpha,
          a.transform.translation.y * (1 - alpha) + b.transform.translation.y * alpha,
          a.transform.translation.z * (1 - alpha) + b.transform.translation.z * alpha};
      out.rotation = Slerp(a.transform.rotation, b.transform.rotation, alpha);
      return out;
    }
  }
  const GroundTruth* nearest = nullptr;
  if (has_prev) nearest = &*(next - 1);
  if (has_next &&
      (nearest == nullptr || AbsDiff(next->stamp_ns, t) < AbsDiff(nearest->stamp_ns, t))) {
    nearest = &*next;
  }
  if (nearest != nullptr &&
      AbsDiff(nearest->stamp_ns, t) < static_cast<uint64_t>(kMaxAssociationNs)) {
    return nearest->transform;
  }
  return std::nullopt;
}

// The published RGB intrinsics of the TUM Kinects, by the "freiburgN" in the folder name; the ROS
// default (525, 525, 319.5, 239.5) for any other folder.
Intrinsics TumIntrinsics(const std::string& path) {
  std::filesystem::path folder = std::filesystem::path(path).lexically_normal();
  if (folder.filename().empty()) folder = folder.parent_path();
  const std::string name = folder.filename().string();
  Intrinsics intrinsics;
  auto set = [&](double fx, double fy, double cx, double cy, std::vector<double> d) {
    intrinsics.fx = fx;
    intrinsics.fy = fy;
    intrinsics.cx = cx;
    intrinsics.cy = cy;
    intrinsics.model = d.empty() ? msgs::DistortionModel::kNone : msgs::DistortionModel::kPlumbBob;
    intrinsics.distortion = std::move(d);
  };
  if (name.find("freiburg1") != std::string::npos) {
    set(517.3, 516.5, 318.6, 255.3, {0.2624, -0.9531, -0.0054, 0.0026, 1.1633});
  } else if (name.find("freiburg2") != std::string::npos) {
    set(520.9, 521.0, 325.1, 249.7, {0.2312, -0.7849, -0.0033, -0.0001, 0.9172});
  } else if (name.find("freiburg3") != std::string::npos) {
    set(535.4, 539.2, 320.1, 247.6, {});
  } else {
    set(525.0, 525.0, 319.5, 239.5, {});
  }
  return intrinsics;
}

struct TumFrame {
  Entry rgb;
  std::optional<Entry> depth;
  std::optional<msgs::RigidTransform> pose;
};

class TumSource : public FrameSource {
 public:
  TumSource(const std::string& path, const DatasetOptions& options, std::vector<TumFrame> frames,
            bool has_depth, bool has_pose, Intrinsics intrinsics, cv::Size rgb_size,
            cv::Size depth_size)
      : FrameSource("tum", path, frames.size()),
        options_(options),
        frames_(std::move(frames)),
        intrinsics_(std::move(intrinsics)),
        rgb_size_(rgb_size),
        depth_size_(depth_size) {
    const uint64_t n = frames_.size();
    const auto depth_count = static_cast<uint64_t>(std::count_if(
        frames_.begin(), frames_.end(), [](const TumFrame& f) { return f.depth.has_value(); }));
    const auto pose_count = static_cast<uint64_t>(std::count_if(
        frames_.begin(), frames_.end(), [](const TumFrame& f) { return f.pose.has_value(); }));
    info_topic_ = AddTopic<msgs::CameraInfo>(TopicName(options.topic_prefix, "camera_info"),
                                             sizeof(msgs::CameraInfo), n);
    image_topic_ = AddTopic<msgs::Image>(
        TopicName(options.topic_prefix, "image"),
        msgs::Image::MessageBytesFor(rgb_size.width, rgb_size.height, msgs::Encoding::kRgb8), n);
    if (has_depth) {
      depth_topic_ =
          AddTopic<msgs::Image>(TopicName(options.topic_prefix, "depth"),
                                msgs::Image::MessageBytesFor(depth_size.width, depth_size.height,
                                                             msgs::Encoding::kDepth16),
                                depth_count);
    }
    if (has_pose) {
      pose_topic_ = AddTopic<msgs::Pose>(TopicName(options.ground_truth_prefix, "pose"),
                                         sizeof(msgs::Pose), pose_count);
    }
    time_range_ = std::make_pair(frames_.front().rgb.stamp_ns, frames_.back().rgb.stamp_ns);
  }

 protected:
  bool ReadFrame(uint64_t index, std::vector<StreamMessage>& out) override {
    if (index >= frames_.size()) return false;
    const TumFrame& frame = frames_[index];
    const uint64_t time = frame.rgb.stamp_ns;
    const auto stamp = static_cast<int64_t>(time);
    const uint64_t sequence = index + 1;
    const std::string& frame_id = options_.camera_frame_id;

    const cv::Mat rgb_file = ReadImageFile(frame.rgb.file, "rgb image", kRgbExpectation);
    if (rgb_file.size() != rgb_size_ || rgb_file.depth() != CV_8U) {
      throw DatasetError("rgb image '" + frame.rgb.file + "' is " + DescribeMat(rgb_file) +
                         ": expected 8-bit " + std::to_string(rgb_size_.width) + "x" +
                         std::to_string(rgb_size_.height) + " like the first frame");
    }
    const cv::Mat rgb = ConvertForEncoding(rgb_file, msgs::Encoding::kRgb8, frame.rgb.file);

    cv::Mat depth_mm;
    if (frame.depth) {
      const cv::Mat depth = ReadImageFile(frame.depth->file, "depth image", kDepthExpectation);
      if (depth.type() != CV_16UC1 || depth.size() != depth_size_) {
        throw DatasetError("depth image '" + frame.depth->file + "' is " + DescribeMat(depth) +
                           ": expected a 16-bit single-channel " +
                           std::to_string(depth_size_.width) + "x" +
                           std::to_string(depth_size_.height) + " PNG like the first frame");
      }
      // 5000 units per metre = 5 per millimetre; v / 5 never ends in .5, so this rounds to nearest.
      depth_mm.create(depth.size(), CV_16UC1);
      for (int y = 0; y < depth.rows; ++y) {
        const auto* in = depth.ptr<uint16_t>(y);
        auto* row = depth_mm.ptr<uint16_t>(y);
        for (int x = 0; x < depth.cols; ++x) row[x] = static_cast<uint16_t>((in[x] + 2) / 5);
      }
    }

    out.push_back(CameraInfoMessage(info_topic_, time, intrinsics_, depth_topic_ ? 0.001 : 0, stamp,
                                    sequence, frame_id));
    out.push_back(
        ImageMessage(image_topic_, time, rgb, msgs::Encoding::kRgb8, stamp, sequence, frame_id));
    if (frame.depth) {
      out.push_back(ImageMessage(*depth_topic_, time, depth_mm, msgs::Encoding::kDepth16, stamp,
                                 sequence, frame_id));
    }
    if (frame.pose) {
      StreamMessage message = NewMessage(*pose_topic_, time, sizeof(msgs::Pose));
      msgs::WriteView<msgs::Pose> pose = msgs::WriteMessage<msgs::Pose>(message.message.bytes());
      FillHeader(pose->header, stamp, sequence, options_.world_frame_id);
      pose->SetParentFrameId(options_.world_frame_id);
      pose->SetChildFrameId(frame_id);
      pose->transform = *frame.pose;
      out.push_back(std::move(message));
    }
    return true;
  }

 private:
  DatasetOptions options_;
  std::vector<TumFrame> frames_;
  Intrinsics intrinsics_;
  cv::Size rgb_size_;
  cv::Size depth_size_;
  size_t info_topic_ = 0;
  size_t image_topic_ = 0;
  std::optional<size_t> depth_topic_;
  std::optional<size_t> pose_topic_;
};

void CheckExists(const Entry& entry, std::string_view what, const std::string& list) {
  std::error_code error;
  if (!std::filesystem::is_regular_file(entry.file, error)) {
    throw DatasetError("missing " + std::string(what) + " '" + entry.file + "' (line " +
                       std::to_string(entry.line) + " of '" + list + "')");
  }
}

}  // namespace

std::unique_ptr<Source> OpenTum(const std::string& path, const DatasetOptions& options) {
  const std::vector<Entry> rgb = ReadImageList(path, "rgb.txt");
  const std::vector<Entry> depth = ReadImageList(path, "depth.txt");
  if (rgb.empty()) {
    throw DatasetError("TUM list '" + JoinPath(path, "rgb.txt") +
                       "' lists no images (expected 'timestamp filename' lines)");
  }
  const std::string gt_file = JoinPath(path, "groundtruth.txt");
  const bool has_pose = std::filesystem::exists(gt_file);
  const std::vector<GroundTruth> ground_truth =
      has_pose ? ReadGroundTruth(gt_file) : std::vector<GroundTruth>();
  const std::vector<int64_t> match = Associate(rgb, depth);

  const uint64_t frame_count = LimitFrames(rgb.size(), options);
  std::vector<TumFrame> frames;
  for (uint64_t i = 0; i < frame_count; ++i) {
    TumFrame frame;
    frame.rgb = rgb[i];
    CheckExists(frame.rgb, "rgb image", JoinPath(path, "rgb.txt"));
    if (match[i] >= 0) {
      frame.depth = depth[static_cast<size_t>(match[i])];
      CheckExists(*frame.depth, "depth image", JoinPath(path, "depth.txt"));
    }
    if (has_pose) frame.pose = PoseAt(ground_truth, frame.rgb.stamp_ns);
    frames.push_back(std::move(frame));
  }

  const cv::Mat first_rgb = ReadImageFile(frames.front().rgb.file, "rgb image", kRgbExpectation);
  if (first_rgb.depth() != CV_8U) {
    throw DatasetError("rgb image '" + frames.front().rgb.file + "' is " + DescribeMat(first_rgb) +
                       ": expected " + std::string(kRgbExpectation));
  }
  cv::Size depth_size;
  const bool has_depth = !depth.empty();
  if (has_depth) {
    // The first associated depth image, else the first listed one.
    const auto with_depth = std::find_if(frames.begin(), frames.end(),
                                         [](const TumFrame& f) { return f.depth.has_value(); });
    const Entry& first = with_depth != frames.end() ? *with_depth->depth : depth.front();
    const cv::Mat first_depth = ReadImageFile(first.file, "depth image", kDepthExpectation);
    if (first_depth.type() != CV_16UC1) {
      throw DatasetError("depth image '" + first.file + "' is " + DescribeMat(first_depth) +
                         ": expected " + std::string(kDepthExpectation));
    }
    depth_size = first_depth.size();
  }
  // A camera_info.yaml in the folder (ROS camera_info) replaces the freiburg table; the
  // camera_info_path option still wins over both.
  DatasetOptions with_folder_info = options;
  const std::string folder_info = (std::filesystem::path(path) / "camera_info.yaml").string();
  if (with_folder_info.camera_info_path.empty() && std::filesystem::is_regular_file(folder_info)) {
    with_folder_info.camera_info_path = folder_info;
  }
  const Intrinsics intrinsics = ResolveIntrinsics(with_folder_info, TumIntrinsics(path),
                                                  static_cast<uint32_t>(first_rgb.cols),
                                                  static_cast<uint32_t>(first_rgb.rows));
  return std::make_unique<TumSource>(path, options, std::move(frames), has_depth, has_pose,
                                     intrinsics, first_rgb.size(), depth_size);
}

}  // namespace probeless::dataset::internal
