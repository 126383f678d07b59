// CameraInfo: pinhole intrinsics and lens distortion of a camera stream.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "probeless/msgs/header.h"
#include "probeless/msgs/layout.h"

namespace probeless::msgs {

// Lens distortion models (OpenCV conventions). Values are part of the wire format.
enum class DistortionModel : uint32_t {
  kNone = 0,                // no distortion; distortion_count 0
  kPlumbBob = 1,            // k1, k2, p1, p2, k3 (5 coefficients)
  kRationalPolynomial = 2,  // k1, k2, p1, p2, k3, k4, k5, k6 (8 coefficients)
};
constexpr std::string_view DescribeEnum(DistortionModel) {
  return "DistortionModel{none=0,plumb_bob=1,rational_polynomial=2}";
}

// "none", "plumb_bob", "rational_polynomial"; "invalid" otherwise.
constexpr std::string_view DistortionModelName(DistortionModel model) {
  switch (model) {
    case DistortionModel::kNone:
      return "none";
    case DistortionModel::kPlumbBob:
      return "plumb_bob";
    case DistortionModel::kRationalPolynomial:
      return "rational_polynomial";
  }
  return "invalid";
}

// Number of coefficients of `model` (0, 5 or 8); 0 for an invalid value.
constexpr uint32_t DistortionCoefficientCount(DistortionModel model) {
  switch (model) {
    case DistortionModel::kNone:
      return 0;
    case DistortionModel::kPlumbBob:
      return 5;
    case DistortionModel::kRationalPolynomial:
      return 8;
  }
  return 0;
}

inline constexpr uint32_t kMaxDistortionCoefficients = 8;

// Calibration of the camera whose images share this header.frame_id (the camera's optical frame:
// x right, y down, z forward along the optical axis, origin at the projection centre). A point
// (X, Y, Z) in that frame (metres) projects, before distortion, to pixel
// u = fx * X / Z + cx, v = fy * Y / Z + cy, with pixel (0, 0) the centre of the top-left pixel.
struct CameraInfo {
  Header header;
  uint32_t width = 0;   // image width in pixels the calibration applies to
  uint32_t height = 0;  // image height in pixels
  double fx = 0;        // focal length along x, pixels
  double fy = 0;        // focal length along y, pixels
  double cx = 0;        // principal point x, pixels
  double cy = 0;        // principal point y, pixels
  DistortionModel distortion_model = DistortionModel::kNone;
  uint32_t distortion_count = 0;  // valid entries of `distortion` (= model's coefficient count)
  double distortion[kMaxDistortionCoefficients] = {};  // OpenCV order, unused entries 0
  // Metres per unit of the matching depth image: 0.001 for depth16 (millimetres), 1 for float32
  // depth in metres, 0 when the camera has no depth.
  double depth_scale = 0;

  static constexpr std::string_view kTypeName = "probeless_msgs/CameraInfo";
  static constexpr bool kHasPayload = false;
  static const uint64_t kLayoutHash;
  static constexpr std::string LayoutDescription() {
    layout::LayoutBuilder b(kTypeName);
    PROBELESS_MSGS_FIELD(b, CameraInfo, header);
    PROBELESS_MSGS_FIELD(b, CameraInfo, width);
    PROBELESS_MSGS_FIELD(b, CameraInfo, height);
    PROBELESS_MSGS_FIELD(b, CameraInfo, fx);
    PROBELESS_MSGS_FIELD(b, CameraInfo, fy);
    PROBELESS_MSGS_FIELD(b, CameraInfo, cx);
    PROBELESS_MSGS_FIELD(b, CameraInfo, cy);
    PROBELESS_MSGS_FIELD(b, CameraInfo, distortion_model);
    PROBELESS_MSGS_FIELD(b, CameraInfo, distortion_count);
    PROBELESS_MSGS_FIELD(b, CameraInfo, distortion);
    PROBELESS_MSGS_FIELD(b, CameraInfo, depth_scale);
    return b.Finish<CameraInfo>();
  }

  // Throws MessageError unless the model is known, distortion_count matches it, width/height and
  // fx/fy are positive and depth_scale is not negative.
  void Validate() const {
    const std::string name = std::string(kTypeName) + " '" + PrintableText(header.FrameId()) + "'";
    if (DistortionModelName(distortion_model) == "invalid") {
      throw MessageError(name + ": invalid distortion model " +
                         std::to_string(static_cast<uint32_t>(distortion_model)));
    }
    if (distortion_count != DistortionCoefficientCount(distortion_model)) {
      throw MessageError(name + ": distortion model " +
                         std::string(DistortionModelName(distortion_model)) + " has " +
                         std::to_string(DistortionCoefficientCount(distortion_model)) +
                         " coefficients, distortion_count is " + std::to_string(distortion_count));
    }
    if (width == 0 || height == 0) throw MessageError(name + ": width and height must be > 0");
    if (!(fx > 0) || !(fy > 0)) throw MessageError(name + ": fx and fy must be > 0");
    if (!(depth_scale >= 0)) throw MessageError(name + ": depth_scale must be >= 0");
  }
};
inline constexpr uint64_t CameraInfo::kLayoutHash =
    layout::Fnv1a64(CameraInfo::LayoutDescription());

static_assert(Message<CameraInfo>);
static_assert(sizeof(CameraInfo) == 176 && alignof(CameraInfo) == 8);
static_assert(offsetof(CameraInfo, width) == 56 && offsetof(CameraInfo, fx) == 64 &&
              offsetof(CameraInfo, cy) == 88 && offsetof(CameraInfo, distortion_model) == 96 &&
              offsetof(CameraInfo, distortion_count) == 100 &&
              offsetof(CameraInfo, distortion) == 104 && offsetof(CameraInfo, depth_scale) == 168);

}  // namespace probeless::msgs
