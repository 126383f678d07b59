#include "probeless/capture/convert.h"

#include <csetjmp>
#include <cstdio>
#include <cstring>
// jpeglib.h needs size_t and FILE declared first.
#include <jpeglib.h>

#include <algorithm>
#include <cmath>

#include "probeless/capture/capture_error.h"

namespace probeless::capture {

std::string_view ErrorKindName(ErrorKind kind) {
  switch (kind) {
    case ErrorKind::kBadInput:
      return "bad input";
    case ErrorKind::kNoDevice:
      return "no device";
    case ErrorKind::kBusy:
      return "busy";
    case ErrorKind::kPermission:
      return "permission denied";
    case ErrorKind::kDisconnected:
      return "disconnected";
    case ErrorKind::kDeviceError:
      return "device error";
  }
  return "device error";
}

std::string_view PixelFormatName(PixelFormat format) {
  switch (format) {
    case PixelFormat::kYuyv:
      return "yuyv";
    case PixelFormat::kMjpeg:
      return "mjpeg";
    case PixelFormat::kRgb24:
      return "rgb24";
    case PixelFormat::kBgr24:
      return "bgr24";
    case PixelFormat::kGrey:
      return "grey";
    case PixelFormat::kKinectRaw11:
      return "kinect_raw11";
    case PixelFormat::kDepthMm:
      return "depth_mm";
  }
  return "invalid";
}

PixelFormat PixelFormatFromName(std::string_view name) {
  if (name == "yuyv" || name == "yuyv422" || name == "yuy2") return PixelFormat::kYuyv;
  if (name == "mjpeg" || name == "mjpg" || name == "jpeg") return PixelFormat::kMjpeg;
  if (name == "rgb24" || name == "rgb" || name == "rgb8") return PixelFormat::kRgb24;
  if (name == "bgr24" || name == "bgr" || name == "bgr8") return PixelFormat::kBgr24;
  if (name == "grey" || name == "gray" || name == "mono8") return PixelFormat::kGrey;
  if (name == "kinect_raw11") return PixelFormat::kKinectRaw11;
  if (name == "depth_mm") return PixelFormat::kDepthMm;
  throw CaptureError(ErrorKind::kBadInput, "unknown pixel format '" + std::string(name) +
                                               "' (expected mjpeg, yuyv, rgb24, bgr24 or grey)");
}

msgs::Encoding OutputEncoding(PixelFormat format) {
  switch (format) {
    case PixelFormat::kYuyv:
    case PixelFormat::kMjpeg:
    case PixelFormat::kRgb24:
      return msgs::Encoding::kRgb8;
    case PixelFormat::kBgr24:
      return msgs::Encoding::kBgr8;
    case PixelFormat::kGrey:
      return msgs::Encoding::kMono8;
    case PixelFormat::kKinectRaw11:
    case PixelFormat::kDepthMm:
      return msgs::Encoding::kDepth16;
  }
  return msgs::Encoding::kInvalid;
}

namespace {

inline uint8_t Clamp8(int v) { return static_cast<uint8_t>(v < 0 ? 0 : (v > 255 ? 255 : v)); }

}  // namespace

void YuyvToRgb(const uint8_t* src, uint32_t src_step, uint32_t width, uint32_t height, uint8_t* dst,
               uint32_t dst_step) {
  for (uint32_t y = 0; y < height; ++y) {
    const uint8_t* s = src + static_cast<size_t>(y) * src_step;
    uint8_t* d = dst + static_cast<size_t>(y) * dst_step;
    for (uint32_t x = 0; x + 1 < width; x += 2, s += 4, d += 6) {
      const int c0 = 298 * (s[0] - 16);
      const int c1 = 298 * (s[2] - 16);
      const int u = s[1] - 128;
      const int v = s[3] - 128;
      const int r = 409 * v + 128;
      const int g = -100 * u - 208 * v + 128;
      const int b = 516 * u + 128;
      d[0] = Clamp8((c0 + r) >> 8);
      d[1] = Clamp8((c0 + g) >> 8);
      d[2] = Clamp8((c0 + b) >> 8);
      d[3] = Clamp8((c1 + r) >> 8);
      d[4] = Clamp8((c1 + g) >> 8);
      d[5] = Clamp8((c1 + b) >> 8);
    }
  }
}

namespace {

struct JpegErrorManager {
  jpeg_error_mgr base;
  std::jmp_buf jump;
  char message[JMSG_LENGTH_MAX];
};

void JpegErrorExit(j_common_ptr info) {
  auto* manager = reinterpret_cast<JpegErrorManager*>(info->err);
  (*info->err->format_message)(info, manager->message);
  std::longjmp(manager->jump, 1);
}

void JpegSilence(j_common_ptr, int) {}

// A reusable decompressor per thread (creating one costs more than decoding a small frame).
struct Decompressor {
  jpeg_decompress_struct info{};
  JpegErrorManager error{};
  Decompressor() {
    info.err = jpeg_std_error(&error.base);
    error.base.error_exit = JpegErrorExit;
    error.base.emit_message = JpegSilence;
    jpeg_create_decompress(&info);
  }
  ~Decompressor() { jpeg_destroy_decompress(&info); }
};

}  // namespace

void DecodeMjpegToRgb(std::span<const uint8_t> jpeg, uint32_t width, uint32_t height, uint8_t* dst,
                      uint32_t dst_step) {
  thread_local Decompressor decompressor;
  jpeg_decompress_struct& info = decompressor.info;
  std::string failure;
  // Nothing with a destructor lives between setjmp and the longjmp sites below.
  if (setjmp(decompressor.error.jump) != 0) {
    jpeg_abort_decompress(&info);
    throw CaptureError(ErrorKind::kBadInput,
                       "MJPEG frame (" + std::to_string(jpeg.size()) +
                           " bytes) is corrupt: " + std::string(decompressor.error.message));
  }
  if (jpeg.size() < 4 || jpeg[0] != 0xFF || jpeg[1] != 0xD8) {
    throw CaptureError(ErrorKind::kBadInput, "MJPEG frame (" + std::to_string(jpeg.size()) +
                                                 " bytes) does not start with a JPEG SOI marker");
  }
  jpeg_mem_src(&info, jpeg.data(), static_cast<unsigned long>(jpeg.size()));
  jpeg_read_header(&info, TRUE);
  if (info.image_width != width || info.image_height != height) {
    const std::string got =
        std::to_string(info.image_width) + "x" + std::to_string(info.image_height);
    jpeg_abort_decompress(&info);
    throw CaptureError(ErrorKind::kBadInput, "MJPEG frame is " + got + ", expected " +
                                                 std::to_string(width) + "x" +
                                                 std::to_string(height));
  }
  info.out_color_space = JCS_RGB;
  info.dct_method = JDCT_ISLOW;
  jpeg_start_decompress(&info);
  JSAMPROW rows[16];
  while (info.output_scanline < info.output_height) {
    const uint32_t batch = std::min<uint32_t>(16, info.output_height - info.output_scanline);
    for (uint32_t i = 0; i < batch; ++i) {
      rows[i] = dst + static_cast<size_t>(info.output_scanline + i) * dst_step;
    }
    jpeg_read_scanlines(&info, rows, batch);
  }
  jpeg_finish_decompress(&info);
}

// --- Kinect depth model
// ---------------------------------------------------------------------------

namespace {

// The valid raw value whose depth is closest to mm (kNoData if the table has none).
uint16_t NearestRaw(const std::array<uint16_t, 2048>& table, uint16_t mm) {
  uint16_t best = KinectDepthModel::kNoData;
  int best_error = 1 << 30;
  for (int raw = 0; raw < KinectDepthModel::kNoData; ++raw) {
    if (table[raw] == 0) continue;
    const int error = std::abs(static_cast<int>(table[raw]) - mm);
    if (error < best_error) {
      best_error = error;
      best = static_cast<uint16_t>(raw);
    }
  }
  return best;
}

}  // namespace

KinectDepthModel::KinectDepthModel(double reference_distance_mm, double reference_pixel_size_mm,
                                   double emitter_distance_cm, double const_shift) {
  // libfreenect registration.c, freenect_raw_to_mm: parameter_coefficient 4, shift_scale 10,
  // pixel_size_factor 1, S2D_CONST_OFFSET 0.375.
  for (int raw = 0; raw < 2048; ++raw) {
    const double fixed_ref_x = ((raw - 4.0 * const_shift) / 4.0) - 0.375;
    const double metric = fixed_ref_x * reference_pixel_size_mm;
    const double mm = 10.0 * ((metric * reference_distance_mm / (emitter_distance_cm - metric)) +
                              reference_distance_mm);
    raw_to_mm_[raw] = (mm > 0 && mm <= kMaxDepthMm && metric < emitter_distance_cm)
                          ? static_cast<uint16_t>(mm)
                          : 0;
  }
  raw_to_mm_[kNoData] = 0;
  for (uint32_t mm = 0; mm <= kMaxDepthMm; ++mm)
    mm_to_raw_[mm] = ComputeRaw(static_cast<uint16_t>(mm));
}

const KinectDepthModel& KinectDepthModel::Default() {
  static const KinectDepthModel model(120.0, 0.1042, 7.5, 200.0);
  return model;
}

uint16_t KinectDepthModel::QuantisationErrorMm(uint16_t mm) const {
  const uint16_t raw = NearestRaw(raw_to_mm_, mm);
  if (raw == kNoData) return 0;
  int step = 1;
  if (raw > 0 && raw_to_mm_[raw - 1] != 0)
    step = std::max(step, raw_to_mm_[raw] - raw_to_mm_[raw - 1]);
  if (raw + 1 < kNoData && raw_to_mm_[raw + 1] != 0) {
    step = std::max(step, raw_to_mm_[raw + 1] - raw_to_mm_[raw]);
  }
  return static_cast<uint16_t>(step);
}

uint16_t KinectDepthModel::ToRaw(uint16_t mm) const {
  if (mm == 0 || mm > kMaxDepthMm) return kNoData;
  return mm_to_raw_[mm];
}

uint16_t KinectDepthModel::ComputeRaw(uint16_t mm) const {
  if (mm == 0) return kNoData;
  const uint16_t raw = NearestRaw(raw_to_mm_, mm);
  // Depths beyond the model's range on either side have no raw value.
  if (raw == kNoData ||
      std::abs(static_cast<int>(raw_to_mm_[raw]) - mm) > QuantisationErrorMm(mm)) {
    return kNoData;
  }
  return raw;
}

void KinectDepthModel::ToMm(const uint16_t* raw, uint16_t* mm, size_t count) const {
  for (size_t i = 0; i < count; ++i) mm[i] = raw_to_mm_[raw[i] & 2047];
}

// --- ConvertFrame
// ---------------------------------------------------------------------------------

namespace {

void CheckSource(const RawFrame& frame, uint32_t packed_step) {
  const uint32_t step = frame.stride != 0 ? frame.stride : packed_step;
  if (step < packed_step) {
    throw CaptureError(ErrorKind::kBadInput, std::string(PixelFormatName(frame.format)) +
                                                 " frame " + std::to_string(frame.width) + "x" +
                                                 std::to_string(frame.height) + ": stride " +
                                                 std::to_string(step) + " is smaller than " +
                                                 std::to_string(packed_step) + " bytes per row");
  }
  const size_t need =
      frame.height == 0 ? 0 : static_cast<size_t>(step) * (frame.height - 1) + packed_step;
  if (frame.data.size() < need) {
    throw CaptureError(ErrorKind::kBadInput, std::string(PixelFormatName(frame.format)) +
                                                 " frame " + std::to_string(frame.width) + "x" +
                                                 std::to_string(frame.height) + " needs " +
                                                 std::to_string(need) + " bytes, the device gave " +
                                                 std::to_string(frame.data.size()));
  }
}

void CopyRows(const RawFrame& frame, uint32_t row_bytes, uint8_t* dst, uint32_t dst_step) {
  const uint32_t src_step = frame.stride != 0 ? frame.stride : row_bytes;
  if (src_step == row_bytes && dst_step == row_bytes) {
    std::memcpy(dst, frame.data.data(), static_cast<size_t>(row_bytes) * frame.height);
    return;
  }
  for (uint32_t y = 0; y < frame.height; ++y) {
    std::memcpy(dst + static_cast<size_t>(y) * dst_step,
                frame.data.data() + static_cast<size_t>(y) * src_step, row_bytes);
  }
}

}  // namespace

void ConvertFrame(const RawFrame& frame, msgs::Image& image, std::span<std::byte> payload,
                  const KinectDepthModel& depth_model) {
  const msgs::Encoding encoding = OutputEncoding(frame.format);
  image.Init(frame.width, frame.height, encoding);
  if (payload.size() < image.PayloadBytes()) {
    throw CaptureError(ErrorKind::kBadInput, "image " + image.Describe() + " needs " +
                                                 std::to_string(image.PayloadBytes()) +
                                                 " bytes, the bus slot has " +
                                                 std::to_string(payload.size()));
  }
  auto* dst = reinterpret_cast<uint8_t*>(payload.data());
  switch (frame.format) {
    case PixelFormat::kYuyv: {
      if (frame.width % 2 != 0) {
        throw CaptureError(ErrorKind::kBadInput,
                           "yuyv frame width " + std::to_string(frame.width) + " is odd");
      }
      CheckSource(frame, frame.width * 2);
      YuyvToRgb(frame.data.data(), frame.stride != 0 ? frame.stride : frame.width * 2, frame.width,
                frame.height, dst, image.step);
      return;
    }
    case PixelFormat::kMjpeg:
      DecodeMjpegToRgb(frame.data, frame.width, frame.height, dst, image.step);
      return;
    case PixelFormat::kRgb24:
    case PixelFormat::kBgr24:
      CheckSource(frame, frame.width * 3);
      CopyRows(frame, frame.width * 3, dst, image.step);
      return;
    case PixelFormat::kGrey:
      CheckSource(frame, frame.width);
      CopyRows(frame, frame.width, dst, image.step);
      return;
    case PixelFormat::kDepthMm:
      CheckSource(frame, frame.width * 2);
      CopyRows(frame, frame.width * 2, dst, image.step);
      return;
    case PixelFormat::kKinectRaw11: {
      CheckSource(frame, frame.width * 2);
      const uint32_t src_step = frame.stride != 0 ? frame.stride : frame.width * 2;
      for (uint32_t y = 0; y < frame.height; ++y) {
        const auto* src = reinterpret_cast<const uint16_t*>(frame.data.data() +
                                                            static_cast<size_t>(y) * src_step);
        depth_model.ToMm(src,
                         reinterpret_cast<uint16_t*>(dst + static_cast<size_t>(y) * image.step),
                         frame.width);
      }
      return;
    }
  }
}

}  // namespace probeless::capture
