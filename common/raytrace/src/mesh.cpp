#include "probeless/raytrace/mesh.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace probeless::raytrace {

void Mesh::Validate(const std::string& what) const {
  const size_t n = positions.size();
  auto check_size = [&](size_t size, const char* name) {
    if (size != 0 && size != n) {
      throw RaytraceError(what + ": " + name + " has " + std::to_string(size) +
                          " entries, expected 0 or " + std::to_string(n) + " (one per vertex)");
    }
  };
  check_size(normals.size(), "normals");
  check_size(uvs.size(), "uvs");
  check_size(colors.size(), "colors");
  for (size_t t = 0; t < triangles.size(); ++t) {
    for (uint32_t i : triangles[t]) {
      if (i >= n) {
        throw RaytraceError(what + ": triangle " + std::to_string(t) + " uses vertex " +
                            std::to_string(i) + " of " + std::to_string(n));
      }
    }
  }
}

void Mesh::ComputeNormals() {
  normals.assign(positions.size(), Vec3{});
  for (const auto& t : triangles) {
    const Vec3 n = Cross(positions[t[1]] - positions[t[0]], positions[t[2]] - positions[t[0]]);
    for (uint32_t i : t) normals[i] += n;
  }
  for (Vec3& n : normals) {
    n = Normalize(n);
    if (Length(n) == 0) n = {0, 1, 0};
  }
}

void Mesh::TransformBy(const Transform& transform) {
  for (Vec3& p : positions) p = transform.Apply(p);
  for (Vec3& n : normals) n = Normalize(transform.ApplyDirection(n));
}

void Mesh::Scale(float factor) {
  for (Vec3& p : positions) p *= factor;
}

void Mesh::Append(const Mesh& other) {
  const uint32_t base = static_cast<uint32_t>(positions.size());
  const size_t n_self = positions.size();
  const size_t n_other = other.positions.size();
  auto merge = [&](auto& mine, const auto& theirs, auto fill) {
    if (mine.empty() && theirs.empty()) return;
    if (mine.empty()) mine.assign(n_self, fill);
    if (theirs.empty()) {
      mine.insert(mine.end(), n_other, fill);
    } else {
      mine.insert(mine.end(), theirs.begin(), theirs.end());
    }
  };
  merge(normals, other.normals, Vec3{0, 1, 0});
  merge(uvs, other.uvs, Vec2{});
  merge(colors, other.colors, Vec3{1, 1, 1});
  positions.insert(positions.end(), other.positions.begin(), other.positions.end());
  for (const auto& t : other.triangles)
    triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
}

std::array<Vec3, 2> Mesh::Bounds() const {
  if (positions.empty()) return {Vec3{}, Vec3{}};
  Vec3 lo = positions[0];
  Vec3 hi = positions[0];
  for (const Vec3& p : positions) {
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], p[k]);
      hi[k] = std::max(hi[k], p[k]);
    }
  }
  return {lo, hi};
}

Mesh MakeBox(Vec3 size) {
  Mesh m;
  const Vec3 h = size * 0.5f;
  // Each face: normal axis, sign; corners built from two tangent axes.
  for (int axis = 0; axis < 3; ++axis) {
    for (int sign = -1; sign <= 1; sign += 2) {
      Vec3 n{};
      n[axis] = static_cast<float>(sign);
      const int a = (axis + 1) % 3;
      const int b = (axis + 2) % 3;
      const uint32_t base = static_cast<uint32_t>(m.positions.size());
      const float corners[4][2] = {{-1, -1}, {1, -1}, {1, 1}, {-1, 1}};
      for (const auto& c : corners) {
        Vec3 p{};
        p[axis] = sign * h[axis];
        p[a] = c[0] * h[a];
        p[b] = c[1] * h[b];
        m.positions.push_back(p);
        m.normals.push_back(n);
        m.uvs.push_back({(c[0] + 1) / 2, (c[1] + 1) / 2});
      }
      // (a, b, axis) is right-handed, so corners in that order are counter-clockwise seen from
      // +axis; flip for the negative face.
      if (sign > 0) {
        m.triangles.push_back({base, base + 1, base + 2});
        m.triangles.push_back({base, base + 2, base + 3});
      } else {
        m.triangles.push_back({base, base + 2, base + 1});
        m.triangles.push_back({base, base + 3, base + 2});
      }
    }
  }
  return m;
}

Mesh MakeSphere(float radius, int segments) {
  if (segments < 3) throw RaytraceError("MakeSphere: segments must be >= 3");
  Mesh m;
  const int rings = std::max(2, segments / 2);
  for (int r = 0; r <= rings; ++r) {
    const double theta = std::numbers::pi * r / rings;  // from +y
    for (int s = 0; s <= segments; ++s) {
      const double phi = 2 * std::numbers::pi * s / segments;
      const Vec3 d{static_cast<float>(std::sin(theta) * std::cos(phi)),
                   static_cast<float>(std::cos(theta)),
                   static_cast<float>(-std::sin(theta) * std::sin(phi))};
      m.positions.push_back(d * radius);
      m.normals.push_back(d);
      m.uvs.push_back({static_cast<float>(s) / segments, 1 - static_cast<float>(r) / rings});
    }
  }
  const uint32_t row = static_cast<uint32_t>(segments + 1);
  for (int r = 0; r < rings; ++r) {
    for (int s = 0; s < segments; ++s) {
      const uint32_t a = r * row + s;
      const uint32_t b = a + row;
      if (r != 0) m.triangles.push_back({a, b, a + 1});
      if (r != rings - 1) m.triangles.push_back({a + 1, b, b + 1});
    }
  }
  return m;
}

Mesh MakePlane(float size_x, float size_z, float uv_repeat) {
  Mesh m;
  const float hx = size_x / 2;
  const float hz = size_z / 2;
  m.positions = {{-hx, 0, -hz}, {hx, 0, -hz}, {hx, 0, hz}, {-hx, 0, hz}};
  m.normals.assign(4, Vec3{0, 1, 0});
  m.uvs = {{0, uv_repeat}, {uv_repeat, uv_repeat}, {uv_repeat, 0}, {0, 0}};
  // Counter-clockwise seen from +y.
  m.triangles = {{0, 2, 1}, {0, 3, 2}};
  return m;
}

Mesh MakeCylinder(float radius, float height, int segments) {
  if (segments < 3) throw RaytraceError("MakeCylinder: segments must be >= 3");
  Mesh m;
  for (int s = 0; s <= segments; ++s) {
    const double phi = 2 * std::numbers::pi * s / segments;
    const Vec3 n{static_cast<float>(std::cos(phi)), 0, static_cast<float>(-std::sin(phi))};
    for (int k = 0; k < 2; ++k) {
      m.positions.push_back({n.x * radius, k * height, n.z * radius});
      m.normals.push_back(n);
      m.uvs.push_back({static_cast<float>(s) / segments, static_cast<float>(k)});
    }
  }
  for (int s = 0; s < segments; ++s) {
    const uint32_t a = 2 * s;
    m.triangles.push_back({a, a + 2, a + 1});
    m.triangles.push_back({a + 1, a + 2, a + 3});
  }
  for (int k = 0; k < 2; ++k) {
    const float y = k * height;
    const Vec3 n{0, k == 0 ? -1.0f : 1.0f, 0};
    const uint32_t centre = static_cast<uint32_t>(m.positions.size());
    m.positions.push_back({0, y, 0});
    m.normals.push_back(n);
    m.uvs.push_back({0.5f, 0.5f});
    for (int s = 0; s <= segments; ++s) {
      const double phi = 2 * std::numbers::pi * s / segments;
      m.positions.push_back({static_cast<float>(std::cos(phi)) * radius, y,
                             static_cast<float>(-std::sin(phi)) * radius});
      m.normals.push_back(n);
      m.uvs.push_back({0.5f + 0.5f * static_cast<float>(std::cos(phi)),
                       0.5f + 0.5f * static_cast<float>(std::sin(phi))});
    }
    for (int s = 0; s < segments; ++s) {
      const uint32_t a = centre + 1 + s;
      if (k == 1) {
        m.triangles.push_back({centre, a, a + 1});
      } else {
        m.triangles.push_back({centre, a + 1, a});
      }
    }
  }
  return m;
}

}  // namespace probeless::raytrace
