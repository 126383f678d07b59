// Differential rendering from G_r (render/differential.h) on analytic buffers: a wall 2 m in front
// of a 320x240 camera, virtual objects rasterised into it (G_r'), the SSDO of both buffers and
// eq. 13-15 against analytic references (the cosine-weighted occlusion of a sphere, its hard
// shadow), real geometry hiding the object, colour bleeding from a red box, bytes outside the
// change kept exactly, face mode's G_r from the proxy head, and the boundary errors.
#include "probeless/render/differential.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <numbers>
#include <vector>

#include "probeless/prt/demo_objects.h"
#include "probeless/prt/prt.h"
#include "probeless/raytrace/mesh.h"
#include "probeless/raytrace/render.h"
#include "probeless/render/msgs_io.h"
#include "probeless/sh/sh.h"
#include "probeless/testing/testing.h"

namespace {

using namespace probeless;
using probeless::testing::ThrownMessage;

constexpr int kW = 320, kH = 240;
constexpr float kWallZ = 2.0f;

// G_r of the wall z = 2 m (normal towards the camera), sRGB colour 235 (white), optionally with a
// real box: the pixels of columns [box_u0, box_u1) at depth box_z.
struct Wall {
  light::Intrinsics k{300, 300, 159.5, 119.5};
  std::vector<float> depth, normals;
  std::vector<uint8_t> colour;
  explicit Wall(int box_u0 = 0, int box_u1 = 0, float box_z = 0) {
    depth.assign(kW * kH, kWallZ);
    normals.assign(3 * kW * kH, 0);
    colour.assign(3 * kW * kH, 235);
    for (int p = 0; p < kW * kH; ++p) {
      normals[3 * p + 2] = -1;
      const int u = p % kW;
      if (u >= box_u0 && u < box_u1) depth[p] = box_z;
    }
  }
  light::GeometryView View() const { return {kW, kH, k, depth, normals, colour}; }
  // The pixel of the wall point (x, y, 2).
  size_t Pixel(double x, double y) const {
    const int u = static_cast<int>(std::lround(k.cx + k.fx * x / kWallZ));
    const int v = static_cast<int>(std::lround(k.cy + k.fy * y / kWallZ));
    return static_cast<size_t>(v) * kW + u;
  }
};

raytrace::Transform At(double x, double y, double z) {
  raytrace::Transform t;
  t.translation = {x, y, z};
  return t;
}

// A white light of `bands` bands: uniform radiance `ambient` plus a directional lamp of `power`
// towards `d` (camera frame), sh::DirectionalLight's projection.
render::ShLightRgb Light(double ambient, sh::Vec3 d, double power) {
  render::ShLightRgb l;
  l.bands = 4;
  const std::vector<double> c = sh::DirectionalLight(d, power, 4);
  for (int k = 0; k < 16; ++k) {
    const double v = c[k] + (k == 0 ? ambient * 2 * std::sqrt(std::numbers::pi) : 0.0);
    for (int ch = 0; ch < 3; ++ch) l.coefficients[k][ch] = static_cast<float>(v);
  }
  return l;
}

// The eq. 13 factor (red channel) of pixel p, 1 outside the window.
float Factor(const render::DifferentialResult& r, size_t p) {
  const int u = static_cast<int>(p % kW), v = static_cast<int>(p / kW);
  const auto& w = r.window;
  if (u < w.x0 || u >= w.x1 || v < w.y0 || v >= w.y1) return 1;
  return r.factor[3 * ((v - w.y0) * w.width() + (u - w.x0))];
}
const float* Indirect(const render::DifferentialResult& r, size_t p) {
  const int u = static_cast<int>(p % kW), v = static_cast<int>(p / kW);
  const auto& w = r.window;
  static const float zero[3] = {0, 0, 0};
  if (u < w.x0 || u >= w.x1 || v < w.y0 || v >= w.y1) return zero;
  return &r.indirect[3 * ((v - w.y0) * w.width() + (u - w.x0))];
}

TEST(Rasterise, SphereIntoTheWallAndARealBoxHidesIt) {
  const raytrace::Mesh sphere = raytrace::MakeSphere(0.15f, 64);
  const Wall wall;
  render::RasterObject o{&sphere, At(0, 0, 1.85), {0.8f, 0.1f, 0.1f}, true};
  render::VirtualGeometry g;
  render::RasteriseObjects(wall.View(), {&o, 1}, &g);
  const size_t centre = wall.Pixel(0, 0);
  EXPECT_EQ(g.object_id[centre], 1);
  EXPECT_NEAR(g.depth[centre], 1.70f, 0.002f);
  EXPECT_NEAR(g.normals[3 * centre + 2], -1.0f, 0.01f);
  EXPECT_EQ(g.colour[3 * centre], raytrace::LinearToSrgb8(0.8f));
  // The silhouette: the tangent cone of the sphere, radius f r / sqrt(z^2 - r^2) pixels.
  const double radius_px = 300 * 0.15 / std::sqrt(1.85 * 1.85 - 0.15 * 0.15);
  EXPECT_NEAR(g.footprint.width(), 2 * radius_px, 2.0);
  EXPECT_NEAR(g.footprint.height(), 2 * radius_px, 2.0);
  EXPECT_NEAR(g.min_virtual_depth, 1.70f, 0.003f);
  EXPECT_EQ(g.object_id[wall.Pixel(0.5, 0)], 0);
  EXPECT_EQ(g.depth[wall.Pixel(0.5, 0)], kWallZ);

  // A real box at 1 m over the left half of the sphere: G_r' keeps it there.
  const Wall boxed(0, 160, 1.0f);
  render::RasteriseObjects(boxed.View(), {&o, 1}, &g);
  EXPECT_EQ(g.object_id[boxed.Pixel(-0.02, 0)], 0);
  EXPECT_EQ(g.depth[boxed.Pixel(-0.02, 0)], 1.0f);
  EXPECT_EQ(g.object_id[boxed.Pixel(0.02, 0)], 1);
  EXPECT_EQ(g.footprint.x0, 160);
}

// Ambient light only: the shading ratio beside a sphere touching the wall is 1 minus its
// cosine-weighted solid angle, sin^2(theta) cos(alpha) = (a / d)^3 for a sphere of radius a at
// distance d from the point (the centre a in front of the wall). Screen-space SSDO sees only the
// samples that reach behind the sphere's front surface within its radius (0.3 m), so it finds part
// of that darkening, less with distance: measured 54 % at 0.24 m, 38 % at 0.3 m (docs/render.md).
// Averaged over the pixels of a ring about the contact point (32 jittered directions are noisy
// per pixel).
TEST(Differential, SphereOnAWallMatchesTheAnalyticOcclusion) {
  const raytrace::Mesh sphere = raytrace::MakeSphere(0.15f, 64);
  const Wall wall;
  render::RasterObject o{&sphere, At(0, 0, kWallZ - 0.15), {0.7f, 0.7f, 0.7f}, true};
  render::VirtualGeometry g;
  render::RasteriseObjects(wall.View(), {&o, 1}, &g);
  render::DifferentialRenderer renderer({});
  render::DifferentialFrame f;
  f.real = wall.View();
  f.with_virtual = &g;
  // Open wall: R = (A_0 / pi) Y_00 L_0 = ambient = 0.99, so with T(x) = min(1, x) the factor of
  // eq. 13 is 1 + R' - R = the ratio R' / R minus 1 % of the darkening.
  f.light = Light(0.99, {0, 0, -1}, 0);
  f.camera_tone = {render::ToneOperator::kClamp, 1, 4};
  render::DifferentialResult r;
  renderer.Compute(f, &r);
  ASSERT_FALSE(r.window.empty());
  double previous = 1;
  for (double ring : {0.2, 0.24, 0.3}) {
    double sum = 0;
    int n = 0;
    for (int a = 0; a < 72; ++a) {
      const double t = a * std::numbers::pi / 36;
      const size_t p = wall.Pixel(ring * std::cos(t), ring * std::sin(t));
      if (g.object_id[p] != 0) continue;
      sum += 1 - Factor(r, p);
      ++n;
    }
    ASSERT_GT(n, 36);
    const double darkening = sum / n;
    const double analytic = 0.99 * std::pow(0.15 / std::hypot(ring, 0.15), 3);
    EXPECT_GT(darkening, 0.3 * analytic) << "ring " << ring << " m";
    EXPECT_LT(darkening, 1.05 * analytic) << "ring " << ring << " m";
    EXPECT_LT(darkening, previous) << "less darkening farther away";
    previous = darkening;
  }
  // Out of the SSDO's reach: the camera byte stays (factor exactly 1).
  EXPECT_EQ(Factor(r, wall.Pixel(0.75, 0)), 1.0f);
}

// A sphere of radius a touching the wall, lit by a lamp from the right (+x) and the camera side at
// 45 degrees: G_r' and the frame of the tests below.
struct SphereBeforeWall {
  static constexpr double a = 0.15;
  const raytrace::Mesh sphere = raytrace::MakeSphere(static_cast<float>(a), 64);
  const Wall wall;
  const sh::Vec3 c{0, 0, kWallZ - a};
  const render::RasterObject o{&sphere, At(c[0], c[1], c[2]), {0.7f, 0.7f, 0.7f}, true};
  const double s = std::sqrt(0.5);
  const sh::Vec3 d{s, 0, -s};  // towards the light
  render::VirtualGeometry g;
  render::DifferentialFrame f;
  SphereBeforeWall() {
    render::RasteriseObjects(wall.View(), {&o, 1}, &g);
    f.real = wall.View();
    f.with_virtual = &g;
    // Irradiance/pi on the open wall: ambient 0.2 + the lamp's cos 45 deg share, about 0.9 in all.
    f.light = Light(0.2, d, 0.7 / s * std::numbers::pi);
    f.camera_tone = {render::ToneOperator::kClamp, 1, 4};
  }
};

// The hard shadow of the sphere falls to the left; the wall darkens there and hardly on the lit
// side (only the ambient part is occluded there).
TEST(Differential, SphereShadowFallsAwayFromTheLight) {
  const SphereBeforeWall scene;
  const Wall& wall = scene.wall;
  const double a = scene.a;
  const sh::Vec3& c = scene.c;
  const sh::Vec3& d = scene.d;
  // The analytic hard shadow: does the ray from the wall point (x, 0, 2) towards d hit the sphere?
  auto shadowed = [&](double x) {
    const double v[3] = {c[0] - x, c[1], c[2] - kWallZ};
    const double along = v[0] * d[0] + v[1] * d[1] + v[2] * d[2];
    const double perp2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2] - along * along;
    return along > 0 && perp2 < a * a;
  };
  ASSERT_TRUE(shadowed(-0.2));
  ASSERT_FALSE(shadowed(0.2));
  render::DifferentialRenderer renderer({});
  render::DifferentialResult r;
  renderer.Compute(scene.f, &r);
  auto mean_darkening = [&](double x) {
    double sum = 0;
    int n = 0;
    for (double y = -0.06; y <= 0.061; y += 0.02) {
      sum += 1 - Factor(r, wall.Pixel(x, y));
      ++n;
    }
    return sum / n;
  };
  const double away = mean_darkening(-0.2), towards = mean_darkening(0.2);
  EXPECT_GT(away, 0.25) << "in the analytic shadow";
  EXPECT_LT(towards, 0.1) << "lit side";
  EXPECT_GT(away, 4 * towards);
}

// The sun's crisp shadow (sun_shadow): the same sphere and lamp as above; the wall points whose
// ray towards the lamp hits the sphere get the lamp's share taken away, up to the analytic edge.
TEST(Differential, SunShadowIsCrispWhereTheRayHitsTheSphere) {
  SphereBeforeWall scene;
  const Wall& wall = scene.wall;
  const double a = scene.a, s = scene.s;
  const sh::Vec3& d = scene.d;
  // On the wall (x, 0, 2) the hard shadow spans x in [-0.15 - a / s, -0.15 + a / s]; the sphere
  // hides it right of x = -0.162.
  const double edge = -0.15 - a / s;
  render::DifferentialOptions options;
  options.tone = render::DifferentialTone::kRatio;
  render::DifferentialFrame& f = scene.f;
  f.dominant = {{static_cast<float>(d[0]), 0.0f, static_cast<float>(d[2])}, 1.0f};
  f.objects = {&scene.o, 1};
  render::DifferentialResult soft, crisp;
  render::DifferentialRenderer(options).Compute(f, &soft);
  options.sun_shadow = true;
  render::DifferentialRenderer(options).Compute(f, &crisp);
  // The lamp's amplitude recovered from the light's own bands 1 and 2-3.
  EXPECT_NEAR(crisp.sun_amplitude[0], 0.7 / s * std::numbers::pi,
              0.01 * 0.7 / s * std::numbers::pi);
  EXPECT_GT(crisp.sun_shadow_pixels, 500);
  auto at = [&](const render::DifferentialResult& r, double x) {
    return Factor(r, wall.Pixel(x, 0));
  };
  // Inside: only the ambient 0.2 of about 0.9 is left (0.22, a little less for the contact
  // occlusion of the rest by SSDO); the soft SH shadow alone keeps much more.
  EXPECT_LT(at(crisp, -0.26), 0.3);
  EXPECT_GT(at(soft, -0.26), at(crisp, -0.26) + 0.2);
  // Crisp: 2 cm inside the edge still dark, 2 cm outside lit.
  EXPECT_LT(at(crisp, edge + 0.02), 0.3);
  EXPECT_GT(at(crisp, edge - 0.02), 0.97);
  // The lit side: the sphere blocks none of the lamp there, so what the SH lobe's SSDO occlusion
  // took from it comes back.
  EXPECT_GE(at(crisp, 0.3), at(soft, 0.3));
  EXPECT_GT(at(crisp, 0.3), 0.97);

  // A smooth light (ambient and a band-1 gradient, nothing above): no delta, no crisp shadow, the
  // same result as without sun_shadow.
  render::ShLightRgb smooth = Light(0.5, d, 0);
  for (int ch = 0; ch < 3; ++ch) smooth.coefficients[3][ch] = 0.3f;
  f.light = smooth;
  render::DifferentialResult off, on;
  options.sun_shadow = false;
  render::DifferentialRenderer(options).Compute(f, &off);
  options.sun_shadow = true;
  render::DifferentialRenderer(options).Compute(f, &on);
  EXPECT_EQ(on.sun_amplitude[0], 0.0f);
  EXPECT_EQ(on.factor, off.factor);
  EXPECT_EQ(on.window.x0, off.window.x0);
}

// A red virtual box against the white wall, lit from the right: its lit +x face bounces red light
// onto the wall to its right (eq. 10-12 in R'_i, eq. 14-15), nothing onto the unlit left side.
TEST(Differential, RedBoxTintsTheWhiteWall) {
  const raytrace::Mesh box = raytrace::MakeBox({0.2f, 0.2f, 0.2f});
  const Wall wall;
  // Left of the camera axis so that its +x face is in view (SSDO sees only what G_r' shows).
  render::RasterObject o{&box, At(-0.3, 0, kWallZ - 0.1), {0.9f, 0.05f, 0.05f}, true};
  render::VirtualGeometry g;
  render::RasteriseObjects(wall.View(), {&o, 1}, &g);
  const sh::Vec3 d{2 / std::sqrt(5.0), 0, -1 / std::sqrt(5.0)};
  render::DifferentialRenderer renderer({});
  render::DifferentialFrame f;
  f.real = wall.View();
  f.with_virtual = &g;
  f.light = Light(0.2, d, 2.0);
  f.dominant = {{static_cast<float>(d[0]), 0, static_cast<float>(d[2])}, 2.0f};
  f.camera_tone = {render::ToneOperator::kClamp, 1, 4};
  const std::vector<uint8_t> camera(3 * kW * kH, 200);
  f.camera_rgb = camera;
  render::DifferentialResult r;
  renderer.Compute(f, &r);
  double right[3] = {0, 0, 0}, left = 0;
  for (double y = -0.06; y <= 0.061; y += 0.02) {
    const float* i = Indirect(r, wall.Pixel(-0.17, y));
    for (int c = 0; c < 3; ++c) right[c] += i[c];
    left += Indirect(r, wall.Pixel(-0.43, y))[0];
  }
  EXPECT_GT(right[0], 0.02) << "red bounce beside the lit face";
  EXPECT_GT(right[0], 8 * right[1]);
  EXPECT_GT(right[0], 8 * right[2]);
  EXPECT_LT(left, 0.1 * right[0]) << "the unlit face bounces nothing";

  // Applied to the camera image: the tinted pixel turns red, far pixels keep their bytes.
  std::vector<uint8_t> image = camera;
  render::ApplyDifferential(r, kW, kH, image);
  const size_t p = wall.Pixel(-0.17, 0);
  EXPECT_GT(image[3 * p], image[3 * p + 1]);
  const size_t far = wall.Pixel(0.75, 0.3);
  EXPECT_EQ(image[3 * far], 200);
  size_t changed_outside = 0;
  for (size_t q = 0; q < image.size() / 3; ++q) {
    const int u = static_cast<int>(q % kW), v = static_cast<int>(q / kW);
    const bool inside = u >= r.window.x0 && u < r.window.x1 && v >= r.window.y0 && v < r.window.y1;
    if (!inside && (image[3 * q] != 200 || image[3 * q + 1] != 200 || image[3 * q + 2] != 200)) {
      ++changed_outside;
    }
  }
  EXPECT_EQ(changed_outside, 0u);
}

// Subsampled windows (step 2) and the average-intensity key tone: same signs, no change without
// objects.
TEST(Differential, StepAndAverageKeyAndNoObjects) {
  const raytrace::Mesh sphere = raytrace::MakeSphere(0.15f, 64);
  const Wall wall;
  render::RasterObject o{&sphere, At(0, 0, kWallZ - 0.15), {0.7f, 0.7f, 0.7f}, true};
  render::VirtualGeometry g;
  render::RasteriseObjects(wall.View(), {&o, 1}, &g);
  render::DifferentialFrame f;
  f.real = wall.View();
  f.with_virtual = &g;
  f.light = Light(0.99, {0, 0, -1}, 0);
  f.camera_tone = {render::ToneOperator::kClamp, 1, 4};
  render::DifferentialOptions fast;
  fast.step = 2;
  render::DifferentialOptions keyed;
  keyed.tone = render::DifferentialTone::kAverageKey;
  render::DifferentialRenderer full_r({}), fast_r(fast), key_r(keyed);
  render::DifferentialResult a, b, k;
  full_r.Compute(f, &a);
  fast_r.Compute(f, &b);
  key_r.Compute(f, &k);
  const size_t p = wall.Pixel(0.24, 0);
  EXPECT_NEAR(Factor(b, p), Factor(a, p), 0.05);
  EXPECT_LT(Factor(k, p), 1.0f);
  EXPECT_NEAR(k.average_real, 0.99f, 0.01f);  // the log-average of a uniformly lit wall
  EXPECT_LT(k.average_with_virtual, k.average_real);

  // kRatio does not depend on the light's brightness: a half as bright light gives the ratio the
  // fixed T gives at full scale.
  render::DifferentialOptions ratio;
  ratio.tone = render::DifferentialTone::kRatio;
  render::DifferentialRenderer ratio_r(ratio);
  f.light = Light(0.5, {0, 0, -1}, 0);
  render::DifferentialResult q;
  ratio_r.Compute(f, &q);
  EXPECT_NEAR(1 - Factor(q, p), (1 - Factor(a, p)) / 0.99, 0.002);
  full_r.Compute(f, &k);
  EXPECT_NEAR(1 - Factor(k, p), 0.5 * (1 - Factor(q, p)), 0.002) << "fixed T: half the shadow";

  render::VirtualGeometry empty;
  render::RasteriseObjects(wall.View(), {}, &empty);
  EXPECT_TRUE(empty.footprint.empty());
  f.with_virtual = &empty;
  full_r.Compute(f, &a);
  EXPECT_TRUE(a.window.empty());
}

// The virtual pixels: a real box right of the sphere (its front face at the sphere's centre depth,
// 2 cm from its rim) occludes the sphere's right rim, whose normals face it, and, lit from the
// camera side, bounces light onto it; the left rim and the centre keep their shading.
TEST(Differential, RealBoxShadowsAndLightsTheVirtualSphereRim) {
  const raytrace::Mesh sphere = raytrace::MakeSphere(0.15f, 64);
  const Wall wall(188, kW, 1.8f);  // columns 188.. = x >= 0.17 m at 1.8 m
  render::RasterObject o{&sphere, At(0, 0, 1.8), {0.7f, 0.7f, 0.7f}, true};
  render::VirtualGeometry g;
  render::RasteriseObjects(wall.View(), {&o, 1}, &g);
  render::DifferentialRenderer renderer({});
  render::DifferentialFrame f;
  f.real = wall.View();
  f.with_virtual = &g;
  const double s2 = std::sqrt(0.5);
  f.light = Light(0.5, {s2, 0, -s2}, 2.0);
  f.dominant = {{static_cast<float>(s2), 0, static_cast<float>(-s2)}, 2.0f};
  f.camera_tone = {render::ToneOperator::kClamp, 1, 4};
  render::DifferentialResult r;
  renderer.Compute(f, &r);
  const auto& vr = r.virtual_rect;
  ASSERT_EQ(vr.x0, g.footprint.x0);
  ASSERT_EQ(r.virtual_modulation.size(), 3u * vr.width() * vr.height());
  auto at = [&](const std::vector<float>& v, size_t p) {
    const int u = static_cast<int>(p % kW), y = static_cast<int>(p / kW);
    return v[3 * ((y - vr.y0) * vr.width() + (u - vr.x0))];
  };
  const size_t centre = wall.Pixel(0, 0);
  EXPECT_GT(at(r.virtual_modulation, centre), 0.98f);
  EXPECT_LT(at(r.virtual_indirect, centre), 1e-3f);
  // The rims: virtual pixels with a real pixel 2 px to their right (left).
  double mod[2] = {0, 0}, add[2] = {0, 0};
  int n[2] = {0, 0};
  for (int v = vr.y0; v < vr.y1; ++v) {
    for (int u = vr.x0; u < vr.x1; ++u) {
      const size_t p = static_cast<size_t>(v) * kW + u;
      if (g.object_id[p] == 0) continue;
      const int side = g.object_id[p + 2] == 0 ? 1 : g.object_id[p - 2] == 0 ? 0 : -1;
      if (side < 0) continue;
      mod[side] += at(r.virtual_modulation, p);
      add[side] += at(r.virtual_indirect, p);
      ++n[side];
    }
  }
  ASSERT_GT(n[0], 20);
  ASSERT_GT(n[1], 20);
  // Measured: left 0.999, right 0.977 (the lamp from the front right is not behind the box's front
  // face: only the ambient part is occluded, and SSDO finds part of it); bounce 0.0001 vs 0.054.
  EXPECT_GT(mod[0] / n[0], 0.995) << "nothing real beside the left rim";
  EXPECT_LT(mod[1] / n[1], 0.99) << "the box occludes the right rim";
  EXPECT_GT(1 - mod[1] / n[1], 5 * (1 - mod[0] / n[0]));
  EXPECT_GT(add[1] / n[1], 0.01) << "the lit box bounces onto the right rim";
  EXPECT_LT(add[0] / n[0], 0.01 * add[1] / n[1]);

  // At the node's step 2 the rim keeps both effects (each virtual pixel takes its nearest sample).
  render::DifferentialOptions fast;
  fast.step = 2;
  render::DifferentialRenderer fast_renderer(fast);
  render::DifferentialResult r2;
  fast_renderer.Compute(f, &r2);
  ASSERT_EQ(r2.virtual_modulation.size(), r.virtual_modulation.size());
  double mod2 = 0, add2 = 0;
  int n2 = 0;
  for (int v = vr.y0; v < vr.y1; ++v) {
    for (int u = vr.x0; u < vr.x1; ++u) {
      const size_t p = static_cast<size_t>(v) * kW + u;
      if (g.object_id[p] == 0 || g.object_id[p + 2] != 0) continue;
      mod2 += at(r2.virtual_modulation, p);
      add2 += at(r2.virtual_indirect, p);
      ++n2;
    }
  }
  EXPECT_LT(mod2 / n2, 0.99);
  EXPECT_GT(add2 / n2, 0.01);

  // Through the GL pass: the modulation and the added radiance reach the object's pixels.
  render::RendererOptions ro;
  ro.width = kW;
  ro.height = kH;
  render::Renderer gl(ro);
  render::VirtualObject object;
  object.mesh.mesh = sphere;
  object.mesh.bands = 3;
  for (const raytrace::Vec3& nrm : sphere.normals) {
    const std::vector<float> t = prt::UnshadowedTransfer(nrm, 3);
    object.mesh.transfer.insert(object.mesh.transfer.end(), t.begin(), t.end());
  }
  object.anchor = render::Anchor::kWorld;
  object.object_to_anchor = At(0, 0, 1.8);
  object.albedo = {0.5f, 0.5f, 0.5f};
  gl.AddObject(object);
  render::FrameInputs in;
  in.camera = {kW, kH, 300, 300, 159.5, 119.5};
  in.light = Light(0.5, {0, 0, -1}, 0);
  render::Composite plain, dark, lit;
  gl.Render(in, plain);
  const std::vector<float> quarter(3 * kW * kH, 0.25f), zero(3 * kW * kH, 0.0f),
      one(3 * kW * kH, 1.0f), add_half(3 * kW * kH, 0.5f);
  in.virtual_rect = {0, 0, kW, kH};
  in.virtual_modulation = quarter;
  in.virtual_indirect = zero;
  gl.Render(in, dark);
  in.virtual_modulation = one;
  in.virtual_indirect = add_half;
  gl.Render(in, lit);
  const size_t c = 3 * centre;
  ASSERT_EQ(plain.coverage[centre], 1);
  // Radiance 0.5 x 0.5 (albedo x ambient): x 0.25 -> 0.0625; + 0.5 x 0.5 -> 0.5.
  EXPECT_NEAR(raytrace::Srgb8ToLinear(plain.rgb[c]), 0.25, 0.01);
  EXPECT_NEAR(raytrace::Srgb8ToLinear(dark.rgb[c]), 0.0625, 0.005);
  EXPECT_NEAR(raytrace::Srgb8ToLinear(lit.rgb[c]), 0.5, 0.01);
  in.virtual_rect = {0, 0, kW + 1, kH};
  EXPECT_EQ(ThrownMessage<render::RenderError>([&] { gl.Render(in, lit); }),
            "frame: virtual shading needs a rect inside the image and 3 values per rect pixel in "
            "both buffers");
}

// object_pixel's hit test: the sphere rests on the wall seen at that pixel, along its normal, in
// the world frame (here the camera 1 m to the right of the world origin).
TEST(Placement, RestsOnTheSurfaceSeenAtThePixel) {
  const Wall wall;
  const raytrace::Mesh sphere = raytrace::MakeSphere(0.15f, 32);
  const raytrace::Mesh* meshes[] = {&sphere};
  const raytrace::Transform camera_to_world = At(1, 0, 0);
  const size_t p = wall.Pixel(0.2, -0.1);
  const auto t = render::PlaceOnSurface(wall.View(), static_cast<double>(p % kW),
                                        static_cast<double>(p / kW), camera_to_world, meshes);
  ASSERT_TRUE(t.has_value());
  // The wall point (0.2, -0.1, 2) in the camera is (1.2, -0.1, 2) in the world; the centre goes
  // 0.15 m towards the camera (the wall's normal), the sphere's radius along it.
  EXPECT_NEAR(t->translation[0], 1.2, 0.01);
  EXPECT_NEAR(t->translation[1], -0.1, 0.01);
  EXPECT_NEAR(t->translation[2], 2 - 0.15, 0.003);
  const Wall holes(0, kW, 0.0f);  // no depth anywhere
  EXPECT_FALSE(render::PlaceOnSurface(holes.View(), 10, 10, camera_to_world, meshes).has_value());
  EXPECT_EQ(ThrownMessage<render::RenderError>(
                [&] { render::PlaceOnSurface(wall.View(), 400, 10, camera_to_world, meshes); }),
            "object_pixel [400, 10] is outside the 320x240 image");
}

// Face mode (no reconstruction): G_r is the proxy head rasterised at the head pose (frontal, 0.6 m
// away). A sphere between a lamp on the right and the right cheek darkens the cheek in its shadow
// and not the left cheek; a sphere behind the head has no pixel in G_r' (the head hides it; the
// renderer passes the head's depth to the GL pass as real_depth).
TEST(FaceMode, ASphereBesideTheFaceShadowsItAndTheHeadHidesOneBehind) {
  const raytrace::Mesh head = prt::ProxyHead(48);
  const light::Intrinsics k{300, 300, 159.5, 119.5};
  const raytrace::Transform face_to_camera = At(0, 0, 0.6);
  const std::vector<uint8_t> camera(3 * kW * kH, 180);
  render::VirtualGeometry g_r;
  render::RasteriseHead(head, face_to_camera, k, kW, kH, camera, &g_r);
  EXPECT_TRUE(g_r.footprint.empty());
  EXPECT_EQ(g_r.depth[0], 0.0f);  // no surface beside the head
  // The camera-frame surface point seen at the face-frame point (x, y) of the cheek.
  auto surface = [&](double x, double y) {
    const int u = static_cast<int>(std::lround(k.cx + k.fx * x / 0.6));
    const int v = static_cast<int>(std::lround(k.cy + k.fy * y / 0.6));
    const size_t p = static_cast<size_t>(v) * kW + u;
    const float z = g_r.depth[p];
    return std::array<double, 4>{(u - k.cx) * z / k.fx, (v - k.cy) * z / k.fy, z,
                                 static_cast<double>(p)};
  };
  const auto right = surface(0.045, 0.035), left = surface(-0.045, 0.035);
  ASSERT_GT(right[2], 0.55);
  ASSERT_LT(right[2], 0.7);
  ASSERT_GT(left[2], 0.55);
  EXPECT_EQ(g_r.colour[3 * static_cast<size_t>(right[3])], 180);  // the observed colour
  EXPECT_EQ(g_r.object_id[static_cast<size_t>(right[3])], 0);     // real

  const sh::Vec3 d{0.6, 0, -0.8};  // towards the lamp: right of and in front of the face
  const raytrace::Mesh sphere = raytrace::MakeSphere(0.03f, 48);
  render::RasterObject o{&sphere,
                         At(right[0] + 0.055 * d[0], right[1], right[2] + 0.055 * d[2]),
                         {0.7f, 0.7f, 0.7f},
                         true};
  render::VirtualGeometry g;
  render::RasteriseObjects(g_r.View(k), {&o, 1}, &g);
  ASSERT_FALSE(g.footprint.empty());
  ASSERT_EQ(g.object_id[static_cast<size_t>(right[3])], 0);  // the cheek point stays visible
  render::DifferentialOptions options;
  options.transfer.radius_m = 0.1f;  // the renderer's face-mode default
  options.transfer.max_occluder_distance_m = 0.2f;
  render::DifferentialRenderer renderer(options);
  render::DifferentialFrame f;
  f.real = g_r.View(k);
  f.with_virtual = &g;
  f.light = Light(0.1, d, 3.0);
  f.camera_tone = {render::ToneOperator::kClamp, 1, 4};
  render::DifferentialResult r;
  renderer.Compute(f, &r);
  auto mean_darkening = [&](size_t p) {
    double sum = 0;
    int n = 0;
    for (int dv = -3; dv <= 3; ++dv) {
      for (int du = -3; du <= 3; ++du) {
        sum += 1 - Factor(r, p + static_cast<size_t>(dv * kW + du));
        ++n;
      }
    }
    return sum / n;
  };
  const double shadowed = mean_darkening(static_cast<size_t>(right[3]));
  const double other = mean_darkening(static_cast<size_t>(left[3]));
  EXPECT_GT(shadowed, 0.3) << "the right cheek, in the sphere's shadow";
  EXPECT_LT(other, 0.02) << "the left cheek";
  // The composite's pixels there are darker (eq. 13 on the camera bytes).
  std::vector<uint8_t> composite = camera;
  render::ApplyDifferential(r, kW, kH, composite);
  EXPECT_LT(composite[3 * static_cast<size_t>(right[3])], 170);
  EXPECT_EQ(composite[3 * static_cast<size_t>(left[3])], 180);

  // Behind the head (face-frame z = 0.25 m, the head ends before): hidden in G_r', visible without
  // the head.
  const raytrace::Mesh behind = raytrace::MakeSphere(0.04f, 32);
  render::RasterObject b{&behind, face_to_camera * At(0, 0, 0.25), {0.7f, 0.7f, 0.7f}, true};
  render::RasteriseObjects(g_r.View(k), {&b, 1}, &g);
  EXPECT_TRUE(g.footprint.empty());
  renderer.Compute({g_r.View(k), &g, f.light, {}, f.camera_tone, {}}, &r);
  EXPECT_TRUE(r.window.empty());
  const std::vector<float> none(kW * kH, 0), no_normals(3 * kW * kH, 0);
  render::RasteriseObjects({kW, kH, k, none, no_normals, {}}, {&b, 1}, &g);
  EXPECT_FALSE(g.footprint.empty());
}

TEST(Differential, Errors) {
  const Wall wall;
  render::VirtualGeometry g;
  render::RasterObject none{};
  EXPECT_EQ(ThrownMessage<render::RenderError>([&] {
              render::RasteriseObjects(wall.View(), {&none, 1}, &g);
            }),
            "render::RasteriseObjects: objects[0]: no mesh");
  raytrace::Mesh bare = raytrace::MakeSphere(0.1f, 8);
  bare.normals.clear();
  render::RasterObject o{&bare, At(0, 0, 1), {1, 1, 1}, true};
  EXPECT_EQ(ThrownMessage<render::RenderError>([&] {
              render::RasteriseObjects(wall.View(), {&o, 1}, &g);
            }),
            "render::RasteriseObjects: objects[0]: the mesh needs one normal per vertex");
  render::DifferentialOptions bad;
  bad.step = 0;
  EXPECT_EQ(ThrownMessage<render::RenderError>([&] { render::DifferentialRenderer r(bad); }),
            "differential: step must be >= 1, got 0");
  render::DifferentialOptions fixed_sun;
  fixed_sun.sun_shadow = true;
  EXPECT_EQ(ThrownMessage<render::RenderError>([&] { render::DifferentialRenderer r(fixed_sun); }),
            "differential: sun_shadow needs tone ratio (the crisp shadow divides R'_d by R_d)");
  fixed_sun.tone = render::DifferentialTone::kRatio;
  fixed_sun.sun_map_size = 8;
  EXPECT_EQ(ThrownMessage<render::RenderError>([&] { render::DifferentialRenderer r(fixed_sun); }),
            "differential: sun_map_size must be in 16..4096, got 8");
  render::DifferentialRenderer renderer({});
  render::DifferentialFrame f;
  f.real = wall.View();
  render::DifferentialResult r;
  EXPECT_EQ(ThrownMessage<render::RenderError>([&] { renderer.Compute(f, &r); }),
            "render::DifferentialRenderer::Compute: with_virtual must be G_r' of the 320x240 G_r "
            "(RasteriseObjects)");
  std::vector<uint8_t> small(10);
  EXPECT_EQ(
      ThrownMessage<render::RenderError>([&] { render::ApplyDifferential(r, kW, kH, small); }),
      "render::ApplyDifferential: camera image has 10 bytes, expected 3 x 320x240");
  EXPECT_EQ(ThrownMessage<render::RenderError>([&] {
              render::RasteriseHead(raytrace::MakeSphere(0.1f, 8), At(0, 0, 1), wall.k, kW, kH,
                                    small, &g);
            }),
            "render::RasteriseHead: camera image of 10 bytes, expected 230400 (320x240 rgb8)");
  EXPECT_EQ(ThrownMessage<render::RenderError>(
                [&] { render::RasteriseHead(bare, At(0, 0, 1), wall.k, kW, kH, {}, &g); }),
            "render::RasteriseHead: render::RasteriseObjects: objects[0]: the mesh needs one "
            "normal per vertex");
  // The renderer's light units (render/msgs_io.h): linear used, face-model refused with a reason.
  std::string why;
  EXPECT_TRUE(render::AcceptLightUnits(msgs::ShLightUnits::kLinear, &why));
  EXPECT_EQ(why, "");
  EXPECT_TRUE(render::AcceptLightUnits(msgs::ShLightUnits::kUnknown, &why));
  EXPECT_EQ(why,
            "light has unknown units (recorded before ShLight had a units field): shaded as linear "
            "radiance");
  EXPECT_FALSE(render::AcceptLightUnits(msgs::ShLightUnits::kFaceModel, &why));
  EXPECT_FALSE(render::AcceptLightUnits(static_cast<msgs::ShLightUnits>(7), &why));
  EXPECT_EQ(why, "light has units 7, not a msgs::ShLightUnits value: not rendered");
}

}  // namespace
