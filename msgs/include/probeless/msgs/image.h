// Image: a camera frame (colour, grey, depth or float) with its pixels in the same bus slot.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <type_traits>

#include "probeless/msgs/header.h"
#include "probeless/msgs/layout.h"

namespace probeless::msgs {

// Pixel encodings. The numeric values are part of the wire format (and of the layout hash).
enum class Encoding : uint32_t {
  kInvalid = 0,  // unset
  kRgb8 = 1,     // 3 x uint8 per pixel, R G B, sRGB-encoded values 0..255
  kBgr8 = 2,     // 3 x uint8 per pixel, B G R, sRGB-encoded values 0..255
  kMono8 = 3,    // 1 x uint8 per pixel, grey 0..255
  kMono16 = 4,   // 1 x uint16 per pixel (host byte order), grey 0..65535
  kDepth16 = 5,  // 1 x uint16 per pixel (16UC1), depth along the optical axis in millimetres,
                 // 0 = invalid (no measurement)
  kFloat32 = 6,  // 1 x float32 per pixel (32FC1); meaning given by the topic (e.g. depth in metres)
  kRgb32f = 7,   // 3 x float32 per pixel (32FC3), R G B, linear (not sRGB); meaning and unit given
                 // by the topic (e.g. scene/indirect: radiance for albedo 1)
};
constexpr std::string_view DescribeEnum(Encoding) {
  return "Encoding{invalid=0,rgb8=1,bgr8=2,mono8=3,mono16=4,depth16=5,float32=6,rgb32f=7}";
}

// The encoding's name as used in params and docs ("rgb8", "depth16", ...); "invalid" for an
// unset or unknown value.
constexpr std::string_view EncodingName(Encoding encoding) {
  switch (encoding) {
    case Encoding::kRgb8:
      return "rgb8";
    case Encoding::kBgr8:
      return "bgr8";
    case Encoding::kMono8:
      return "mono8";
    case Encoding::kMono16:
      return "mono16";
    case Encoding::kDepth16:
      return "depth16";
    case Encoding::kFloat32:
      return "float32";
    case Encoding::kRgb32f:
      return "rgb32f";
    case Encoding::kInvalid:
      break;
  }
  return "invalid";
}

// The encoding named `name` ("rgb8", "bgr8", "mono8", "mono16", "depth16", "float32", "rgb32f").
// Throws MessageError for any other name.
inline Encoding EncodingFromName(std::string_view name) {
  for (Encoding e : {Encoding::kRgb8, Encoding::kBgr8, Encoding::kMono8, Encoding::kMono16,
                     Encoding::kDepth16, Encoding::kFloat32, Encoding::kRgb32f}) {
    if (EncodingName(e) == name) return e;
  }
  throw MessageError("unknown image encoding '" + std::string(name) +
                     "' (expected rgb8, bgr8, mono8, mono16, depth16, float32 or rgb32f)");
}

// Channels per pixel (3 for rgb8/bgr8/rgb32f, else 1); 0 for an invalid encoding.
constexpr uint32_t ChannelCount(Encoding encoding) {
  switch (encoding) {
    case Encoding::kRgb8:
    case Encoding::kBgr8:
    case Encoding::kRgb32f:
      return 3;
    case Encoding::kMono8:
    case Encoding::kMono16:
    case Encoding::kDepth16:
    case Encoding::kFloat32:
      return 1;
    case Encoding::kInvalid:
      break;
  }
  return 0;
}

// Bytes per channel (1, 2 or 4); 0 for an invalid encoding.
constexpr uint32_t BytesPerChannel(Encoding encoding) {
  switch (encoding) {
    case Encoding::kRgb8:
    case Encoding::kBgr8:
    case Encoding::kMono8:
      return 1;
    case Encoding::kMono16:
    case Encoding::kDepth16:
      return 2;
    case Encoding::kFloat32:
    case Encoding::kRgb32f:
      return 4;
    case Encoding::kInvalid:
      break;
  }
  return 0;
}

// Bytes per pixel (3 for rgb8/bgr8, 1 mono8, 2 mono16/depth16, 4 float32, 12 rgb32f); 0 for
// invalid.
constexpr uint32_t BytesPerPixel(Encoding encoding) {
  return ChannelCount(encoding) * BytesPerChannel(encoding);
}

// An image. The pixels follow the struct in the same bus slot (payload): row y starts at payload
// byte y * step; pixel x of that row at byte x * BytesPerPixel(encoding) within the row. Pixel
// (0, 0) is the top-left of the image as seen by the camera (x right, y down), in the camera
// frame header.frame_id. header.stamp_* is the middle of the exposure.
struct Image {
  Header header;
  uint32_t width = 0;   // pixels per row
  uint32_t height = 0;  // rows
  uint32_t step = 0;    // bytes per row, >= width * BytesPerPixel(encoding)
  Encoding encoding = Encoding::kInvalid;
  uint8_t reserved[56] = {};  // zero; pads the struct to 128 bytes (payload 64-byte aligned)

  static constexpr std::string_view kTypeName = "probeless_msgs/Image";
  static constexpr bool kHasPayload = true;
  static const uint64_t kLayoutHash;
  static constexpr std::string LayoutDescription() {
    layout::LayoutBuilder b(kTypeName);
    PROBELESS_MSGS_FIELD(b, Image, header);
    PROBELESS_MSGS_FIELD(b, Image, width);
    PROBELESS_MSGS_FIELD(b, Image, height);
    PROBELESS_MSGS_FIELD(b, Image, step);
    PROBELESS_MSGS_FIELD(b, Image, encoding);
    PROBELESS_MSGS_FIELD(b, Image, reserved);
    return b.Finish<Image>();
  }

  // Payload bytes of a tightly packed (step = width * bytes per pixel) image.
  static constexpr size_t PackedPayloadBytes(uint32_t width, uint32_t height, Encoding encoding) {
    return static_cast<size_t>(width) * BytesPerPixel(encoding) * height;
  }
  // Whole bus message bytes (struct + packed payload): the max_message_bytes a publisher needs.
  static constexpr size_t MessageBytesFor(uint32_t width, uint32_t height, Encoding encoding) {
    return sizeof(Image) + PackedPayloadBytes(width, height, encoding);
  }

  // Sets width, height, encoding and a packed step (width * bytes per pixel). Throws MessageError
  // for an invalid encoding.
  void Init(uint32_t new_width, uint32_t new_height, Encoding new_encoding) {
    if (BytesPerPixel(new_encoding) == 0) {
      throw MessageError("Image: invalid encoding " +
                         std::to_string(static_cast<uint32_t>(new_encoding)));
    }
    width = new_width;
    height = new_height;
    encoding = new_encoding;
    step = new_width * BytesPerPixel(new_encoding);
  }

  // Payload bytes this image needs: step * height.
  constexpr size_t PayloadBytes() const { return static_cast<size_t>(step) * height; }

  // Throws MessageError unless the encoding is valid, step >= width * bytes per pixel, step is a
  // multiple of the channel size, and `payload_bytes` >= PayloadBytes().
  void Validate(size_t payload_bytes) const {
    const uint32_t bpp = BytesPerPixel(encoding);
    if (bpp == 0) {
      throw MessageError("Image: invalid encoding " +
                         std::to_string(static_cast<uint32_t>(encoding)));
    }
    if (static_cast<uint64_t>(step) < static_cast<uint64_t>(width) * bpp) {
      throw MessageError("Image " + Describe() + ": step " + std::to_string(step) +
                         " is smaller than width * " + std::to_string(bpp) + " bytes per pixel");
    }
    if (step % BytesPerChannel(encoding) != 0) {
      throw MessageError("Image " + Describe() + ": step " + std::to_string(step) +
                         " is not a multiple of the " + std::to_string(BytesPerChannel(encoding)) +
                         "-byte channel size");
    }
    if (payload_bytes < PayloadBytes()) {
      throw MessageError("Image " + Describe() + " needs " + std::to_string(PayloadBytes()) +
                         " payload bytes, got " + std::to_string(payload_bytes));
    }
  }

  // "640x480 rgb8 (step 1920)" for messages.
  std::string Describe() const {
    return std::to_string(width) + "x" + std::to_string(height) + " " +
           std::string(EncodingName(encoding)) + " (step " + std::to_string(step) + ")";
  }
};
inline constexpr uint64_t Image::kLayoutHash = layout::Fnv1a64(Image::LayoutDescription());

static_assert(Message<Image>);
static_assert(sizeof(Image) == 128 && alignof(Image) == 8);
static_assert(offsetof(Image, header) == 0 && offsetof(Image, width) == 56 &&
              offsetof(Image, height) == 60 && offsetof(Image, step) == 64 &&
              offsetof(Image, encoding) == 68 && offsetof(Image, reserved) == 72);
static_assert(Image::PackedPayloadBytes(640, 480, Encoding::kRgb8) == 921'600);
static_assert(Image::PackedPayloadBytes(640, 480, Encoding::kDepth16) == 614'400);

namespace internal {
template <class T>
constexpr std::string_view ChannelTypeName() {
  if constexpr (std::is_same_v<T, uint8_t>) return "uint8";
  if constexpr (std::is_same_v<T, uint16_t>) return "uint16";
  if constexpr (std::is_same_v<T, float>) return "float32";
}
constexpr std::string_view ChannelTypeName(Encoding encoding) {
  switch (BytesPerChannel(encoding)) {
    case 1:
      return "uint8";
    case 2:
      return "uint16";
    case 4:
      return "float32";
  }
  return "none";
}
template <class T>
concept Channel =
    std::is_same_v<T, uint8_t> || std::is_same_v<T, uint16_t> || std::is_same_v<T, float>;

template <class T>
void CheckChannelType(const Image& image) {
  const bool match = (std::is_same_v<T, uint8_t> && BytesPerChannel(image.encoding) == 1) ||
                     (std::is_same_v<T, uint16_t> && BytesPerChannel(image.encoding) == 2) ||
                     (std::is_same_v<T, float> && BytesPerChannel(image.encoding) == 4);
  if (!match) {
    throw MessageError("Image " + image.Describe() + ": encoding " +
                       std::string(EncodingName(image.encoding)) + " has " +
                       std::string(ChannelTypeName(image.encoding)) + " channels, not " +
                       std::string(ChannelTypeName<T>()));
  }
}
}  // namespace internal

// All channels of the image as T (uint8_t for rgb8/bgr8/mono8, uint16_t for mono16/depth16, float
// for float32/rgb32f): PayloadBytes() / sizeof(T) elements including any row padding (row y starts
// at element y * step / sizeof(T)). `payload` is the payload of a ReadView/WriteView. Throws
// MessageError if the image is invalid (see Validate), the payload too small, or T does not match
// the encoding.
template <internal::Channel T>
std::span<const T> ImageChannels(const Image& image, std::span<const std::byte> payload) {
  internal::CheckChannelType<T>(image);
  image.Validate(payload.size());
  return {reinterpret_cast<const T*>(payload.data()), image.PayloadBytes() / sizeof(T)};
}
template <internal::Channel T>
std::span<T> ImageChannels(const Image& image, std::span<std::byte> payload) {
  internal::CheckChannelType<T>(image);
  image.Validate(payload.size());
  return {reinterpret_cast<T*>(payload.data()), image.PayloadBytes() / sizeof(T)};
}

// Row y as T: width * ChannelCount(encoding) elements (no row padding). Same checks as
// ImageChannels, plus y < height.
template <internal::Channel T>
std::span<const T> ImageRow(const Image& image, std::span<const std::byte> payload, uint32_t y) {
  const std::span<const T> all = ImageChannels<T>(image, payload);
  if (y >= image.height) {
    throw MessageError("Image " + image.Describe() + ": row " + std::to_string(y) +
                       " out of range");
  }
  return all.subspan(static_cast<size_t>(y) * image.step / sizeof(T),
                     static_cast<size_t>(image.width) * ChannelCount(image.encoding));
}
template <internal::Channel T>
std::span<T> ImageRow(const Image& image, std::span<std::byte> payload, uint32_t y) {
  const std::span<T> all = ImageChannels<T>(image, payload);
  if (y >= image.height) {
    throw MessageError("Image " + image.Describe() + ": row " + std::to_string(y) +
                       " out of range");
  }
  return all.subspan(static_cast<size_t>(y) * image.step / sizeof(T),
                     static_cast<size_t>(image.width) * ChannelCount(image.encoding));
}

}  // namespace probeless::msgs
