// TransferBuffer: per-pixel spherical-harmonic transfer vectors (precomputed radiance transfer).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>

#include "probeless/msgs/header.h"
#include "probeless/msgs/layout.h"
#include "probeless/msgs/sh_light.h"

namespace probeless::msgs {

// Payload layouts of a TransferBuffer. Values are part of the wire format.
enum class TransferLayout : uint32_t {
  kInvalid = 0,
  // float32, pixel-major: the coefficient_count values of pixel (x, y) are contiguous at element
  // (y * width + x) * coefficient_count + k; no row padding.
  kInterleavedFloat32 = 1,
};
constexpr std::string_view DescribeEnum(TransferLayout) {
  return "TransferLayout{invalid=0,interleaved_float32=1}";
}

// For each pixel of the view of camera header.frame_id, the transfer vector T (coefficient_count
// values, same SH basis, order and frame convention as ShLight): the radiance leaving the surface
// seen at that pixel towards the camera, for albedo 1, is sum_k T[k] * L[k] for each colour
// channel, where L are ShLight coefficients expressed in the same frame (header.frame_id). T
// includes the cosine term, visibility (self-shadowing) and the Lambertian 1/pi; dimensionless.
// Pixels with no surface have T = 0.
struct TransferBuffer {
  Header header;
  uint32_t width = 0;              // pixels
  uint32_t height = 0;             // pixels
  uint32_t coefficient_count = 0;  // bands^2: 1, 4, 9, 16 or 25
  TransferLayout layout = TransferLayout::kInvalid;
  uint8_t reserved[56] = {};  // zero; pads the struct to 128 bytes

  static constexpr std::string_view kTypeName = "probeless_msgs/TransferBuffer";
  static constexpr bool kHasPayload = true;
  static const uint64_t kLayoutHash;
  static constexpr std::string LayoutDescription() {
    layout::LayoutBuilder b(kTypeName);
    PROBELESS_MSGS_FIELD(b, TransferBuffer, header);
    PROBELESS_MSGS_FIELD(b, TransferBuffer, width);
    PROBELESS_MSGS_FIELD(b, TransferBuffer, height);
    PROBELESS_MSGS_FIELD(b, TransferBuffer, coefficient_count);
    PROBELESS_MSGS_FIELD(b, TransferBuffer, layout);
    PROBELESS_MSGS_FIELD(b, TransferBuffer, reserved);
    return b.Finish<TransferBuffer>();
  }

  // Payload bytes for width x height pixels of `count` float32 coefficients.
  static constexpr size_t PayloadBytesFor(uint32_t w, uint32_t h, uint32_t count) {
    return static_cast<size_t>(w) * h * count * sizeof(float);
  }
  // Whole bus message bytes: the max_message_bytes a publisher needs.
  static constexpr size_t MessageBytesFor(uint32_t w, uint32_t h, uint32_t count) {
    return sizeof(TransferBuffer) + PayloadBytesFor(w, h, count);
  }
  constexpr size_t PayloadBytes() const {
    return PayloadBytesFor(width, height, coefficient_count);
  }

  // Sets width, height, coefficient_count and the interleaved float32 layout. Throws
  // MessageError unless `count` is 1, 4, 9, 16 or 25.
  void Init(uint32_t new_width, uint32_t new_height, uint32_t count) {
    CheckCount(count);
    width = new_width;
    height = new_height;
    coefficient_count = count;
    layout = TransferLayout::kInterleavedFloat32;
  }

  // Throws MessageError unless the layout is kInterleavedFloat32, coefficient_count is a square
  // in 1..25, width * height <= 2^40 and `payload_bytes` >= PayloadBytes().
  void Validate(size_t payload_bytes) const {
    const std::string name =
        std::string(kTypeName) + " " + std::to_string(width) + "x" + std::to_string(height);
    if (layout != TransferLayout::kInterleavedFloat32) {
      throw MessageError(name + ": unknown layout " +
                         std::to_string(static_cast<uint32_t>(layout)));
    }
    CheckCount(coefficient_count);
    if (static_cast<uint64_t>(width) * height > (uint64_t{1} << 40)) {
      throw MessageError(name + ": too many pixels");
    }
    if (payload_bytes < PayloadBytes()) {
      throw MessageError(name + " x " + std::to_string(coefficient_count) + " needs " +
                         std::to_string(PayloadBytes()) + " payload bytes, got " +
                         std::to_string(payload_bytes));
    }
  }

 private:
  static void CheckCount(uint32_t count) {
    for (uint32_t bands = 1; bands <= kMaxShBands; ++bands) {
      if (count == ShCoefficientCount(bands)) return;
    }
    throw MessageError(std::string(kTypeName) + ": coefficient_count " + std::to_string(count) +
                       " is not 1, 4, 9, 16 or 25");
  }
};
inline constexpr uint64_t TransferBuffer::kLayoutHash =
    layout::Fnv1a64(TransferBuffer::LayoutDescription());

static_assert(Message<TransferBuffer>);
static_assert(sizeof(TransferBuffer) == 128 && alignof(TransferBuffer) == 8);
static_assert(offsetof(TransferBuffer, width) == 56 && offsetof(TransferBuffer, height) == 60 &&
              offsetof(TransferBuffer, coefficient_count) == 64 &&
              offsetof(TransferBuffer, layout) == 68 && offsetof(TransferBuffer, reserved) == 72);

// All coefficients (width * height * coefficient_count floats). `payload` is the payload of a
// ReadView or WriteView. Throws MessageError if the buffer fails Validate(payload.size()).
inline std::span<const float> TransferCoefficients(const TransferBuffer& t,
                                                   std::span<const std::byte> payload) {
  t.Validate(payload.size());
  return {reinterpret_cast<const float*>(payload.data()), t.PayloadBytes() / sizeof(float)};
}
inline std::span<float> TransferCoefficients(const TransferBuffer& t,
                                             std::span<std::byte> payload) {
  t.Validate(payload.size());
  return {reinterpret_cast<float*>(payload.data()), t.PayloadBytes() / sizeof(float)};
}

// The coefficient_count values of pixel (x, y). Same checks, plus x < width and y < height.
inline std::span<const float> PixelTransfer(const TransferBuffer& t,
                                            std::span<const std::byte> payload, uint32_t x,
                                            uint32_t y) {
  const std::span<const float> all = TransferCoefficients(t, payload);
  if (x >= t.width || y >= t.height) {
    throw MessageError(std::string(TransferBuffer::kTypeName) + ": pixel (" + std::to_string(x) +
                       ", " + std::to_string(y) + ") outside " + std::to_string(t.width) + "x" +
                       std::to_string(t.height));
  }
  return all.subspan((static_cast<size_t>(y) * t.width + x) * t.coefficient_count,
                     t.coefficient_count);
}

}  // namespace probeless::msgs
