// Private: the intrinsics a dataset source publishes (calibration files are probeless_calib's) and
// its CameraInfo messages.
#pragma once

#include <cstdint>
#include <string_view>

#include "probeless/calib/calibration.h"
#include "probeless/dataset/datasets.h"
#include "probeless/dataset/source.h"

namespace probeless::dataset::internal {

using calib::Intrinsics;

// The intrinsics to publish for `width` x `height` images: options.camera_info_path when set
// (read with calib::ReadCalibrationFile; its stated size must match: else DatasetError naming
// both), else `fallback`. Width and height are set. Calibration file errors are DatasetError with
// calib's message.
Intrinsics ResolveIntrinsics(const DatasetOptions& options, const Intrinsics& fallback,
                             uint32_t width, uint32_t height);

// A CameraInfo message on `topic_index` at `log_time_ns` with `intrinsics` and `depth_scale`
// (metres per depth unit, 0 without depth), stamped `stamp_ns`, `sequence`, `frame_id`.
StreamMessage CameraInfoMessage(size_t topic_index, uint64_t log_time_ns,
                                const Intrinsics& intrinsics, double depth_scale, int64_t stamp_ns,
                                uint64_t sequence, std::string_view frame_id);

}  // namespace probeless::dataset::internal
