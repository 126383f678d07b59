// Checks of the path tracer against closed forms and the legacy renderer: white furnace, BSDF
// energy conservation, direct light equal to Render, area and disc lights against their analytic
// irradiance, the virtual light probe, determinism and correlation, errors, blackbody colours.
#include "probeless/raytrace/pathtrace.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <string>

#include "probeless/raytrace/render.h"
#include "probeless/raytrace/scene.h"
#include "probeless/testing/expect.h"

namespace probeless::raytrace {
namespace {

constexpr float kPi = static_cast<float>(std::numbers::pi);

Camera TestCamera(int width = 80, int height = 60) {
  Camera c;
  c.width = width;
  c.height = height;
  c.fx = c.fy = 75;
  c.cx = (width - 1) / 2.0;
  c.cy = (height - 1) / 2.0;
  return c;  // identity pose: looking along world +z, world y down
}

Material Diffuse(Vec3 albedo) {
  Material m;
  m.albedo = albedo;
  return m;
}

// The sample mean and the standard error of the mean of `values`.
struct MeanError {
  double mean = 0;
  double error = 0;
};
MeanError Stats(const std::vector<double>& values) {
  MeanError s;
  for (double v : values) s.mean += v;
  s.mean /= static_cast<double>(values.size());
  double var = 0;
  for (double v : values) var += (v - s.mean) * (v - s.mean);
  var /= static_cast<double>(values.size() - 1);
  s.error = std::sqrt(var / static_cast<double>(values.size()));
  return s;
}

// A closed box of albedo a whose walls emit L_e, seen from inside: L = L_e / (1 - a), with Russian
// roulette from the first vertex (the default) and from the third.
class WhiteFurnace : public ::testing::TestWithParam<int> {};

TEST_P(WhiteFurnace, ConvergesToGeometricSeries) {
  Scene scene;
  Material wall = Diffuse({0.6f, 0.6f, 0.6f});
  wall.emission = {0.2f, 0.2f, 0.2f};
  scene.AddObject(MakeBox({2, 2, 2}), wall, {}, 1);
  scene.Commit();
  PathTraceOptions options;
  options.samples_per_pixel = 16;
  options.max_bounces = 1000;
  options.russian_roulette_after = GetParam();
  ThreadPool pool(2);
  const Frame f = PathTrace(scene, TestCamera(40, 30), options, &pool);
  std::vector<double> pixels;
  for (size_t p = 0; p < f.object_ids.size(); ++p) {
    ASSERT_EQ(f.object_ids[p], 1u);
    pixels.push_back(f.linear_rgb[3 * p]);
  }
  const MeanError s = Stats(pixels);
  const double expected = 0.2 / (1 - 0.6);
  // Pixels are independent estimates: the mean is within 4 standard errors.
  EXPECT_NEAR(s.mean, expected, 4 * s.error) << "standard error " << s.error;
  EXPECT_LT(s.error, 0.01 * expected);
}

INSTANTIATE_TEST_SUITE_P(PathTrace, WhiteFurnace, ::testing::Values(0, 2), [](const auto& info) {
  return "RouletteAfter" + std::to_string(info.param);
});

// A huge plane under a uniform environment of radiance 1, direct light only: each pixel reads the
// BSDF's directional albedo at its viewing angle.
std::vector<double> PlaneAlbedo(const Material& material, double view_elevation_deg) {
  Scene scene;
  scene.AddObject(MakePlane(4000, 4000), material, {}, 1);
  scene.environment().sh[0] = Vec3{1, 1, 1} * (2 * std::sqrt(kPi));
  scene.Commit();
  Camera camera = TestCamera(24, 24);
  camera.fx = camera.fy = 400;  // a narrow view: one viewing angle
  const double e = view_elevation_deg * std::numbers::pi / 180;
  const Vec3 eye{0, 1, 0};
  const Vec3 target{0, static_cast<float>(1 - std::tan(e)), 1};
  camera.camera_to_world = Transform::LookAt(eye, target, {0, 1, 0});
  PathTraceOptions options;
  options.samples_per_pixel = 64;
  options.max_bounces = 0;
  const Frame f = PathTrace(scene, camera, options);
  std::vector<double> out;
  for (size_t p = 0; p < f.object_ids.size(); ++p) {
    if (f.object_ids[p] == 1) out.push_back(f.linear_rgb[3 * p + 1]);
  }
  return out;
}

TEST(PathTrace, GgxPlusDiffuseConservesEnergy) {
  for (float roughness : {0.1f, 0.4f, 1.0f}) {
    for (float f0 : {0.04f, 0.5f, 1.0f}) {
      for (double elevation : {80.0, 45.0, 12.0}) {
        Material white = Diffuse({1, 1, 1});
        white.specular_f0 = f0;
        white.roughness = roughness;
        const MeanError w = Stats(PlaneAlbedo(white, elevation));
        // White diffuse under any lobe: total albedo E + 1 (1 - E) = 1 by construction.
        EXPECT_NEAR(w.mean, 1.0, 0.01 + 4 * w.error)
            << "white, roughness " << roughness << " f0 " << f0 << " elevation " << elevation;
        Material black = white;
        black.albedo = {0, 0, 0};
        const MeanError b = Stats(PlaneAlbedo(black, elevation));
        EXPECT_LE(b.mean, 1.0 + 4 * b.error)
            << "lobe only, roughness " << roughness << " f0 " << f0 << " elevation " << elevation;
        EXPECT_GT(b.mean, 0.3 * f0);
      }
    }
  }
}

// The GGX lobe alone (f0 = 1, no diffuse) against its directional albedo
// E(mu) = int D G2 / (4 mu_o mu_i) mu_i dw_i by an independent 2000 x 4000 midpoint quadrature.
TEST(PathTrace, GgxLobeMatchesQuadrature) {
  struct Case {
    float roughness;
    double elevation;
    double albedo;
  };
  for (const Case& c :
       {Case{1.0f, 80, 0.30982}, Case{1.0f, 45, 0.37677}, Case{1.0f, 12, 0.63417},
        Case{0.4f, 80, 0.96714}, Case{0.4f, 45, 0.95123}, Case{0.4f, 12, 0.87039}}) {
    Material m = Diffuse({0, 0, 0});
    m.specular_f0 = 1;
    m.roughness = c.roughness;
    const MeanError e = Stats(PlaneAlbedo(m, c.elevation));
    EXPECT_NEAR(e.mean, c.albedo, 0.004 + 4 * e.error)
        << "roughness " << c.roughness << " elevation " << c.elevation;
  }
}

Scene& DirectScene(Scene& scene) {
  scene.AddObject(MakePlane(10, 10), Diffuse({0.9f, 0.8f, 0.7f}),
                  {Mat3::AxisAngle({1, 0, 0}, -kPi / 2), {0, 0, 3}}, 1);
  scene.AddObject(MakeSphere(0.4f, 96), Diffuse({0.3f, 0.6f, 0.9f}),
                  {Mat3::Identity(), {0.4, 0.1, 2.3}}, 2);
  scene.AddObject(MakeBox({0.3f, 0.3f, 0.3f}), Diffuse({0.8f, 0.8f, 0.2f}),
                  {Mat3::AxisAngle({0, 1, 0}, 0.4), {-0.5, -0.2, 2.4}}, 3);
  scene.directional_lights().push_back({Normalize({0.5f, -1, -1}), {2, 2, 2}, true});
  scene.point_lights().push_back({{-1, -1.2f, 1.5f}, {1.5f, 1.5f, 1.5f}, true});
  scene.Commit();
  return scene;
}

TEST(PathTrace, DirectLightEqualsRender) {
  Scene scene;
  DirectScene(scene);
  const Camera camera = TestCamera();
  const Frame r = Render(scene, camera, RenderOptions{});
  PathTraceOptions options;
  options.samples_per_pixel = 64;
  options.max_bounces = 0;
  options.all_lights = true;  // delta lights: exact NEE, only the pixel footprint differs
  ThreadPool pool(2);
  const Frame p = PathTrace(scene, camera, options, &pool);
  EXPECT_EQ(p.object_ids, r.object_ids);
  EXPECT_EQ(p.depth_mm, r.depth_mm);
  ASSERT_EQ(p.normals.size(), r.normals.size());
  for (size_t i = 0; i < p.normals.size(); ++i) ASSERT_NEAR(p.normals[i], r.normals[i], 1e-6f);
  // Away from silhouettes and shadow edges (the path tracer box-filters the pixel), equal to noise.
  int compared = 0;
  double worst = 0;
  for (int y = 1; y + 1 < camera.height; ++y) {
    for (int x = 1; x + 1 < camera.width; ++x) {
      const size_t c = static_cast<size_t>(y) * camera.width + x;
      bool smooth = true;
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          const size_t q = c + dy * camera.width + dx;
          smooth = smooth && r.object_ids[q] == r.object_ids[c] &&
                   std::abs(r.linear_rgb[3 * q] - r.linear_rgb[3 * c]) < 0.02f;
        }
      }
      if (!smooth) continue;
      ++compared;
      for (int k = 0; k < 3; ++k) {
        worst = std::max(worst, static_cast<double>(
                                    std::abs(p.linear_rgb[3 * c + k] - r.linear_rgb[3 * c + k])));
      }
    }
  }
  EXPECT_GT(compared, camera.width * camera.height / 2);
  EXPECT_LT(worst, 0.01);

  // One light chosen per vertex: unbiased, so the difference is noise of zero mean.
  options.all_lights = false;
  const Frame q = PathTrace(scene, camera, options, &pool);
  std::vector<double> diff;
  for (size_t i = 0; i < q.object_ids.size(); ++i) {
    if (r.object_ids[i] != 0) diff.push_back(q.linear_rgb[3 * i] - p.linear_rgb[3 * i]);
  }
  const MeanError d = Stats(diff);
  EXPECT_NEAR(d.mean, 0, 4 * d.error + 1e-4);
}

// A white plane below a sphere light (radius R, radiance L, centre at height h): irradiance
// E = pi L (R / h)^2 at the foot point; below a rectangle lamp the form-factor formula; a small
// uniform disc sun gives its irradiance times the cosine.
TEST(PathTrace, AreaAndDiscLightsGiveAnalyticIrradiance) {
  for (const int kind : {0, 1, 2}) {
    const bool sphere = kind == 0;
    Scene scene;
    scene.AddObject(MakePlane(50, 50), Diffuse({1, 1, 1}), {}, 1);
    Camera camera = TestCamera(16, 16);
    camera.fx = camera.fy = 2000;  // a tiny patch around the foot point
    camera.camera_to_world = Transform::LookAt({0, 1, -0.3f}, {0, 0, 0}, {0, 0, 1});
    float expected = 0;
    if (sphere) {
      AreaLight l;
      l.shape = AreaLight::Shape::kSphere;
      l.centre = {0, 1.5f, 0};
      l.radius = 0.3f;
      l.radiance = {2, 2, 2};
      scene.area_lights().push_back(l);
      expected = kPi * 2 * (0.3f / 1.5f) * (0.3f / 1.5f) / kPi;
    } else if (kind == 1) {
      // Rectangle 2a x 2b at height c, centred above: four corner form factors (Howell C-11).
      AreaLight l;
      const float a = 0.4f, b = 0.25f, c = 1.2f;
      l.centre = {0, c, 0};
      l.half_u = {a, 0, 0};
      l.half_v = {0, 0, b};  // u x v = -y: facing the plane
      l.radiance = {3, 3, 3};
      scene.area_lights().push_back(l);
      const float ra = std::sqrt(a * a + c * c), rb = std::sqrt(b * b + c * c);
      const float f = (a / ra * std::atan(b / ra) + b / rb * std::atan(a / rb)) / (2 * kPi);
      expected = 3 * 4 * f;
    } else {
      DirectionalLight sun;
      sun.direction = Normalize({0.2f, 1, 0.1f});
      sun.irradiance = {3, 3, 3};
      sun.angular_radius = 0.05f;
      scene.directional_lights().push_back(sun);
      expected = 3 * sun.direction.y / kPi;  // cos-weighted: exact to O(r^2) for a small disc
    }
    scene.Commit();
    PathTraceOptions options;
    options.samples_per_pixel = 256;
    options.max_bounces = 0;
    const Frame f = PathTrace(scene, camera, options);
    std::vector<double> pixels;
    for (size_t p = 0; p < f.object_ids.size(); ++p) {
      ASSERT_EQ(f.object_ids[p], 1u);
      pixels.push_back(f.linear_rgb[3 * p]);
    }
    const MeanError s = Stats(pixels);
    EXPECT_NEAR(s.mean, expected, 0.002 * expected + 4 * s.error) << "light kind " << kind;
  }
}

TEST(PathTrace, RectangleLightIsOneSidedAndSeenByTheCamera) {
  Scene scene;
  AreaLight l;
  l.centre = {0, 0, 2};
  l.half_u = {0.5f, 0, 0};
  l.half_v = {0, 0.5f, 0};  // normal u x v = +z: away from the camera
  l.radiance = {1.5f, 1, 0.5f};
  l.id = 9;
  scene.area_lights().push_back(l);
  scene.Commit();
  PathTraceOptions options;
  options.samples_per_pixel = 4;
  const Camera camera = TestCamera();
  const size_t centre = static_cast<size_t>(camera.height / 2) * camera.width + camera.width / 2;
  Frame f = PathTrace(scene, camera, options);
  EXPECT_EQ(f.object_ids[centre], 9u);
  EXPECT_NEAR(f.depth_m[centre], 2, 1e-5f);
  EXPECT_NEAR(f.normals[3 * centre + 2], -1, 1e-6f);
  EXPECT_EQ(f.linear_rgb[3 * centre], 0.0f);  // its back
  std::swap(scene.area_lights()[0].half_u, scene.area_lights()[0].half_v);
  f = PathTrace(scene, camera, options);
  EXPECT_FLOAT_EQ(f.linear_rgb[3 * centre], 1.5f);
  EXPECT_FLOAT_EQ(f.linear_rgb[3 * centre + 2], 0.5f);
  EXPECT_EQ(f.object_ids[0], 0u);
}

TEST(PathTrace, IncidentRadianceShOfAnEnvironmentAndAnOccluder) {
  Scene scene;
  scene.environment().sh[0] = Vec3{1, 1, 1} * (2 * std::sqrt(kPi));
  scene.environment().sh[2] = Vec3{0.5f, 0.5f, 0.5f};
  scene.Commit();
  PathTraceOptions options;
  ThreadPool pool(2);
  const std::array<Vec3, 9> sh = IncidentRadianceSh(scene, {0, 0, 0}, 20000, options, &pool);
  EXPECT_NEAR(sh[0].x, 2 * std::sqrt(kPi), 0.01);
  EXPECT_NEAR(sh[2].x, 0.5f, 0.01);
  for (int i : {1, 3, 4, 5, 6, 7, 8}) EXPECT_NEAR(sh[i].y, 0, 0.01) << i;
  // A black floor below the probe hides the lower hemisphere: c_0 halves.
  Scene floor;
  floor.environment().sh[0] = Vec3{1, 1, 1} * (2 * std::sqrt(kPi));
  floor.AddObject(MakePlane(4000, 4000), Diffuse({0, 0, 0}), {}, 1);
  floor.Commit();
  const std::array<Vec3, 9> half = IncidentRadianceSh(floor, {0, 0.5f, 0}, 20000, options, &pool);
  EXPECT_NEAR(half[0].x, std::sqrt(kPi), 0.01);
  // Y_1,-1 = -sqrt(3 / (4 pi)) y: its integral over y > 0 is -sqrt(3 pi) / 2.
  EXPECT_NEAR(half[1].x, -std::sqrt(3 * kPi) / 2, 0.02);
  EXPECT_NEAR(half[3].x, 0, 0.01);
}

TEST(PathTrace, DeterministicAndCorrelated) {
  Scene scene;
  DirectScene(scene);
  scene.environment().sh[0] = {0.5f, 0.6f, 0.8f};
  PathTraceOptions options;
  options.samples_per_pixel = 8;
  options.max_bounces = 3;
  options.seed = 7;
  ThreadPool pool(2);
  const Camera camera = TestCamera();
  const Frame a = PathTrace(scene, camera, options, &pool);
  const Frame b = PathTrace(scene, camera, options, nullptr);
  EXPECT_EQ(a.linear_rgb, b.linear_rgb);
  EXPECT_EQ(a.srgb, b.srgb);
  EXPECT_EQ(a.rays, b.rays);
  options.rows_per_task = 3;
  EXPECT_EQ(PathTrace(scene, camera, options, &pool).linear_rgb, a.linear_rgb);
  options.rows_per_task = 8;

  // A tiny box far behind the camera, out of every path: no pixel changes.
  Scene far;
  DirectScene(far);
  far.environment().sh[0] = {0.5f, 0.6f, 0.8f};
  far.AddObject(MakeBox({0.01f, 0.01f, 0.01f}), Diffuse({1, 0, 0}),
                {Mat3::Identity(), {0, 50, -500}}, 5);
  far.Commit();
  EXPECT_EQ(PathTrace(far, camera, options, &pool).linear_rgb, a.linear_rgb);

  // A visible box: its pixels change, pixels whose paths never reach it do not.
  Scene near;
  DirectScene(near);
  near.environment().sh[0] = {0.5f, 0.6f, 0.8f};
  near.AddObject(MakeBox({0.2f, 0.2f, 0.2f}), Diffuse({1, 0, 0}),
                 {Mat3::Identity(), {0.6, -0.5, 2.0}}, 6);
  near.Commit();
  const Frame c = PathTrace(near, camera, options, &pool);
  int changed = 0, unchanged = 0, box = 0;
  for (size_t p = 0; p < c.object_ids.size(); ++p) {
    const bool differs = c.linear_rgb[3 * p] != a.linear_rgb[3 * p] ||
                         c.linear_rgb[3 * p + 1] != a.linear_rgb[3 * p + 1] ||
                         c.linear_rgb[3 * p + 2] != a.linear_rgb[3 * p + 2];
    if (c.object_ids[p] == 6) {
      ++box;
      EXPECT_TRUE(differs) << p;
    }
    (differs ? changed : unchanged) += 1;
  }
  EXPECT_GT(box, 20);
  EXPECT_GT(changed, box);
  EXPECT_GT(unchanged, static_cast<int>(c.object_ids.size()) / 10);
  options.seed = 8;
  EXPECT_NE(PathTrace(scene, camera, options, &pool).linear_rgb, a.linear_rgb);
}

TEST(PathTrace, ExposureScalesAndProgressReports) {
  Scene scene;
  DirectScene(scene);
  PathTraceOptions options;
  options.samples_per_pixel = 2;
  std::vector<std::pair<int, int>> calls;
  options.progress = [&](int done, int total) { calls.emplace_back(done, total); };
  ThreadPool pool(2);
  const Camera camera = TestCamera();
  const Frame a = PathTrace(scene, camera, options, &pool);
  ASSERT_FALSE(calls.empty());
  EXPECT_EQ(calls.back(), std::make_pair(camera.height, camera.height));
  for (size_t i = 1; i < calls.size(); ++i) EXPECT_GT(calls[i].first, calls[i - 1].first);
  options.exposure = 2;
  const Frame b = PathTrace(scene, camera, options, &pool);
  for (size_t i = 0; i < a.linear_rgb.size(); ++i) ASSERT_EQ(b.linear_rgb[i], 2 * a.linear_rgb[i]);
}

TEST(PathTrace, InvalidInputsThrowPreciseErrors) {
  Scene scene;
  PROBELESS_EXPECT_THROWS_MESSAGE(PathTrace(scene, TestCamera(8, 8), PathTraceOptions{}),
                                  RaytraceError, "PathTrace: scene not committed");
  scene.Commit();
  const Camera camera = TestCamera(8, 8);
  PathTraceOptions options;
  options.samples_per_pixel = 0;
  PROBELESS_EXPECT_THROWS_MESSAGE(PathTrace(scene, camera, options), RaytraceError,
                                  "PathTraceOptions: samples_per_pixel must be >= 1, got 0");
  options = {};
  options.max_bounces = -1;
  PROBELESS_EXPECT_THROWS_MESSAGE(PathTrace(scene, camera, options), RaytraceError,
                                  "PathTraceOptions: max_bounces must be >= 0, got -1");
  options = {};
  options.rows_per_task = 0;
  PROBELESS_EXPECT_THROWS_MESSAGE(PathTrace(scene, camera, options), RaytraceError,
                                  "PathTraceOptions: rows_per_task must be >= 1, got 0");
  PROBELESS_EXPECT_THROWS_MESSAGE(IncidentRadianceSh(scene, {}, 0, PathTraceOptions{}),
                                  RaytraceError,
                                  "IncidentRadianceSh: directions must be >= 1, got 0");
  Material m;
  m.roughness = 0;
  PROBELESS_EXPECT_THROWS_MESSAGE(scene.AddObject(MakeBox({1, 1, 1}), m, {}, 1), RaytraceError,
                                  "Scene::AddObject: Material::roughness must be in (0, 1], got 0");
  m.roughness = 1.5f;
  PROBELESS_EXPECT_THROWS_MESSAGE(
      scene.AddObject(MakeBox({1, 1, 1}), m, {}, 1), RaytraceError,
      "Scene::AddObject: Material::roughness must be in (0, 1], got 1.5");
  m.roughness = 0.5f;
  m.specular_f0 = 2;
  PROBELESS_EXPECT_THROWS_MESSAGE(
      scene.AddObject(MakeBox({1, 1, 1}), m, {}, 1), RaytraceError,
      "Scene::AddObject: Material::specular_f0 must be in [0, 1], got 2");
  m.specular_f0 = 0.5f;
  m.emission = {-1, 0, 0};
  PROBELESS_EXPECT_THROWS_MESSAGE(scene.AddObject(MakeBox({1, 1, 1}), m, {}, 1), RaytraceError,
                                  "Scene::AddObject: Material::emission must be >= 0");
  AreaLight l;
  l.half_v = {0, 0, 0};
  scene.area_lights().push_back(l);
  PROBELESS_EXPECT_THROWS_MESSAGE(
      PathTrace(scene, camera, PathTraceOptions{}), RaytraceError,
      "PathTrace: area light 0: half_u and half_v must span a non-zero area");
  scene.area_lights()[0] = AreaLight{.shape = AreaLight::Shape::kSphere, .radius = 0};
  PROBELESS_EXPECT_THROWS_MESSAGE(PathTrace(scene, camera, PathTraceOptions{}), RaytraceError,
                                  "PathTrace: area light 0: radius must be > 0, got 0");
  PROBELESS_EXPECT_THROWS_MESSAGE(BlackbodyRgb(500), RaytraceError,
                                  "BlackbodyRgb: kelvin must be in [1000, 40000], got 500");
}

TEST(PathTrace, BlackbodyColours) {
  const Vec3 w = BlackbodyRgb(6500);
  EXPECT_NEAR(w.x, 1, 0.06);
  EXPECT_NEAR(w.y, 1, 0.06);
  EXPECT_NEAR(w.z, 1, 0.06);
  EXPECT_NEAR(0.2126f * w.x + 0.7152f * w.y + 0.0722f * w.z, 1, 1e-5);
  const Vec3 warm = BlackbodyRgb(2700);
  EXPECT_GT(warm.x, 1.2f * warm.y);
  EXPECT_GT(warm.y, 1.5f * warm.z);
  const Vec3 cold = BlackbodyRgb(15000);
  EXPECT_GT(cold.z, cold.x);
}

TEST(PathTrace, ProceduralPatternsInTheObjectFrame) {
  ProceduralPattern checker;
  checker.kind = ProceduralPattern::Kind::kChecker;
  checker.color_b = {0, 0, 1};
  checker.period_m = 0.1f;
  const Vec3 base{1, 0, 0};
  EXPECT_NE(PatternAlbedo(checker, base, {0.01f, 0.01f, 0.01f}).z,
            PatternAlbedo(checker, base, {0.11f, 0.01f, 0.01f}).z);
  ProceduralPattern stripes = checker;
  stripes.kind = ProceduralPattern::Kind::kStripes;
  stripes.axis = {0, 1, 0};
  // Constant along the other axes.
  EXPECT_EQ(PatternAlbedo(stripes, base, {0.3f, 0.02f, 0.7f}).z,
            PatternAlbedo(stripes, base, {-0.4f, 0.02f, 0.1f}).z);
  ProceduralPattern noise = checker;
  noise.kind = ProceduralPattern::Kind::kValueNoise;
  for (int i = 0; i < 100; ++i) {
    const Vec3 a = PatternAlbedo(noise, base, {0.013f * i, 0.007f * i, -0.02f * i});
    ASSERT_GE(a.z, 0);
    ASSERT_LE(a.z, 1);
    ASSERT_NEAR(a.x + a.z, 1, 1e-5f);
  }
  // Surface() evaluates it in the object frame: a moved object keeps its pattern.
  Material m = Diffuse(base);
  m.pattern = checker;
  for (const double shift : {0.0, 0.37}) {
    Scene scene;
    scene.AddObject(MakePlane(1, 1), m, {Mat3::AxisAngle({1, 0, 0}, -kPi / 2), {shift, 0, 2}}, 1);
    scene.Commit();
    const Ray ray{{static_cast<float>(shift) + 0.05f, 0.05f, 0}, {0, 0, 1}};
    std::vector<Hit> hit(1);
    scene.Intersect({&ray, 1}, hit);
    const SurfacePoint s = scene.Surface(ray, hit[0]);
    EXPECT_NEAR(s.object_position.x, 0.05f, 1e-5f);
    EXPECT_EQ(s.albedo.z, PatternAlbedo(checker, base, s.object_position).z);
  }
}

}  // namespace
}  // namespace probeless::raytrace
