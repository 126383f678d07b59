// Camera intrinsics for capture nodes: read from calibration files (ROS camera_info YAML, OpenCV
// FileStorage YAML/XML), written as ROS camera_info YAML (tools/calibrate), a field-of-view
// default, and the order of precedence file > device factory values > default.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "probeless/msgs/camera_info.h"

namespace probeless::capture {

// Pinhole intrinsics in pixels (pixel (0, 0) is the centre of the top-left pixel; camera optical
// frame x right, y down, z forward) and lens distortion in OpenCV order.
struct Intrinsics {
  uint32_t width = 0;  // image size the calibration is for, pixels; 0 = not stated
  uint32_t height = 0;
  double fx = 0;  // focal lengths, pixels
  double fy = 0;
  double cx = 0;  // principal point, pixels
  double cy = 0;
  msgs::DistortionModel model = msgs::DistortionModel::kNone;
  std::vector<double> distortion;  // DistortionCoefficientCount(model) entries
};

// Reads a ROS camera_info YAML file (camera_calibration / camera_info_manager format) or an OpenCV
// FileStorage YAML/XML file (chosen by content: "%YAML:1.x", "<?xml" or "<opencv_storage" means
// FileStorage; keys camera_matrix|cameraMatrix|K, distortion_coefficients|distCoeffs|D,
// image_width|width, image_height|height). Same rules as common/dataset's reader. Throws
// CaptureError(kBadInput) naming the file and the missing or malformed entry.
Intrinsics ReadCalibrationFile(const std::string& path);

// The ROS camera_info YAML text for `intrinsics` (camera_name, image size, camera_matrix,
// distortion_model, distortion_coefficients, rectification_matrix = I, projection_matrix = [K|0]).
std::string CameraInfoYaml(const Intrinsics& intrinsics, const std::string& camera_name);
// Writes CameraInfoYaml to `path`. Throws CaptureError(kBadInput) if it cannot be written.
void WriteCameraInfoYaml(const std::string& path, const Intrinsics& intrinsics,
                         const std::string& camera_name);

// A pinhole guess from a horizontal field of view in degrees (0 < fov < 180): fx = fy =
// width / (2 tan(fov / 2)), principal point at the image centre ((w-1)/2, (h-1)/2), no distortion.
Intrinsics IntrinsicsFromFieldOfView(uint32_t width, uint32_t height, double horizontal_fov_deg);

// `intrinsics` for images of another size with the same field of view (a calibration at 1280x720
// used at 640x360): focal lengths and principal point scaled per axis.
Intrinsics ScaleIntrinsics(const Intrinsics& intrinsics, uint32_t width, uint32_t height);

// Which intrinsics a capture node publishes for width x height images, and why.
struct ResolvedIntrinsics {
  Intrinsics intrinsics;    // width/height set to the images'
  std::string source;       // "calibration file 'x.yaml'", "device factory values",
                            // "default from a 60 deg horizontal field of view (not calibrated)"
  bool calibrated = false;  // from a file or the device
};
// The calibration file `path` if not empty (its stated size must match, or have the same aspect
// ratio, in which case it is scaled; else CaptureError(kBadInput) naming both sizes), else
// `factory`, else IntrinsicsFromFieldOfView(width, height, default_fov_deg).
ResolvedIntrinsics ResolveIntrinsics(const std::string& path,
                                     const std::optional<Intrinsics>& factory, uint32_t width,
                                     uint32_t height, double default_fov_deg = 60.0);

// Fills the calibration fields of `out` (not its header).
void FillCameraInfo(const Intrinsics& intrinsics, double depth_scale, msgs::CameraInfo& out);

}  // namespace probeless::capture
