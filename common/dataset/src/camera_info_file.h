// Private: camera intrinsics from calibration files, defaults, and CameraInfo messages.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "probeless/dataset/datasets.h"
#include "probeless/dataset/source.h"
#include "probeless/msgs/camera_info.h"

namespace probeless::dataset::internal {

// Pinhole intrinsics (pixels; pixel (0, 0) is the centre of the top-left pixel) and distortion.
struct Intrinsics {
  uint32_t width = 0;  // image size the calibration is for; 0 = not stated
  uint32_t height = 0;
  double fx = 0;
  double fy = 0;
  double cx = 0;
  double cy = 0;
  msgs::DistortionModel model = msgs::DistortionModel::kNone;
  std::vector<double> distortion;  // DistortionCoefficientCount(model) entries, OpenCV order
};

// Reads a ROS camera_info YAML file or an OpenCV FileStorage YAML/XML file (chosen by content:
// "%YAML:1.x", "<?xml" or "<opencv_storage" means FileStorage). Throws DatasetError naming the
// file and the missing or malformed entry.
Intrinsics ReadCameraInfoFile(const std::string& path);

// The default guess for a camera of unknown calibration: 60 degree horizontal field of view
// (fx = fy = width / (2 tan 30 deg)), principal point at the image centre ((w-1)/2, (h-1)/2), no
// distortion.
Intrinsics GuessIntrinsics(uint32_t width, uint32_t height);

// The intrinsics to publish for `width` x `height` images: options.camera_info_path when set
// (its stated size must match: else DatasetError naming both), else `fallback`. Width and height
// are set.
Intrinsics ResolveIntrinsics(const DatasetOptions& options, const Intrinsics& fallback,
                             uint32_t width, uint32_t height);

// Fills the calibration fields of `out` (not the header) with `intrinsics` and `depth_scale`
// (metres per depth unit, 0 without depth).
void FillCameraInfo(const Intrinsics& intrinsics, double depth_scale, msgs::CameraInfo& out);

}  // namespace probeless::dataset::internal

namespace probeless::dataset::internal {

// A CameraInfo message on `topic_index` at `log_time_ns` with `intrinsics` and `depth_scale`,
// stamped `stamp_ns`, `sequence`, `frame_id`.
StreamMessage CameraInfoMessage(size_t topic_index, uint64_t log_time_ns,
                                const Intrinsics& intrinsics, double depth_scale, int64_t stamp_ns,
                                uint64_t sequence, std::string_view frame_id);

}  // namespace probeless::dataset::internal
