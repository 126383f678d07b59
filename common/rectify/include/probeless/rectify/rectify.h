// Lens-distortion rectification of camera streams (the role of ROS image_proc / depth_image_proc
// rectify): undistortion maps computed once per calibration, colour and grey resampled
// bilinearly, depth resampled without mixing across depth discontinuities, and the rectified
// CameraInfo as ROS writes it. The rectify node (nodes/rectify) runs it in front of every consumer
// that assumes a pinhole camera (docs/rectify.md). OpenCV stays in src/.
#pragma once

#include <array>
#include <cstddef>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>

#include "probeless/error/error.h"
#include "probeless/msgs/camera_info.h"
#include "probeless/msgs/image.h"

namespace probeless::rectify {

// Bad input (a malformed or inconsistent camera_info, an image that does not match its
// calibration, an unsupported encoding, bad options): one line naming the topic or file given as
// `source`, e.g. "/camera/camera_info: distortion coefficient 2 (p1) is NaN".
class RectifyError : public InputError {
 public:
  using InputError::InputError;
};

// How depth images (depth16, float32) are resampled. Neither mixes depths across a discontinuity.
enum class DepthInterpolation {
  kNearest,    // the nearest source pixel: never invents a depth (default)
  kEdgeAware,  // bilinear where the four source neighbours are valid and agree within
               // depth_edge_tolerance, else the nearest pixel
};

struct RectifyOptions {
  // Free scaling of the rectified camera (OpenCV getOptimalNewCameraMatrix): < 0 keeps the
  // calibrated camera matrix K (ROS's P = [K | 0], what tools/calibrate writes); 0 = the new camera
  // sees only valid pixels; 1 = every source pixel is kept (black corners). Otherwise in [0, 1].
  double alpha = -1;
  DepthInterpolation depth_interpolation = DepthInterpolation::kNearest;
  // kEdgeAware: neighbours whose depths differ by more than this fraction of the nearest of them
  // count as a discontinuity (0.03 = 3 cm at 1 m, above Kinect noise, far below object gaps).
  double depth_edge_tolerance = 0.03;
};

// True when `info` carries a non-zero distortion coefficient (a model with only zeros is none).
bool HasDistortion(const msgs::CameraInfo& info);

// Throws RectifyError "<source>: ..." unless `info` is usable: a known distortion model,
// distortion_count equal to its coefficient count (0, 5 or 8), finite coefficients, positive
// width, height and focal lengths, a finite principal point.
void ValidateCameraInfo(const msgs::CameraInfo& info, std::string_view source);

// The camera after rectification, as ROS writes it: distortion plumb_bob with five zeros, fx fy
// cx cy = the new camera matrix (the left 3x3 of ROS's projection matrix P; the rectification
// matrix R is the identity for one camera), same size, header and depth_scale. Validates `info`
// like ValidateCameraInfo.
msgs::CameraInfo RectifiedCameraInfo(const msgs::CameraInfo& info, const RectifyOptions& options,
                                     std::string_view source);

// Process-wide OpenCV worker threads used by Rectify (1 = one core, the default of the node).
// Results do not depend on it.
void SetThreads(int threads);

// Undistortion maps for one calibration, computed once (OpenCV initUndistortRectifyMap with
// R = I), and the resampling of images of that camera. Immutable after construction: Rectify may
// be called from several threads.
class Rectifier {
 public:
  // Throws RectifyError "<source>: ..." for an unusable `info` (ValidateCameraInfo) or options
  // (alpha > 1, depth_edge_tolerance <= 0). `source` names the camera_info topic or file in later
  // errors too.
  explicit Rectifier(const msgs::CameraInfo& info, const RectifyOptions& options = {},
                     std::string_view source = "camera_info");
  ~Rectifier();
  Rectifier(Rectifier&&) noexcept;
  Rectifier& operator=(Rectifier&&) noexcept;

  // True when `info` has the calibration these maps were made for (size, intrinsics, model and
  // coefficients; the header is ignored): the node's cache key.
  bool Matches(const msgs::CameraInfo& info) const;
  // The rectified camera (RectifiedCameraInfo of the constructor's info; header as given then).
  const msgs::CameraInfo& rectified_info() const;
  // No distortion and an unchanged camera matrix: Rectify copies the pixels.
  bool passthrough() const;
  // Pixel (x right, y down, pixel centres at integers) of the distorted source image that
  // rectified pixel (x, y) samples, e.g. for tests; x < width, y < height.
  std::array<float, 2> SourcePixel(uint32_t x, uint32_t y) const;

  // Rectifies `in` (header and size; pixels in `in_pixels`, in.step bytes per row) into `out`
  // (header copied, same size and encoding, packed step) and `out_pixels` (e.g. a loaned bus slot's
  // payload; at least Image::PackedPayloadBytes bytes; must not overlap `in_pixels`: resampling
  // reads neighbours of pixels already written). rgb8, bgr8, mono8, mono16, rgb32f:
  // bilinear; depth16, float32 (depth; 0 or non-finite = no measurement): options'
  // depth_interpolation. Pixels whose source falls outside the image are 0. Throws RectifyError
  // "<image_source>: ..." when the size differs from the calibration's (naming both sources), or
  // for an invalid encoding or too small buffers.
  void Rectify(const msgs::Image& in, std::span<const std::byte> in_pixels, msgs::Image& out,
               std::span<std::byte> out_pixels, std::string_view image_source = "image") const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// `in` copied unchanged into `out` (header, size and encoding copied, packed step) and
// `out_pixels` (at least Image::PackedPayloadBytes bytes): the stream of a camera without any
// calibration yet. Throws RectifyError "<image_source>: ..." for an invalid encoding or too small
// buffers, as Rectifier::Rectify does.
void CopyImage(const msgs::Image& in, std::span<const std::byte> in_pixels, msgs::Image& out,
               std::span<std::byte> out_pixels, std::string_view image_source = "image");

}  // namespace probeless::rectify
