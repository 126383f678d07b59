#include "probeless/raytrace/render.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "frame_buffers.h"
#include "sh_basis.h"

namespace probeless::raytrace {
namespace {

constexpr float kInvPi = static_cast<float>(1 / std::numbers::pi);

float SrgbEncode(double linear) {
  linear = std::clamp(linear, 0.0, 1.0);
  return static_cast<float>(linear <= 0.0031308 ? 12.92 * linear
                                                : 1.055 * std::pow(linear, 1 / 2.4) - 0.055);
}

uint64_t SplitMix64(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

float Uniform(uint64_t& state) {
  state = SplitMix64(state);
  return static_cast<float>(state >> 40) * (1.0f / 16777216.0f);
}

Vec3 ClampNonNegative(Vec3 v) {
  return {std::max(v.x, 0.0f), std::max(v.y, 0.0f), std::max(v.z, 0.0f)};
}

// A shadow ray and the radiance it carries to its surface point when unoccluded.
struct LightSample {
  size_t point = 0;  // index of the receiving point
  Vec3 radiance;     // outgoing radiance contribution towards the viewer
};

// Appends the shadow rays of every enabled light that faces `s` (viewed from direction `to_eye`).
void CollectLights(const Scene& scene, const SurfacePoint& s, Vec3 to_eye, size_t point,
                   float epsilon, std::vector<Ray>& rays, std::vector<LightSample>& samples) {
  const Vec3 origin = s.position + s.geometric_normal * epsilon;
  auto add = [&](Vec3 to_light_unit, Vec3 irradiance, Vec3 ray_dir, float t_far) {
    const float cos_theta = Dot(s.normal, to_light_unit);
    if (cos_theta <= 0 || Dot(s.geometric_normal, to_light_unit) <= 0) return;
    Vec3 brdf = s.albedo * kInvPi;
    const Material& m = *s.material;
    if (m.specular > 0) {
      const Vec3 h = Normalize(to_light_unit + to_eye);
      const float n_h = std::max(0.0f, Dot(s.normal, h));
      const float lobe = m.specular * (m.shininess + 8) /
                         (8 * static_cast<float>(std::numbers::pi)) * std::pow(n_h, m.shininess);
      brdf += Vec3{lobe, lobe, lobe};
    }
    rays.push_back(Ray{origin, ray_dir, 0, t_far});
    samples.push_back({point, brdf * irradiance * cos_theta});
  };
  for (const DirectionalLight& l : scene.directional_lights()) {
    if (!l.enabled) continue;
    const Vec3 d = Normalize(l.direction);
    add(d, l.irradiance, d, 1e30f);
  }
  for (const PointLight& l : scene.point_lights()) {
    if (!l.enabled) continue;
    const Vec3 to = l.position - origin;
    const float r2 = Dot(to, to);
    if (r2 <= 0) continue;
    add(to / std::sqrt(r2), l.intensity / r2, to, 1 - 1e-4f);
  }
}

// Outgoing radiance from the environment's (unshadowed) irradiance at `s`.
Vec3 EnvironmentShading(const Environment& env, const SurfacePoint& s) {
  if (env.scale == 0) return {};
  const Vec3 e = ClampNonNegative(internal::ShIrradiance(env.sh, s.normal)) * env.scale;
  return s.albedo * kInvPi * e;
}

// Resolves shadow rays: adds each visible sample's radiance to out[point].
void ResolveLights(const Scene& scene, const std::vector<Ray>& rays,
                   const std::vector<LightSample>& samples, bool shadows,
                   std::vector<uint8_t>& visible, std::vector<Vec3>& out) {
  visible.assign(rays.size(), 1);
  if (shadows && !rays.empty()) scene.Occluded(rays, visible);
  for (size_t i = 0; i < samples.size(); ++i) {
    if (visible[i]) out[samples[i].point] += samples[i].radiance;
  }
}

}  // namespace

uint8_t LinearToSrgb8(float linear) {
  static const std::vector<uint8_t> lut = [] {
    std::vector<uint8_t> t(16385);
    for (size_t i = 0; i < t.size(); ++i) {
      t[i] = static_cast<uint8_t>(std::lround(SrgbEncode(static_cast<double>(i) / 16384) * 255));
    }
    return t;
  }();
  if (!(linear > 0)) return 0;
  if (linear >= 1) return 255;
  return lut[static_cast<size_t>(linear * 16384 + 0.5f)];
}

float Srgb8ToLinear(uint8_t srgb) {
  static const std::array<float, 256> lut = [] {
    std::array<float, 256> t{};
    for (int i = 0; i < 256; ++i) {
      const double c = i / 255.0;
      t[i] = static_cast<float>(c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4));
    }
    return t;
  }();
  return lut[srgb];
}

void Camera::Validate() const {
  if (width < 1 || height < 1) {
    throw RaytraceError("Camera: width and height must be >= 1, got " + std::to_string(width) +
                        "x" + std::to_string(height));
  }
  if (!(fx > 0) || !(fy > 0)) throw RaytraceError("Camera: fx and fy must be > 0");
}

Frame Render(const Scene& scene, const Camera& camera, const RenderOptions& options,
             ThreadPool* pool) {
  camera.Validate();
  if (options.bounce_samples < 1) throw RaytraceError("RenderOptions: bounce_samples must be >= 1");
  if (options.rows_per_task < 1) throw RaytraceError("RenderOptions: rows_per_task must be >= 1");
  Frame frame = internal::EmptyFrame(camera.width, camera.height);
  const int rows = options.rows_per_task;
  const size_t tasks = (static_cast<size_t>(camera.height) + rows - 1) / rows;
  std::vector<uint64_t> rays_per_task(tasks, 0);
  const Mat3& rot = camera.camera_to_world.rotation;
  const Mat3 world_to_camera = rot.Transposed();
  const Vec3 eye{static_cast<float>(camera.camera_to_world.translation[0]),
                 static_cast<float>(camera.camera_to_world.translation[1]),
                 static_cast<float>(camera.camera_to_world.translation[2])};
  const Environment& env = scene.environment();

  auto task = [&](size_t t) {
    const int y0 = static_cast<int>(t) * rows;
    const int y1 = std::min(camera.height, y0 + rows);
    const size_t first = static_cast<size_t>(y0) * camera.width;
    const size_t n = static_cast<size_t>(y1 - y0) * camera.width;
    std::vector<Ray> primary;
    internal::PixelCentreRays(camera, eye, y0, y1, primary);
    std::vector<Hit> hits(n);
    scene.Intersect(primary, hits);
    uint64_t ray_count = n;
    std::vector<SurfacePoint> surfaces(n);
    std::vector<Vec3> radiance(n);
    std::vector<Ray> shadow_rays;
    std::vector<LightSample> samples;
    std::vector<uint8_t> visible;
    for (size_t i = 0; i < n; ++i) {
      const size_t p = first + i;
      if (hits[i].object < 0) {
        if (env.scale != 0) {
          radiance[i] =
              ClampNonNegative(internal::EvaluateSh9(env.sh, Normalize(primary[i].direction))) *
              env.scale;
        }
        continue;
      }
      const SurfacePoint s = scene.Surface(primary[i], hits[i]);
      surfaces[i] = s;
      // The camera-frame z of the hit is t: the camera-frame direction has z = 1.
      frame.depth_m[p] = hits[i].t;
      const double mm = std::round(static_cast<double>(hits[i].t) * 1000);
      frame.depth_mm[p] = mm >= 1 && mm <= 65535 ? static_cast<uint16_t>(mm) : 0;
      const Vec3 n_cam = world_to_camera * s.normal;
      frame.normals[3 * p] = n_cam.x;
      frame.normals[3 * p + 1] = n_cam.y;
      frame.normals[3 * p + 2] = n_cam.z;
      frame.object_ids[p] = s.object_id;
      for (int c = 0; c < 3; ++c) frame.albedo[3 * p + c] = s.albedo[c];
      radiance[i] = EnvironmentShading(env, s);
      CollectLights(scene, s, Normalize(-primary[i].direction), i, options.ray_epsilon, shadow_rays,
                    samples);
    }
    ResolveLights(scene, shadow_rays, samples, options.shadows, visible, radiance);
    if (options.shadows) ray_count += shadow_rays.size();

    if (options.diffuse_bounce) {
      const int spp = options.bounce_samples;
      std::vector<Ray> bounce;
      std::vector<size_t> owner;
      for (size_t i = 0; i < n; ++i) {
        if (hits[i].object < 0) continue;
        const SurfacePoint& s = surfaces[i];
        const Vec3 nrm = s.normal;
        const Vec3 helper = std::abs(nrm.x) > 0.5f ? Vec3{0, 1, 0} : Vec3{1, 0, 0};
        const Vec3 tx = Normalize(Cross(helper, nrm));
        const Vec3 ty = Cross(nrm, tx);
        uint64_t state = SplitMix64(options.seed ^ SplitMix64(options.frame_index + 0x51ED) ^
                                    SplitMix64((first + i) * 0x2545F4914F6CDD1Dull));
        for (int k = 0; k < spp; ++k) {
          const float r1 = Uniform(state);
          const float r2 = Uniform(state);
          const float r = std::sqrt(r1);
          const float phi = 2 * static_cast<float>(std::numbers::pi) * r2;
          const Vec3 d = tx * (r * std::cos(phi)) + ty * (r * std::sin(phi)) +
                         nrm * std::sqrt(std::max(0.0f, 1 - r1));
          bounce.push_back(Ray{s.position + s.geometric_normal * options.ray_epsilon, d, 0, 1e30f});
          owner.push_back(i);
        }
      }
      std::vector<Hit> bounce_hits(bounce.size());
      scene.Intersect(bounce, bounce_hits);
      ray_count += bounce.size();
      std::vector<Vec3> secondary(bounce.size());
      shadow_rays.clear();
      samples.clear();
      std::vector<Vec3> secondary_albedo(bounce.size());
      for (size_t k = 0; k < bounce.size(); ++k) {
        if (bounce_hits[k].object < 0) continue;
        const SurfacePoint s = scene.Surface(bounce[k], bounce_hits[k]);
        secondary[k] = EnvironmentShading(env, s);
        CollectLights(scene, s, Normalize(-bounce[k].direction), k, options.ray_epsilon,
                      shadow_rays, samples);
      }
      ResolveLights(scene, shadow_rays, samples, options.shadows, visible, secondary);
      if (options.shadows) ray_count += shadow_rays.size();
      const float weight = 1.0f / static_cast<float>(spp);
      for (size_t k = 0; k < bounce.size(); ++k) {
        const size_t i = owner[k];
        radiance[i] += surfaces[i].albedo * secondary[k] * weight;
      }
    }
    for (size_t i = 0; i < n; ++i) {
      const size_t p = first + i;
      for (int c = 0; c < 3; ++c) {
        frame.linear_rgb[3 * p + c] = radiance[i][c];
        frame.srgb[3 * p + c] = LinearToSrgb8(radiance[i][c]);
      }
    }
    rays_per_task[t] = ray_count;
  };
  if (pool != nullptr) {
    pool->ParallelFor(tasks, task);
  } else {
    for (size_t t = 0; t < tasks; ++t) task(t);
  }
  for (uint64_t r : rays_per_task) frame.rays += r;
  return frame;
}

LightingGroundTruth LightingAt(const Scene& scene, Vec3 point, const Mat3& frame_to_world) {
  LightingGroundTruth out;
  const Environment& env = scene.environment();
  if (env.scale != 0) {
    out.sh = internal::ProjectRotated(
        [&](Vec3 w) { return internal::EvaluateSh9(env.sh, w) * env.scale; }, frame_to_world);
  }
  const Mat3 world_to_frame = frame_to_world.Transposed();
  auto add = [&](Vec3 d_world, Vec3 irradiance) {
    const Vec3 d = Normalize(world_to_frame * d_world);
    const std::array<float, 9> y = ShBasis9(d);
    for (int i = 0; i < 9; ++i) out.sh[i] += irradiance * y[i];
    const float mean = (irradiance.x + irradiance.y + irradiance.z) / 3;
    if (mean > out.dominant_irradiance) {
      out.dominant_irradiance = mean;
      out.dominant_direction = d;
    }
  };
  for (const DirectionalLight& l : scene.directional_lights()) {
    if (l.enabled) add(Normalize(l.direction), l.irradiance);
  }
  for (const PointLight& l : scene.point_lights()) {
    if (!l.enabled) continue;
    const Vec3 to = l.position - point;
    const float r2 = Dot(to, to);
    if (r2 > 0) add(to, l.intensity / r2);
  }
  return out;
}

}  // namespace probeless::raytrace
