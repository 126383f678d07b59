// Pose: a stamped rigid transform between two named frames.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "probeless/msgs/geometry.h"
#include "probeless/msgs/header.h"
#include "probeless/msgs/layout.h"

namespace probeless::msgs {

// The transform from child_frame_id to parent_frame_id at time header.stamp_*:
//   p_parent = R(transform.rotation) * p_child + transform.translation
// i.e. transform.translation is the child origin in the parent frame (metres) and
// transform.rotation (unit quaternion w, x, y, z) rotates child axes into parent axes. The camera
// pose in a world frame is therefore parent = "world", child = the camera frame.
// header.frame_id is set equal to parent_frame_id.
struct Pose {
  Header header;
  char parent_frame_id[kFrameIdCapacity] = {};  // NUL-terminated, at most 31 characters
  char child_frame_id[kFrameIdCapacity] = {};   // NUL-terminated, at most 31 characters
  RigidTransform transform;                     // child -> parent; metres, unit quaternion

  static constexpr std::string_view kTypeName = "probeless_msgs/Pose";
  static constexpr bool kHasPayload = false;
  static const uint64_t kLayoutHash;
  static constexpr std::string LayoutDescription() {
    layout::LayoutBuilder b(kTypeName);
    PROBELESS_MSGS_FIELD(b, Pose, header);
    PROBELESS_MSGS_FIELD(b, Pose, parent_frame_id);
    PROBELESS_MSGS_FIELD(b, Pose, child_frame_id);
    PROBELESS_MSGS_FIELD(b, Pose, transform);
    return b.Finish<Pose>();
  }

  std::string_view ParentFrameId() const { return FixedString(parent_frame_id); }
  std::string_view ChildFrameId() const { return FixedString(child_frame_id); }
  // Sets parent_frame_id and header.frame_id; throws MessageError beyond 31 characters.
  void SetParentFrameId(std::string_view id) {
    SetFixedString(parent_frame_id, id, "parent_frame_id");
    header.SetFrameId(id);
  }
  // Throws MessageError beyond 31 characters.
  void SetChildFrameId(std::string_view id) {
    SetFixedString(child_frame_id, id, "child_frame_id");
  }
};
inline constexpr uint64_t Pose::kLayoutHash = layout::Fnv1a64(Pose::LayoutDescription());

static_assert(Message<Pose>);
static_assert(sizeof(Pose) == 176 && alignof(Pose) == 8);
static_assert(offsetof(Pose, parent_frame_id) == 56 && offsetof(Pose, child_frame_id) == 88 &&
              offsetof(Pose, transform) == 120);

}  // namespace probeless::msgs
