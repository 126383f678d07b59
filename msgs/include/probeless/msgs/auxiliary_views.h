// AuxiliaryViews: the auxiliary orthographic depth views of one G_r (Gruber et al. 2015 §5.1: left,
// right and top of the frustum, and one from the light direction), as depth planes in one bus slot.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>

#include "probeless/msgs/header.h"
#include "probeless/msgs/layout.h"

namespace probeless::msgs {

// What an auxiliary view shows. Values are part of the wire format.
enum class AuxiliaryViewRole : uint32_t {
  kInvalid = 0,
  kLeft = 1,   // rays along the camera's +x (the scene seen from the camera's left)
  kRight = 2,  // rays along the camera's -x
  kTop = 3,    // rays along the camera's +y (downwards in the image)
  kLight = 4,  // rays along minus the direction towards the (dominant) light
};
constexpr std::string_view DescribeEnum(AuxiliaryViewRole) {
  return "AuxiliaryViewRole{invalid=0,left=1,right=2,top=3,light=4}";
}
// The role's lower-case name ("left", "right", "top", "light"; "invalid" otherwise), for messages.
constexpr std::string_view AuxiliaryViewRoleName(AuxiliaryViewRole role) {
  switch (role) {
    case AuxiliaryViewRole::kLeft:
      return "left";
    case AuxiliaryViewRole::kRight:
      return "right";
    case AuxiliaryViewRole::kTop:
      return "top";
    case AuxiliaryViewRole::kLight:
      return "light";
    default:
      return "invalid";
  }
}

// One orthographic view. View frame: x right, y down, z = the direction of the (parallel) rays,
// origin on the image plane; pixel (u, v) sees the ray through view point
// ((u - (width - 1) / 2) * pixel_size_m, (v - (height - 1) / 2) * pixel_size_m, 0) along +z.
// Its depth plane (width * height float32 at depth_offset in the payload, row-major) holds the
// view-frame z in metres of the first surface on that ray, 0 = none. rotation (row-major) and
// translation map the view frame into the optical frame of the camera of the message's G_r:
// p_camera = rotation * p_view + translation (metres). Normals are not carried (the transfer
// does not use them).
struct AuxiliaryView {
  AuxiliaryViewRole role = AuxiliaryViewRole::kInvalid;
  uint32_t width = 0;         // pixels
  uint32_t height = 0;        // pixels
  float pixel_size_m = 0;     // metres per pixel
  float rotation[9] = {};     // view -> camera, row-major, orthonormal
  float translation[3] = {};  // view origin in the camera frame, metres
  uint64_t depth_offset = 0;  // byte offset of the depth plane in the payload (multiple of 4)
  uint8_t reserved[8] = {};   // zero

  static constexpr std::string_view kTypeName = "probeless_msgs/AuxiliaryView";
  static constexpr bool kHasPayload = false;
  static const uint64_t kLayoutHash;
  static constexpr std::string LayoutDescription() {
    layout::LayoutBuilder b(kTypeName);
    PROBELESS_MSGS_FIELD(b, AuxiliaryView, role);
    PROBELESS_MSGS_FIELD(b, AuxiliaryView, width);
    PROBELESS_MSGS_FIELD(b, AuxiliaryView, height);
    PROBELESS_MSGS_FIELD(b, AuxiliaryView, pixel_size_m);
    PROBELESS_MSGS_FIELD(b, AuxiliaryView, rotation);
    PROBELESS_MSGS_FIELD(b, AuxiliaryView, translation);
    PROBELESS_MSGS_FIELD(b, AuxiliaryView, depth_offset);
    PROBELESS_MSGS_FIELD(b, AuxiliaryView, reserved);
    return b.Finish<AuxiliaryView>();
  }
  // Bytes of the view's depth plane in the payload: width x height float32 (metres).
  constexpr size_t DepthPlaneBytes() const {
    return static_cast<size_t>(width) * height * sizeof(float);
  }
};
inline constexpr uint64_t AuxiliaryView::kLayoutHash =
    layout::Fnv1a64(AuxiliaryView::LayoutDescription());
static_assert(sizeof(AuxiliaryView) == 80 && alignof(AuxiliaryView) == 8);
static_assert(offsetof(AuxiliaryView, pixel_size_m) == 12 &&
              offsetof(AuxiliaryView, rotation) == 16 &&
              offsetof(AuxiliaryView, translation) == 52 &&
              offsetof(AuxiliaryView, depth_offset) == 64 &&
              offsetof(AuxiliaryView, reserved) == 72);

inline constexpr uint32_t kMaxAuxiliaryViews = 4;
inline constexpr uint32_t kMaxAuxiliaryViewPixels = 4096;  // per side

// Up to 4 auxiliary views of the G_r with the same header (stamp, sequence, frame_id = the camera
// optical frame the views' rotation / translation map into). views[i] for i < view_count are
// used; the rest are zero. The depth planes follow the struct in the payload.
struct AuxiliaryViews {
  Header header;
  uint32_t view_count = 0;  // 0..4
  uint32_t reserved0 = 0;   // zero
  AuxiliaryView views[kMaxAuxiliaryViews];

  static constexpr std::string_view kTypeName = "probeless_msgs/AuxiliaryViews";
  static constexpr bool kHasPayload = true;
  static const uint64_t kLayoutHash;
  static constexpr std::string LayoutDescription() {
    layout::LayoutBuilder b(kTypeName);
    PROBELESS_MSGS_FIELD(b, AuxiliaryViews, header);
    PROBELESS_MSGS_FIELD(b, AuxiliaryViews, view_count);
    PROBELESS_MSGS_FIELD(b, AuxiliaryViews, reserved0);
    PROBELESS_MSGS_FIELD(b, AuxiliaryViews, views);
    return b.Finish<AuxiliaryViews>();
  }

  // Payload bytes of `count` views of w x h pixels in the standard layout (each depth plane at
  // the next multiple of 64).
  static constexpr size_t StandardPayloadBytes(uint32_t count, uint32_t w, uint32_t h) {
    if (count == 0) return 0;
    return (count - 1) * AlignUp(static_cast<size_t>(w) * h * sizeof(float)) +
           static_cast<size_t>(w) * h * sizeof(float);
  }
  // Whole bus message bytes: the max_message_bytes a publisher needs.
  static constexpr size_t MessageBytesFor(uint32_t count, uint32_t w, uint32_t h) {
    return sizeof(AuxiliaryViews) + StandardPayloadBytes(count, w, h);
  }

  // Assigns the depth offsets of views[0 .. view_count) (width and height set) consecutively,
  // each at a multiple of 64. Throws MessageError if view_count > 4.
  void SetStandardLayout() {
    CheckCount();
    uint64_t offset = 0;
    for (uint32_t i = 0; i < view_count; ++i) {
      views[i].depth_offset = offset;
      offset = AlignUp(offset + views[i].DepthPlaneBytes());
    }
  }

  // Payload bytes the planes need: the end of the last plane.
  constexpr size_t PayloadBytes() const {
    size_t end = 0;
    for (uint32_t i = 0; i < view_count && i < kMaxAuxiliaryViews; ++i) {
      const size_t e = views[i].depth_offset + views[i].DepthPlaneBytes();
      if (e > end) end = e;
    }
    return end;
  }

  // Throws MessageError (one line naming the view) unless view_count <= 4 and every used view
  // has a known role, 1..4096 pixels per side, a finite pixel_size_m > 0, a finite orthonormal
  // rotation (|R^T R - I| <= 1e-3) and translation, a depth offset that is a multiple of 4 with
  // the plane inside `payload_bytes`, and no two planes overlap.
  void Validate(size_t payload_bytes) const {
    CheckCount();
    for (uint32_t i = 0; i < view_count; ++i) {
      const AuxiliaryView& v = views[i];
      const std::string name = std::string(kTypeName) + " view " + std::to_string(i) + " (" +
                               std::string(AuxiliaryViewRoleName(v.role)) + " " +
                               std::to_string(v.width) + "x" + std::to_string(v.height) + ")";
      if (v.role == AuxiliaryViewRole::kInvalid ||
          static_cast<uint32_t>(v.role) > static_cast<uint32_t>(AuxiliaryViewRole::kLight)) {
        throw MessageError(name + ": unknown role " +
                           std::to_string(static_cast<uint32_t>(v.role)));
      }
      if (v.width < 1 || v.height < 1 || v.width > kMaxAuxiliaryViewPixels ||
          v.height > kMaxAuxiliaryViewPixels) {
        throw MessageError(name + ": width and height must be in 1..4096");
      }
      if (!(v.pixel_size_m > 0) || !std::isfinite(v.pixel_size_m)) {
        throw MessageError(name + ": pixel_size_m must be finite and > 0");
      }
      for (float t : v.translation) {
        if (!std::isfinite(t)) throw MessageError(name + ": non-finite translation");
      }
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) {
          double dot = 0;  // column r . column c
          for (int k = 0; k < 3; ++k) dot += double{v.rotation[3 * k + r]} * v.rotation[3 * k + c];
          if (!(std::fabs(dot - (r == c ? 1.0 : 0.0)) <= 1e-3)) {
            throw MessageError(name + ": rotation is not orthonormal");
          }
        }
      }
      if (v.depth_offset % alignof(float) != 0) {
        throw MessageError(name + ": depth offset must be a multiple of 4");
      }
      if (v.depth_offset > payload_bytes || v.DepthPlaneBytes() > payload_bytes - v.depth_offset) {
        throw MessageError(name + ": depth plane (offset " + std::to_string(v.depth_offset) + ", " +
                           std::to_string(v.DepthPlaneBytes()) + " bytes) exceeds the payload of " +
                           std::to_string(payload_bytes) + " bytes");
      }
      for (uint32_t j = 0; j < i; ++j) {
        const AuxiliaryView& o = views[j];
        if (v.depth_offset < o.depth_offset + o.DepthPlaneBytes() &&
            o.depth_offset < v.depth_offset + v.DepthPlaneBytes()) {
          throw MessageError(name + ": depth plane overlaps view " + std::to_string(j) + "'s");
        }
      }
    }
  }

 private:
  void CheckCount() const {
    if (view_count > kMaxAuxiliaryViews) {
      throw MessageError(std::string(kTypeName) + ": view_count " + std::to_string(view_count) +
                         " exceeds 4");
    }
  }
  static constexpr size_t AlignUp(size_t bytes) {
    return (bytes + kPayloadAlignment - 1) / kPayloadAlignment * kPayloadAlignment;
  }
};
inline constexpr uint64_t AuxiliaryViews::kLayoutHash =
    layout::Fnv1a64(AuxiliaryViews::LayoutDescription());

static_assert(Message<AuxiliaryViews>);
static_assert(sizeof(AuxiliaryViews) == 384 && alignof(AuxiliaryViews) == 8);
static_assert(offsetof(AuxiliaryViews, view_count) == 56 &&
              offsetof(AuxiliaryViews, reserved0) == 60 && offsetof(AuxiliaryViews, views) == 64);

// The depth plane of view `index` (width * height floats, metres). `payload` is the payload of a
// ReadView or WriteView. Throws MessageError if the message fails Validate(payload.size()) or
// index >= view_count.
inline std::span<const float> AuxiliaryDepth(const AuxiliaryViews& a,
                                             std::span<const std::byte> payload, uint32_t index) {
  a.Validate(payload.size());
  if (index >= a.view_count) {
    throw MessageError(std::string(AuxiliaryViews::kTypeName) + ": view " + std::to_string(index) +
                       " of " + std::to_string(a.view_count));
  }
  const AuxiliaryView& v = a.views[index];
  return {reinterpret_cast<const float*>(payload.data() + v.depth_offset),
          static_cast<size_t>(v.width) * v.height};
}
inline std::span<float> AuxiliaryDepth(const AuxiliaryViews& a, std::span<std::byte> payload,
                                       uint32_t index) {
  const std::span<const float> c = AuxiliaryDepth(a, std::span<const std::byte>(payload), index);
  return {const_cast<float*>(c.data()), c.size()};
}

}  // namespace probeless::msgs
