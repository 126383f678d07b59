// Unit tests of the near-field light (point_light.h) on analytic G-buffers: a floor, a back wall
// and a sphere seen by a pinhole camera, shaded by a known point lamp or a distant light (the
// image model of docs/light.md, "Near-field lamps"), plus the model choice and boundary errors.
#include "probeless/light/point_light.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <string>
#include <utility>

#include "probeless/testing/testing.h"

namespace {

using namespace probeless;
using light::Vec3f;

using probeless::testing::ThrownMessage;

constexpr double kPi = std::numbers::pi;
constexpr double kY0 = 0.28209479177387814;

// A 160 x 120 camera (x right, y down, z forward) looking at a floor (y = 1, normal -y), a back
// wall (z = 4, normal -z) and a sphere (centre (0.3, 0.5, 2.5), radius 0.4). Per pixel: depth,
// normal and an albedo (floor 0.4, wall 0.7, sphere 0.5 — told apart by colour).
struct Scene {
  int w = 160, h = 120;
  light::Intrinsics k{150, 150, 79.5, 59.5};
  std::vector<float> depth, normals, albedo;
  std::vector<uint8_t> colour;
  Scene() {
    depth.assign(w * h, 0);
    normals.assign(3 * w * h, 0);
    albedo.assign(w * h, 0);
    colour.assign(3 * w * h, 0);
    const double c[3] = {0.3, 0.5, 2.5}, radius = 0.4;
    for (int v = 0; v < h; ++v) {
      for (int u = 0; u < w; ++u) {
        const double d[3] = {(u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0};  // ray with z = 1
        double t = INFINITY, n[3] = {0, 0, 0}, a = 0;
        uint8_t rgb[3] = {0, 0, 0};
        if (d[1] > 0 && 1.0 / d[1] < t) {
          t = 1.0 / d[1], n[0] = 0, n[1] = -1, n[2] = 0, a = 0.4;
          rgb[0] = 150, rgb[1] = 110, rgb[2] = 70;
        }
        if (4.0 < t) {
          t = 4.0, n[0] = 0, n[1] = 0, n[2] = -1, a = 0.7;
          rgb[0] = 200, rgb[1] = 200, rgb[2] = 200;
        }
        // Sphere: |t d - c|^2 = r^2.
        const double dd = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        const double dc = d[0] * c[0] + d[1] * c[1] + d[2] * c[2];
        const double cc = c[0] * c[0] + c[1] * c[1] + c[2] * c[2];
        const double disc = dc * dc - dd * (cc - radius * radius);
        if (disc > 0) {
          const double ts = (dc - std::sqrt(disc)) / dd;
          if (ts > 0 && ts < t) {
            t = ts, a = 0.5;
            for (int i = 0; i < 3; ++i) n[i] = (t * d[i] - c[i]) / radius;
            rgb[0] = 60, rgb[1] = 90, rgb[2] = 200;
          }
        }
        const size_t p = static_cast<size_t>(v) * w + u;
        depth[p] = static_cast<float>(t);
        for (int i = 0; i < 3; ++i) {
          normals[3 * p + i] = static_cast<float>(n[i]);
          colour[3 * p + i] = rgb[i];
        }
        albedo[p] = static_cast<float>(a);
      }
    }
  }
  light::GeometryView View() const { return {w, h, k, depth, normals, {}}; }
  void Point(size_t p, double* x) const {
    const int u = static_cast<int>(p % w), v = static_cast<int>(p / w);
    x[0] = (u - k.cx) * depth[p] / k.fx, x[1] = (v - k.cy) * depth[p] / k.fy, x[2] = depth[p];
  }
  // I = albedo (P max(0, n.w) / (pi r^2) + ambient Y_0): the image model, no shadows.
  std::vector<float> LitByLamp(const double* lamp, double power, double ambient) const {
    std::vector<float> out(w * h);
    for (size_t p = 0; p < out.size(); ++p) {
      double x[3];
      Point(p, x);
      const double v[3] = {lamp[0] - x[0], lamp[1] - x[1], lamp[2] - x[2]};
      const double r2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
      const double cosine =
          (normals[3 * p] * v[0] + normals[3 * p + 1] * v[1] + normals[3 * p + 2] * v[2]) /
          std::sqrt(r2);
      out[p] = static_cast<float>(albedo[p] *
                                  (power * std::max(0.0, cosine) / (kPi * r2) + ambient * kY0));
    }
    return out;
  }
  std::vector<float> LitByDistant(const double* d, double irradiance, double ambient) const {
    std::vector<float> out(w * h);
    for (size_t p = 0; p < out.size(); ++p) {
      const double cosine =
          normals[3 * p] * d[0] + normals[3 * p + 1] * d[1] + normals[3 * p + 2] * d[2];
      out[p] = static_cast<float>(albedo[p] *
                                  (irradiance * std::max(0.0, cosine) / kPi + ambient * kY0));
    }
    return out;
  }
  // SurfaceLightingTruth's dominant direction for a lamp: the normalised mean of irradiance x
  // unit direction over every 8th pixel.
  Vec3f TrueDirection(const double* lamp) const {
    double s[3] = {0, 0, 0};
    for (int v = 4; v < h; v += 8) {
      for (int u = 4; u < w; u += 8) {
        double x[3];
        Point(static_cast<size_t>(v) * w + u, x);
        const double d[3] = {lamp[0] - x[0], lamp[1] - x[1], lamp[2] - x[2]};
        const double r2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        for (int i = 0; i < 3; ++i) s[i] += d[i] / (r2 * std::sqrt(r2));
      }
    }
    const double len = std::sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2]);
    return {static_cast<float>(s[0] / len), static_cast<float>(s[1] / len),
            static_cast<float>(s[2] / len)};
  }
};

// The SSDO transfer (default options, one thread) of the scene's G-buffer with its colour.
light::TransferResult TransferOf(const Scene& s) {
  light::TransferOptions to;
  to.threads = 1;
  light::TransferResult t;
  light::TransferComputer(to).Compute(
      light::GeometryView{s.w, s.h, s.k, s.depth, s.normals, s.colour}, {}, nullptr, &t);
  return t;
}

double AngleDeg(const Vec3f& a, const Vec3f& b) {
  const double dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  return std::acos(std::clamp(dot, -1.0, 1.0)) * 180 / kPi;
}

TEST(PointLight, RecoversLampPositionAndDirection) {
  const double lamp[3] = {-0.5, -0.6, 2.0};
  for (bool colour : {false, true}) {
    // Without colour one albedo is fitted: the scene has one (0.6); with colour, each object has
    // its own and the fit gets one per chromaticity group.
    Scene s;
    if (!colour) std::fill(s.albedo.begin(), s.albedo.end(), 0.6f);
    const std::vector<float> image = s.LitByLamp(lamp, 3.0, 0.1);
    light::PointLightOptions o;
    if (!colour) o.albedo_groups = 0;
    const auto e = light::EstimatePointLight(
        s.View(), image, o, 3, nullptr,
        colour ? std::span<const uint8_t>(s.colour) : std::span<const uint8_t>());
    ASSERT_TRUE(e.valid);
    ASSERT_EQ(e.lamps.size(), 1u);
    const auto& p = e.lamps[0].position;
    const double dist =
        std::sqrt((p[0] - lamp[0]) * (p[0] - lamp[0]) + (p[1] - lamp[1]) * (p[1] - lamp[1]) +
                  (p[2] - lamp[2]) * (p[2] - lamp[2]));
    EXPECT_LT(dist, 0.03) << "colour " << colour << ": lamp at " << p[0] << " " << p[1] << " "
                          << p[2];
    EXPECT_LT(AngleDeg(e.light.dominant_direction, s.TrueDirection(lamp)), 1.0);
    EXPECT_GT(e.light.confidence, 0.9f);
    // One albedo equal to PointLightOptions::albedo: the intensity is the lamp's (with groups it is
    // scaled by the albedos' row mean).
    if (!colour) {
      EXPECT_NEAR(e.lamps[0].intensity, 3.0, 0.05);
    }
    EXPECT_TRUE(e.prefers_point) << "residual point " << e.median_residual_point << ", distant "
                                 << e.median_residual_distant << ", spread " << e.spread_deg;
  }
}

TEST(PointLight, SecondLampIsFound) {
  const Scene s;
  const double a[3] = {-0.6, -0.6, 2.0}, b[3] = {1.2, 0.2, 1.8};
  std::vector<float> image = s.LitByLamp(a, 3.0, 0.1);
  const std::vector<float> second = s.LitByLamp(b, 1.5, 0.0);
  for (size_t i = 0; i < image.size(); ++i) image[i] += second[i];
  light::PointLightOptions o;
  o.max_lamps = 2;
  const auto e = light::EstimatePointLight(s.View(), image, o, 3, nullptr, s.colour);
  ASSERT_TRUE(e.valid);
  ASSERT_EQ(e.lamps.size(), 2u);
  for (const auto& [truth, lamp] : {std::pair{a, e.lamps[0]}, std::pair{b, e.lamps[1]}}) {
    const auto& p = lamp.position;
    const double dist = std::hypot(p[0] - truth[0], p[1] - truth[1], p[2] - truth[2]);
    EXPECT_LT(dist, 0.05) << p[0] << " " << p[1] << " " << p[2];
  }
}

TEST(PointLight, DistantLightMakesAutoPickDistant) {
  const Scene s;
  const double d0[3] = {-0.4, -0.8, -0.3};
  const double len = std::sqrt(d0[0] * d0[0] + d0[1] * d0[1] + d0[2] * d0[2]);
  const double d[3] = {d0[0] / len, d0[1] / len, d0[2] / len};
  const std::vector<float> image = s.LitByDistant(d, 2.0, 0.1);
  light::PointLightOptions o;
  o.screen_rows = 0;  // the full rule (the screen is ScreenKeepsTheDistantResultBitIdentical's)
  const auto e = light::EstimatePointLight(s.View(), image, o, 3, nullptr, s.colour);
  ASSERT_TRUE(e.valid);
  EXPECT_FALSE(e.prefers_point) << "residual point " << e.median_residual_point << ", distant "
                                << e.median_residual_distant << ", spread " << e.spread_deg;
  // Whatever the point model did, its direction at the scene is the light's.
  EXPECT_LT(
      AngleDeg(e.light.dominant_direction,
               {static_cast<float>(d[0]), static_cast<float>(d[1]), static_cast<float>(d[2])}),
      5.0);
}

// The model choice of EstimateSceneLight on the transfer of the same G-buffer: distant keeps
// EstimateLight's estimate; point and auto take the lamp fit under a lamp; auto keeps the distant
// estimate under a distant light.
TEST(PointLight, SceneLightSelectsTheModel) {
  const Scene s;
  const light::GeometryView view{s.w, s.h, s.k, s.depth, s.normals, s.colour};
  const light::TransferResult t = TransferOf(s);
  const double lamp[3] = {-0.5, -0.6, 2.0};
  const std::vector<float> lamp_image = s.LitByLamp(lamp, 3.0, 0.1);
  light::SceneLightOptions o;
  for (auto model :
       {light::LightModel::kDistant, light::LightModel::kPoint, light::LightModel::kAuto}) {
    o.model = model;
    const auto r = light::EstimateSceneLight(view, t, lamp_image, o, s.colour);
    ASSERT_TRUE(r.light.valid);
    if (model == light::LightModel::kDistant) {
      EXPECT_EQ(r.used, light::LightModel::kDistant);
      EXPECT_FALSE(r.point.valid);  // not run
      EXPECT_EQ(r.light.coefficients, r.distant.coefficients);
    } else {
      EXPECT_EQ(r.used, light::LightModel::kPoint) << light::LightModelName(model);
      EXPECT_FALSE(r.point.screened_out);
      EXPECT_EQ(r.light.coefficients, r.point.light.coefficients);
      EXPECT_LT(AngleDeg(r.light.dominant_direction, s.TrueDirection(lamp)), 1.0);
    }
  }
  const double d[3] = {0, -0.8, -0.6};
  o.model = light::LightModel::kAuto;
  const auto r = light::EstimateSceneLight(view, t, s.LitByDistant(d, 2.0, 0.1), o, s.colour);
  EXPECT_TRUE(r.point.valid || r.point.screened_out);
  EXPECT_EQ(r.used, light::LightModel::kDistant);
  EXPECT_EQ(r.light.coefficients, r.distant.coefficients);
}

double Distance(const Vec3f& a, const Vec3f& b) {
  return std::hypot(a[0] - b[0], a[1] - b[1], a[2] - b[2]);
}

// Two frames of a stream: the lamp moves by 0.25 m between them. The second frame started from the
// first frame's lamp (PointLightTracker) ends where a cold start on that frame ends, both when the
// previous lamp is close (the warm fit is kept) and when the tracker holds a wrong lamp (the cold
// search takes over).
TEST(PointLight, WarmStartConvergesToTheColdLamp) {
  const Scene s;
  const double first[3] = {-0.5, -0.6, 2.0}, second[3] = {-0.3, -0.75, 2.1};
  const std::vector<float> image1 = s.LitByLamp(first, 3.0, 0.1);
  const std::vector<float> image2 = s.LitByLamp(second, 2.5, 0.1);
  light::PointLightOptions o;
  o.select_model = false;
  const auto cold = light::EstimatePointLight(s.View(), image2, o, 3, nullptr, s.colour);
  ASSERT_TRUE(cold.valid);
  EXPECT_FALSE(cold.warm_started);
  EXPECT_LT(std::hypot(cold.lamps[0].position[0] - second[0], cold.lamps[0].position[1] - second[1],
                       cold.lamps[0].position[2] - second[2]),
            0.03);

  light::PointLightTracker tracker;
  const auto e1 =
      light::EstimatePointLight(s.View(), image1, o, 3, nullptr, s.colour, nullptr, &tracker);
  ASSERT_TRUE(e1.valid);
  ASSERT_TRUE(tracker.Active());
  EXPECT_NEAR(tracker.position[0], e1.lamps[0].position[0], 1e-6);
  const auto warm =
      light::EstimatePointLight(s.View(), image2, o, 3, nullptr, s.colour, nullptr, &tracker);
  ASSERT_TRUE(warm.valid);
  EXPECT_TRUE(warm.warm_started);
  EXPECT_LT(Distance(warm.lamps[0].position, cold.lamps[0].position), 0.01);
  EXPECT_LT(AngleDeg(warm.light.dominant_direction, cold.light.dominant_direction), 0.2);
  EXPECT_NEAR(tracker.position[2], warm.lamps[0].position[2], 1e-6);  // updated

  // A wrong lamp behind the camera: the warm fit is worse than the previous frame's, the cold
  // search runs too and wins.
  tracker.position = {0.5f, 1.5f, -1.0f};
  tracker.intensity = {0.2f};
  const auto wrong =
      light::EstimatePointLight(s.View(), image2, o, 3, nullptr, s.colour, nullptr, &tracker);
  ASSERT_TRUE(wrong.valid);
  EXPECT_FALSE(wrong.warm_started);  // the cold fit was kept
  EXPECT_LT(Distance(wrong.lamps[0].position, cold.lamps[0].position), 0.01);
}

// Under a distant light the screen rejects the point model on its subset of rows and auto returns
// EstimateLight's estimate, bit for bit the distant model's; the tracker is left empty.
TEST(PointLight, ScreenKeepsTheDistantResultBitIdentical) {
  const Scene s;
  const light::GeometryView view{s.w, s.h, s.k, s.depth, s.normals, s.colour};
  const light::TransferResult t = TransferOf(s);
  const double d0[3] = {-0.4, -0.8, -0.3};
  const double len = std::sqrt(d0[0] * d0[0] + d0[1] * d0[1] + d0[2] * d0[2]);
  const double d[3] = {d0[0] / len, d0[1] / len, d0[2] / len};
  const std::vector<float> image = s.LitByDistant(d, 2.0, 0.1);
  light::SceneLightOptions o;
  o.model = light::LightModel::kDistant;
  const auto distant = light::EstimateSceneLight(view, t, image, o, s.colour);
  o.model = light::LightModel::kAuto;
  light::PointLightTracker tracker;
  tracker.position = {0, -1, 2};  // a lamp from an earlier frame: not used, warm fits run
  tracker.intensity = {1};
  for (int screen_rows : {400, 0}) {
    o.point.screen_rows = screen_rows;
    tracker.position = {0, -1, 2};
    tracker.intensity = {1};
    const auto warm = light::EstimateSceneLight(view, t, image, o, s.colour, &tracker);
    // The warm fit is rejected, so the frame gets the cold fit (screened) a fresh stream makes.
    EXPECT_FALSE(warm.point.warm_started);
    EXPECT_EQ(warm.point.screened_out, screen_rows > 0) << screen_rows;
    EXPECT_EQ(warm.used, light::LightModel::kDistant);
    EXPECT_EQ(warm.light.coefficients, distant.light.coefficients);
    EXPECT_FALSE(tracker.Active());  // reset: the next frame starts cold
    const auto r = light::EstimateSceneLight(view, t, image, o, s.colour, &tracker);
    EXPECT_EQ(r.point.screened_out, screen_rows > 0) << screen_rows;
    EXPECT_EQ(r.used, light::LightModel::kDistant);
    EXPECT_EQ(r.light.coefficients, distant.light.coefficients);  // bit-identical
    EXPECT_EQ(r.light.dominant_direction, distant.light.dominant_direction);
    EXPECT_EQ(r.light.intensity, distant.light.intensity);
    EXPECT_FALSE(tracker.Active());
  }
  // Under a lamp the screen lets the point model through: the same choice and lamp as without it.
  const double lamp[3] = {-0.5, -0.6, 2.0};
  const std::vector<float> lamp_image = s.LitByLamp(lamp, 3.0, 0.1);
  o.point.screen_rows = 400;
  const auto screened = light::EstimateSceneLight(view, t, lamp_image, o, s.colour);
  o.point.screen_rows = 0;
  const auto unscreened = light::EstimateSceneLight(view, t, lamp_image, o, s.colour);
  EXPECT_FALSE(screened.point.screened_out);
  EXPECT_EQ(screened.used, light::LightModel::kPoint);
  EXPECT_EQ(unscreened.used, light::LightModel::kPoint);
  ASSERT_FALSE(screened.point.lamps.empty());
  ASSERT_FALSE(unscreened.point.lamps.empty());
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(screened.point.lamps[0].position[k], unscreened.point.lamps[0].position[k], 0.01);
  }
}

TEST(PointLight, BadInputThrowsClearErrors) {
  Scene s;
  const std::vector<float> image = s.LitByLamp(std::array<double, 3>{0, -0.5, 2}.data(), 2, 0.1);
  std::vector<float> none(s.depth.size(), 0.0f);
  light::GeometryView empty{s.w, s.h, s.k, none, s.normals, {}};
  EXPECT_EQ(
      ThrownMessage<light::LightError>([&] { light::EstimatePointLight(empty, image, {}, 3); }),
      "light::EstimatePointLight: no valid pixels (depth > 0 with a normal)");
  light::GeometryView nan = s.View();
  nan.intrinsics.fx = NAN;
  EXPECT_EQ(ThrownMessage<light::LightError>([&] { light::EstimatePointLight(nan, image, {}, 3); }),
            "light::EstimatePointLight: non-finite intrinsics");
  EXPECT_EQ(ThrownMessage<light::LightError>(
                [&] { light::EstimatePointLight(s.View(), std::span(image).first(10), {}, 3); }),
            "light::EstimatePointLight: intensity has 10 values, expected 160x120");
  light::PointLightOptions three;
  three.max_lamps = 3;
  EXPECT_EQ(ThrownMessage<light::LightError>(
                [&] { light::EstimatePointLight(s.View(), image, three, 3); }),
            "light::EstimatePointLight: max_lamps must be 1 or 2");
  light::PointLightOptions screen;
  screen.screen_rows = -1;
  EXPECT_EQ(ThrownMessage<light::LightError>(
                [&] { light::EstimatePointLight(s.View(), image, screen, 3); }),
            "light::EstimatePointLight: screen_rows must be >= 0, warm_lm_iterations and "
            "screen_lm_iterations >= 1");
  EXPECT_EQ(ThrownMessage<light::LightError>([] { light::ParseLightModel("near"); }),
            "light::ParseLightModel: light model must be distant, point or auto, got 'near'");
  EXPECT_EQ(light::ParseLightModel("auto"), light::LightModel::kAuto);
  EXPECT_STREQ(light::LightModelName(light::LightModel::kPoint), "point");
}

}  // namespace
