// Small geometry types of the reconstruction: 3-vectors, rigid poses, pinhole intrinsics and
// row-major images. Frames: camera x right, y down, z forward (OpenCV); a pose maps camera
// coordinates to world coordinates (p_world = R p_camera + t), metres.
#pragma once

#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "probeless/error/error.h"
#include "probeless/msgs/geometry.h"

namespace probeless::recon {

// Bad input at the library boundary (wrong depth encoding, empty frame, invalid intrinsics or
// options): one line naming the input and what was expected.
class ReconError : public InputError {
 public:
  using InputError::InputError;
};

// A float 3-vector (metres for points).
struct Vec3f {
  float x = 0;
  float y = 0;
  float z = 0;
};
inline Vec3f operator+(Vec3f a, Vec3f b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline Vec3f operator-(Vec3f a, Vec3f b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline Vec3f operator*(float s, Vec3f a) { return {s * a.x, s * a.y, s * a.z}; }
inline float Dot(Vec3f a, Vec3f b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline Vec3f Cross(Vec3f a, Vec3f b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline float Norm(Vec3f a) { return std::sqrt(Dot(a, a)); }
// a / |a|; (0, 0, 0) for a zero vector.
inline Vec3f Normalized(Vec3f a) {
  const float n = Norm(a);
  return n > 0 ? (1.0f / n) * a : Vec3f{};
}

// A rigid transform p' = R p + t in double precision (R row-major). As a camera pose it maps the
// camera frame to the world frame.
struct Pose {
  double r[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  double t[3] = {0, 0, 0};

  // R p + t.
  Vec3f Apply(Vec3f p) const {
    return {static_cast<float>(r[0] * p.x + r[1] * p.y + r[2] * p.z + t[0]),
            static_cast<float>(r[3] * p.x + r[4] * p.y + r[5] * p.z + t[1]),
            static_cast<float>(r[6] * p.x + r[7] * p.y + r[8] * p.z + t[2])};
  }
  // R p.
  Vec3f Rotate(Vec3f p) const {
    return {static_cast<float>(r[0] * p.x + r[1] * p.y + r[2] * p.z),
            static_cast<float>(r[3] * p.x + r[4] * p.y + r[5] * p.z),
            static_cast<float>(r[6] * p.x + r[7] * p.y + r[8] * p.z)};
  }
  Vec3f Translation() const {
    return {static_cast<float>(t[0]), static_cast<float>(t[1]), static_cast<float>(t[2])};
  }
  // The inverse transform (R^T, -R^T t).
  Pose Inverse() const;
  // Rotation angle of R in radians, in [0, pi].
  double RotationAngle() const;
  // Re-orthonormalises R (after many compositions).
  void Orthonormalize();

  // exp of the twist xi = (wx, wy, wz, tx, ty, tz): rotation by the rotation vector w (Rodrigues,
  // radians) and translation (tx, ty, tz) (metres; not the SE(3) left Jacobian, a first-order
  // update as in KinectFusion's ICP).
  static Pose FromTwist(const double xi[6]);
  // From a message transform (child -> parent). Throws ReconError for a non-finite or zero
  // quaternion or a non-finite translation.
  static Pose FromMsg(const msgs::RigidTransform& transform);
  // As a message transform (unit quaternion w >= 0).
  msgs::RigidTransform ToMsg() const;
  // From a row-major 4x4 matrix (the last row is ignored).
  static Pose FromMatrix(const double m[16]);
};
// a * b: apply b first, then a.
Pose operator*(const Pose& a, const Pose& b);

// Pinhole intrinsics of a width x height image: u = fx x / z + cx, v = fy y / z + cy, pixel (0, 0)
// the centre of the top-left pixel.
struct Intrinsics {
  int width = 0;
  int height = 0;
  float fx = 0;
  float fy = 0;
  float cx = 0;
  float cy = 0;

  // The intrinsics of the image downsampled `level` times by 2 (pixel centres preserved).
  Intrinsics Level(int level) const;
  // Throws ReconError "<what>: ..." unless width, height > 0 and fx, fy, cx, cy are finite with
  // fx, fy > 0.
  void Validate(const std::string& what) const;
};

// A row-major image of T; pixel (x, y) is data[y * width + x].
template <class T>
struct Image {
  int width = 0;
  int height = 0;
  std::vector<T> data;

  void Resize(int w, int h) {
    width = w;
    height = h;
    data.resize(static_cast<size_t>(w) * h);
  }
  T& At(int x, int y) { return data[static_cast<size_t>(y) * width + x]; }
  const T& At(int x, int y) const { return data[static_cast<size_t>(y) * width + x]; }
  bool Empty() const { return width == 0 || height == 0; }
};
// Depth in metres along the optical axis; 0 = invalid.
using DepthImage = Image<float>;
// Points or normals; a point with z = 0 (normal (0, 0, 0)) = invalid.
using Vec3Image = Image<Vec3f>;
// Grey values 0..255 (colour guidance of the merge).
using GreyImage = Image<uint8_t>;

}  // namespace probeless::recon
