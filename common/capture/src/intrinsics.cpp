#include "probeless/capture/intrinsics.h"

#include <sstream>

#include "probeless/capture/capture_error.h"

namespace probeless::capture {

namespace {

ResolvedIntrinsics Resolve(const std::string& path, const std::optional<Intrinsics>& factory,
                           uint32_t width, uint32_t height, double default_fov_deg) {
  ResolvedIntrinsics result;
  if (!path.empty()) {
    Intrinsics file = calib::ReadCalibrationFile(path);
    const bool stated = file.width != 0 && file.height != 0;
    if (stated && (file.width != width || file.height != height)) {
      // Same aspect ratio: the same sensor area at another resolution.
      if (static_cast<uint64_t>(file.width) * height !=
          static_cast<uint64_t>(file.height) * width) {
        throw CaptureError(ErrorKind::kBadInput,
                           "calibration file '" + path + "' is for " + std::to_string(file.width) +
                               "x" + std::to_string(file.height) + " images, the camera delivers " +
                               std::to_string(width) + "x" + std::to_string(height) +
                               ": calibrate at this size (tools/calibrate) or change the size");
      }
      file = calib::ScaleIntrinsics(file, width, height);
      result.source = "calibration file '" + path + "' (scaled to " + std::to_string(width) + "x" +
                      std::to_string(height) + ")";
    } else {
      result.source = "calibration file '" + path + "'";
    }
    file.width = width;
    file.height = height;
    result.intrinsics = file;
    result.calibrated = true;
    return result;
  }
  if (factory) {
    result.intrinsics = calib::ScaleIntrinsics(*factory, width, height);
    result.source = "device factory values";
    result.calibrated = true;
    return result;
  }
  result.intrinsics = calib::IntrinsicsFromFieldOfView(width, height, default_fov_deg);
  std::ostringstream s;
  s << "default from a " << default_fov_deg
    << " deg horizontal field of view (NOT calibrated: set param camera_info_url)";
  result.source = s.str();
  return result;
}

}  // namespace

ResolvedIntrinsics ResolveIntrinsics(const std::string& path,
                                     const std::optional<Intrinsics>& factory, uint32_t width,
                                     uint32_t height, double default_fov_deg) {
  try {
    return Resolve(path, factory, width, height, default_fov_deg);
  } catch (const calib::CalibrationError& e) {
    throw CaptureError(ErrorKind::kBadInput, e.what());
  }
}

}  // namespace probeless::capture
