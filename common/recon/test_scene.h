// Analytic scenes for the recon tests: depth images of planes and spheres rendered exactly.
#pragma once

#include <cmath>
#include <vector>

#include "probeless/recon/math.h"
#include "probeless/recon/tsdf_volume.h"

namespace probeless::recon::testing {

struct Sphere {
  Vec3f centre;
  float radius;
};
struct Plane {  // n . p = offset, n unit
  Vec3f n;
  float offset;
};

struct Scene {
  std::vector<Plane> planes;
  std::vector<Sphere> spheres;

  // Distance along the unit ray o + t d to the first surface, 0 if none.
  float Hit(Vec3f o, Vec3f d) const {
    float best = 1e9f;
    for (const Plane& p : planes) {
      const float den = Dot(p.n, d);
      if (std::fabs(den) < 1e-6f) continue;
      const float t = (p.offset - Dot(p.n, o)) / den;
      if (t > 1e-4f && t < best) best = t;
    }
    for (const Sphere& s : spheres) {
      const Vec3f oc = o - s.centre;
      const float b = Dot(oc, d);
      const float c = Dot(oc, oc) - s.radius * s.radius;
      const float disc = b * b - c;
      if (disc < 0) continue;
      const float t = -b - std::sqrt(disc);
      if (t > 1e-4f && t < best) best = t;
    }
    return best < 1e8f ? best : 0.0f;
  }

  // Depth (z in the camera) seen from camera_to_world.
  DepthImage Render(const Pose& camera_to_world, const Intrinsics& k) const {
    DepthImage out;
    out.Resize(k.width, k.height);
    const Vec3f o = camera_to_world.Translation();
    for (int y = 0; y < k.height; ++y)
      for (int x = 0; x < k.width; ++x) {
        const Vec3f ray{(x - k.cx) / k.fx, (y - k.cy) / k.fy, 1.0f};
        const float len = Norm(ray);
        const float t = Hit(o, camera_to_world.Rotate((1.0f / len) * ray));
        out.At(x, y) = t / len;
      }
    return out;
  }
};

inline Intrinsics TestIntrinsics(int w = 320, int h = 240) {
  Intrinsics k;
  k.width = w;
  k.height = h;
  k.fx = k.fy = 525.0f * w / 640.0f;
  k.cx = (w - 1) * 0.5f;
  k.cy = (h - 1) * 0.5f;
  return k;
}

// A corner of a room (three walls) with a sphere in it, in front of a camera at the origin.
inline Scene CornerScene() {
  Scene s;
  s.planes.push_back({Normalized({0, 0, -1}), -1.6f});   // back wall z = 1.6
  s.planes.push_back({Normalized({-1, 0, 0}), -0.6f});   // right wall x = 0.6
  s.planes.push_back({Normalized({0, -1, 0}), -0.45f});  // floor y = 0.45
  s.spheres.push_back({{-0.15f, 0.05f, 1.2f}, 0.2f});
  return s;
}

// The 2 m volume the test scenes were laid out for: x, y in [-1, 1], z in [0.2, 2.2].
inline VolumeOptions TestVolumeOptions() {
  VolumeOptions o;
  o.origin = {-1.0f, -1.0f, 0.2f};
  return o;
}

inline Pose PoseFrom(double rx, double ry, double rz, double tx, double ty, double tz) {
  const double xi[6] = {rx, ry, rz, tx, ty, tz};
  return Pose::FromTwist(xi);
}

}  // namespace probeless::recon::testing
