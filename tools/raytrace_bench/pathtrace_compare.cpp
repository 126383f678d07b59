// pathtrace_compare: exports a scene for an independent renderer and renders it with PathTrace,
// for the cross-check against Mitsuba 3 (mitsuba_compare.py; test tooling, not run by CI).
//
//   pathtrace_compare --out DIR [--scene interior|outdoor] [--spp N] [--bounces N]
//
// Writes DIR/scene.json (camera, lights, environment, objects with their albedo), DIR/<k>.obj
// (each object's triangles in the world frame with vertex normals, so both renderers see the
// same tessellation) and DIR/probeless.pfm (PathTrace's linear RGB, PFM row order bottom-up).
// Only features both renderers define identically are used: Lambertian albedo, delta directional
// and point lights, rectangle and sphere area lights, a constant environment.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <stdexcept>
#include <string>
#include <vector>

#include "probeless/node/flags.h"
#include "probeless/node/main.h"
#include "probeless/parse/number.h"
#include "probeless/raytrace/pathtrace.h"
#include "probeless/raytrace/render.h"
#include "probeless/raytrace/scene.h"

namespace {

using namespace probeless::raytrace;

struct Exported {
  Mesh mesh;  // world frame
  Vec3 albedo;
};

struct CompareScene {
  Scene scene;
  Camera camera;
  Vec3 target;
  Vec3 up{0, 1, 0};
  std::vector<Exported> objects;
  Vec3 sky;  // constant environment radiance

  void Add(Mesh mesh, Vec3 albedo, const Transform& t) {
    Material m;
    m.albedo = albedo;
    scene.AddObject(mesh, m, t, static_cast<uint32_t>(objects.size() + 1));
    if (mesh.normals.empty()) mesh.ComputeNormals();
    mesh.TransformBy(t);
    objects.push_back({std::move(mesh), albedo});
  }
};

Transform At(Vec3 p, double yaw = 0) {
  return Transform{Mat3::AxisAngle({0, 1, 0}, yaw), {p.x, p.y, p.z}};
}

void LookFrom(CompareScene& c, Vec3 eye, Vec3 target) {
  c.camera.width = 320;
  c.camera.height = 240;
  c.camera.fx = c.camera.fy = 260;
  c.camera.cx = (c.camera.width - 1) / 2.0;
  c.camera.cy = (c.camera.height - 1) / 2.0;
  c.camera.camera_to_world = Transform::LookAt(eye, target, c.up);
  c.target = target;
}

// A room open towards the camera: two lamps (a ceiling panel, a sphere), a point light, a dim sky
// through the opening, a few diffuse objects.
void BuildInterior(CompareScene& c) {
  c.Add(MakeBox({4, 0.1f, 4}), {0.7f, 0.6f, 0.5f}, At({0, -0.05f, 0}));
  c.Add(MakeBox({4, 0.1f, 4}), {0.8f, 0.8f, 0.8f}, At({0, 2.55f, 0}));
  c.Add(MakeBox({4, 2.5f, 0.1f}), {0.6f, 0.7f, 0.6f}, At({0, 1.25f, 2.05f}));
  c.Add(MakeBox({0.1f, 2.5f, 4}), {0.8f, 0.3f, 0.25f}, At({-2.05f, 1.25f, 0}));
  c.Add(MakeBox({0.1f, 2.5f, 4}), {0.25f, 0.3f, 0.8f}, At({2.05f, 1.25f, 0}));
  c.Add(MakeSphere(0.4f, 64), {0.9f, 0.9f, 0.9f}, At({-0.6f, 0.4f, 0.8f}));
  c.Add(MakeBox({0.6f, 1.0f, 0.6f}), {0.8f, 0.7f, 0.3f}, At({0.7f, 0.5f, 1.0f}, 0.4));
  AreaLight panel;
  panel.centre = {0, 2.45f, 0.8f};
  panel.half_u = {0.4f, 0, 0};
  panel.half_v = {0, 0, 0.3f};  // u x v = -y: downwards
  panel.radiance = {6, 5.5f, 5};
  c.scene.area_lights().push_back(panel);
  AreaLight bulb;
  bulb.shape = AreaLight::Shape::kSphere;
  bulb.centre = {1.4f, 1.8f, 1.6f};
  bulb.radius = 0.1f;
  bulb.radiance = {12, 9, 5};
  c.scene.area_lights().push_back(bulb);
  c.scene.point_lights().push_back({{-1.5f, 2.0f, -0.5f}, {1.5f, 1.5f, 2.0f}, true});
  c.sky = {0.15f, 0.2f, 0.3f};
  LookFrom(c, {0, 1.3f, -2.6f}, {0, 0.9f, 1.0f});
}

// Objects on a ground plane under a delta sun, a point light and a uniform sky.
void BuildOutdoor(CompareScene& c) {
  c.Add(MakeBox({40, 0.1f, 40}), {0.5f, 0.5f, 0.45f}, At({0, -0.05f, 0}));
  c.Add(MakeSphere(0.5f, 64), {0.8f, 0.2f, 0.2f}, At({-0.7f, 0.5f, 1.5f}));
  c.Add(MakeBox({0.8f, 0.8f, 0.8f}), {0.2f, 0.6f, 0.9f}, At({0.8f, 0.4f, 1.8f}, 0.6));
  c.Add(MakeCylinder(0.25f, 1.2f, 48), {0.9f, 0.85f, 0.7f}, At({0.1f, 0, 3.0f}));
  c.Add(MakeBox({3, 2, 0.2f}), {0.7f, 0.7f, 0.7f}, At({0, 1, 4.2f}));
  c.scene.directional_lights().push_back({Normalize({-0.6f, 1.0f, -0.4f}), {3, 2.8f, 2.5f}, true});
  c.scene.point_lights().push_back({{1.2f, 1.5f, 0.5f}, {2, 2, 2}, true});
  c.sky = {0.3f, 0.4f, 0.6f};
  LookFrom(c, {0, 1.4f, -1.8f}, {0, 0.5f, 2.0f});
}

void WriteObj(const std::string& path, const Mesh& m) {
  std::ofstream out(path);
  for (const Vec3& p : m.positions) out << "v " << p.x << " " << p.y << " " << p.z << "\n";
  for (const Vec3& n : m.normals) out << "vn " << n.x << " " << n.y << " " << n.z << "\n";
  for (const auto& t : m.triangles) {
    out << "f";
    for (uint32_t i : t) out << " " << i + 1 << "//" << i + 1;
    out << "\n";
  }
  if (!out) throw std::runtime_error("cannot write '" + path + "'");
}

std::string Json(Vec3 v) {
  char b[96];
  std::snprintf(b, sizeof(b), "[%.9g, %.9g, %.9g]", v.x, v.y, v.z);
  return b;
}

void WriteScene(const std::string& dir, const CompareScene& c, int spp, int bounces) {
  std::ofstream out(dir + "/scene.json");
  const auto& t = c.camera.camera_to_world.translation;
  const double fov_x = 2 * std::atan(c.camera.width / (2 * c.camera.fx)) * 180 / std::numbers::pi;
  out << "{\n  \"camera\": {\"width\": " << c.camera.width << ", \"height\": " << c.camera.height
      << ", \"fov_x_deg\": " << fov_x << ", \"eye\": "
      << Json({static_cast<float>(t[0]), static_cast<float>(t[1]), static_cast<float>(t[2])})
      << ", \"target\": " << Json(c.target) << ", \"up\": " << Json(c.up) << "},\n";
  out << "  \"spp\": " << spp << ",\n  \"max_bounces\": " << bounces << ",\n";
  out << "  \"sky\": " << Json(c.sky) << ",\n  \"directional\": [";
  const auto& dl = c.scene.directional_lights();
  for (size_t i = 0; i < dl.size(); ++i) {
    out << (i ? ", " : "") << "{\"to_light\": " << Json(Normalize(dl[i].direction))
        << ", \"irradiance\": " << Json(dl[i].irradiance) << "}";
  }
  out << "],\n  \"point\": [";
  const auto& pl = c.scene.point_lights();
  for (size_t i = 0; i < pl.size(); ++i) {
    out << (i ? ", " : "") << "{\"position\": " << Json(pl[i].position)
        << ", \"intensity\": " << Json(pl[i].intensity) << "}";
  }
  out << "],\n  \"area\": [";
  const auto& al = c.scene.area_lights();
  for (size_t i = 0; i < al.size(); ++i) {
    const AreaLight& a = al[i];
    out << (i ? ", " : "") << "{\"shape\": \""
        << (a.shape == AreaLight::Shape::kRectangle ? "rectangle" : "sphere")
        << "\", \"centre\": " << Json(a.centre) << ", \"half_u\": " << Json(a.half_u)
        << ", \"half_v\": " << Json(a.half_v) << ", \"radius\": " << a.radius
        << ", \"radiance\": " << Json(a.radiance) << "}";
  }
  out << "],\n  \"objects\": [";
  for (size_t i = 0; i < c.objects.size(); ++i) {
    out << (i ? ", " : "") << "\n    {\"obj\": \"" << i
        << ".obj\", \"albedo\": " << Json(c.objects[i].albedo) << "}";
  }
  out << "\n  ]\n}\n";
  if (!out) throw std::runtime_error("cannot write " + dir + "/scene.json");
  for (size_t i = 0; i < c.objects.size(); ++i) {
    WriteObj(dir + "/" + std::to_string(i) + ".obj", c.objects[i].mesh);
  }
}

void WritePfm(const std::string& path, const Frame& f) {
  std::ofstream out(path, std::ios::binary);
  out << "PF\n" << f.width << " " << f.height << "\n-1.0\n";  // -1: little-endian floats
  for (int y = f.height - 1; y >= 0; --y) {
    out.write(reinterpret_cast<const char*>(&f.linear_rgb[static_cast<size_t>(y) * f.width * 3]),
              static_cast<std::streamsize>(f.width * 3 * sizeof(float)));
  }
  if (!out) throw std::runtime_error("cannot write '" + path + "'");
}

int Run(int argc, char** argv) {
  std::string dir, which = "interior";
  int spp = 256, bounces = 3;
  probeless::node::FlagParser flags(
      "pathtrace_compare",
      "exports a scene for an independent renderer (Mitsuba 3) and renders it with PathTrace");
  flags.Add("--out", &dir, "DIR", "scene.json, the objects' .obj and probeless.pfm (required)");
  flags.AddChoice("--scene", &which, {"interior", "outdoor"}, "the scene");
  flags.Add("--spp", &spp, "N", "paths per pixel", 1);
  flags.Add("--bounces", &bounces, "N", "maximum bounces", 0);
  if (!flags.Parse(argc, argv)) return 0;
  if (dir.empty()) throw probeless::node::UsageError("--out DIR is required");
  CompareScene c;
  if (which == "interior") {
    BuildInterior(c);
  } else if (which == "outdoor") {
    BuildOutdoor(c);
  } else {
    throw probeless::node::UsageError("--scene must be interior or outdoor, got '" + which + "'");
  }
  c.scene.environment().sh[0] = c.sky * (2 * std::sqrt(std::numbers::pi_v<float>));
  c.scene.Commit();
  std::filesystem::create_directories(dir);
  WriteScene(dir, c, spp, bounces);
  PathTraceOptions options;
  options.samples_per_pixel = spp;
  options.max_bounces = bounces;
  options.russian_roulette_after = 3;
  ThreadPool pool(2);
  const Frame f = PathTrace(c.scene, c.camera, options, &pool);
  WritePfm(dir + "/probeless.pfm", f);
  std::printf("wrote %s/scene.json, %zu objects, probeless.pfm (%d spp, %d bounces)\n", dir.c_str(),
              c.objects.size(), spp, bounces);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return probeless::node::RunMain("pathtrace_compare", [&] { return Run(argc, argv); });
}
