// A ray-traceable scene: meshes placed in a world frame with materials, lights and an environment,
// plus batched ray queries (closest hit and occlusion) on a thread pool, backed by Embree 3.
//
// Radiometry (the units of msgs::ShLight): linear RGB where 1 is full scale; a Lambertian surface
// of albedo a receiving irradiance E reflects radiance a E / pi, so a white surface lit by a
// uniform environment of radiance 1 reads 1.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "probeless/parallel/thread_pool.h"
#include "probeless/raytrace/geometry.h"
#include "probeless/raytrace/mesh.h"

namespace probeless::raytrace {

// The project's one thread pool (probeless/parallel/thread_pool.h): ParallelFor(count, fn) and
// thread_count(); the batched queries and renders take an optional pool.
using ThreadPool = parallel::ThreadPool;

// A linear-RGB image used as albedo texture or lat-long environment. Pixel (x, y) at
// linear_rgb[(y * width + x) * 3 + c].
struct Texture {
  int width = 0;
  int height = 0;
  std::vector<float> linear_rgb;

  // Bilinear lookup with wrap-around at (u, v), u right, v up (OBJ convention), in [0, 1).
  Vec3 Sample(float u, float v) const;
};
// Reads an 8-bit PNG/JPEG (sRGB, converted to linear) or a 32-bit float image. Throws
// RaytraceError "cannot read texture '<path>'..." on failure.
Texture LoadTexture(const std::string& path);

// A solid-texture albedo pattern evaluated at the hit position in the OBJECT frame (no uvs
// needed; it moves with the object). It blends the base albedo (texture, vertex colours or
// Material::albedo) with `color_b`; Material::albedo_scale applies to the blend. Used by Render
// and PathTrace alike.
struct ProceduralPattern {
  enum class Kind {
    kNone,        // the base albedo
    kChecker,     // 3D checkerboard of cubes of edge period_m: base and color_b alternate
    kValueNoise,  // smooth value noise of feature size period_m: lerp(base, color_b, n), n in [0,1]
    kStripes,     // slabs of width period_m / 2 across `axis`: base and color_b alternate
  };
  Kind kind = Kind::kNone;
  Vec3 color_b{0.2f, 0.2f, 0.2f};  // the second linear RGB albedo in [0, 1]
  float period_m = 0.1f;           // metres (> 0): checker cell, stripe period, noise feature size
  Vec3 axis{1, 0, 0};              // stripes: across this object-frame axis (any non-zero length)
};

// The albedo of `pattern` at `object_position` (object frame, metres) blending `base` with
// pattern.color_b (returns `base` for kNone). Deterministic: a pure function of its arguments.
Vec3 PatternAlbedo(const ProceduralPattern& pattern, Vec3 base, Vec3 object_position);

// Surface reflectance: Lambertian albedo (texture, else vertex colours, else `albedo`, each
// blended by `pattern` and multiplied by `albedo_scale`) plus an optional Blinn-Phong lobe for
// Render's direct lights, or a GGX lobe for PathTrace. PathTrace's BSDF is energy conserving:
// with E(mu) the GGX lobe's directional albedo, the diffuse part is
// albedo / pi * (1 - E(mu_o)) (1 - E(mu_i)) / (1 - E_avg), so the total directional albedo is
// E + albedo (1 - E) <= 1 (exactly 1 for a white material; docs/raytrace.md "Path tracing").
struct Material {
  Vec3 albedo{0.8f, 0.8f, 0.8f};  // linear RGB in [0, 1]
  float albedo_scale = 1;
  std::shared_ptr<const Texture> texture;  // null = none; needs mesh uvs
  float specular = 0;                      // Blinn-Phong weight ks in [0, 1] (0 = off; Render only)
  float shininess = 32;                    // Blinn-Phong exponent (Render only)
  ProceduralPattern pattern;               // solid albedo pattern (kNone = off)
  // GGX (Trowbridge-Reitz, Smith height-correlated masking, Fresnel-Schlick) reflectance at
  // normal incidence in [0, 1]; 0 = no specular lobe (pure Lambert). PathTrace only.
  float specular_f0 = 0;
  // GGX roughness in (0, 1]: alpha = roughness^2. PathTrace only; AddObject checks the range.
  float roughness = 0.5f;
  // Linear RGB radiance emitted from both sides of the surface (0 = none). PathTrace only: seen by
  // camera and bounce rays, not sampled by next-event estimation (use AreaLight for lamps).
  Vec3 emission{0, 0, 0};
};

// A light at infinity: parallel rays arriving from `direction` (unit, world frame, pointing from
// the scene towards the light). `irradiance` is linear RGB irradiance on a surface facing it.
// With angular_radius > 0 it is a uniform disc of that angular radius around `direction` (the
// sun: 0.0047 rad) of radiance irradiance / (pi sin^2 angular_radius), giving soft shadows in
// PathTrace; Render treats every directional light as a delta light.
struct DirectionalLight {
  Vec3 direction{0, -1, 0};
  Vec3 irradiance{3.14159265f, 3.14159265f, 3.14159265f};
  bool enabled = true;
  float angular_radius = 0;  // radians, [0, pi / 2); 0 = a delta (parallel) light
};

// An isotropic point light at `position` (world, metres); `intensity` is linear RGB radiant
// intensity: irradiance intensity * cos / r^2 at distance r.
struct PointLight {
  Vec3 position{0, 2, 0};
  Vec3 intensity{1, 1, 1};
  bool enabled = true;
};

// A one-sided Lambertian emitter of constant radiance, analytic (not in the BVH): PathTrace's
// camera and bounce rays see it (its front emits `radiance`, its back is black and absorbs the
// path), next-event estimation samples it (rectangle by area, sphere by the solid angle of its
// cone), and it blocks PathTrace's shadow rays towards other lights. Render ignores area lights.
struct AreaLight {
  enum class Shape { kRectangle, kSphere };
  Shape shape = Shape::kRectangle;
  Vec3 centre{0, 2, 0};  // world, metres
  // Rectangle: half-edge vectors (world, metres, orthogonal, non-zero); it is the set
  // centre + s half_u + t half_v, s, t in [-1, 1], emitting towards Normalize(Cross(half_u,
  // half_v)) only.
  Vec3 half_u{0.25f, 0, 0};
  Vec3 half_v{0, 0, 0.25f};
  float radius = 0.1f;     // sphere: metres (> 0); emits outwards everywhere
  Vec3 radiance{1, 1, 1};  // linear RGB emitted radiance
  bool enabled = true;
  uint32_t id = 0;  // the object-id image value where it is seen directly (0 = background)
};

// Distant environment light (unshadowed in Render, shadowed in PathTrace: docs/raytrace.md):
// incident radiance
// L(w) = sum_i sh[i] Y_i(w), w a world-frame direction, 9 coefficients (bands 0..2, convention of
// msgs/sh_light.h), linear RGB each, multiplied by `scale`. A lat-long map is projected to these
// 9 coefficients by SetEnvironmentMap.
struct Environment {
  std::array<Vec3, 9> sh{};
  float scale = 1;
};

// One ray for the batched queries: origin (world, metres), direction (world, any non-zero length;
// t is in units of its length), interval [t_near, t_far].
struct Ray {
  Vec3 origin;
  Vec3 direction;
  float t_near = 0;
  float t_far = 1e30f;
};

// Closest hit of a ray. object = index returned by Scene::AddObject, or -1 for a miss.
struct Hit {
  int32_t object = -1;
  uint32_t triangle = 0;
  float t = 0;  // ray parameter of the hit
  float u = 0;  // barycentric weight of vertex 1
  float v = 0;  // barycentric weight of vertex 2
};

// The scene's description of a hit point (world frame).
struct SurfacePoint {
  Vec3 position;
  Vec3 normal;            // unit shading normal, facing the ray origin
  Vec3 geometric_normal;  // unit, facing the ray origin
  Vec3 albedo;            // linear RGB (texture / vertex colours / albedo, pattern, scale)
  Vec3 object_position;   // the hit in the object's own frame (metres): the pattern's argument
  const Material* material = nullptr;
  uint32_t object_id = 0;  // the object's id (AddObject)
};

namespace internal {
struct SceneAccess;  // the path tracer's private view of the scene (src/scene_access.h)
}  // namespace internal

class Scene {
 public:
  Scene();
  ~Scene();
  Scene(const Scene&) = delete;
  Scene& operator=(const Scene&) = delete;

  // Adds `mesh` (object frame) placed by `object_to_world` with `material`; `id` is what the
  // object-id image shows for it (> 0; ids need not be unique). Returns the object's index.
  // Throws RaytraceError for an invalid mesh, id 0 or an invalid material (roughness outside
  // (0, 1], specular_f0 outside [0, 1], pattern period <= 0, stripes axis zero, negative emission).
  int AddObject(Mesh mesh, Material material, const Transform& object_to_world, uint32_t id);
  // Moves object `index` (its mesh keeps its object-frame shape). Takes effect at Commit().
  void SetObjectTransform(int index, const Transform& object_to_world);
  // Hides (false) or shows object `index`. Takes effect at Commit().
  void SetObjectVisible(int index, bool visible);
  const Transform& ObjectTransform(int index) const;
  uint32_t ObjectId(int index) const;
  int object_count() const;
  // Total triangles of all objects.
  size_t triangle_count() const;

  // Lights: replace the lists (take effect immediately; lights are not part of the BVH).
  std::vector<DirectionalLight>& directional_lights();
  const std::vector<DirectionalLight>& directional_lights() const;
  std::vector<PointLight>& point_lights();
  const std::vector<PointLight>& point_lights() const;
  // Area lights (PathTrace only; not in the BVH, take effect immediately). Validated by PathTrace.
  std::vector<AreaLight>& area_lights();
  const std::vector<AreaLight>& area_lights() const;
  Environment& environment();
  const Environment& environment() const;
  // Sets the environment to the band-0..2 projection of a lat-long map (world frame: the map's
  // column u covers azimuth phi = 2 pi (u + 0.5) / width measured from +x towards +z, row v the
  // polar angle theta = pi (v + 0.5) / height from +y (up) downwards), radiance times `scale`.
  void SetEnvironmentMap(const Texture& map, float scale);

  // Builds or updates the acceleration structure. Must be called after AddObject /
  // SetObjectTransform / SetObjectVisible and before any query.
  void Commit();

  // Closest hits of `rays` into `hits` (same size), using `pool` (null = calling thread). Thread-
  // safe between Commits. Throws RaytraceError if the sizes differ or the scene is not committed.
  void Intersect(std::span<const Ray> rays, std::span<Hit> hits, ThreadPool* pool = nullptr) const;
  // Visibility of `rays` into `visible` (1 = nothing hit in [t_near, t_far], 0 = occluded): the
  // batched occlusion query of shadow rays and PRT bakes. Same contract as Intersect.
  void Occluded(std::span<const Ray> rays, std::span<uint8_t> visible,
                ThreadPool* pool = nullptr) const;
  // Surface attributes at `hit` of `ray` (hit.object >= 0).
  SurfacePoint Surface(const Ray& ray, const Hit& hit) const;

  // Internal: the Embree scene handle (RTCScene) for the renderer.
  void* embree_scene() const;

 private:
  friend struct internal::SceneAccess;
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace probeless::raytrace
