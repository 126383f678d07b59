#include "probeless/prt/demo_objects.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "probeless/prt/prt.h"

namespace probeless::prt {

namespace {

using raytrace::Mat3;
using raytrace::Mesh;
using raytrace::Transform;
using raytrace::Vec3;

constexpr float kPi = std::numbers::pi_v<float>;

void Paint(Mesh& mesh, Vec3 colour) { mesh.colors.assign(mesh.positions.size(), colour); }

const raytrace::HeadModel& Head() {
  static const raytrace::HeadModel head = raytrace::MakeHead({0.62f, 0.42f, 0.33f}, 64);
  return head;
}

Vec3 Mean(const std::vector<Vec3>& points, int first, int last) {
  Vec3 sum;
  for (int i = first; i <= last; ++i) sum += points[i];
  return sum / static_cast<float>(last - first + 1);
}

// Centre (x, z) and half extents of the head's horizontal slice at height y (face frame).
struct Slice {
  float cx = 0, cz = 0, rx = 0, rz = 0;
};
Slice HeadSlice(float y) {
  float xmin = 1e9f, xmax = -1e9f, zmin = 1e9f, zmax = -1e9f;
  for (const Vec3& p : Head().mesh.positions) {
    if (std::abs(p.y - y) > 0.006f) continue;
    xmin = std::min(xmin, p.x), xmax = std::max(xmax, p.x);
    zmin = std::min(zmin, p.z), zmax = std::max(zmax, p.z);
  }
  if (xmin > xmax) return {0, 0.08f, 0.075f, 0.1f};
  return {(xmin + xmax) / 2, (zmin + zmax) / 2, (xmax - xmin) / 2, (zmax - zmin) / 2};
}

}  // namespace

Mesh ProxyHead(int resolution) {
  if (resolution < 8) throw PrtError("ProxyHead: resolution must be >= 8");
  return raytrace::MakeHead({0.5f, 0.5f, 0.5f}, resolution).mesh;
}

Mesh MakeTorus(float major, float minor, int segments_major, int segments_minor) {
  if (!(major > 0) || !(minor > 0) || segments_major < 3 || segments_minor < 3) {
    throw PrtError("MakeTorus: radii must be > 0 and segments >= 3");
  }
  Mesh m;
  for (int i = 0; i < segments_major; ++i) {
    const float u = 2 * kPi * static_cast<float>(i) / static_cast<float>(segments_major);
    const Vec3 centre{major * std::cos(u), major * std::sin(u), 0};
    const Vec3 radial{std::cos(u), std::sin(u), 0};
    for (int j = 0; j < segments_minor; ++j) {
      const float v = 2 * kPi * static_cast<float>(j) / static_cast<float>(segments_minor);
      const Vec3 n = radial * std::cos(v) + Vec3{0, 0, 1} * std::sin(v);
      m.positions.push_back(centre + n * minor);
      m.normals.push_back(n);
    }
  }
  for (int i = 0; i < segments_major; ++i) {
    for (int j = 0; j < segments_minor; ++j) {
      const uint32_t a = i * segments_minor + j;
      const uint32_t b = ((i + 1) % segments_major) * segments_minor + j;
      const uint32_t c = ((i + 1) % segments_major) * segments_minor + (j + 1) % segments_minor;
      const uint32_t d = i * segments_minor + (j + 1) % segments_minor;
      m.triangles.push_back({a, b, c});
      m.triangles.push_back({a, c, d});
    }
  }
  return m;
}

Mesh MakeClownNose(int segments) {
  Mesh nose = raytrace::MakeSphere(0.022f, segments);
  const Vec3 tip = Head().landmarks[30];
  nose.TransformBy(Transform{Mat3::Identity(), {tip.x, tip.y, tip.z - 0.012}});
  Paint(nose, {0.75f, 0.03f, 0.02f});
  return nose;
}

Mesh MakeCap(int segments) {
  const auto bounds = Head().mesh.Bounds();
  const float crown = bounds[0].y;
  const float rim_y = crown + 0.06f;  // the cap's rim, above the brows
  const Slice s = HeadSlice(rim_y);
  // Dome: upper half of an ellipsoid through the rim slightly larger than the head.
  Mesh dome;
  const int rings = segments / 4;
  const float ry = rim_y - crown + 0.008f;
  const float rx = s.rx + 0.008f, rz = s.rz + 0.008f;
  for (int r = 0; r <= rings; ++r) {
    const float t = 0.5f * kPi * static_cast<float>(r) / static_cast<float>(rings);  // 0 = top
    for (int i = 0; i <= segments; ++i) {
      const float a = 2 * kPi * static_cast<float>(i) / static_cast<float>(segments);
      const Vec3 unit{std::sin(t) * std::cos(a), -std::cos(t), std::sin(t) * std::sin(a)};
      dome.positions.push_back({s.cx + rx * unit.x, rim_y + ry * unit.y, s.cz + rz * unit.z});
      dome.normals.push_back(raytrace::Normalize({unit.x / rx, unit.y / ry, unit.z / rz}));
    }
  }
  for (int r = 0; r < rings; ++r) {
    for (int i = 0; i < segments; ++i) {
      const uint32_t a = r * (segments + 1) + i, b = a + 1;
      const uint32_t c = a + segments + 1, d = c + 1;
      dome.triangles.push_back({a, b, d});
      dome.triangles.push_back({a, d, c});
    }
  }
  // Orientation check: make triangles counter-clockwise seen from outside.
  for (auto& tri : dome.triangles) {
    const Vec3 p0 = dome.positions[tri[0]];
    const Vec3 n = raytrace::Cross(dome.positions[tri[1]] - p0, dome.positions[tri[2]] - p0);
    if (raytrace::Dot(n, dome.normals[tri[0]]) < 0) std::swap(tri[1], tri[2]);
  }
  Paint(dome, {0.05f, 0.15f, 0.6f});
  // Visor: a flat box over the forehead.
  Mesh visor = raytrace::MakeBox({rx * 1.3f, 0.006f, 0.08f});
  visor.TransformBy(
      Transform{Mat3::AxisAngle({1, 0, 0}, -0.15), {s.cx, rim_y + 0.002f, s.cz - rz - 0.03f}});
  Paint(visor, {0.05f, 0.15f, 0.6f});
  dome.Append(visor);
  return dome;
}

Mesh MakeGlasses(int segments) {
  const auto& lm = Head().landmarks;
  const Vec3 right_eye = Mean(lm, 36, 41), left_eye = Mean(lm, 42, 47);
  const float front = std::min(right_eye.z, left_eye.z) - 0.02f;
  const float ring_radius = 0.021f, tube = 0.0022f;
  Mesh glasses;
  for (const Vec3& eye : {right_eye, left_eye}) {
    Mesh ring = MakeTorus(ring_radius, tube, segments, 8);
    ring.TransformBy(Transform{Mat3::Identity(), {eye.x, eye.y, front}});
    glasses.Append(ring);
  }
  const float gap = std::abs(left_eye.x - right_eye.x) - 2 * ring_radius;
  Mesh bridge = raytrace::MakeBox({gap, 0.003f, 0.003f});
  bridge.TransformBy(
      Transform{Mat3::Identity(),
                {(left_eye.x + right_eye.x) / 2, (left_eye.y + right_eye.y) / 2 - 0.006f, front}});
  glasses.Append(bridge);
  const Slice s = HeadSlice((left_eye.y + right_eye.y) / 2);
  for (float side : {-1.0f, 1.0f}) {
    const float x = s.cx + side * (s.rx + 0.004f);
    const float length = (s.cz + 0.02f) - front;
    Mesh temple = raytrace::MakeBox({0.003f, 0.004f, length});
    temple.TransformBy(Transform{Mat3::Identity(), {x, right_eye.y, front + length / 2}});
    glasses.Append(temple);
    Mesh hinge = raytrace::MakeBox(
        {std::abs(x - (side < 0 ? right_eye.x : left_eye.x)) - ring_radius + 0.003f, 0.004f,
         0.003f});
    hinge.TransformBy(
        Transform{Mat3::Identity(),
                  {(x + (side < 0 ? right_eye.x - ring_radius : left_eye.x + ring_radius)) / 2,
                   right_eye.y, front}});
    glasses.Append(hinge);
  }
  glasses.ComputeNormals();
  Paint(glasses, {0.04f, 0.04f, 0.04f});
  return glasses;
}

std::vector<std::string> DemoObjectNames() { return {"nose", "cap", "glasses"}; }

Mesh MakeDemoObject(const std::string& name) {
  if (name == "nose") return MakeClownNose();
  if (name == "cap") return MakeCap();
  if (name == "glasses") return MakeGlasses();
  throw PrtError("unknown demo object '" + name + "' (expected nose, cap or glasses)");
}

Mesh MakeBenchmarkObject(int vertices) {
  if (vertices < 100) throw PrtError("MakeBenchmarkObject: vertices must be >= 100");
  // A UV sphere with segments s has about s * s / 2 vertices.
  const int segments = std::max(8, static_cast<int>(std::sqrt(2.0 * vertices)));
  Mesh m = raytrace::MakeSphere(0.05f, segments);
  const Vec3 tip = Head().landmarks[30];
  m.TransformBy(Transform{Mat3::Identity(), {tip.x + 0.12f, tip.y + 0.02f, tip.z - 0.03f}});
  Mesh plate = raytrace::MakeBox({0.2f, 0.01f, 0.2f});
  plate.TransformBy(Transform{Mat3::Identity(), {tip.x + 0.12f, tip.y + 0.08f, tip.z - 0.03f}});
  m.Append(plate);
  m.ComputeNormals();
  return m;
}

}  // namespace probeless::prt
