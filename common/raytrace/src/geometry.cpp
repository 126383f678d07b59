#include "probeless/raytrace/geometry.h"

#include <algorithm>

namespace probeless::raytrace {

Mat3 Mat3::AxisAngle(const std::array<double, 3>& axis, double angle_rad) {
  const double n = std::sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]);
  if (!(n > 0)) return Identity();
  const double h = angle_rad / 2;
  const double s = std::sin(h) / n;
  return FromQuaternion(std::cos(h), axis[0] * s, axis[1] * s, axis[2] * s);
}

Mat3 Mat3::FromQuaternion(double w, double x, double y, double z) {
  const double n = std::sqrt(w * w + x * x + y * y + z * z);
  if (n > 0) {
    w /= n;
    x /= n;
    y /= n;
    z /= n;
  } else {
    w = 1;
  }
  Mat3 r;
  r.m = {{{1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)},
          {2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)},
          {2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)}}};
  return r;
}

Mat3 Mat3::FromEulerZyx(double yaw, double pitch, double roll) {
  return AxisAngle({0, 0, 1}, yaw) * AxisAngle({0, 1, 0}, pitch) * AxisAngle({1, 0, 0}, roll);
}

std::array<double, 4> Mat3::ToQuaternion() const {
  // Shepperd's method.
  const double t = m[0][0] + m[1][1] + m[2][2];
  double w, x, y, z;
  if (t > 0) {
    const double s = std::sqrt(t + 1) * 2;
    w = s / 4;
    x = (m[2][1] - m[1][2]) / s;
    y = (m[0][2] - m[2][0]) / s;
    z = (m[1][0] - m[0][1]) / s;
  } else if (m[0][0] > m[1][1] && m[0][0] > m[2][2]) {
    const double s = std::sqrt(1 + m[0][0] - m[1][1] - m[2][2]) * 2;
    w = (m[2][1] - m[1][2]) / s;
    x = s / 4;
    y = (m[0][1] + m[1][0]) / s;
    z = (m[0][2] + m[2][0]) / s;
  } else if (m[1][1] > m[2][2]) {
    const double s = std::sqrt(1 + m[1][1] - m[0][0] - m[2][2]) * 2;
    w = (m[0][2] - m[2][0]) / s;
    x = (m[0][1] + m[1][0]) / s;
    y = s / 4;
    z = (m[1][2] + m[2][1]) / s;
  } else {
    const double s = std::sqrt(1 + m[2][2] - m[0][0] - m[1][1]) * 2;
    w = (m[1][0] - m[0][1]) / s;
    x = (m[0][2] + m[2][0]) / s;
    y = (m[1][2] + m[2][1]) / s;
    z = s / 4;
  }
  const double n = std::sqrt(w * w + x * x + y * y + z * z);
  const double sign = w < 0 ? -1 : 1;
  return {sign * w / n, sign * x / n, sign * y / n, sign * z / n};
}

Mat3 Mat3::Transposed() const {
  Mat3 r;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) r.m[i][j] = m[j][i];
  }
  return r;
}

Mat3 Mat3::operator*(const Mat3& b) const {
  Mat3 r;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      r.m[i][j] = m[i][0] * b.m[0][j] + m[i][1] * b.m[1][j] + m[i][2] * b.m[2][j];
    }
  }
  return r;
}

Transform Transform::Inverse() const {
  Transform r;
  r.rotation = rotation.Transposed();
  for (int i = 0; i < 3; ++i) {
    r.translation[i] = -(r.rotation.m[i][0] * translation[0] + r.rotation.m[i][1] * translation[1] +
                         r.rotation.m[i][2] * translation[2]);
  }
  return r;
}

Transform Transform::operator*(const Transform& b) const {
  Transform r;
  r.rotation = rotation * b.rotation;
  for (int i = 0; i < 3; ++i) {
    r.translation[i] = rotation.m[i][0] * b.translation[0] + rotation.m[i][1] * b.translation[1] +
                       rotation.m[i][2] * b.translation[2] + translation[i];
  }
  return r;
}

Transform Transform::LookAt(Vec3 eye, Vec3 target, Vec3 up) {
  Vec3 z = Normalize(target - eye);
  if (Length(z) == 0) z = {0, 0, 1};
  // Right-handed x right, y down, z forward: x = y cross z with y ~ -up.
  Vec3 x = Normalize(Cross(-up, z));
  if (Length(x) == 0) x = Normalize(Cross(Vec3{0, 0, 1}, z));
  if (Length(x) == 0) x = {1, 0, 0};
  const Vec3 y = Cross(z, x);
  Transform t;
  for (int i = 0; i < 3; ++i) {
    t.rotation.m[i][0] = x[i];
    t.rotation.m[i][1] = y[i];
    t.rotation.m[i][2] = z[i];
  }
  t.translation = {eye.x, eye.y, eye.z};
  return t;
}

}  // namespace probeless::raytrace
