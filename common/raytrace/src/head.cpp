// The procedural head bust (face frame: x subject's left, y chin, z into the head).
#include <algorithm>
#include <cmath>
#include <numbers>
#include <optional>

#include "probeless/raytrace/mesh.h"

namespace probeless::raytrace {
namespace {

constexpr Vec3 kCentre{0, 0.035f, 0.085f};   // head ellipsoid centre
constexpr Vec3 kAxes{0.075f, 0.115f, 0.1f};  // semi-axes (y: below the centre)
constexpr float kUpperAxisY = 0.15f;   // y semi-axis above the centre: crown 115 mm above the eyes
constexpr float kHairlineY = -0.065f;  // front hairline at the midline, 65 mm above the eyes
// Human proportions (face frame, eye line y = 0, eye centres at x = +-0.032: inter-pupil 64 mm):
// nose tip ~30 mm and mouth line 62 mm below the eye line, chin ~44 mm below the mouth line. Seen
// by face_orbit's camera, the ground-truth landmarks give eye-mouth / inter-ocular 1.01 and
// eye-nose tip 0.50, the tracked Yale B faces 1.02 and 0.47 (face_track::kTrackerCanonical): the
// similarity the face-light sampler fits then puts its samples where they are on a Yale B face.
constexpr float kMouthY = 0.062f;

float Gauss(float d, float sigma) { return std::exp(-d * d / (2 * sigma * sigma)); }
float SmoothStep(float lo, float hi, float x) {
  const float t = std::clamp((x - lo) / (hi - lo), 0.0f, 1.0f);
  return t * t * (3 - 2 * t);
}

// Forward (-z) relief of the face at face-frame (x, y), metres.
float FaceRelief(float x, float y) {
  const float ax = std::abs(x);
  // Nose: a ridge from the bridge to the tip, then the base.
  float nose_height = 0;
  if (y > -0.02f && y < 0.044f) {
    const float rise = 0.004f + 0.020f * SmoothStep(-0.005f, 0.028f, y);
    const float fall = 1 - SmoothStep(0.030f, 0.042f, y);
    const float width = 0.006f + 0.008f * SmoothStep(-0.007f, 0.035f, y);
    nose_height = rise * fall * Gauss(x, width);
  }
  const float brow = 0.006f * Gauss(y + 0.022f, 0.006f) * Gauss(ax - 0.033f, 0.02f);
  const float socket = -0.007f * Gauss(ax - 0.032f, 0.011f) * Gauss(y, 0.009f);
  // Lips: an upper and a lower bulge with the mouth line (kMouthY) in the crease between them.
  const float lips = (0.004f * Gauss(y - kMouthY + 0.004f, 0.0035f) +
                      0.005f * Gauss(y - kMouthY - 0.005f, 0.004f)) *
                     Gauss(x, 0.02f);
  const float chin = 0.006f * Gauss(y - 0.106f, 0.012f) * Gauss(x, 0.022f);
  const float cheeks = 0.004f * Gauss(ax - 0.04f, 0.012f) * Gauss(y - 0.028f, 0.015f);
  return nose_height + brow + socket + lips + chin + cheeks;
}

Vec3 SkinAlbedo(Vec3 p, Vec3 d, Vec3 skin) {
  const float ax = std::abs(p.x);
  // Hair: the top, sides and back of the head; on the front above a hairline that drops towards
  // the temples (a forehead of ~40 mm above the brows).
  const Vec3 hair{0.09f, 0.06f, 0.04f};
  if (d.z < -0.5f) {
    if (p.y < kHairlineY + 0.02f * SmoothStep(0.025f, 0.065f, ax)) return hair;
  } else if (d.y < -0.45f || (d.z > 0.2f && d.y < 0.1f)) {
    return hair;
  }
  // Brows.
  if (d.z < 0 && std::abs(p.y + 0.024f + 0.004f * Gauss(ax - 0.03f, 0.012f)) < 0.0045f &&
      ax > 0.011f && ax < 0.054f)
    return {0.07f, 0.045f, 0.035f};
  // Lips.
  const float lx = p.x / 0.025f;
  const float ly = (p.y - kMouthY) / 0.0095f;
  if (d.z < 0 && lx * lx + ly * ly < 1) {
    if (std::abs(p.y - kMouthY) < 0.0015f && std::abs(p.x) < 0.021f) return {0.15f, 0.04f, 0.04f};
    return {0.55f, 0.18f, 0.18f};
  }
  return skin;
}

// Closest hit of the ray o + t dir (t > 0) with the mesh (Moller-Trumbore), brute force.
std::optional<Vec3> CastRay(const Mesh& mesh, Vec3 o, Vec3 dir) {
  float best = 1e30f;
  for (const auto& tri : mesh.triangles) {
    const Vec3 a = mesh.positions[tri[0]];
    const Vec3 e1 = mesh.positions[tri[1]] - a;
    const Vec3 e2 = mesh.positions[tri[2]] - a;
    const Vec3 p = Cross(dir, e2);
    const float det = Dot(e1, p);
    if (std::abs(det) < 1e-12f) continue;
    const float inv = 1 / det;
    const Vec3 s = o - a;
    const float u = Dot(s, p) * inv;
    if (u < 0 || u > 1) continue;
    const Vec3 q = Cross(s, e1);
    const float v = Dot(dir, q) * inv;
    if (v < 0 || u + v > 1) continue;
    const float t = Dot(e2, q) * inv;
    if (t > 0 && t < best) best = t;
  }
  if (best == 1e30f) return std::nullopt;
  return o + dir * best;
}

// Face-frame (x, y) of the 68 iBUG landmarks, metres.
std::vector<std::array<float, 2>> LandmarkLayout() {
  std::vector<std::array<float, 2>> l;
  for (int i = 0; i <= 16; ++i) {  // jaw, subject's right ear to left ear via the chin
    const double t = std::numbers::pi * i / 16;
    l.push_back({static_cast<float>(-0.068 * std::cos(t)),
                 static_cast<float>(0.005 + 0.112 * std::sin(t))});
  }
  const float brow_x[5] = {-0.054f, -0.045f, -0.035f, -0.024f, -0.013f};
  const float brow_y[5] = {-0.018f, -0.026f, -0.029f, -0.028f, -0.024f};
  for (int i = 0; i < 5; ++i) l.push_back({brow_x[i], brow_y[i]});
  for (int i = 4; i >= 0; --i) l.push_back({-brow_x[i], brow_y[i]});
  for (float y : {0.0f, 0.009f, 0.018f, 0.028f}) l.push_back({0, y});
  for (float x : {-0.014f, -0.007f, 0.0f, 0.007f, 0.014f}) l.push_back({x, 0.039f});
  const float eye[6][2] = {{-0.046f, 0}, {-0.037f, -0.005f}, {-0.027f, -0.005f},
                           {-0.018f, 0}, {-0.027f, 0.004f},  {-0.037f, 0.004f}};
  for (const auto& e : eye) l.push_back({e[0], e[1]});
  const float left_eye[6][2] = {{0.018f, 0}, {0.027f, -0.005f}, {0.037f, -0.005f},
                                {0.046f, 0}, {0.037f, 0.004f},  {0.027f, 0.004f}};
  for (const auto& e : left_eye) l.push_back({e[0], e[1]});
  // Mouth: offsets (x, y - kMouthY).
  const float mouth[20][2] = {
      {-0.024f, 0.000f}, {-0.015f, -0.007f}, {-0.005f, -0.009f}, {0.0f, -0.008f},
      {0.005f, -0.009f}, {0.015f, -0.007f},  {0.024f, 0.000f},   {0.015f, 0.007f},
      {0.005f, 0.009f},  {0.0f, 0.010f},     {-0.005f, 0.009f},  {-0.015f, 0.007f},
      {-0.019f, 0.000f}, {-0.007f, -0.001f}, {0.0f, -0.001f},    {0.007f, -0.001f},
      {0.019f, 0.000f},  {0.007f, 0.001f},   {0.0f, 0.001f},     {-0.007f, 0.001f}};
  for (const auto& m : mouth) l.push_back({m[0], kMouthY + m[1]});
  return l;
}

}  // namespace

HeadModel MakeHead(Vec3 skin, int resolution) {
  if (resolution < 16) throw RaytraceError("MakeHead: resolution must be >= 16");
  HeadModel head;
  Mesh& m = head.mesh;
  // Head: a displaced ellipsoid (UV sphere with its poles on the y axis).
  const int segments = resolution * 2;
  const int rings = resolution;
  for (int r = 0; r <= rings; ++r) {
    const double theta = std::numbers::pi * r / rings;
    for (int s = 0; s <= segments; ++s) {
      const double phi = 2 * std::numbers::pi * s / segments;
      const Vec3 d{static_cast<float>(std::sin(theta) * std::sin(phi)),
                   static_cast<float>(-std::cos(theta)),
                   static_cast<float>(-std::sin(theta) * std::cos(phi))};
      Vec3 p =
          kCentre + Vec3{kAxes.x * d.x, (d.y < 0 ? kUpperAxisY : kAxes.y) * d.y, kAxes.z * d.z};
      // Face relief on the front, ears on the sides.
      const float front = SmoothStep(0.1f, 0.5f, -d.z);
      p.z -= front * FaceRelief(p.x, p.y);
      const float ear = 0.011f * Gauss(p.y - 0.02f, 0.018f) * Gauss(p.z - 0.09f, 0.014f) *
                        SmoothStep(0.8f, 0.95f, std::abs(d.x));
      p.x += d.x > 0 ? ear : -ear;
      m.positions.push_back(p);
      m.colors.push_back(SkinAlbedo(p, d, skin));
    }
  }
  const uint32_t row = static_cast<uint32_t>(segments + 1);
  for (int r = 0; r < rings; ++r) {
    for (int s = 0; s < segments; ++s) {
      const uint32_t a = r * row + s;
      const uint32_t b = a + row;
      // Orientation: outward normals (checked below by the signed volume).
      if (r != 0) m.triangles.push_back({a, a + 1, b});
      if (r != rings - 1) m.triangles.push_back({a + 1, b + 1, b});
    }
  }
  // Flip if the signed volume is negative (inward-facing triangles).
  double volume = 0;
  for (const auto& t : m.triangles) {
    volume += Dot(m.positions[t[0]], Cross(m.positions[t[1]], m.positions[t[2]]));
  }
  if (volume < 0) {
    for (auto& t : m.triangles) std::swap(t[1], t[2]);
  }
  m.ComputeNormals();

  // Neck and shoulders.
  Mesh neck = MakeCylinder(0.052f, 0.2f, 48);
  neck.TransformBy({Mat3::Identity(), {0, 0.1, 0.095}});
  neck.colors.assign(neck.positions.size(), skin);
  m.Append(neck);
  Mesh shoulders = MakeSphere(1, 64);
  for (Vec3& p : shoulders.positions) p = {p.x * 0.21f, p.y * 0.08f + 0.32f, p.z * 0.11f + 0.1f};
  shoulders.ComputeNormals();
  shoulders.colors.assign(shoulders.positions.size(), Vec3{0.12f, 0.2f, 0.35f});
  m.Append(shoulders);

  // Eyes: spheres protruding 4 mm from the sockets, white with an iris and a pupil facing -z.
  for (float side : {-1.0f, 1.0f}) {
    const float ex = side * 0.032f;
    const std::optional<Vec3> socket = CastRay(m, {ex, 0, -0.5f}, {0, 0, 1});
    const float radius = 0.016f;
    const Vec3 centre{ex, 0, (socket ? socket->z : -0.01f) + radius - 0.005f};
    Mesh eye = MakeSphere(radius, 48);
    eye.colors.resize(eye.positions.size());
    for (size_t i = 0; i < eye.positions.size(); ++i) {
      const Vec3 n = eye.normals[i];
      const float angle = std::acos(std::clamp(-n.z, -1.0f, 1.0f));
      // Eyelids (skin, slightly shaded) over the top and bottom of the ball: a ~10 mm high opening.
      const bool lid = n.y < -0.33f || n.y > 0.36f;
      const bool lashes = n.y < -0.24f && n.z < 0;
      eye.colors[i] = lid             ? skin * 0.8f
                      : lashes        ? Vec3{0.05f, 0.035f, 0.03f}
                      : angle < 0.16f ? Vec3{0.02f, 0.02f, 0.02f}
                      : angle < 0.35f ? Vec3{0.22f, 0.13f, 0.07f}
                                      : Vec3{0.8f, 0.78f, 0.74f};
      eye.positions[i] = eye.positions[i] + centre;
    }
    m.Append(eye);
  }
  m.uvs.clear();

  // Landmarks: the layout projected onto the surface along +z.
  for (const auto& xy : LandmarkLayout()) {
    const std::optional<Vec3> p = CastRay(m, {xy[0], xy[1], -0.5f}, {0, 0, 1});
    head.landmarks.push_back(p ? *p : Vec3{xy[0], xy[1], 0});
  }
  return head;
}

}  // namespace probeless::raytrace
