#include "probeless/raytrace/scene.h"

#include <embree3/rtcore.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <deque>
#include <exception>
#include <numbers>

#include "embree_internal.h"
#include "probeless/raytrace/render.h"
#include "scene_access.h"
#include "sh_basis.h"

namespace probeless::raytrace {

// --- Texture ---------------------------------------------------------------------------------

Vec3 Texture::Sample(float u, float v) const {
  if (width <= 0 || height <= 0) return {1, 1, 1};
  const float fx = (u - std::floor(u)) * width - 0.5f;
  const float fy = (1 - (v - std::floor(v))) * height - 0.5f;
  const int x0 = static_cast<int>(std::floor(fx));
  const int y0 = static_cast<int>(std::floor(fy));
  const float ax = fx - x0;
  const float ay = fy - y0;
  auto at = [&](int x, int y) {
    x = ((x % width) + width) % width;
    y = ((y % height) + height) % height;
    const float* p = &linear_rgb[(static_cast<size_t>(y) * width + x) * 3];
    return Vec3{p[0], p[1], p[2]};
  };
  return (at(x0, y0) * (1 - ax) + at(x0 + 1, y0) * ax) * (1 - ay) +
         (at(x0, y0 + 1) * (1 - ax) + at(x0 + 1, y0 + 1) * ax) * ay;
}

// --- Scene -----------------------------------------------------------------------------------

namespace {

struct Object {
  Mesh mesh;  // object frame
  Material material;
  Transform transform;
  std::array<float, 9> rotation{};  // transform.rotation in float, row-major (the path tracer's)
  uint32_t id = 0;
  bool visible = true;
  bool dirty = true;
  // Object-frame positions, 3 floats per vertex + 1 padding float (Embree reads 16 bytes).
  std::vector<float> padded_positions;
  RTCScene sub_scene = nullptr;    // the mesh's own BVH, built once
  RTCGeometry geometry = nullptr;  // the triangle mesh inside sub_scene
  RTCGeometry instance = nullptr;  // the instance in the top-level scene (moves cheaply)
  unsigned geom_id = 0;            // instance id in the top-level scene
};

void StoreRotation(Object& o) {
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c)
      o.rotation[3 * r + c] = static_cast<float>(o.transform.rotation.m[r][c]);
  }
}

void ErrorCallback(void*, RTCError code, const char* message) {
  (void)code;
  (void)message;  // reported through rtcGetDeviceError where it matters
}

}  // namespace

struct Scene::Impl {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  std::deque<Object> objects;  // stable addresses: Embree shares their buffers
  std::vector<int> object_of_geom;
  std::vector<DirectionalLight> directional;
  std::vector<PointLight> points;
  std::vector<AreaLight> areas;
  Environment environment;
  bool committed = false;
  bool structure_changed = true;
};

Scene::Scene() : impl_(std::make_unique<Impl>()) {
  impl_->device = rtcNewDevice("threads=2,set_affinity=0");
  if (impl_->device == nullptr) throw RaytraceError("Scene: cannot create the Embree device");
  rtcSetDeviceErrorFunction(impl_->device, ErrorCallback, nullptr);
  impl_->scene = rtcNewScene(impl_->device);
  rtcSetSceneFlags(impl_->scene, RTC_SCENE_FLAG_DYNAMIC);
  rtcSetSceneBuildQuality(impl_->scene, RTC_BUILD_QUALITY_MEDIUM);
}

Scene::~Scene() {
  for (Object& o : impl_->objects) {
    rtcReleaseGeometry(o.instance);
    rtcReleaseGeometry(o.geometry);
    rtcReleaseScene(o.sub_scene);
  }
  rtcReleaseScene(impl_->scene);
  rtcReleaseDevice(impl_->device);
}

namespace {

std::string Str(float v) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%g", v);
  return buffer;
}

void ValidateMaterial(const Material& m) {
  const std::string what = "Scene::AddObject: Material::";
  if (!(m.roughness > 0 && m.roughness <= 1)) {
    throw RaytraceError(what + "roughness must be in (0, 1], got " + Str(m.roughness));
  }
  if (!(m.specular_f0 >= 0 && m.specular_f0 <= 1)) {
    throw RaytraceError(what + "specular_f0 must be in [0, 1], got " + Str(m.specular_f0));
  }
  if (m.pattern.kind != ProceduralPattern::Kind::kNone && !(m.pattern.period_m > 0)) {
    throw RaytraceError(what + "pattern.period_m must be > 0, got " + Str(m.pattern.period_m));
  }
  if (m.pattern.kind == ProceduralPattern::Kind::kStripes && Length(m.pattern.axis) == 0) {
    throw RaytraceError(what + "pattern.axis must be non-zero for stripes");
  }
  if (!(m.emission.x >= 0 && m.emission.y >= 0 && m.emission.z >= 0)) {
    throw RaytraceError(what + "emission must be >= 0");
  }
}

// Integer lattice hash to [0, 1): the value-noise lattice (fixed, no seed: a solid texture).
float LatticeValue(int64_t x, int64_t y, int64_t z) {
  uint64_t h = static_cast<uint64_t>(x) * 0x9E3779B97F4A7C15ull ^
               static_cast<uint64_t>(y) * 0xC2B2AE3D27D4EB4Full ^
               static_cast<uint64_t>(z) * 0x165667B19E3779F9ull;
  h ^= h >> 31;
  h *= 0xBF58476D1CE4E5B9ull;
  h ^= h >> 29;
  return static_cast<float>(h >> 40) * (1.0f / 16777216.0f);
}

// Trilinear value noise with smoothstep weights, in [0, 1].
float ValueNoise(Vec3 p) {
  const float fx = std::floor(p.x), fy = std::floor(p.y), fz = std::floor(p.z);
  const auto ix = static_cast<int64_t>(fx), iy = static_cast<int64_t>(fy),
             iz = static_cast<int64_t>(fz);
  auto smooth = [](float t) { return t * t * (3 - 2 * t); };
  const float ax = smooth(p.x - fx), ay = smooth(p.y - fy), az = smooth(p.z - fz);
  float result = 0;
  for (int c = 0; c < 8; ++c) {
    const int dx = c & 1, dy = (c >> 1) & 1, dz = (c >> 2) & 1;
    const float w = (dx ? ax : 1 - ax) * (dy ? ay : 1 - ay) * (dz ? az : 1 - az);
    result += w * LatticeValue(ix + dx, iy + dy, iz + dz);
  }
  return result;
}

}  // namespace

Vec3 PatternAlbedo(const ProceduralPattern& pattern, Vec3 base, Vec3 p) {
  using Kind = ProceduralPattern::Kind;
  if (pattern.kind == Kind::kNone || !(pattern.period_m > 0)) return base;
  // Offsets keep faces of round-sized boxes off the cell boundaries (no flicker between cells).
  constexpr float kOffset = 0.1234f;
  const Vec3 q = p / pattern.period_m;
  float t = 0;
  switch (pattern.kind) {
    case Kind::kChecker: {
      const auto cell = static_cast<int64_t>(std::floor(q.x + kOffset)) +
                        static_cast<int64_t>(std::floor(q.y + kOffset)) +
                        static_cast<int64_t>(std::floor(q.z + kOffset));
      t = (cell & 1) != 0 ? 1.0f : 0.0f;
      break;
    }
    case Kind::kStripes: {
      const float s = Dot(q, Normalize(pattern.axis)) + kOffset;
      t = s - std::floor(s) >= 0.5f ? 1.0f : 0.0f;
      break;
    }
    case Kind::kValueNoise:
      // Two octaves for a less grid-like look; weights sum to 1 so t stays in [0, 1].
      t = 0.7f * ValueNoise(q + Vec3{kOffset, kOffset, kOffset}) +
          0.3f * ValueNoise(q * 2.0f + Vec3{17.1f, 5.3f, 9.7f});
      break;
    case Kind::kNone:
      break;
  }
  return base * (1 - t) + pattern.color_b * t;
}

int Scene::AddObject(Mesh mesh, Material material, const Transform& object_to_world, uint32_t id) {
  if (id == 0) throw RaytraceError("Scene::AddObject: object id must be > 0");
  mesh.Validate("Scene::AddObject");
  if (mesh.triangles.empty()) throw RaytraceError("Scene::AddObject: mesh has no triangles");
  if (material.texture && mesh.uvs.empty()) {
    throw RaytraceError("Scene::AddObject: textured material needs a mesh with uvs");
  }
  ValidateMaterial(material);
  if (mesh.normals.empty()) mesh.ComputeNormals();
  Object o;
  o.mesh = std::move(mesh);
  o.material = std::move(material);
  o.transform = object_to_world;
  StoreRotation(o);
  o.id = id;
  o.padded_positions.assign(o.mesh.positions.size() * 3 + 1, 0);
  for (size_t i = 0; i < o.mesh.positions.size(); ++i) {
    for (int k = 0; k < 3; ++k) o.padded_positions[3 * i + k] = o.mesh.positions[i][k];
  }
  o.geometry = rtcNewGeometry(impl_->device, RTC_GEOMETRY_TYPE_TRIANGLE);
  rtcSetSharedGeometryBuffer(o.geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                             o.padded_positions.data(), 0, 3 * sizeof(float),
                             o.mesh.positions.size());
  rtcSetSharedGeometryBuffer(o.geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                             o.mesh.triangles.data(), 0, 3 * sizeof(uint32_t),
                             o.mesh.triangles.size());
  rtcCommitGeometry(o.geometry);
  o.sub_scene = rtcNewScene(impl_->device);
  rtcSetSceneBuildQuality(o.sub_scene, RTC_BUILD_QUALITY_HIGH);
  rtcAttachGeometry(o.sub_scene, o.geometry);
  rtcCommitScene(o.sub_scene);
  o.instance = rtcNewGeometry(impl_->device, RTC_GEOMETRY_TYPE_INSTANCE);
  rtcSetGeometryInstancedScene(o.instance, o.sub_scene);
  o.geom_id = rtcAttachGeometry(impl_->scene, o.instance);
  const int index = static_cast<int>(impl_->objects.size());
  if (impl_->object_of_geom.size() <= o.geom_id) impl_->object_of_geom.resize(o.geom_id + 1, -1);
  impl_->object_of_geom[o.geom_id] = index;
  impl_->objects.push_back(std::move(o));
  impl_->committed = false;
  return index;
}

namespace {
Object& CheckedObject(std::deque<Object>& objects, int index, const char* what) {
  if (index < 0 || static_cast<size_t>(index) >= objects.size()) {
    throw RaytraceError(std::string(what) + ": no object " + std::to_string(index));
  }
  return objects[index];
}
}  // namespace

void Scene::SetObjectTransform(int index, const Transform& object_to_world) {
  Object& o = CheckedObject(impl_->objects, index, "Scene::SetObjectTransform");
  o.transform = object_to_world;
  StoreRotation(o);
  o.dirty = true;
  impl_->committed = false;
}

void Scene::SetObjectVisible(int index, bool visible) {
  Object& o = CheckedObject(impl_->objects, index, "Scene::SetObjectVisible");
  if (o.visible != visible) {
    o.visible = visible;
    o.dirty = true;
    impl_->committed = false;
  }
}

const Transform& Scene::ObjectTransform(int index) const {
  return CheckedObject(impl_->objects, index, "Scene::ObjectTransform").transform;
}
uint32_t Scene::ObjectId(int index) const {
  return CheckedObject(impl_->objects, index, "Scene::ObjectId").id;
}
int Scene::object_count() const { return static_cast<int>(impl_->objects.size()); }
size_t Scene::triangle_count() const {
  size_t n = 0;
  for (const Object& o : impl_->objects) n += o.mesh.triangles.size();
  return n;
}

std::vector<DirectionalLight>& Scene::directional_lights() { return impl_->directional; }
const std::vector<DirectionalLight>& Scene::directional_lights() const {
  return impl_->directional;
}
std::vector<PointLight>& Scene::point_lights() { return impl_->points; }
const std::vector<PointLight>& Scene::point_lights() const { return impl_->points; }
std::vector<AreaLight>& Scene::area_lights() { return impl_->areas; }
const std::vector<AreaLight>& Scene::area_lights() const { return impl_->areas; }
Environment& Scene::environment() { return impl_->environment; }
const Environment& Scene::environment() const { return impl_->environment; }

void Scene::SetEnvironmentMap(const Texture& map, float scale) {
  if (map.width < 1 || map.height < 1 ||
      map.linear_rgb.size() != static_cast<size_t>(map.width) * map.height * 3) {
    throw RaytraceError("Scene::SetEnvironmentMap: empty or inconsistent map");
  }
  std::array<Vec3, 9> sh{};
  for (int v = 0; v < map.height; ++v) {
    const double theta = std::numbers::pi * (v + 0.5) / map.height;
    const float solid_angle = static_cast<float>((2 * std::numbers::pi / map.width) *
                                                 (std::numbers::pi / map.height) * std::sin(theta));
    for (int u = 0; u < map.width; ++u) {
      const double phi = 2 * std::numbers::pi * (u + 0.5) / map.width;
      const Vec3 w{static_cast<float>(std::sin(theta) * std::cos(phi)),
                   static_cast<float>(std::cos(theta)),
                   static_cast<float>(std::sin(theta) * std::sin(phi))};
      const float* p = &map.linear_rgb[(static_cast<size_t>(v) * map.width + u) * 3];
      const Vec3 radiance{p[0], p[1], p[2]};
      const std::array<float, 9> y = ShBasis9(w);
      for (int i = 0; i < 9; ++i) sh[i] += radiance * (y[i] * solid_angle);
    }
  }
  impl_->environment.sh = sh;
  impl_->environment.scale = scale;
}

void Scene::Commit() {
  for (Object& o : impl_->objects) {
    if (!o.dirty) continue;
    float xfm[12];  // 3x4 column-major: rotation columns, then translation
    for (int col = 0; col < 3; ++col) {
      for (int row = 0; row < 3; ++row) {
        xfm[col * 3 + row] = static_cast<float>(o.transform.rotation.m[row][col]);
      }
    }
    for (int row = 0; row < 3; ++row)
      xfm[9 + row] = static_cast<float>(o.transform.translation[row]);
    rtcSetGeometryTransform(o.instance, 0, RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR, xfm);
    if (o.visible) {
      rtcEnableGeometry(o.instance);
    } else {
      rtcDisableGeometry(o.instance);
    }
    rtcCommitGeometry(o.instance);
    o.dirty = false;
  }
  rtcCommitScene(impl_->scene);
  const RTCError error = rtcGetDeviceError(impl_->device);
  if (error != RTC_ERROR_NONE) {
    throw RaytraceError("Scene::Commit: Embree error " + std::to_string(static_cast<int>(error)));
  }
  impl_->committed = true;
}

void* Scene::embree_scene() const { return impl_->scene; }

namespace internal {

RTCScene SceneAccess::Handle(const Scene& scene) { return scene.impl_->scene; }

int SceneAccess::ObjectOfInstance(const Scene& scene, unsigned inst_id) {
  return scene.impl_->object_of_geom[inst_id];
}

void SceneAccess::CheckCommitted(const Scene& scene, const char* what) {
  if (!scene.impl_->committed) throw RaytraceError(std::string(what) + ": scene not committed");
}

bool SceneAccess::HasEmission(const Scene& scene) {
  for (const Object& o : scene.impl_->objects) {
    const Vec3 e = o.material.emission;
    if (o.visible && (e.x > 0 || e.y > 0 || e.z > 0)) return true;
  }
  return false;
}

}  // namespace internal

namespace internal {

void ToEmbree(const Ray& r, RTCRay& out) {
  out.org_x = r.origin.x;
  out.org_y = r.origin.y;
  out.org_z = r.origin.z;
  out.tnear = r.t_near;
  out.dir_x = r.direction.x;
  out.dir_y = r.direction.y;
  out.dir_z = r.direction.z;
  out.time = 0;
  out.tfar = r.t_far;
  out.mask = 0xFFFFFFFFu;
  out.id = 0;
  out.flags = 0;
}

void IntersectStream(RTCScene scene, RTCRayHit* rays, size_t count, bool coherent) {
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  if (coherent) context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  for (size_t i = 0; i < count; ++i) {
    rays[i].hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rays[i].hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  }
  rtcIntersect1M(scene, &context, rays, static_cast<unsigned>(count), sizeof(RTCRayHit));
}

void OccludedStream(RTCScene scene, RTCRay* rays, size_t count, size_t stride) {
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  rtcOccluded1M(scene, &context, rays, static_cast<unsigned>(count), stride);
}

}  // namespace internal

namespace {
constexpr size_t kChunk = 1024;

void CheckQuery(bool committed, size_t rays, size_t out, const char* what) {
  if (!committed) throw RaytraceError(std::string(what) + ": scene not committed");
  if (rays != out) {
    throw RaytraceError(std::string(what) + ": " + std::to_string(rays) + " rays but " +
                        std::to_string(out) + " outputs");
  }
}

void ForChunks(size_t count, ThreadPool* pool, const std::function<void(size_t)>& fn) {
  const size_t chunks = (count + kChunk - 1) / kChunk;
  if (pool != nullptr && chunks > 1) {
    pool->ParallelFor(chunks, fn);
  } else {
    for (size_t c = 0; c < chunks; ++c) fn(c);
  }
}
}  // namespace

void Scene::Intersect(std::span<const Ray> rays, std::span<Hit> hits, ThreadPool* pool) const {
  CheckQuery(impl_->committed, rays.size(), hits.size(), "Scene::Intersect");
  ForChunks(rays.size(), pool, [&](size_t chunk) {
    const size_t begin = chunk * kChunk;
    const size_t end = std::min(rays.size(), begin + kChunk);
    std::vector<RTCRayHit> stream(end - begin);
    for (size_t i = begin; i < end; ++i) internal::ToEmbree(rays[i], stream[i - begin].ray);
    internal::IntersectStream(impl_->scene, stream.data(), stream.size(), false);
    for (size_t i = begin; i < end; ++i) {
      const RTCRayHit& r = stream[i - begin];
      Hit& h = hits[i];
      if (r.hit.geomID == RTC_INVALID_GEOMETRY_ID) {
        h = Hit{};
        continue;
      }
      h.object = impl_->object_of_geom[r.hit.instID[0]];
      h.triangle = r.hit.primID;
      h.t = r.ray.tfar;
      h.u = r.hit.u;
      h.v = r.hit.v;
    }
  });
}

void Scene::Occluded(std::span<const Ray> rays, std::span<uint8_t> visible,
                     ThreadPool* pool) const {
  CheckQuery(impl_->committed, rays.size(), visible.size(), "Scene::Occluded");
  ForChunks(rays.size(), pool, [&](size_t chunk) {
    const size_t begin = chunk * kChunk;
    const size_t end = std::min(rays.size(), begin + kChunk);
    std::vector<RTCRay> stream(end - begin);
    for (size_t i = begin; i < end; ++i) internal::ToEmbree(rays[i], stream[i - begin]);
    internal::OccludedStream(impl_->scene, stream.data(), stream.size());
    for (size_t i = begin; i < end; ++i) {
      visible[i] = std::isinf(stream[i - begin].tfar) && stream[i - begin].tfar < 0 ? 0 : 1;
    }
  });
}

namespace {
// Albedo, object-frame position, material and id of a hit (shared by both Surface variants).
void SurfaceAlbedo(const Object& o, const std::array<uint32_t, 3>& tri, float w0, float u, float v,
                   SurfacePoint& s) {
  const Material& m = o.material;
  Vec3 albedo = m.albedo;
  if (m.texture) {
    const Vec2 a = o.mesh.uvs[tri[0]], b = o.mesh.uvs[tri[1]], c = o.mesh.uvs[tri[2]];
    albedo = m.texture->Sample(a.u * w0 + b.u * u + c.u * v, a.v * w0 + b.v * u + c.v * v);
  } else if (!o.mesh.colors.empty()) {
    albedo = o.mesh.colors[tri[0]] * w0 + o.mesh.colors[tri[1]] * u + o.mesh.colors[tri[2]] * v;
  }
  s.object_position =
      o.mesh.positions[tri[0]] * w0 + o.mesh.positions[tri[1]] * u + o.mesh.positions[tri[2]] * v;
  albedo = PatternAlbedo(m.pattern, albedo, s.object_position);
  s.albedo = albedo * m.albedo_scale;
  s.material = &m;
  s.object_id = o.id;
}
}  // namespace

SurfacePoint Scene::Surface(const Ray& ray, const Hit& hit) const {
  const Object& o = impl_->objects.at(static_cast<size_t>(hit.object));
  const auto& tri = o.mesh.triangles[hit.triangle];
  const float w0 = 1 - hit.u - hit.v;
  SurfacePoint s;
  s.position = ray.origin + ray.direction * hit.t;
  const Vec3 p0 = o.mesh.positions[tri[0]];
  const Mat3& r = o.transform.rotation;
  Vec3 ng = Normalize(r * Cross(o.mesh.positions[tri[1]] - p0, o.mesh.positions[tri[2]] - p0));
  Vec3 n = Normalize(r * (o.mesh.normals[tri[0]] * w0 + o.mesh.normals[tri[1]] * hit.u +
                          o.mesh.normals[tri[2]] * hit.v));
  if (Length(n) == 0) n = ng;
  if (Dot(ng, ray.direction) > 0) ng = -ng;
  if (Dot(n, ng) < 0) n = -n;
  s.normal = n;
  s.geometric_normal = ng;
  SurfaceAlbedo(o, tri, w0, hit.u, hit.v, s);
  return s;
}

namespace internal {

SurfacePoint SceneAccess::Surface(const Scene& scene, const Hit& hit, Vec3 origin, Vec3 direction) {
  const Object& o = scene.impl_->objects[static_cast<size_t>(hit.object)];
  const auto& tri = o.mesh.triangles[hit.triangle];
  const float w0 = 1 - hit.u - hit.v;
  const float* r = o.rotation.data();
  auto rotate = [r](Vec3 v) {
    return Vec3{r[0] * v.x + r[1] * v.y + r[2] * v.z, r[3] * v.x + r[4] * v.y + r[5] * v.z,
                r[6] * v.x + r[7] * v.y + r[8] * v.z};
  };
  auto unit = [](Vec3 v) {
    const float n2 = Dot(v, v);
    return n2 > 0 ? v * (1 / std::sqrt(n2)) : Vec3{};
  };
  SurfacePoint s;
  s.position = origin + direction * hit.t;
  const Vec3 p0 = o.mesh.positions[tri[0]];
  Vec3 ng = unit(rotate(Cross(o.mesh.positions[tri[1]] - p0, o.mesh.positions[tri[2]] - p0)));
  Vec3 n = unit(rotate(o.mesh.normals[tri[0]] * w0 + o.mesh.normals[tri[1]] * hit.u +
                       o.mesh.normals[tri[2]] * hit.v));
  if (Dot(n, n) == 0) n = ng;
  if (Dot(ng, direction) > 0) ng = -ng;
  if (Dot(n, ng) < 0) n = -n;
  s.normal = n;
  s.geometric_normal = ng;
  SurfaceAlbedo(o, tri, w0, hit.u, hit.v, s);
  return s;
}

}  // namespace internal

}  // namespace probeless::raytrace
