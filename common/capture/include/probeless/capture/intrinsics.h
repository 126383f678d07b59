// Camera intrinsics for capture nodes: the device-facing order of precedence calibration file >
// device factory values > field-of-view default. Calibration files themselves (ROS camera_info
// YAML, OpenCV FileStorage YAML/XML; reading, writing, scaling) are probeless_calib's
// (probeless/calib/calibration.h); capture reports its errors as CaptureError(kBadInput).
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "probeless/calib/calibration.h"

namespace probeless::capture {

// Pinhole intrinsics in pixels and lens distortion (calib::Intrinsics).
using calib::Intrinsics;

// Which intrinsics a capture node publishes for width x height images, and why.
struct ResolvedIntrinsics {
  Intrinsics intrinsics;    // width/height set to the images'
  std::string source;       // "calibration file 'x.yaml'", "device factory values",
                            // "default from a 60 deg horizontal field of view (not calibrated)"
  bool calibrated = false;  // from a file or the device
};
// The calibration file `path` if not empty (read with calib::ReadCalibrationFile; its stated size
// must match, or have the same aspect ratio, in which case it is scaled; else
// CaptureError(kBadInput) naming both sizes), else `factory`, else
// calib::IntrinsicsFromFieldOfView(width, height, default_fov_deg). Every calib::CalibrationError
// (unreadable or malformed file, field of view outside (0, 180)) becomes CaptureError(kBadInput)
// with the same message.
ResolvedIntrinsics ResolveIntrinsics(const std::string& path,
                                     const std::optional<Intrinsics>& factory, uint32_t width,
                                     uint32_t height,
                                     double default_fov_deg = calib::kDefaultFieldOfViewDeg);

}  // namespace probeless::capture
