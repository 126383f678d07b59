// The path-tracing benchmark scene: a furnished 5 x 3 x 6 m room with a window in its +x wall,
// ~20 boxes, spheres and cylinders (Lambert, GGX, procedural patterns), a sun disc and a blue
// sky through the window, and two lamps (a ceiling panel and a sphere), seen by a 640x480 camera.
#pragma once

#include <cmath>
#include <numbers>

#include "probeless/raytrace/pathtrace.h"
#include "probeless/raytrace/render.h"
#include "probeless/raytrace/scene.h"

namespace raytrace_bench {

namespace rt = probeless::raytrace;

// Fills `scene` (empty) with the room and commits it; returns the camera.
inline rt::Camera BuildPathTraceRoom(rt::Scene& scene) {
  using rt::Mat3;
  using rt::Material;
  using rt::Transform;
  using rt::Vec3;
  auto diffuse = [](Vec3 albedo) {
    Material m;
    m.albedo = albedo;
    return m;
  };
  auto at = [](Vec3 p, double yaw = 0) {
    return Transform{Mat3::AxisAngle({0, 1, 0}, yaw), {p.x, p.y, p.z}};
  };
  uint32_t id = 1;
  auto box = [&](Vec3 size, Vec3 centre, const Material& m, double yaw = 0) {
    scene.AddObject(rt::MakeBox(size), m, at(centre, yaw), id++);
  };
  // Shell: floor y = 0, ceiling y = 3, walls at x = +-2.5 and z = +-3 (0.1 m thick).
  Material floor = diffuse({0.55f, 0.42f, 0.3f});
  floor.pattern.kind = rt::ProceduralPattern::Kind::kStripes;
  floor.pattern.color_b = {0.45f, 0.33f, 0.22f};
  floor.pattern.period_m = 0.3f;
  floor.pattern.axis = {1, 0, 0};
  floor.specular_f0 = 0.04f;
  floor.roughness = 0.45f;
  box({5.2f, 0.1f, 6.2f}, {0, -0.05f, 0}, floor);
  box({5.2f, 0.1f, 6.2f}, {0, 3.05f, 0}, diffuse({0.85f, 0.85f, 0.82f}));
  const Material wall = diffuse({0.75f, 0.72f, 0.65f});
  box({0.1f, 3, 6}, {-2.55f, 1.5f, 0}, wall);
  box({5, 3, 0.1f}, {0, 1.5f, 3.05f}, wall);
  box({5, 3, 0.1f}, {0, 1.5f, -3.05f}, wall);
  // The +x wall with a 1.6 x 1.4 m window (z in [-0.8, 0.8], y in [0.9, 2.3]).
  box({0.1f, 0.9f, 6}, {2.55f, 0.45f, 0}, wall);
  box({0.1f, 0.7f, 6}, {2.55f, 2.65f, 0}, wall);
  box({0.1f, 1.4f, 2.2f}, {2.55f, 1.6f, -1.9f}, wall);
  box({0.1f, 1.4f, 2.2f}, {2.55f, 1.6f, 1.9f}, wall);
  // Furniture: a table (top + 4 legs), a chair-like block, a shelf, spheres, cylinders.
  Material wood = diffuse({0.5f, 0.3f, 0.15f});
  wood.pattern.kind = rt::ProceduralPattern::Kind::kValueNoise;
  wood.pattern.color_b = {0.35f, 0.2f, 0.1f};
  wood.pattern.period_m = 0.05f;
  wood.specular_f0 = 0.04f;
  wood.roughness = 0.6f;
  box({1.4f, 0.05f, 0.8f}, {0.3f, 0.75f, 1.2f}, wood);
  for (const float dx : {-0.65f, 0.65f}) {
    for (const float dz : {-0.35f, 0.35f}) {
      scene.AddObject(rt::MakeCylinder(0.03f, 0.725f, 16), wood, at({0.3f + dx, 0, 1.2f + dz}),
                      id++);
    }
  }
  Material checker = diffuse({0.8f, 0.8f, 0.8f});
  checker.pattern.kind = rt::ProceduralPattern::Kind::kChecker;
  checker.pattern.color_b = {0.1f, 0.1f, 0.1f};
  checker.pattern.period_m = 0.1f;
  box({0.5f, 0.5f, 0.5f}, {-1.2f, 0.25f, 1.8f}, checker, 0.5);
  box({0.4f, 1.8f, 1.2f}, {-2.25f, 0.9f, -1.0f}, diffuse({0.3f, 0.35f, 0.5f}));
  box({0.3f, 0.3f, 0.3f}, {-2.25f, 1.95f, -1.2f}, diffuse({0.7f, 0.2f, 0.15f}), 0.3);
  Material metal = diffuse({0, 0, 0});
  metal.specular_f0 = 0.9f;
  metal.roughness = 0.25f;
  scene.AddObject(rt::MakeSphere(0.15f), metal, at({0.0f, 0.93f, 1.1f}), id++);
  Material plastic = diffuse({0.1f, 0.5f, 0.2f});
  plastic.specular_f0 = 0.04f;
  plastic.roughness = 0.2f;
  scene.AddObject(rt::MakeSphere(0.12f), plastic, at({0.6f, 0.9f, 1.3f}), id++);
  scene.AddObject(rt::MakeSphere(0.3f), diffuse({0.8f, 0.75f, 0.6f}), at({1.3f, 0.3f, -0.8f}),
                  id++);
  scene.AddObject(rt::MakeCylinder(0.2f, 0.9f), diffuse({0.6f, 0.6f, 0.65f}), at({-1.5f, 0, -2.3f}),
                  id++);
  scene.AddObject(rt::MakeCylinder(0.1f, 0.4f), plastic, at({1.8f, 0, 2.2f}), id++);
  // Lights: the sun through the window, the sky, a ceiling panel and a sphere lamp.
  rt::DirectionalLight sun;
  sun.direction = rt::Normalize({1, 0.7f, 0.25f});
  sun.irradiance = rt::BlackbodyRgb(5800) * 8.0f;
  sun.angular_radius = 0.0047f;
  scene.directional_lights().push_back(sun);
  scene.environment().sh[0] = Vec3{0.5f, 0.7f, 1.0f} * (2 * std::sqrt(std::numbers::pi_v<float>));
  scene.environment().sh[1] = Vec3{-0.3f, -0.4f, -0.6f};  // brighter upwards (Y_1,-1 = -c y)
  rt::AreaLight panel;
  panel.centre = {-0.5f, 2.99f, 0};
  panel.half_u = {0.3f, 0, 0};
  panel.half_v = {0, 0, 0.3f};  // u x v = -y: emits downwards
  panel.radiance = rt::BlackbodyRgb(4000) * 6.0f;
  panel.id = id++;
  scene.area_lights().push_back(panel);
  rt::AreaLight bulb;
  bulb.shape = rt::AreaLight::Shape::kSphere;
  bulb.centre = {-1.8f, 1.6f, 2.4f};
  bulb.radius = 0.08f;
  bulb.radiance = rt::BlackbodyRgb(2700) * 40.0f;
  bulb.id = id++;
  scene.area_lights().push_back(bulb);
  scene.Commit();
  rt::Camera camera;  // 640x480, fx = fy = 525
  camera.fx = camera.fy = 400;
  camera.camera_to_world = Transform::LookAt({-2.0f, 1.6f, -2.6f}, {1.0f, 0.9f, 1.2f}, {0, 1, 0});
  return camera;
}

}  // namespace raytrace_bench
