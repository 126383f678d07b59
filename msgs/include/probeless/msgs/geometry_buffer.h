// GeometryBuffer: per-pixel depth, normals and colour of a view, as planes in one bus slot.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>

#include "probeless/msgs/header.h"
#include "probeless/msgs/layout.h"

namespace probeless::msgs {

// A G-buffer of width x height pixels seen by the camera header.frame_id (optical frame: x right,
// y down, z forward). Three planes follow the struct in the payload, each tightly packed in row-
// major order (pixel (x, y) is element y * width + x) and starting at the given byte offset from
// the payload start (a multiple of 64 when written by Init):
//   depth:   float32 per pixel, distance along the optical axis (z) in metres; 0 = no surface
//   normals: 3 x float32 per pixel (x, y, z), unit surface normal in the camera frame pointing
//            towards the camera side of the surface; (0, 0, 0) = no surface
//   colour:  3 x uint8 per pixel, R G B, sRGB-encoded (albedo or observed colour, by topic)
struct GeometryBuffer {
  Header header;
  uint32_t width = 0;           // pixels
  uint32_t height = 0;          // pixels
  uint64_t depth_offset = 0;    // byte offset of the depth plane in the payload
  uint64_t normals_offset = 0;  // byte offset of the normals plane in the payload
  uint64_t colour_offset = 0;   // byte offset of the colour plane in the payload
  uint8_t reserved[40] = {};    // zero; pads the struct to 128 bytes

  static constexpr std::string_view kTypeName = "probeless_msgs/GeometryBuffer";
  static constexpr bool kHasPayload = true;
  static const uint64_t kLayoutHash;
  static constexpr std::string LayoutDescription() {
    layout::LayoutBuilder b(kTypeName);
    PROBELESS_MSGS_FIELD(b, GeometryBuffer, header);
    PROBELESS_MSGS_FIELD(b, GeometryBuffer, width);
    PROBELESS_MSGS_FIELD(b, GeometryBuffer, height);
    PROBELESS_MSGS_FIELD(b, GeometryBuffer, depth_offset);
    PROBELESS_MSGS_FIELD(b, GeometryBuffer, normals_offset);
    PROBELESS_MSGS_FIELD(b, GeometryBuffer, colour_offset);
    PROBELESS_MSGS_FIELD(b, GeometryBuffer, reserved);
    return b.Finish<GeometryBuffer>();
  }

  // Bytes of each plane for width x height pixels.
  static constexpr size_t DepthPlaneBytes(uint32_t w, uint32_t h) {
    return static_cast<size_t>(w) * h * sizeof(float);
  }
  static constexpr size_t NormalsPlaneBytes(uint32_t w, uint32_t h) {
    return static_cast<size_t>(w) * h * 3 * sizeof(float);
  }
  static constexpr size_t ColourPlaneBytes(uint32_t w, uint32_t h) {
    return static_cast<size_t>(w) * h * 3;
  }
  // Payload bytes of the standard layout written by Init (planes in order depth, normals, colour,
  // each starting at a multiple of 64).
  static constexpr size_t StandardPayloadBytes(uint32_t w, uint32_t h) {
    return AlignUp(AlignUp(DepthPlaneBytes(w, h)) + NormalsPlaneBytes(w, h)) +
           ColourPlaneBytes(w, h);
  }
  // Whole bus message bytes (struct + standard payload): the max_message_bytes a publisher needs.
  static constexpr size_t MessageBytesFor(uint32_t w, uint32_t h) {
    return sizeof(GeometryBuffer) + StandardPayloadBytes(w, h);
  }

  // Sets width, height and the standard plane offsets.
  constexpr void Init(uint32_t new_width, uint32_t new_height) {
    width = new_width;
    height = new_height;
    depth_offset = 0;
    normals_offset = AlignUp(DepthPlaneBytes(width, height));
    colour_offset = AlignUp(normals_offset + NormalsPlaneBytes(width, height));
  }

  // Payload bytes the planes need: the end of the last plane.
  constexpr size_t PayloadBytes() const {
    size_t end = depth_offset + DepthPlaneBytes(width, height);
    if (normals_offset + NormalsPlaneBytes(width, height) > end) {
      end = normals_offset + NormalsPlaneBytes(width, height);
    }
    if (colour_offset + ColourPlaneBytes(width, height) > end) {
      end = colour_offset + ColourPlaneBytes(width, height);
    }
    return end;
  }

  // Throws MessageError unless width * height <= 2^40, the float planes' offsets are multiples of
  // 4, every plane lies within `payload_bytes` and no two planes overlap.
  void Validate(size_t payload_bytes) const {
    const std::string name =
        std::string(kTypeName) + " " + std::to_string(width) + "x" + std::to_string(height);
    if (static_cast<uint64_t>(width) * height > (uint64_t{1} << 40)) {
      throw MessageError(name + ": too many pixels");
    }
    if (depth_offset % alignof(float) != 0 || normals_offset % alignof(float) != 0) {
      throw MessageError(name + ": depth and normals offsets must be multiples of 4");
    }
    struct Plane {
      const char* name;
      uint64_t begin;
      uint64_t bytes;
    };
    const Plane planes[3] = {{"depth", depth_offset, DepthPlaneBytes(width, height)},
                             {"normals", normals_offset, NormalsPlaneBytes(width, height)},
                             {"colour", colour_offset, ColourPlaneBytes(width, height)}};
    for (const Plane& plane : planes) {
      if (plane.begin > payload_bytes || plane.bytes > payload_bytes - plane.begin) {
        throw MessageError(name + ": " + plane.name + " plane (offset " +
                           std::to_string(plane.begin) + ", " + std::to_string(plane.bytes) +
                           " bytes) exceeds the payload of " + std::to_string(payload_bytes) +
                           " bytes");
      }
    }
    for (int i = 0; i < 3; ++i) {
      for (int j = i + 1; j < 3; ++j) {
        if (planes[i].begin < planes[j].begin + planes[j].bytes &&
            planes[j].begin < planes[i].begin + planes[i].bytes) {
          throw MessageError(name + ": " + planes[i].name + " and " + planes[j].name +
                             " planes overlap");
        }
      }
    }
  }

 private:
  static constexpr size_t AlignUp(size_t bytes) {
    return (bytes + kPayloadAlignment - 1) / kPayloadAlignment * kPayloadAlignment;
  }
};
inline constexpr uint64_t GeometryBuffer::kLayoutHash =
    layout::Fnv1a64(GeometryBuffer::LayoutDescription());

static_assert(Message<GeometryBuffer>);
static_assert(sizeof(GeometryBuffer) == 128 && alignof(GeometryBuffer) == 8);
static_assert(offsetof(GeometryBuffer, width) == 56 && offsetof(GeometryBuffer, height) == 60 &&
              offsetof(GeometryBuffer, depth_offset) == 64 &&
              offsetof(GeometryBuffer, normals_offset) == 72 &&
              offsetof(GeometryBuffer, colour_offset) == 80 &&
              offsetof(GeometryBuffer, reserved) == 88);

// The depth plane (width * height floats, metres). `payload` is the payload of a ReadView or
// WriteView. Throws MessageError if the buffer fails Validate(payload.size()).
inline std::span<const float> DepthPlane(const GeometryBuffer& g,
                                         std::span<const std::byte> payload) {
  g.Validate(payload.size());
  return {reinterpret_cast<const float*>(payload.data() + g.depth_offset),
          static_cast<size_t>(g.width) * g.height};
}
inline std::span<float> DepthPlane(const GeometryBuffer& g, std::span<std::byte> payload) {
  g.Validate(payload.size());
  return {reinterpret_cast<float*>(payload.data() + g.depth_offset),
          static_cast<size_t>(g.width) * g.height};
}

// The normals plane (3 * width * height floats, x y z per pixel). Same checks as DepthPlane.
inline std::span<const float> NormalsPlane(const GeometryBuffer& g,
                                           std::span<const std::byte> payload) {
  g.Validate(payload.size());
  return {reinterpret_cast<const float*>(payload.data() + g.normals_offset),
          static_cast<size_t>(g.width) * g.height * 3};
}
inline std::span<float> NormalsPlane(const GeometryBuffer& g, std::span<std::byte> payload) {
  g.Validate(payload.size());
  return {reinterpret_cast<float*>(payload.data() + g.normals_offset),
          static_cast<size_t>(g.width) * g.height * 3};
}

// The colour plane (3 * width * height bytes, R G B per pixel). Same checks as DepthPlane.
inline std::span<const uint8_t> ColourPlane(const GeometryBuffer& g,
                                            std::span<const std::byte> payload) {
  g.Validate(payload.size());
  return {reinterpret_cast<const uint8_t*>(payload.data() + g.colour_offset),
          static_cast<size_t>(g.width) * g.height * 3};
}
inline std::span<uint8_t> ColourPlane(const GeometryBuffer& g, std::span<std::byte> payload) {
  g.Validate(payload.size());
  return {reinterpret_cast<uint8_t*>(payload.data() + g.colour_offset),
          static_cast<size_t>(g.width) * g.height * 3};
}

}  // namespace probeless::msgs
