#include "camera_info_file.h"

#include "internal.h"

namespace probeless::dataset::internal {

Intrinsics ResolveIntrinsics(const DatasetOptions& options, const Intrinsics& fallback,
                             uint32_t width, uint32_t height) {
  Intrinsics intrinsics = fallback;
  if (!options.camera_info_path.empty()) {
    try {
      intrinsics = calib::ReadCalibrationFile(options.camera_info_path);
    } catch (const calib::CalibrationError& e) {
      throw DatasetError(e.what());
    }
    if ((intrinsics.width != 0 && intrinsics.width != width) ||
        (intrinsics.height != 0 && intrinsics.height != height)) {
      throw DatasetError("calibration file '" + options.camera_info_path + "' is for " +
                         std::to_string(intrinsics.width) + "x" +
                         std::to_string(intrinsics.height) + " images, the dataset's are " +
                         std::to_string(width) + "x" + std::to_string(height));
    }
  }
  intrinsics.width = width;
  intrinsics.height = height;
  return intrinsics;
}

StreamMessage CameraInfoMessage(size_t topic_index, uint64_t log_time_ns,
                                const Intrinsics& intrinsics, double depth_scale, int64_t stamp_ns,
                                uint64_t sequence, std::string_view frame_id) {
  StreamMessage message = NewMessage(topic_index, log_time_ns, sizeof(msgs::CameraInfo));
  msgs::WriteView<msgs::CameraInfo> view =
      msgs::WriteMessage<msgs::CameraInfo>(message.message.bytes());
  FillHeader(view->header, stamp_ns, sequence, frame_id);
  calib::FillCameraInfo(intrinsics, depth_scale, *view);
  return message;
}

}  // namespace probeless::dataset::internal
