// Small vector, rotation and rigid-transform types of the ray tracer (single precision for
// shading, double precision for poses). Units: metres; frames are named at each use.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>

namespace probeless::raytrace {

// A 3-vector: a position (metres), a direction (unit unless stated) or a linear RGB triple.
struct Vec3 {
  float x = 0;
  float y = 0;
  float z = 0;

  constexpr float& operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }
  constexpr float operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
};

constexpr Vec3 operator+(Vec3 a, Vec3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
constexpr Vec3 operator-(Vec3 a, Vec3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
constexpr Vec3 operator-(Vec3 a) { return {-a.x, -a.y, -a.z}; }
constexpr Vec3 operator*(Vec3 a, float s) { return {a.x * s, a.y * s, a.z * s}; }
constexpr Vec3 operator*(float s, Vec3 a) { return {a.x * s, a.y * s, a.z * s}; }
constexpr Vec3 operator/(Vec3 a, float s) { return {a.x / s, a.y / s, a.z / s}; }
// Component-wise product (colour modulation).
constexpr Vec3 operator*(Vec3 a, Vec3 b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }
constexpr Vec3& operator+=(Vec3& a, Vec3 b) { return a = a + b; }
constexpr Vec3& operator*=(Vec3& a, float s) { return a = a * s; }
constexpr float Dot(Vec3 a, Vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
constexpr Vec3 Cross(Vec3 a, Vec3 b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline float Length(Vec3 a) { return std::sqrt(Dot(a, a)); }
// a / |a|; (0, 0, 0) for a zero vector.
inline Vec3 Normalize(Vec3 a) {
  const float n = Length(a);
  return n > 0 ? a / n : Vec3{};
}

// A texture coordinate (u right, v up; OBJ convention).
struct Vec2 {
  float u = 0;
  float v = 0;
};

// A 3x3 rotation matrix, row-major: m[row][col]; applied to column vectors.
struct Mat3 {
  std::array<std::array<double, 3>, 3> m{{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}};

  static Mat3 Identity() { return {}; }
  // Rotation of `angle_rad` about the unit `axis` (right-handed).
  static Mat3 AxisAngle(const std::array<double, 3>& axis, double angle_rad);
  // Rotation from the unit quaternion (w, x, y, z) (Hamilton convention, scalar first).
  static Mat3 FromQuaternion(double w, double x, double y, double z);
  // Intrinsic rotations Rz(yaw) * Ry(pitch) * Rx(roll), radians.
  static Mat3 FromEulerZyx(double yaw, double pitch, double roll);
  // Unit quaternion (w, x, y, z) with w >= 0.
  std::array<double, 4> ToQuaternion() const;
  Mat3 Transposed() const;
  Vec3 operator*(Vec3 v) const {
    return {static_cast<float>(m[0][0] * v.x + m[0][1] * v.y + m[0][2] * v.z),
            static_cast<float>(m[1][0] * v.x + m[1][1] * v.y + m[1][2] * v.z),
            static_cast<float>(m[2][0] * v.x + m[2][1] * v.y + m[2][2] * v.z)};
  }
  Mat3 operator*(const Mat3& b) const;
};

// A rigid transform child -> parent: p_parent = rotation * p_child + translation (metres). The
// same convention as msgs::RigidTransform (e.g. a camera pose is camera -> world).
struct Transform {
  Mat3 rotation;
  std::array<double, 3> translation{0, 0, 0};

  // Maps a point from the child to the parent frame.
  Vec3 Apply(Vec3 p) const {
    const Vec3 r = rotation * p;
    return {static_cast<float>(r.x + translation[0]), static_cast<float>(r.y + translation[1]),
            static_cast<float>(r.z + translation[2])};
  }
  // Maps a direction (no translation).
  Vec3 ApplyDirection(Vec3 d) const { return rotation * d; }
  // parent -> child.
  Transform Inverse() const;
  // this * b: first b, then this.
  Transform operator*(const Transform& b) const;
  // A transform placing the child origin at `eye` with its +z axis towards `target` and its -y
  // axis as close as possible to `up` (a camera-style frame: x right, y down, z forward).
  static Transform LookAt(Vec3 eye, Vec3 target, Vec3 up);
};

}  // namespace probeless::raytrace
