// Geometry building blocks of messages: vectors, quaternions and rigid transforms.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "probeless/msgs/layout.h"

namespace probeless::msgs {

// A 3-vector (metres when it is a position or translation).
struct Vector3 {
  double x = 0;
  double y = 0;
  double z = 0;

  static constexpr std::string_view kTypeName = "probeless_msgs/Vector3";
  static constexpr bool kHasPayload = false;
  static const uint64_t kLayoutHash;
  static constexpr std::string LayoutDescription() {
    layout::LayoutBuilder b(kTypeName);
    PROBELESS_MSGS_FIELD(b, Vector3, x);
    PROBELESS_MSGS_FIELD(b, Vector3, y);
    PROBELESS_MSGS_FIELD(b, Vector3, z);
    return b.Finish<Vector3>();
  }
};
inline constexpr uint64_t Vector3::kLayoutHash = layout::Fnv1a64(Vector3::LayoutDescription());

// A rotation as a unit quaternion w + xi + yj + zk (Hamilton convention, scalar first). The
// identity is (1, 0, 0, 0); the value-initialised (0, 0, 0, 0) means "unset".
struct Quaternion {
  double w = 0;
  double x = 0;
  double y = 0;
  double z = 0;

  static constexpr std::string_view kTypeName = "probeless_msgs/Quaternion";
  static constexpr bool kHasPayload = false;
  static const uint64_t kLayoutHash;
  static constexpr std::string LayoutDescription() {
    layout::LayoutBuilder b(kTypeName);
    PROBELESS_MSGS_FIELD(b, Quaternion, w);
    PROBELESS_MSGS_FIELD(b, Quaternion, x);
    PROBELESS_MSGS_FIELD(b, Quaternion, y);
    PROBELESS_MSGS_FIELD(b, Quaternion, z);
    return b.Finish<Quaternion>();
  }
};
inline constexpr uint64_t Quaternion::kLayoutHash =
    layout::Fnv1a64(Quaternion::LayoutDescription());

// A rigid transform from a child frame to a parent frame: p_parent = R(rotation) * p_child +
// translation. translation is the child origin expressed in the parent frame, in metres.
struct RigidTransform {
  Vector3 translation;
  Quaternion rotation;

  static constexpr std::string_view kTypeName = "probeless_msgs/RigidTransform";
  static constexpr bool kHasPayload = false;
  static const uint64_t kLayoutHash;
  static constexpr std::string LayoutDescription() {
    layout::LayoutBuilder b(kTypeName);
    PROBELESS_MSGS_FIELD(b, RigidTransform, translation);
    PROBELESS_MSGS_FIELD(b, RigidTransform, rotation);
    return b.Finish<RigidTransform>();
  }

  // Maps a point given in the child frame to the parent frame (the quaternion is used as given;
  // it should be unit length).
  constexpr Vector3 Apply(const Vector3& p) const {
    const Quaternion& q = rotation;
    // v' = v + 2w (u x v) + 2 u x (u x v), with u = (x, y, z).
    const double cx = q.y * p.z - q.z * p.y;
    const double cy = q.z * p.x - q.x * p.z;
    const double cz = q.x * p.y - q.y * p.x;
    const double ccx = q.y * cz - q.z * cy;
    const double ccy = q.z * cx - q.x * cz;
    const double ccz = q.x * cy - q.y * cx;
    return {p.x + 2 * (q.w * cx + ccx) + translation.x, p.y + 2 * (q.w * cy + ccy) + translation.y,
            p.z + 2 * (q.w * cz + ccz) + translation.z};
  }
};
inline constexpr uint64_t RigidTransform::kLayoutHash =
    layout::Fnv1a64(RigidTransform::LayoutDescription());

static_assert(Message<Vector3> && Message<Quaternion> && Message<RigidTransform>);
static_assert(sizeof(Vector3) == 24 && alignof(Vector3) == 8);
static_assert(sizeof(Quaternion) == 32 && alignof(Quaternion) == 8);
static_assert(sizeof(RigidTransform) == 56 && offsetof(RigidTransform, rotation) == 24);

}  // namespace probeless::msgs
