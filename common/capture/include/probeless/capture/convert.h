// Pixel formats of capture devices and their conversion into probeless images, written straight
// into the destination (a bus slot): YUYV -> rgb8, MJPEG -> rgb8 (libjpeg-turbo), RGB24/BGR24/GREY
// copies, Kinect 11-bit disparity -> depth16 millimetres.
//
// All functions are single-threaded and allocation-free on the hot path (MJPEG decode uses the
// decoder's own small state). Errors: sizes that do not fit and corrupt JPEG data throw
// CaptureError(kBadInput) with one line naming the frame.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>

#include "probeless/msgs/image.h"

namespace probeless::capture {

// Raw pixel formats delivered by devices.
enum class PixelFormat {
  kYuyv,         // YUV 4:2:2 packed Y0 U Y1 V (V4L2 YUYV), BT.601 limited range
  kMjpeg,        // one JPEG image per frame (Huffman tables may be omitted, as MJPEG allows)
  kRgb24,        // R G B bytes
  kBgr24,        // B G R bytes
  kGrey,         // 8-bit luminance
  kKinectRaw11,  // uint16 per pixel, Kinect v1 11-bit raw disparity (0..2047, 2047 = no data)
  kDepthMm,      // uint16 per pixel, depth along z in millimetres, 0 = no data
};

// "yuyv", "mjpeg", "rgb24", "bgr24", "grey", "kinect_raw11", "depth_mm".
std::string_view PixelFormatName(PixelFormat format);
// Parses the names above (also "yuyv422", "mjpg", "rgb", "bgr", "gray", "mono8"); throws
// CaptureError(kBadInput) listing the accepted names otherwise.
PixelFormat PixelFormatFromName(std::string_view name);
// The probeless encoding a frame of `format` is published as: rgb8 for yuyv/mjpeg/rgb24, bgr8,
// mono8, depth16 for both depth formats.
msgs::Encoding OutputEncoding(PixelFormat format);

// A frame as the device delivered it; `data` is borrowed (valid until the device's next call).
struct RawFrame {
  PixelFormat format = PixelFormat::kRgb24;
  uint32_t width = 0;   // pixels
  uint32_t height = 0;  // rows
  uint32_t stride = 0;  // bytes per row of `data`; 0 = packed (ignored for MJPEG)
  std::span<const uint8_t> data;
  int64_t stamp_mono_ns = 0;  // mid-exposure, CLOCK_MONOTONIC ns (best estimate of the device)
  uint64_t sequence = 0;      // device frame counter, from 1
};

// YUYV (BT.601 limited range, as UVC cameras send) -> RGB, 8-bit fixed point. `width` must be
// even; `src_step` >= 2 * width, `dst_step` >= 3 * width; spans must hold height rows.
void YuyvToRgb(const uint8_t* src, uint32_t src_step, uint32_t width, uint32_t height, uint8_t* dst,
               uint32_t dst_step);

// Decodes one JPEG (MJPEG frame) of exactly width x height into RGB rows at `dst` (dst_step bytes
// apart), with libjpeg-turbo, no intermediate image. Throws CaptureError(kBadInput) for corrupt
// data or another size.
void DecodeMjpegToRgb(std::span<const uint8_t> jpeg, uint32_t width, uint32_t height, uint8_t* dst,
                      uint32_t dst_step);

// The libfreenect depth model of a Kinect v1 (registration.c: zero plane at 120 mm, 0.1042 mm
// reference pixel, 7.5 cm emitter–camera distance, const_shift 200): raw 11-bit disparity ->
// millimetres along z. Raw values whose depth falls outside (0, 10000] mm, and 2047, map to 0.
class KinectDepthModel {
 public:
  static constexpr uint16_t kNoData = 2047;  // raw "no measurement"
  static constexpr uint16_t kMaxDepthMm = 10000;
  // Table for the default (factory typical) parameters.
  static const KinectDepthModel& Default();
  // Table for explicit zero-plane parameters (from a device's calibration).
  KinectDepthModel(double reference_distance_mm, double reference_pixel_size_mm,
                   double emitter_distance_cm, double const_shift);
  // Millimetres for raw value `raw` (values >= 2048 are masked to 11 bits).
  uint16_t ToMm(uint16_t raw) const { return raw_to_mm_[raw & 2047]; }
  // The raw value whose depth is closest to `mm`; kNoData for 0 or depths the model cannot give.
  uint16_t ToRaw(uint16_t mm) const;
  // Largest difference in mm between `mm` and ToMm(ToRaw(mm)) around `mm`: the quantisation step.
  uint16_t QuantisationErrorMm(uint16_t mm) const;
  // Converts `count` raw values to millimetres (dst may not alias src).
  void ToMm(const uint16_t* raw, uint16_t* mm, size_t count) const;

 private:
  uint16_t ComputeRaw(uint16_t mm) const;
  std::array<uint16_t, 2048> raw_to_mm_{};
  std::array<uint16_t, kMaxDepthMm + 1> mm_to_raw_{};
};

// Writes `frame` into `image` (header not touched; width/height/encoding/step set to the packed
// layout of OutputEncoding) and its `payload` (a bus slot's payload). Throws
// CaptureError(kBadInput) if the payload is too small, the frame's data is shorter than its size
// says, or it is corrupt.
void ConvertFrame(const RawFrame& frame, msgs::Image& image, std::span<std::byte> payload,
                  const KinectDepthModel& depth_model = KinectDepthModel::Default());

}  // namespace probeless::capture
