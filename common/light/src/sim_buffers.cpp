#include "probeless/light/sim_buffers.h"

#include <algorithm>
#include <cmath>

namespace probeless::light {

GeometryStorage GeometryFromSimFrame(const sim::SimFrame& frame, bool sensor_effects,
                                     const DepthGeometryOptions& depth_options,
                                     float* measured_noise) {
  GeometryStorage g;
  const auto& r = frame.render;
  g.width = r.width;
  g.height = r.height;
  g.intrinsics = {frame.camera.fx, frame.camera.fy, frame.camera.cx, frame.camera.cy};
  const size_t pixels = static_cast<size_t>(r.width) * r.height;
  if (!sensor_effects) {
    g.depth = r.depth_m;
    g.normals = r.normals;
    g.colour = r.srgb;
    g.grey.resize(pixels);
    for (size_t i = 0; i < pixels; ++i) {
      float s = 0;
      for (int c = 0; c < 3; ++c) s += std::clamp(r.linear_rgb[3 * i + c], 0.0f, 1.0f);
      g.grey[i] = s / 3;
    }
  } else {
    g.depth.resize(pixels);
    for (size_t i = 0; i < pixels; ++i) g.depth[i] = frame.depth_mm[i] * 0.001f;
    const float noise = DepthGeometry(g.depth, g.width, g.height, g.intrinsics, depth_options,
                                      &g.normals, &g.reliability);
    if (measured_noise != nullptr) *measured_noise = noise;
    g.colour = frame.rgb;
    SrgbToLinearGrey(g.colour, &g.grey);
  }
  return g;
}

AuxiliaryStorage RenderAuxiliaryViews(const raytrace::Scene& scene, const raytrace::Camera& camera,
                                      const AuxiliaryViewOptions& options,
                                      raytrace::ThreadPool* pool) {
  using raytrace::Vec3;
  AuxiliaryStorage out;
  const raytrace::Transform& c2w = camera.camera_to_world;
  const Vec3 cam_pos{static_cast<float>(c2w.translation[0]), static_cast<float>(c2w.translation[1]),
                     static_cast<float>(c2w.translation[2])};
  const Vec3 forward = c2w.ApplyDirection({0, 0, 1});
  const Vec3 centre = cam_pos + forward * options.centre_distance_m;
  struct Spec {
    AuxiliaryRole role;
    Vec3 dir;  // world viewing direction
  };
  std::vector<Spec> specs;
  if (options.left_right_top) {
    specs.push_back({AuxiliaryRole::kLeft, c2w.ApplyDirection({1, 0, 0})});
    specs.push_back({AuxiliaryRole::kRight, c2w.ApplyDirection({-1, 0, 0})});
    specs.push_back({AuxiliaryRole::kTop,
                     options.top_along_camera_y ? c2w.ApplyDirection({0, 1, 0}) : Vec3{0, -1, 0}});
  }
  if (options.light_view) {
    const auto& l = options.light_direction;
    specs.push_back({AuxiliaryRole::kLight, -c2w.ApplyDirection({l[0], l[1], l[2]})});
  }
  const raytrace::Transform w2c = c2w.Inverse();
  const int n = options.resolution;
  const float pixel = options.extent_m / n;
  out.depth.resize(specs.size());
  for (size_t s = 0; s < specs.size(); ++s) {
    const Vec3 z = raytrace::Normalize(specs[s].dir);
    const Vec3 helper = std::abs(z.y) > 0.9f ? Vec3{0, 0, 1} : Vec3{0, -1, 0};
    const Vec3 x = raytrace::Normalize(raytrace::Cross(helper, z));
    const Vec3 y = raytrace::Cross(z, x);
    const Vec3 origin = centre - z * options.standoff_m;
    std::vector<raytrace::Ray> rays(static_cast<size_t>(n) * n);
    const float h = 0.5f * (n - 1);
    for (int v = 0; v < n; ++v) {
      for (int u = 0; u < n; ++u) {
        rays[v * n + u].origin = origin + x * ((u - h) * pixel) + y * ((v - h) * pixel);
        rays[v * n + u].direction = z;
      }
    }
    std::vector<raytrace::Hit> hits(rays.size());
    scene.Intersect(rays, hits, pool);
    auto& depth = out.depth[s];
    depth.resize(rays.size());
    for (size_t i = 0; i < rays.size(); ++i) depth[i] = hits[i].object >= 0 ? hits[i].t : 0.0f;
    // view -> camera = world -> camera * view -> world.
    const Vec3 cx = w2c.ApplyDirection(x), cy = w2c.ApplyDirection(y), cz = w2c.ApplyDirection(z);
    const Vec3 t = w2c.Apply(origin);
    OrthographicView view;
    view.role = specs[s].role;
    view.width = view.height = n;
    view.pixel_size_m = pixel;
    view.rotation = {cx.x, cy.x, cz.x, cx.y, cy.y, cz.y, cx.z, cy.z, cz.z};
    view.translation = {t.x, t.y, t.z};
    view.depth = depth;
    out.buffers.views.push_back(view);
  }
  return out;
}

raytrace::LightingGroundTruth SurfaceLightingTruth(const raytrace::Scene& scene,
                                                   const sim::SimFrame& frame, int stride) {
  using raytrace::Vec3;
  if (stride < 1) throw LightError("light::SurfaceLightingTruth: stride must be >= 1");
  const raytrace::Camera& cam = frame.camera;
  const raytrace::Transform& c2w = cam.camera_to_world;
  const raytrace::Mat3 w2c = c2w.rotation.Transposed();
  const auto& r = frame.render;
  std::vector<Vec3> points;
  for (int v = stride / 2; v < r.height; v += stride) {
    for (int u = stride / 2; u < r.width; u += stride) {
      const float d = r.depth_m[static_cast<size_t>(v) * r.width + u];
      if (!(d > 0)) continue;
      points.push_back(c2w.Apply({static_cast<float>(d * (u - cam.cx) / cam.fx),
                                  static_cast<float>(d * (v - cam.cy) / cam.fy), d}));
    }
  }
  const Vec3 eye{static_cast<float>(c2w.translation[0]), static_cast<float>(c2w.translation[1]),
                 static_cast<float>(c2w.translation[2])};
  if (points.empty()) return raytrace::LightingAt(scene, eye, c2w.rotation);
  // Per light: mean RGB irradiance and mean (grey irradiance x unit direction) over the points.
  struct Sum {
    Vec3 irradiance{0, 0, 0};
    Vec3 weighted_direction{0, 0, 0};
  };
  std::vector<Sum> sums;
  raytrace::LightingGroundTruth out;
  auto add = [&](size_t light, Vec3 d_world, Vec3 irradiance) {
    const Vec3 d = raytrace::Normalize(w2c * d_world);
    const auto y = raytrace::ShBasis9(d);
    for (int i = 0; i < 9; ++i) out.sh[i] += irradiance * y[i];
    if (sums.size() <= light) sums.resize(light + 1);
    sums[light].irradiance += irradiance;
    sums[light].weighted_direction += d * ((irradiance.x + irradiance.y + irradiance.z) / 3);
  };
  const auto& directional = scene.directional_lights();
  const auto& point = scene.point_lights();
  for (const Vec3& p : points) {
    for (size_t k = 0; k < directional.size(); ++k) {
      if (directional[k].enabled) add(k, directional[k].direction, directional[k].irradiance);
    }
    for (size_t k = 0; k < point.size(); ++k) {
      if (!point[k].enabled) continue;
      const Vec3 to = point[k].position - p;
      const float r2 = raytrace::Dot(to, to);
      if (r2 > 0) add(directional.size() + k, to, point[k].intensity / r2);
    }
  }
  const float inv = 1.0f / static_cast<float>(points.size());
  for (auto& c : out.sh) c *= inv;
  // The environment is the same at every point: LightingAt at the camera minus its lights.
  const raytrace::LightingGroundTruth at_eye = raytrace::LightingAt(scene, eye, c2w.rotation);
  std::array<Vec3, 9> lights_at_eye{};
  auto add_eye = [&](Vec3 d_world, Vec3 irradiance) {
    const auto y = raytrace::ShBasis9(raytrace::Normalize(w2c * d_world));
    for (int i = 0; i < 9; ++i) lights_at_eye[i] += irradiance * y[i];
  };
  for (const auto& l : directional) {
    if (l.enabled) add_eye(l.direction, l.irradiance);
  }
  for (const auto& l : point) {
    const Vec3 to = l.position - eye;
    if (l.enabled && raytrace::Dot(to, to) > 0) add_eye(to, l.intensity / raytrace::Dot(to, to));
  }
  for (int i = 0; i < 9; ++i) out.sh[i] += at_eye.sh[i] - lights_at_eye[i];
  for (const Sum& s : sums) {
    const float mean = (s.irradiance.x + s.irradiance.y + s.irradiance.z) / 3 * inv;
    const float len = raytrace::Length(s.weighted_direction);
    if (mean > out.dominant_irradiance && len > 0) {
      out.dominant_irradiance = mean;
      out.dominant_direction = s.weighted_direction / len;
    }
  }
  return out;
}

}  // namespace probeless::light
