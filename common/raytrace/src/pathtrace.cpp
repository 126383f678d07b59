#include "probeless/raytrace/pathtrace.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <string>
#include <thread>
#include <vector>

#include "bsdf.h"
#include "embree_internal.h"
#include "frame_buffers.h"
#include "scene_access.h"
#include "sh_basis.h"

namespace probeless::raytrace {
namespace {

constexpr float kPi = static_cast<float>(std::numbers::pi);
constexpr float kInf = std::numeric_limits<float>::infinity();
// Paths per wavefront: big enough for Embree streams, small enough to stay in cache.
constexpr size_t kWavePaths = 16384;
// Shadow rays towards sampled light points stop this fraction short (the lamp's own surface).
constexpr float kShadowShorten = 1e-3f;

std::string Str(double v) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%g", v);
  return buffer;
}

// v / |v| with one division (hot paths); (0, 0, 0) for a zero vector.
inline Vec3 Unit(Vec3 v) {
  const float n2 = Dot(v, v);
  return n2 > 0 ? v * (1 / std::sqrt(n2)) : Vec3{};
}

float Luminance(Vec3 c) { return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z; }
float MaxComponent(Vec3 c) { return std::max(c.x, std::max(c.y, c.z)); }
Vec3 ClampNonNegative(Vec3 v) {
  return {std::max(v.x, 0.0f), std::max(v.y, 0.0f), std::max(v.z, 0.0f)};
}
// Power heuristic (beta = 2) weight of the strategy with density a against one with density b.
float PowerHeuristic(float a, float b) {
  const float a2 = a * a, b2 = b * b;
  return a2 + b2 > 0 ? a2 / (a2 + b2) : 0.0f;
}

uint64_t Mix(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// The seed of one path: a hash of exactly these five numbers (the correlation contract).
uint64_t PathSeed(uint64_t seed, uint64_t frame_index, uint64_t a, uint64_t b, uint64_t s) {
  uint64_t h = Mix(seed ^ 0x5EED5EED5EED5EEDull);
  h = Mix(h ^ frame_index);
  h = Mix(h ^ a);
  h = Mix(h ^ (b * 0x2545F4914F6CDD1Dull));
  return Mix(h ^ (s * 0x9E6C63D0676A9A99ull));
}

// SplitMix64 stream of one path.
struct Rng {
  uint64_t state = 0;
  uint64_t Bits() {
    state += 0x9E3779B97F4A7C15ull;
    uint64_t z = state;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  // 24 bits to [0, 1), through int32: an unsigned 64-bit conversion costs a branchy sequence.
  static float Unit24(uint64_t bits) {
    return static_cast<float>(static_cast<int32_t>(bits)) * (1.0f / 16777216.0f);
  }
  // One uniform in [0, 1) (24 bits).
  float Next() { return Unit24(Bits() >> 40); }
  // Two uniforms in [0, 1) from one draw (24 bits each): half the hashing per dimension.
  void Next2(float* a, float* b) {
    const uint64_t z = Bits();
    *a = Unit24(z >> 40);
    *b = Unit24((z >> 8) & 0xFFFFFF);
  }
};

// A light prepared for sampling (world frame).
struct Light {
  enum class Kind { kDirectional, kDisc, kPoint, kRectangle, kSphere };
  Kind kind = Kind::kDirectional;
  Vec3 direction;                // directional / disc: unit, towards the light
  Vec3 power;                    // directional: irradiance; point: intensity; disc / area: radiance
  float cos_max = 1;             // disc: cos(angular radius)
  float sin_max = 0;             // disc: sin(angular radius)
  float solid_angle = 0;         // disc
  Vec3 position;                 // point position; rectangle / sphere centre
  Vec3 half_u, half_v;           // rectangle
  float inv_u2 = 0, inv_v2 = 0;  // rectangle: 1 / |half_u|^2, 1 / |half_v|^2
  Vec3 frame_t, frame_b;         // disc: tangents around `direction` (cone sampling)
  Vec3 normal;                   // rectangle: the emitting side
  float area = 0;                // rectangle
  float radius = 0;              // sphere radius; rectangle: bounding radius
  float luminance = 0;           // of `power`
  uint32_t id = 0;
};

// Where a ray meets an area light.
struct LightHit {
  int light = -1;  // index into the light list; -1 = none
  float t = kInf;
  bool front = false;
};

float OneMinusCos(float sin2, float cos) { return sin2 / (1 + cos); }

std::vector<Light> PrepareLights(const Scene& scene) {
  std::vector<Light> lights;
  for (const DirectionalLight& d : scene.directional_lights()) {
    if (!d.enabled) continue;
    if (!(d.angular_radius >= 0 && d.angular_radius < kPi / 2)) {
      throw RaytraceError("PathTrace: DirectionalLight::angular_radius must be in [0, pi/2), got " +
                          Str(d.angular_radius));
    }
    if (Length(d.direction) == 0)
      throw RaytraceError("PathTrace: DirectionalLight with zero direction");
    Light l;
    l.direction = Normalize(d.direction);
    l.luminance = Luminance(d.irradiance);
    if (d.angular_radius > 0) {
      l.kind = Light::Kind::kDisc;
      l.sin_max = std::sin(d.angular_radius);
      l.cos_max = std::cos(d.angular_radius);
      l.solid_angle = 2 * kPi * OneMinusCos(l.sin_max * l.sin_max, l.cos_max);
      // Radiance of a disc giving `irradiance` on a surface facing it.
      l.power = d.irradiance / (kPi * l.sin_max * l.sin_max);
      const internal::Frame3 f(l.direction);
      l.frame_t = f.t;
      l.frame_b = f.b;
    } else {
      l.power = d.irradiance;
    }
    if (l.luminance > 0) lights.push_back(l);
  }
  for (const PointLight& p : scene.point_lights()) {
    if (!p.enabled) continue;
    Light l;
    l.kind = Light::Kind::kPoint;
    l.position = p.position;
    l.power = p.intensity;
    l.luminance = Luminance(p.intensity);
    if (l.luminance > 0) lights.push_back(l);
  }
  const auto& areas = scene.area_lights();
  for (size_t i = 0; i < areas.size(); ++i) {
    const AreaLight& a = areas[i];
    if (!a.enabled) continue;
    const std::string what = "PathTrace: area light " + std::to_string(i) + ": ";
    if (!(a.radiance.x >= 0 && a.radiance.y >= 0 && a.radiance.z >= 0)) {
      throw RaytraceError(what + "radiance must be >= 0");
    }
    Light l;
    l.position = a.centre;
    l.power = a.radiance;
    l.luminance = Luminance(a.radiance);
    l.id = a.id;
    if (a.shape == AreaLight::Shape::kRectangle) {
      const Vec3 c = Cross(a.half_u, a.half_v);
      if (!(Length(c) > 0))
        throw RaytraceError(what + "half_u and half_v must span a non-zero area");
      l.kind = Light::Kind::kRectangle;
      l.half_u = a.half_u;
      l.half_v = a.half_v;
      l.inv_u2 = 1 / Dot(a.half_u, a.half_u);
      l.inv_v2 = 1 / Dot(a.half_v, a.half_v);
      l.normal = Normalize(c);
      l.area = 4 * Length(c);
      l.radius = Length(a.half_u + a.half_v);
      l.radius = std::max(l.radius, Length(a.half_u - a.half_v));
    } else {
      if (!(a.radius > 0)) throw RaytraceError(what + "radius must be > 0, got " + Str(a.radius));
      l.kind = Light::Kind::kSphere;
      l.radius = a.radius;
    }
    lights.push_back(l);  // kept even when black: it still occludes and is seen
  }
  return lights;
}

bool IsArea(const Light& l) {
  return l.kind == Light::Kind::kRectangle || l.kind == Light::Kind::kSphere;
}

// Ray parameter of the nearest hit of (o, d) with area light `l` in (t_min, t_max), or kInf.
[[gnu::always_inline]] inline float IntersectArea(const Light& l, Vec3 o, Vec3 d, float t_min,
                                                  float t_max, bool* front) {
  if (l.kind == Light::Kind::kRectangle) {
    const float denom = Dot(d, l.normal);
    if (denom == 0) return kInf;
    const float t = Dot(l.position - o, l.normal) / denom;
    if (!(t > t_min && t < t_max)) return kInf;
    const Vec3 q = o + d * t - l.position;
    const float s = Dot(q, l.half_u) * l.inv_u2;
    const float r = Dot(q, l.half_v) * l.inv_v2;
    if (std::abs(s) > 1 || std::abs(r) > 1) return kInf;
    *front = denom < 0;
    return t;
  }
  const Vec3 oc = o - l.position;
  const float a = Dot(d, d);
  const float b = Dot(oc, d);
  const float c = Dot(oc, oc) - l.radius * l.radius;
  const float disc = b * b - a * c;
  if (disc < 0) return kInf;
  const float root = std::sqrt(disc);
  const float t0 = (-b - root) / a;
  const float t1 = (-b + root) / a;
  const float t = t0 > t_min ? t0 : t1;
  if (!(t > t_min && t < t_max)) return kInf;
  *front = c > 0;  // from outside the first root is the outer surface
  return t;
}

// The nearest of the area lights `area` (indices into `lights`) along (o, d) before t_max.
LightHit NearestAreaLight(const std::vector<Light>& lights, const std::vector<int>& area, Vec3 o,
                          Vec3 d, float t_max) {
  LightHit best;
  best.t = t_max;
  for (const int i : area) {
    bool front = false;
    const float t = IntersectArea(lights[i], o, d, 0, best.t, &front);
    if (t < best.t) best = {i, t, front};
  }
  return best;
}

std::vector<int> AreaIndices(const std::vector<Light>& lights) {
  std::vector<int> area;
  for (size_t i = 0; i < lights.size(); ++i) {
    if (IsArea(lights[i])) area.push_back(static_cast<int>(i));
  }
  return area;
}

// The unshadowed-contribution estimate used to choose one light per vertex: > 0 wherever the light
// can contribute at (p, n), 0 only where it cannot (so the choice stays unbiased).
[[gnu::always_inline]] inline float Importance(const Light& l, Vec3 p, Vec3 n) {
  switch (l.kind) {
    case Light::Kind::kDirectional:
      return l.luminance * std::max(0.0f, Dot(n, l.direction));
    case Light::Kind::kDisc:
      return l.luminance * std::max(0.0f, Dot(n, l.direction) + l.sin_max);
    case Light::Kind::kPoint: {
      const Vec3 to = l.position - p;
      const float r2 = Dot(to, to);
      if (!(r2 > 0)) return 0;
      return l.luminance * std::max(0.0f, Dot(n, to)) / (r2 * std::sqrt(r2));
    }
    case Light::Kind::kRectangle: {
      const Vec3 to = l.position - p;
      const float side = -Dot(to, l.normal);  // > 0: p is on the emitting side
      if (!(side > 0)) return 0;
      const float d2 = Dot(to, to);
      const float inv_d = 1 / std::sqrt(d2);
      const float horizon = std::clamp((Dot(to, n) + l.radius) * inv_d, 0.0f, 1.0f);
      const float cos_l = std::max(side * inv_d, 0.1f);
      return l.luminance * l.area * cos_l * horizon / std::max(d2, l.area);
    }
    case Light::Kind::kSphere: {
      const Vec3 to = l.position - p;
      const float d2 = Dot(to, to);
      const float r2 = l.radius * l.radius;
      if (!(d2 > r2)) return 0;  // inside: only the unlit back faces are visible
      const float horizon = std::clamp((Dot(to, n) + l.radius) / std::sqrt(d2), 0.0f, 1.0f);
      return l.luminance * kPi * r2 * horizon / d2;
    }
  }
  return 0;
}

// Solid-angle density with which light `l` samples direction `w` from `p`, hitting it at
// distance t (area lights) — the light side of the MIS weights.
float LightPdf(const Light& l, Vec3 p, Vec3 w, float t) {
  switch (l.kind) {
    case Light::Kind::kDisc:
      return 1 / l.solid_angle;
    case Light::Kind::kRectangle: {
      const float cos_l = std::abs(Dot(w, l.normal));
      return cos_l > 0 ? t * t / (l.area * cos_l) : 0.0f;
    }
    case Light::Kind::kSphere: {
      const Vec3 to = l.position - p;
      const float d2 = Dot(to, to);
      const float sin2 = std::min(1.0f, l.radius * l.radius / d2);
      const float cos_max = std::sqrt(std::max(0.0f, 1 - sin2));
      return 1 / (2 * kPi * OneMinusCos(sin2, cos_max));
    }
    default:
      return 0;
  }
}

// Direction in the cone of half-angle acos(cos_max) around unit `axis` (with tangents t, b),
// uniform in solid angle.
Vec3 SampleCone(Vec3 axis, Vec3 t, Vec3 b, float sin2_max, float cos_max, float u1, float u2) {
  const float one_minus_cos = u1 * OneMinusCos(sin2_max, cos_max);
  const float cos_t = 1 - one_minus_cos;
  const float sin_t = std::sqrt(std::max(0.0f, one_minus_cos * (2 - one_minus_cos)));
  float sin_phi, cos_phi;
  internal::SinCos2Pi(u2, &sin_phi, &cos_phi);
  return Unit(t * (sin_t * cos_phi) + b * (sin_t * sin_phi) + axis * cos_t);
}

// One next-event sample: the shadow ray in Embree's layout (streamed with this struct's stride, so
// there is no conversion pass) and what it adds to its path when unoccluded.
struct alignas(16) ShadowRay {
  RTCRay ray;
  Vec3 contribution;
  uint32_t path = 0;
};

struct Path {
  Rng rng;
  Vec3 throughput{1, 1, 1};
  Vec3 radiance;
  Vec3 prev_origin;    // the previous vertex (shadow-ray origin), for MIS
  Vec3 prev_normal;    // its shading normal
  float prev_pdf = 0;  // solid-angle pdf of the BSDF draw of the current ray; 0 = camera
  // The sum of light importances at the previous vertex; -1 = all lights were sampled there.
  float prev_light_sum = 0;
  int depth = 0;       // surface vertices before the current ray
  bool final = false;  // the current ray only gathers emitted light (max_bounces reached)
};

// The wavefront buffers, one set per thread and reused between tasks: large fresh vectors would
// be mapped and page-faulted anew for every tile. The ray buffers only grow (no clearing pass).
struct TracerBuffers {
  std::vector<Path> paths;
  std::vector<uint32_t> active, next_active;
  std::vector<RTCRayHit> stream, next_stream;
  std::vector<ShadowRay> shadows;
  // The callers' per-task inputs and outputs.
  std::vector<Ray> start;
  std::vector<Rng> rngs;
  std::vector<Vec3> radiance;
};

TracerBuffers& ThreadBuffers() {
  static thread_local TracerBuffers buffers;
  return buffers;
}

// An Embree ray from o along d up to t_far (t_near 0, mask all, time 0).
inline void SetRay(RTCRay& r, Vec3 o, Vec3 d, float t_far) {
  r.org_x = o.x;
  r.org_y = o.y;
  r.org_z = o.z;
  r.tnear = 0;
  r.dir_x = d.x;
  r.dir_y = d.y;
  r.dir_z = d.z;
  r.time = 0;
  r.tfar = t_far;
  r.mask = 0xFFFFFFFFu;
  r.id = 0;
  r.flags = 0;
}

// The wavefront path tracer of one batch of paths (one thread; no shared mutable state).
class Tracer {
 public:
  Tracer(const Scene& scene, const PathTraceOptions& options, const std::vector<Light>& lights)
      : scene_(scene),
        handle_(internal::SceneAccess::Handle(scene)),
        options_(options),
        lights_(lights),
        area_(AreaIndices(lights)),
        importance_(lights.size()),
        has_emission_(internal::SceneAccess::HasEmission(scene)),
        has_disc_(std::any_of(lights.begin(), lights.end(),
                              [](const Light& l) { return l.kind == Light::Kind::kDisc; })),
        b_(ThreadBuffers()),
        paths_(b_.paths),
        active_(b_.active),
        next_active_(b_.next_active),
        stream_(b_.stream),
        next_stream_(b_.next_stream),
        shadows_(b_.shadows) {}

  // Traces the paths starting with `start` (unit directions), each with its own random stream;
  // radiance per path into `out` (same order). Returns the number of rays traced.
  uint64_t Trace(const std::vector<Ray>& start, const std::vector<Rng>& rngs,
                 std::vector<Vec3>& out) {
    const size_t n = start.size();
    paths_.assign(n, Path{});
    for (size_t i = 0; i < n; ++i) paths_[i].rng = rngs[i];
    active_.resize(n);
    for (size_t i = 0; i < n; ++i) active_[i] = static_cast<uint32_t>(i);
    // Each path queues at most one ray and (one light, or all of them) + 1 shadow rays per wave.
    if (stream_.size() < n) stream_.resize(n);
    if (next_stream_.size() < n) next_stream_.resize(n);
    const size_t shadows_per_path = options_.all_lights ? lights_.size() + 1 : 2;
    if (shadows_.size() < n * shadows_per_path) shadows_.resize(n * shadows_per_path);
    for (size_t k = 0; k < n; ++k) internal::ToEmbree(start[k], stream_[k].ray);
    uint64_t traced = 0;
    bool coherent = true;  // the first wave: camera rays of neighbouring pixels
    while (!active_.empty()) {
      const size_t count = active_.size();
      internal::IntersectStream(handle_, stream_.data(), count, coherent);
      coherent = false;
      traced += count;
      shadow_count_ = 0;
      next_active_.clear();
      for (size_t k = 0; k < count; ++k) Shade(active_[k], stream_[k]);
      if (shadow_count_ > 0) {
        internal::OccludedStream(handle_, &shadows_[0].ray, shadow_count_, sizeof(ShadowRay));
        traced += shadow_count_;
        for (size_t i = 0; i < shadow_count_; ++i) {
          const ShadowRay& s = shadows_[i];
          const bool occluded = std::isinf(s.ray.tfar) && s.ray.tfar < 0;
          if (!occluded) paths_[s.path].radiance += s.contribution;
        }
      }
      std::swap(active_, next_active_);
      std::swap(stream_, next_stream_);
    }
    out.resize(n);
    for (size_t i = 0; i < n; ++i) {
      const Vec3 r = paths_[i].radiance;
      // One numerically broken path must not poison a pixel: it counts as black.
      out[i] = std::isfinite(r.x + r.y + r.z) ? r : Vec3{};
    }
    return traced;
  }

 private:
  // Does an area light other than `skip` cross the segment o + t d, t in (0, t_far)?
  bool BlockedByAreaLight(int skip, Vec3 o, Vec3 d, float t_far) const {
    for (const int i : area_) {
      if (i == skip) continue;
      bool front = false;
      if (IntersectArea(lights_[i], o, d, 0, t_far, &front) < kInf) return true;
    }
    return false;
  }

  // Queues a shadow ray (o, d, up to t_far) adding `contribution` to path `index` if unoccluded,
  // unless an area light other than `skip` (analytic, not in the BVH) already blocks it; skip = -2:
  // the ray was already tested against all area lights.
  void PushShadow(Vec3 o, Vec3 d, float t_far, Vec3 contribution, uint32_t index, int skip) {
    if (skip != -2 && BlockedByAreaLight(skip, o, d, t_far)) return;
    ShadowRay& s = shadows_[shadow_count_++];
    SetRay(s.ray, o, d, t_far);
    s.contribution = contribution;
    s.path = index;
  }

  // MIS weight of a BSDF-sampled ray reaching light `l` at distance t.
  float BsdfSideWeight(const Path& p, int l, Vec3 w, float t) const {
    if (p.prev_pdf <= 0 || p.prev_light_sum == 0) return 1;  // camera ray / no light strategy
    const float importance = Importance(lights_[l], p.prev_origin, p.prev_normal);
    const float select =
        p.prev_light_sum < 0 ? (importance > 0 ? 1.0f : 0.0f) : importance / p.prev_light_sum;
    return PowerHeuristic(p.prev_pdf, select * LightPdf(lights_[l], p.prev_origin, w, t));
  }

  // Radiance of the environment and the sun discs along an escaping ray d, with the BSDF-side MIS
  // weights of the discs.
  Vec3 Sky(const Path& p, Vec3 d) const {
    Vec3 l;
    const Environment& env = scene_.environment();
    if (env.scale != 0) l = ClampNonNegative(internal::EvaluateSh9(env.sh, d)) * env.scale;
    if (has_disc_) {
      for (size_t i = 0; i < lights_.size(); ++i) {
        const Light& disc = lights_[i];
        if (disc.kind == Light::Kind::kDisc && Dot(d, disc.direction) >= disc.cos_max) {
          l += disc.power * BsdfSideWeight(p, static_cast<int>(i), d, kInf);
        }
      }
    }
    return l;
  }

  // Radiance (before the path throughput) that the ray (o, d) receives from an area light before
  // t_geom or, when it escapes (t_geom = inf), from the environment and the sun discs, with the
  // BSDF-side MIS weights. *absorbed: the ray ended on an area light (front or back).
  Vec3 Emitted(const Path& p, Vec3 o, Vec3 d, float t_geom, float* t_light, bool* absorbed) const {
    const LightHit lh = NearestAreaLight(lights_, area_, o, d, t_geom);
    *t_light = lh.t;
    if (lh.light >= 0) {
      *absorbed = true;
      if (!lh.front) return {};  // an emitter's back is black
      return lights_[lh.light].power * BsdfSideWeight(p, lh.light, d, lh.t);
    }
    *absorbed = false;
    if (t_geom < kInf) return {};
    return Sky(p, d);
  }

  void Shade(uint32_t index, const RTCRayHit& rh) {
    Path& p = paths_[index];
    const Vec3 ray_origin{rh.ray.org_x, rh.ray.org_y, rh.ray.org_z};
    const Vec3 ray_direction{rh.ray.dir_x, rh.ray.dir_y, rh.ray.dir_z};
    const bool miss = rh.hit.geomID == RTC_INVALID_GEOMETRY_ID;
    float t_light = kInf;
    bool absorbed = false;
    const Vec3 e =
        Emitted(p, ray_origin, ray_direction, miss ? kInf : rh.ray.tfar, &t_light, &absorbed);
    p.radiance += p.throughput * e;
    if (miss || absorbed) return;
    Hit hit;
    hit.object = internal::SceneAccess::ObjectOfInstance(scene_, rh.hit.instID[0]);
    hit.triangle = rh.hit.primID;
    hit.t = rh.ray.tfar;
    hit.u = rh.hit.u;
    hit.v = rh.hit.v;
    const SurfacePoint s = internal::SceneAccess::Surface(scene_, hit, ray_origin, ray_direction);
    const Material& m = *s.material;
    if (m.emission.x > 0 || m.emission.y > 0 || m.emission.z > 0) {
      p.radiance += p.throughput * m.emission;
    }
    // A degenerate (zero-area) triangle has no normal to shade with: the path ends there.
    if (p.final || Dot(s.geometric_normal, s.geometric_normal) == 0) return;
    const Vec3 wo = -ray_direction;
    // Interpolated normals can face away from the viewer at silhouettes: fall back to the facet.
    const Vec3 n = Dot(s.normal, wo) > 1e-4f ? s.normal : s.geometric_normal;
    const internal::Bsdf bsdf(s.albedo, m.specular_f0, m.roughness, n, wo);
    const Vec3 origin = s.position + s.geometric_normal * options_.ray_epsilon;
    // A fixed count of uniforms per vertex keeps the stream's dimensions aligned between paths.
    float u[8];
    for (int k = 0; k < 8; k += 2) p.rng.Next2(&u[k], &u[k + 1]);
    float light_sum = 0;
    for (size_t i = 0; i < lights_.size(); ++i) {
      importance_[i] = Importance(lights_[i], origin, n);
      light_sum += importance_[i];
    }
    if (light_sum > 0 && options_.all_lights) {
      for (size_t i = 0; i < lights_.size(); ++i) {
        if (importance_[i] > 0) SampleLight(index, p, bsdf, origin, s.geometric_normal, i, 1, u);
      }
      light_sum = -1;  // tells BsdfSideWeight that every light was sampled with probability 1
    } else if (light_sum > 0) {
      // Choose one light by its importance (CDF walk over a handful of lights).
      const float target = u[0] * light_sum;
      size_t chosen = 0;
      float cumulative = 0;
      for (size_t i = 0; i < lights_.size(); ++i) {
        if (importance_[i] <= 0) continue;
        chosen = i;
        cumulative += importance_[i];
        if (target < cumulative) break;
      }
      SampleLight(index, p, bsdf, origin, s.geometric_normal, chosen,
                  importance_[chosen] / light_sum, u);
    }

    Vec3 wi, weight;
    float pdf = 0;
    if (!bsdf.Sample(u[3], u[4], u[5], &wi, &weight, &pdf)) return;
    if (Dot(wi, s.geometric_normal) <= 0) return;  // below the facet: would leak light
    const int vertex = p.depth;
    p.throughput = p.throughput * weight;
    p.depth += 1;
    p.final = p.depth > options_.max_bounces;
    if (vertex >= options_.russian_roulette_after) {
      const float q = std::min(1.0f, MaxComponent(p.throughput));
      if (!(u[6] < q)) return;
      p.throughput = p.throughput / q;
    } else if (!(MaxComponent(p.throughput) > 0)) {
      return;
    }
    p.prev_origin = origin;
    p.prev_normal = n;
    p.prev_pdf = pdf;
    p.prev_light_sum = light_sum;
    if (p.final && !has_emission_) {
      // The last ray only gathers emitters: without emissive surfaces an occlusion query
      // (up to the nearest area light, or unbounded towards the sky) is enough.
      float t_final = kInf;
      bool absorbed_final = false;
      const Vec3 ef = Emitted(p, origin, wi, kInf, &t_final, &absorbed_final);
      if (MaxComponent(ef) > 0) {
        PushShadow(origin, wi, t_final < kInf ? t_final : 1e30f, p.throughput * ef, index, -2);
      }
      return;
    }
    SetRay(next_stream_[next_active_.size()].ray, origin, wi, 1e30f);
    next_active_.push_back(index);
  }

  // Adds the shadow ray of light `chosen`, picked with probability `select`, to the stream.
  void SampleLight(uint32_t index, const Path& p, const internal::Bsdf& bsdf, Vec3 origin, Vec3 ng,
                   size_t chosen, float select, const float* u) {
    const Light& l = lights_[chosen];
    Vec3 wi;
    Vec3 incident;        // radiance (area, disc) or irradiance (delta) along wi
    float light_pdf = 0;  // solid angle; 0 = delta light
    Vec3 direction;       // of the shadow ray (not unit for point and rectangle lights)
    float t_far = 1e30f;
    switch (l.kind) {
      case Light::Kind::kDirectional:
        wi = l.direction;
        incident = l.power;
        direction = wi;
        break;
      case Light::Kind::kDisc:
        wi = SampleCone(l.direction, l.frame_t, l.frame_b, l.sin_max * l.sin_max, l.cos_max, u[1],
                        u[2]);
        incident = l.power;
        light_pdf = 1 / l.solid_angle;
        direction = wi;
        break;
      case Light::Kind::kPoint: {
        const Vec3 to = l.position - origin;
        const float r2 = Dot(to, to);
        const float inv_r2 = 1 / r2;
        wi = to * std::sqrt(inv_r2);
        incident = l.power * inv_r2;
        direction = to;
        t_far = 1 - 1e-4f;
        break;
      }
      case Light::Kind::kRectangle: {
        const Vec3 y = l.position + l.half_u * (2 * u[1] - 1) + l.half_v * (2 * u[2] - 1);
        const Vec3 to = y - origin;
        const float d2 = Dot(to, to);
        const float d = std::sqrt(d2);
        wi = to * (1 / d);
        const float cos_l = -Dot(wi, l.normal);
        if (!(cos_l > 0)) return;
        incident = l.power;
        light_pdf = d2 / (l.area * cos_l);
        direction = to;
        t_far = 1 - kShadowShorten;
        break;
      }
      case Light::Kind::kSphere: {
        const Vec3 to = l.position - origin;
        const float d2 = Dot(to, to);
        const float sin2 = l.radius * l.radius / d2;
        if (!(sin2 < 1)) return;
        const float cos_max = std::sqrt(1 - sin2);
        const float d = std::sqrt(d2);
        const Vec3 axis = to * (1 / d);
        const internal::Frame3 f(axis);
        wi = SampleCone(axis, f.t, f.b, sin2, cos_max, u[1], u[2]);
        bool front = false;
        float t = IntersectArea(l, origin, wi, 0, kInf, &front);
        if (!(t < kInf)) t = d * cos_max;  // grazing the silhouette: the tangent point
        incident = l.power;
        light_pdf = 1 / (2 * kPi * OneMinusCos(sin2, cos_max));
        direction = wi;
        t_far = t * (1 - kShadowShorten);
        break;
      }
    }
    if (Dot(wi, ng) <= 0) return;
    float bsdf_pdf = 0;
    const Vec3 f = bsdf.Eval(wi, &bsdf_pdf);
    if (!(MaxComponent(f) > 0)) return;
    float weight = 1 / select;
    if (light_pdf > 0) {
      weight = PowerHeuristic(select * light_pdf, bsdf_pdf) / (select * light_pdf);
    }
    PushShadow(origin, direction, t_far, p.throughput * f * incident * weight, index,
               IsArea(l) ? static_cast<int>(chosen) : -1);
  }

  const Scene& scene_;
  RTCScene handle_;
  const PathTraceOptions& options_;
  const std::vector<Light>& lights_;
  const std::vector<int> area_;  // indices of the area lights in lights_
  std::vector<float> importance_;
  bool has_emission_ = false;
  bool has_disc_ = false;
  TracerBuffers& b_;
  std::vector<Path>& paths_;
  std::vector<uint32_t>& active_;
  std::vector<uint32_t>& next_active_;
  std::vector<RTCRayHit>& stream_;       // this wave's rays (the first active_.size())
  std::vector<RTCRayHit>& next_stream_;  // the next wave's, in next_active_ order
  std::vector<ShadowRay>& shadows_;      // this wave's shadow rays (the first shadow_count_)
  size_t shadow_count_ = 0;
};

// Runs fn(task) for every task on `pool` in one dynamic ParallelFor (no barriers between groups:
// they would idle a thread on every uneven group); `on_caller` runs on the calling thread after
// each of its own tasks.
void RunTasks(size_t tasks, ThreadPool* pool, const std::function<void(size_t)>& fn,
              const std::function<void()>& on_caller) {
  const std::thread::id caller = std::this_thread::get_id();
  parallel::ParallelFor(pool, tasks, [&](size_t t) {
    fn(t);
    if (on_caller && std::this_thread::get_id() == caller) on_caller();
  });
}

}  // namespace

void PathTraceOptions::Validate() const {
  const std::string what = "PathTraceOptions: ";
  if (samples_per_pixel < 1) {
    throw RaytraceError(what + "samples_per_pixel must be >= 1, got " +
                        std::to_string(samples_per_pixel));
  }
  if (max_bounces < 0) {
    throw RaytraceError(what + "max_bounces must be >= 0, got " + std::to_string(max_bounces));
  }
  if (russian_roulette_after < 0) {
    throw RaytraceError(what + "russian_roulette_after must be >= 0, got " +
                        std::to_string(russian_roulette_after));
  }
  if (!(exposure >= 0) || !std::isfinite(exposure)) {
    throw RaytraceError(what + "exposure must be finite and >= 0, got " + Str(exposure));
  }
  if (rows_per_task < 1) {
    throw RaytraceError(what + "rows_per_task must be >= 1, got " + std::to_string(rows_per_task));
  }
  if (!(ray_epsilon >= 0)) {
    throw RaytraceError(what + "ray_epsilon must be >= 0, got " + Str(ray_epsilon));
  }
}

Frame PathTrace(const Scene& scene, const Camera& camera, const PathTraceOptions& options,
                ThreadPool* pool) {
  camera.Validate();
  options.Validate();
  internal::SceneAccess::CheckCommitted(scene, "PathTrace");
  const std::vector<Light> lights = PrepareLights(scene);
  const std::vector<int> area = AreaIndices(lights);
  Frame frame = internal::EmptyFrame(camera.width, camera.height);
  const int rows = options.rows_per_task;
  const size_t tasks = (static_cast<size_t>(camera.height) + rows - 1) / rows;
  std::vector<uint64_t> rays_per_task(tasks, 0);
  const Mat3& rot = camera.camera_to_world.rotation;
  const Mat3 world_to_camera = rot.Transposed();
  const Vec3 eye{static_cast<float>(camera.camera_to_world.translation[0]),
                 static_cast<float>(camera.camera_to_world.translation[1]),
                 static_cast<float>(camera.camera_to_world.translation[2])};
  const int spp = options.samples_per_pixel;

  auto task = [&](size_t t) {
    const int y0 = static_cast<int>(t) * rows;
    const int y1 = std::min(camera.height, y0 + rows);
    const size_t first = static_cast<size_t>(y0) * camera.width;
    const size_t n = static_cast<size_t>(y1 - y0) * camera.width;
    uint64_t traced = 0;

    // The pixel-centre rays: depth, normals and ids exactly as Render defines them.
    std::vector<Ray> centre;
    internal::PixelCentreRays(camera, eye, y0, y1, centre);
    std::vector<Hit> hits(n);
    scene.Intersect(centre, hits);
    traced += n;
    for (size_t i = 0; i < n; ++i) {
      const size_t p = first + i;
      const LightHit lh = NearestAreaLight(lights, area, centre[i].origin, centre[i].direction,
                                           hits[i].object >= 0 ? hits[i].t : kInf);
      Vec3 normal;
      float z = 0;
      uint32_t id = 0;
      if (lh.light >= 0) {
        const Light& l = lights[lh.light];
        const Vec3 q = centre[i].origin + centre[i].direction * lh.t;
        normal = l.kind == Light::Kind::kRectangle ? l.normal : Normalize(q - l.position);
        if (Dot(normal, centre[i].direction) > 0) normal = -normal;
        z = lh.t;  // the camera-frame direction has z = 1
        id = l.id;
      } else if (hits[i].object >= 0) {
        const SurfacePoint s = scene.Surface(centre[i], hits[i]);
        normal = s.normal;
        z = hits[i].t;
        id = s.object_id;
        for (int c = 0; c < 3; ++c) frame.albedo[3 * p + c] = s.albedo[c];
      } else {
        continue;
      }
      frame.depth_m[p] = z;
      const double mm = std::round(static_cast<double>(z) * 1000);
      frame.depth_mm[p] = mm >= 1 && mm <= 65535 ? static_cast<uint16_t>(mm) : 0;
      const Vec3 n_cam = world_to_camera * normal;
      frame.normals[3 * p] = n_cam.x;
      frame.normals[3 * p + 1] = n_cam.y;
      frame.normals[3 * p + 2] = n_cam.z;
      frame.object_ids[p] = id;
    }

    // The paths, a wave of whole samples of every pixel of the tile at a time.
    Tracer tracer(scene, options, lights);
    const int batch = static_cast<int>(std::max<size_t>(1, kWavePaths / n));
    std::vector<Vec3> sum(n);
    std::vector<Ray>& start = ThreadBuffers().start;
    std::vector<Rng>& rngs = ThreadBuffers().rngs;
    std::vector<Vec3>& radiance = ThreadBuffers().radiance;
    for (int s0 = 0; s0 < spp; s0 += batch) {
      const int s1 = std::min(spp, s0 + batch);
      start.clear();
      rngs.clear();
      for (int s = s0; s < s1; ++s) {
        for (int y = y0; y < y1; ++y) {
          for (int x = 0; x < camera.width; ++x) {
            Rng rng{PathSeed(options.seed, options.frame_index, static_cast<uint64_t>(x),
                             static_cast<uint64_t>(y), static_cast<uint64_t>(s))};
            float jx, jy;
            rng.Next2(&jx, &jy);
            jx -= 0.5f;
            jy -= 0.5f;
            const Vec3 d_cam{static_cast<float>((x + jx - camera.cx) / camera.fx),
                             static_cast<float>((y + jy - camera.cy) / camera.fy), 1.0f};
            start.push_back(Ray{eye, Normalize(rot * d_cam), 0, 1e30f});
            rngs.push_back(rng);
          }
        }
      }
      traced += tracer.Trace(start, rngs, radiance);
      // The wave holds whole samples of the tile, pixel order within each (no division per path).
      for (size_t k = 0; k < radiance.size(); k += n) {
        for (size_t i = 0; i < n; ++i) sum[i] += radiance[k + i];
      }
    }
    const float scale = options.exposure / static_cast<float>(spp);
    for (size_t i = 0; i < n; ++i) {
      const size_t p = first + i;
      for (int c = 0; c < 3; ++c) {
        frame.linear_rgb[3 * p + c] = sum[i][c] * scale;
        frame.srgb[3 * p + c] = LinearToSrgb8(sum[i][c] * scale);
      }
    }
    rays_per_task[t] = traced;
  };
  std::atomic<int> rows_done{0};
  int reported = 0;
  std::function<void()> report;
  if (options.progress) {
    report = [&] {
      const int done = rows_done.load();
      if (done > reported) options.progress(reported = done, camera.height);
    };
  }
  RunTasks(
      tasks, pool,
      [&](size_t t) {
        task(t);
        rows_done +=
            std::min(camera.height, (static_cast<int>(t) + 1) * rows) - static_cast<int>(t) * rows;
      },
      report);
  if (report) report();  // the rows the other threads finished last
  for (uint64_t r : rays_per_task) frame.rays += r;
  return frame;
}

std::array<Vec3, 9> IncidentRadianceSh(const Scene& scene, Vec3 point, int directions,
                                       const PathTraceOptions& options, ThreadPool* pool) {
  options.Validate();
  internal::SceneAccess::CheckCommitted(scene, "IncidentRadianceSh");
  if (directions < 1) {
    throw RaytraceError("IncidentRadianceSh: directions must be >= 1, got " +
                        std::to_string(directions));
  }
  const std::vector<Light> lights = PrepareLights(scene);
  const size_t count = static_cast<size_t>(directions);
  const size_t per_task = 4096;
  const size_t tasks = (count + per_task - 1) / per_task;
  std::vector<std::array<Vec3, 9>> partial(tasks);
  // One global shift of the azimuth sequence (Cranley-Patterson) keeps it stratified.
  Rng shift{PathSeed(options.seed, options.frame_index, 0xD1EC7105ull, 0, 0)};
  const float azimuth_shift = shift.Next();
  constexpr double kGolden = 0.6180339887498949;
  auto task = [&](size_t t) {
    const size_t begin = t * per_task;
    const size_t end = std::min(count, begin + per_task);
    std::vector<Ray>& start = ThreadBuffers().start;
    std::vector<Rng>& rngs = ThreadBuffers().rngs;
    start.clear();
    rngs.clear();
    std::vector<Vec3> dirs;
    for (size_t k = begin; k < end; ++k) {
      Rng rng{PathSeed(options.seed, options.frame_index, 0xD1EC7105ull, k, 1)};
      // Equal-area map of (u, v): z = 1 - 2u stratified in N slabs, azimuth by the golden ratio.
      const double u = (static_cast<double>(k) + rng.Next()) / static_cast<double>(count);
      double v = static_cast<double>(k) * kGolden + azimuth_shift;
      v -= std::floor(v);
      const double z = 1 - 2 * u;
      const double r = std::sqrt(std::max(0.0, 1 - z * z));
      const double phi = 2 * std::numbers::pi * v;
      const Vec3 w{static_cast<float>(r * std::cos(phi)), static_cast<float>(r * std::sin(phi)),
                   static_cast<float>(z)};
      dirs.push_back(w);
      start.push_back(Ray{point, w, 0, 1e30f});
      rngs.push_back(rng);
    }
    Tracer tracer(scene, options, lights);
    std::vector<Vec3>& radiance = ThreadBuffers().radiance;
    tracer.Trace(start, rngs, radiance);
    std::array<Vec3, 9> sh{};
    for (size_t i = 0; i < dirs.size(); ++i) {
      const std::array<float, 9> y = ShBasis9(dirs[i]);
      for (int c = 0; c < 9; ++c) sh[c] += radiance[i] * y[c];
    }
    partial[t] = sh;
  };
  RunTasks(tasks, pool, task, nullptr);
  std::array<Vec3, 9> out{};
  const float weight = 4 * kPi / static_cast<float>(count) * options.exposure;
  for (const auto& p : partial) {
    for (int c = 0; c < 9; ++c) out[c] += p[c] * weight;
  }
  return out;
}

Vec3 BlackbodyRgb(double kelvin) {
  if (!(kelvin >= 1000 && kelvin <= 40000)) {
    throw RaytraceError("BlackbodyRgb: kelvin must be in [1000, 40000], got " + Str(kelvin));
  }
  // CIE 1931 2-degree matching functions as the multi-lobe Gaussian fit of Wyman, Sloan and
  // Shirley (JCGT 2013): accurate to a few 0.1 % of the tabulated functions, no table needed.
  auto lobe = [](double l, double mu, double s1, double s2) {
    const double t = (l - mu) / (l < mu ? s1 : s2);
    return std::exp(-0.5 * t * t);
  };
  double x = 0, y = 0, z = 0;
  constexpr double kC2 = 1.4387769e-2;  // m K, second radiation constant
  for (int nm = 360; nm <= 830; ++nm) {
    const double l = nm;
    const double lm = l * 1e-9;
    const double planck = 1 / (lm * lm * lm * lm * lm * (std::exp(kC2 / (lm * kelvin)) - 1));
    x += planck * (1.056 * lobe(l, 599.8, 37.9, 31.0) + 0.362 * lobe(l, 442.0, 16.0, 26.7) -
                   0.065 * lobe(l, 501.1, 20.4, 26.2));
    y += planck * (0.821 * lobe(l, 568.8, 46.9, 40.5) + 0.286 * lobe(l, 530.9, 16.3, 31.1));
    z += planck * (1.217 * lobe(l, 437.0, 11.8, 36.0) + 0.681 * lobe(l, 459.0, 26.0, 13.8));
  }
  // XYZ -> linear Rec. 709 (D65).
  Vec3 rgb{static_cast<float>(3.2404542 * x - 1.5371385 * y - 0.4985314 * z),
           static_cast<float>(-0.9692660 * x + 1.8760108 * y + 0.0415560 * z),
           static_cast<float>(0.0556434 * x - 0.2040259 * y + 1.0572252 * z)};
  rgb = ClampNonNegative(rgb);
  return rgb / Luminance(rgb);
}

}  // namespace probeless::raytrace
