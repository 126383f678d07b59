#include "probeless/recon/math.h"

#include <algorithm>

namespace probeless::recon {

Pose Pose::Inverse() const {
  Pose inv;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) inv.r[i * 3 + j] = r[j * 3 + i];
  for (int i = 0; i < 3; ++i) {
    inv.t[i] = -(inv.r[i * 3 + 0] * t[0] + inv.r[i * 3 + 1] * t[1] + inv.r[i * 3 + 2] * t[2]);
  }
  return inv;
}

Pose operator*(const Pose& a, const Pose& b) {
  Pose c;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      c.r[i * 3 + j] = a.r[i * 3 + 0] * b.r[0 * 3 + j] + a.r[i * 3 + 1] * b.r[1 * 3 + j] +
                       a.r[i * 3 + 2] * b.r[2 * 3 + j];
    }
    c.t[i] = a.r[i * 3 + 0] * b.t[0] + a.r[i * 3 + 1] * b.t[1] + a.r[i * 3 + 2] * b.t[2] + a.t[i];
  }
  return c;
}

double Pose::RotationAngle() const {
  const double c = std::clamp((r[0] + r[4] + r[8] - 1) / 2, -1.0, 1.0);
  return std::acos(c);
}

void Pose::Orthonormalize() {
  // Gram-Schmidt on the rows.
  double* a = r;
  double* b = r + 3;
  double* c = r + 6;
  double n = std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
  for (int i = 0; i < 3; ++i) a[i] /= n;
  const double d = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  for (int i = 0; i < 3; ++i) b[i] -= d * a[i];
  n = std::sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2]);
  for (int i = 0; i < 3; ++i) b[i] /= n;
  c[0] = a[1] * b[2] - a[2] * b[1];
  c[1] = a[2] * b[0] - a[0] * b[2];
  c[2] = a[0] * b[1] - a[1] * b[0];
}

Pose Pose::FromTwist(const double xi[6]) {
  Pose p;
  const double theta = std::sqrt(xi[0] * xi[0] + xi[1] * xi[1] + xi[2] * xi[2]);
  if (theta > 1e-12) {
    const double kx = xi[0] / theta, ky = xi[1] / theta, kz = xi[2] / theta;
    const double c = std::cos(theta), s = std::sin(theta), v = 1 - c;
    p.r[0] = c + kx * kx * v;
    p.r[1] = kx * ky * v - kz * s;
    p.r[2] = kx * kz * v + ky * s;
    p.r[3] = ky * kx * v + kz * s;
    p.r[4] = c + ky * ky * v;
    p.r[5] = ky * kz * v - kx * s;
    p.r[6] = kz * kx * v - ky * s;
    p.r[7] = kz * ky * v + kx * s;
    p.r[8] = c + kz * kz * v;
  }
  p.t[0] = xi[3];
  p.t[1] = xi[4];
  p.t[2] = xi[5];
  return p;
}

Pose Pose::FromMsg(const msgs::RigidTransform& transform) {
  const msgs::Quaternion& q = transform.rotation;
  const double n = std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
  if (!std::isfinite(n) || n < 1e-9) {
    throw ReconError("pose: rotation quaternion must be finite and non-zero");
  }
  const msgs::Vector3& tr = transform.translation;
  if (!std::isfinite(tr.x) || !std::isfinite(tr.y) || !std::isfinite(tr.z)) {
    throw ReconError("pose: translation must be finite");
  }
  const double w = q.w / n, x = q.x / n, y = q.y / n, z = q.z / n;
  Pose p;
  p.r[0] = 1 - 2 * (y * y + z * z);
  p.r[1] = 2 * (x * y - w * z);
  p.r[2] = 2 * (x * z + w * y);
  p.r[3] = 2 * (x * y + w * z);
  p.r[4] = 1 - 2 * (x * x + z * z);
  p.r[5] = 2 * (y * z - w * x);
  p.r[6] = 2 * (x * z - w * y);
  p.r[7] = 2 * (y * z + w * x);
  p.r[8] = 1 - 2 * (x * x + y * y);
  p.t[0] = tr.x;
  p.t[1] = tr.y;
  p.t[2] = tr.z;
  return p;
}

msgs::RigidTransform Pose::ToMsg() const {
  msgs::RigidTransform out;
  out.translation = {t[0], t[1], t[2]};
  const double trace = r[0] + r[4] + r[8];
  double w, x, y, z;
  if (trace > 0) {
    const double s = std::sqrt(trace + 1.0) * 2;
    w = 0.25 * s;
    x = (r[7] - r[5]) / s;
    y = (r[2] - r[6]) / s;
    z = (r[3] - r[1]) / s;
  } else if (r[0] > r[4] && r[0] > r[8]) {
    const double s = std::sqrt(1.0 + r[0] - r[4] - r[8]) * 2;
    w = (r[7] - r[5]) / s;
    x = 0.25 * s;
    y = (r[1] + r[3]) / s;
    z = (r[2] + r[6]) / s;
  } else if (r[4] > r[8]) {
    const double s = std::sqrt(1.0 + r[4] - r[0] - r[8]) * 2;
    w = (r[2] - r[6]) / s;
    x = (r[1] + r[3]) / s;
    y = 0.25 * s;
    z = (r[5] + r[7]) / s;
  } else {
    const double s = std::sqrt(1.0 + r[8] - r[0] - r[4]) * 2;
    w = (r[3] - r[1]) / s;
    x = (r[2] + r[6]) / s;
    y = (r[5] + r[7]) / s;
    z = 0.25 * s;
  }
  const double n = std::sqrt(w * w + x * x + y * y + z * z) * (w < 0 ? -1 : 1);
  out.rotation = {w / n, x / n, y / n, z / n};
  return out;
}

Pose Pose::FromMatrix(const double m[16]) {
  Pose p;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) p.r[i * 3 + j] = m[i * 4 + j];
    p.t[i] = m[i * 4 + 3];
  }
  return p;
}

Intrinsics Intrinsics::Level(int level) const {
  Intrinsics out = *this;
  const float s = 1.0f / static_cast<float>(1 << level);
  out.width = width >> level;
  out.height = height >> level;
  out.fx = fx * s;
  out.fy = fy * s;
  out.cx = (cx + 0.5f) * s - 0.5f;
  out.cy = (cy + 0.5f) * s - 0.5f;
  return out;
}

void Intrinsics::Validate(const std::string& what) const {
  if (width <= 0 || height <= 0) {
    throw ReconError(what + ": image size must be positive, got " + std::to_string(width) + "x" +
                     std::to_string(height));
  }
  if (!std::isfinite(fx) || !std::isfinite(fy) || !std::isfinite(cx) || !std::isfinite(cy)) {
    throw ReconError(what + ": intrinsics must be finite (fx, fy, cx, cy)");
  }
  if (!(fx > 0) || !(fy > 0)) throw ReconError(what + ": fx and fy must be > 0");
}

}  // namespace probeless::recon
