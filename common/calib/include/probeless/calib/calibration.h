// Camera calibration files, once for the whole project: pinhole intrinsics read from ROS
// camera_info YAML or OpenCV FileStorage YAML/XML files, written as ROS camera_info YAML, a
// field-of-view guess, scaling to another resolution, and the CameraInfo message fields.
// probeless_capture and probeless_dataset translate CalibrationError into their own error types
// (same text); docs/capture.md and docs/dataset.md describe the files.
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "probeless/error/error.h"
#include "probeless/msgs/camera_info.h"

namespace probeless::calib {

// A calibration file that cannot be read, parsed or written, or a bad argument: one line naming the
// file (if any) and the missing or malformed entry, e.g.
// "calibration file 'cam.yaml': camera matrix has 8 entries, expected 9 (3x3)".
class CalibrationError : public InputError {
 public:
  using InputError::InputError;
};

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

// The horizontal field of view of the guess for a camera of unknown calibration, degrees.
inline constexpr double kDefaultFieldOfViewDeg = 60.0;

// Reads a ROS camera_info YAML file (camera_calibration / camera_info_manager format: image_width,
// image_height, camera_matrix, distortion_model plumb_bob | rational_polynomial,
// distortion_coefficients) or an OpenCV FileStorage YAML/XML file (chosen by content: "%YAML:1.x",
// "<?xml" or "<opencv_storage" means FileStorage; keys camera_matrix|cameraMatrix|K,
// distortion_coefficients|distCoeffs|dist_coeffs|distortion|D, image_width|width,
// image_height|height). 0, 4 (k3 = 0 added), 5 or 8 distortion coefficients. Throws
// CalibrationError "calibration file '<path>'..." naming the missing or malformed entry, or
// "cannot read calibration file '<path>'".
Intrinsics ReadCalibrationFile(const std::string& path);

// The ROS camera_info YAML text for `intrinsics` (camera_name, image size, camera_matrix,
// distortion_model, distortion_coefficients, rectification_matrix = I, projection_matrix = [K|0]);
// ReadCalibrationFile reads it back exactly (10 significant digits).
std::string CameraInfoYaml(const Intrinsics& intrinsics, const std::string& camera_name);

// Writes CameraInfoYaml to `path`. Throws CalibrationError if it cannot be written.
void WriteCameraInfoYaml(const std::string& path, const Intrinsics& intrinsics,
                         const std::string& camera_name);

// A pinhole guess from a horizontal field of view in degrees: fx = fy =
// width / (2 tan(fov / 2)), principal point at the image centre ((w-1)/2, (h-1)/2), no distortion.
// Throws CalibrationError "field of view <fov> deg is outside (0, 180)".
Intrinsics IntrinsicsFromFieldOfView(uint32_t width, uint32_t height,
                                     double horizontal_fov_deg = kDefaultFieldOfViewDeg);

// `intrinsics` for images of another size with the same field of view (a calibration at 1280x720
// used at 640x360): focal lengths and principal point scaled per axis (about the image corner).
// Intrinsics without a stated size are only given the new size.
Intrinsics ScaleIntrinsics(const Intrinsics& intrinsics, uint32_t width, uint32_t height);

// Fills the calibration fields of `out` (not its header) with `intrinsics` and `depth_scale`
// (metres per depth unit, 0 without depth). Intrinsics without distortion (model none) are
// written as ROS writes an undistorted camera: plumb_bob with five zeros.
void FillCameraInfo(const Intrinsics& intrinsics, double depth_scale, msgs::CameraInfo& out);

}  // namespace probeless::calib
