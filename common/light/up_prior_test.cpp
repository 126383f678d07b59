// Unit tests of the light prior (LightPrior in SolveLight), the up direction from geometry
// (EstimateUpDirection) and the scene pipeline's grey-world light colour: a tilted camera over a
// floor with a wall, exact normals; random transfer rows with a known light.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <numbers>
#include <random>
#include <vector>

#include "probeless/light/estimate.h"
#include "probeless/light/fusion.h"
#include "probeless/light/pipeline.h"
#include "probeless/light/up_direction.h"
#include "probeless/sh/sh.h"
#include "probeless/testing/testing.h"

namespace {

using namespace probeless;
using probeless::testing::ThrownMessage;

constexpr double kDeg = std::numbers::pi / 180;

double AngleDeg(const light::Vec3f& a, const std::array<double, 3>& b) {
  const double d = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  return std::acos(std::clamp(d, -1.0, 1.0)) / kDeg;
}

// A 160 x 120 camera pitched down by `pitch_deg` and rolled by `roll_deg`, 1.5 m above a floor,
// a wall 3 m ahead (world y up, camera optical frame). `floor` false: the wall fills the view.
struct TiltedView {
  int w = 160, h = 120;
  light::Intrinsics k{150, 150, 79.5, 59.5};
  std::vector<float> depth, normals;
  std::array<double, 3> up_camera{};  // world up in the camera frame
  TiltedView(double pitch_deg, double roll_deg, bool floor = true) {
    depth.assign(w * h, 0);
    normals.assign(3 * w * h, 0);
    const double p = pitch_deg * kDeg, r = roll_deg * kDeg;
    // Camera axes in the world (x right, y down, z forward): pitch about x, then roll about z.
    auto rot = [&](std::array<double, 3> c) {  // camera -> world
      const double x1 = std::cos(r) * c[0] - std::sin(r) * c[1];
      const double y1 = std::sin(r) * c[0] + std::cos(r) * c[1];
      const double z1 = c[2];
      // Optical frame: world = (x, -y, z) before the pitch; pitch tips forward downwards.
      const double wy = -(std::cos(p) * y1 + std::sin(p) * z1);
      const double wz = -std::sin(p) * y1 + std::cos(p) * z1;
      return std::array<double, 3>{x1, wy, wz};
    };
    const std::array<double, 3> ex = rot({1, 0, 0}), ey = rot({0, 1, 0}), ez = rot({0, 0, 1});
    up_camera = {ex[1], ey[1], ez[1]};  // R^T (0, 1, 0)
    for (int v = 0; v < h; ++v) {
      for (int u = 0; u < w; ++u) {
        const std::array<double, 3> c{(u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0};
        const std::array<double, 3> d = rot(c);  // world ray (camera at (0, 1.5, 0))
        double t = INFINITY;
        std::array<double, 3> n{};
        if (floor && d[1] < 0 && 1.5 / -d[1] < t) t = 1.5 / -d[1], n = {0, 1, 0};
        if (d[2] > 0 && 3.0 / d[2] < t) t = 3.0 / d[2], n = {0, 0, -1};
        if (!std::isfinite(t)) continue;
        const size_t i = static_cast<size_t>(v) * w + u;
        depth[i] = static_cast<float>(t);  // z = 1 along the camera ray
        normals[3 * i] = static_cast<float>(n[0] * ex[0] + n[1] * ex[1] + n[2] * ex[2]);
        normals[3 * i + 1] = static_cast<float>(n[0] * ey[0] + n[1] * ey[1] + n[2] * ey[2]);
        normals[3 * i + 2] = static_cast<float>(n[0] * ez[0] + n[1] * ez[1] + n[2] * ez[2]);
      }
    }
  }
  light::GeometryView View() const { return {w, h, k, depth, normals, {}}; }
  // The shading of a light from above and in front: I = 0.5 (0.2 + max(0, n.l)), l = (0, -0.8,
  // -0.6) in the camera frame.
  std::vector<float> Shaded() const {
    const std::array<double, 3> l{0, -0.8, -0.6};
    std::vector<float> grey(static_cast<size_t>(w) * h, 0);
    for (size_t i = 0; i < grey.size(); ++i) {
      const float* nn = &normals[3 * i];
      grey[i] = static_cast<float>(
          0.5 * (0.2 + std::max(0.0, nn[0] * l[0] + nn[1] * l[1] + nn[2] * l[2])));
    }
    return grey;
  }
  // The pipeline's G-buffer input with image `grey` (borrowed; no colour).
  light::SceneFrame Input(std::span<const float> grey) const {
    light::SceneFrame f;
    f.width = w;
    f.height = h;
    f.intrinsics = k;
    f.grey = grey;
    f.gbuffer_depth = depth;
    f.gbuffer_normals = normals;
    return f;
  }
};

TEST(UpDirection, FindsTheFloorOfATiltedRolledCamera) {
  for (const auto& [pitch, roll] : {std::pair{35.0, 10.0}, {10.0, -15.0}, {50.0, 0.0}}) {
    const TiltedView view(pitch, roll);
    const light::UpDirection up = light::EstimateUpDirection(view.View());
    ASSERT_TRUE(up.valid) << pitch << " " << roll;
    EXPECT_LT(AngleDeg(up.up, view.up_camera), 0.5) << pitch << " " << roll;
    EXPECT_GT(up.support, 0.05f) << pitch << " " << roll;
  }
}

TEST(UpDirection, NoHorizontalSurfaceGivesNoUp) {
  const TiltedView wall(5, 0, /*floor=*/false);
  const light::UpDirection up = light::EstimateUpDirection(wall.View());
  EXPECT_FALSE(up.valid);
}

TEST(UpDirection, BadOptionsThrow) {
  const TiltedView view(30, 0);
  light::UpDirectionOptions o;
  o.stride = 0;
  EXPECT_EQ(ThrownMessage<light::LightError>([&] { light::EstimateUpDirection(view.View(), o); }),
            "light::EstimateUpDirection: stride must be >= 1, got 0");
  o = {};
  o.kernel_deg = 70;
  EXPECT_EQ(ThrownMessage<light::LightError>([&] { light::EstimateUpDirection(view.View(), o); }),
            "light::EstimateUpDirection: need 0 < kernel_deg <= search_deg < 90 (degrees)");
}

// Rows of random transfer and the targets of light `l`.
void RandomRows(const std::vector<double>& l, int m, std::vector<float>* rows,
                std::vector<float>* targets) {
  const int cc = static_cast<int>(l.size());
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> uni(-0.5, 0.5);
  rows->assign(static_cast<size_t>(m) * cc, 0);
  targets->assign(m, 0);
  for (int i = 0; i < m; ++i) {
    double s = 0;
    for (int k = 0; k < cc; ++k) {
      (*rows)[i * cc + k] = static_cast<float>(uni(rng));
      s += (*rows)[i * cc + k] * l[k];
    }
    (*targets)[i] = static_cast<float>(s);
  }
}

TEST(LightPrior, PullsTowardsTheZonalLightAndLeavesAConsistentOneAlone) {
  const int cc = 9;
  const std::array<float, 4> zonal{1, 0.9f, 1.0f, 0};
  const light::Vec3f up{0, -0.8f, -0.6f};
  // The prior's own light: l_k = rho_k l_0.
  std::array<double, sh::kMaxCoefficients> y{};
  sh::EvaluateBasis<double>(3, up[0], up[1], up[2], y.data());
  std::vector<double> zonal_light(cc);
  zonal_light[0] = 1.0;
  for (int k = 1; k < cc; ++k) {
    const int l = sh::DegreeOf(k);
    zonal_light[k] = zonal[l] / (2 * l + 1) * y[k] / y[0];
  }
  std::vector<float> rows, targets;
  light::EstimateOptions o;
  o.robust = false;
  o.ridge = 0;
  o.smoothness = 0;
  o.direction_bands = 0;
  o.prior = {.weight = 10, .up = up, .zonal = zonal};
  RandomRows(zonal_light, 400, &rows, &targets);
  auto e = light::SolveLight(rows, targets, cc, o);
  ASSERT_TRUE(e.valid);
  for (int k = 0; k < cc; ++k) EXPECT_NEAR(e.coefficients[k], zonal_light[k], 1e-4) << k;
  // A light from the side, exact data: the fit explains it (R^2 = 1), the prior stays out even
  // at a huge weight.
  const std::vector<double> side = {1.0, 0.0, 0.0, -0.6, 0.0, 0.0, -0.1, 0.0, 0.2};
  RandomRows(side, 400, &rows, &targets);
  o.prior.weight = 1e4;
  e = light::SolveLight(rows, targets, cc, o);
  for (int k = 0; k < cc; ++k) EXPECT_NEAR(e.coefficients[k], side[k], 1e-4) << k;
  // Noisy data (about half the variance unexplained): a weak prior barely moves the light, a
  // strong one takes over its shape.
  std::mt19937_64 rng(11);
  std::normal_distribution<double> noise(0, 0.2);
  for (float& t : targets) t += static_cast<float>(noise(rng));
  o.prior.weight = 0;
  const light::LightEstimate free = light::SolveLight(rows, targets, cc, o);
  o.prior.weight = 1e-4;
  e = light::SolveLight(rows, targets, cc, o);
  for (int k = 0; k < cc; ++k) EXPECT_NEAR(e.coefficients[k], free.coefficients[k], 1e-3) << k;
  o.prior.weight = 1e4;
  e = light::SolveLight(rows, targets, cc, o);
  for (int k = 1; k < cc; ++k) {
    EXPECT_NEAR(e.coefficients[k] / e.coefficients[0], zonal_light[k], 1e-2) << k;
  }
  // No up direction: no prior.
  o.prior.up = {0, 0, 0};
  e = light::SolveLight(rows, targets, cc, o);
  for (int k = 0; k < cc; ++k) EXPECT_EQ(e.coefficients[k], free.coefficients[k]) << k;
  o.prior.weight = -1;
  EXPECT_EQ(ThrownMessage<light::LightError>([&] { light::SolveLight(rows, targets, cc, o); }),
            "light::SolveLight: prior.weight must be finite and >= 0");
}

TEST(ScenePipeline, GreyWorldColourIsTheMeanLinearColour) {
  const TiltedView view(30, 0);
  const size_t n = static_cast<size_t>(view.w) * view.h;
  std::vector<float> grey(n, 0.3f);
  std::vector<uint8_t> colour(3 * n);
  for (size_t i = 0; i < n; ++i)
    colour[3 * i] = 200, colour[3 * i + 1] = 120, colour[3 * i + 2] = 60;
  light::ScenePipelineOptions o;
  o.transfer.directions = 16;
  o.light_model = light::LightModel::kDistant;
  o.shadow.enabled = false;
  light::SceneFrame f = view.Input(grey);
  f.colour = colour;
  light::ScenePipeline pipeline(o);
  const auto& r = pipeline.Process(f);
  const double lin[3] = {light::SrgbToLinear(200), light::SrgbToLinear(120),
                         light::SrgbToLinear(60)};
  const double mean = (lin[0] + lin[1] + lin[2]) / 3;
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(r.colour[c], lin[c] / mean, 1e-4) << c;
  // Off, or without a colour image: white.
  o.grey_world_colour = false;
  light::ScenePipeline white(o);
  EXPECT_EQ(white.Process(f).colour, (std::array<float, 3>{1, 1, 1}));
  f.colour = {};
  light::ScenePipeline none{light::ScenePipelineOptions{}};
  EXPECT_EQ(none.Process(f).colour, (std::array<float, 3>{1, 1, 1}));
}

TEST(ScenePipeline, PriorIsOnByDefaultAboutTheEstimatedUp) {
  const TiltedView view(30, 5);
  const std::vector<float> grey = view.Shaded();
  light::ScenePipelineOptions o;
  ASSERT_GT(o.estimate.prior.weight, 0);
  o.transfer.directions = 16;
  o.light_model = light::LightModel::kDistant;
  o.shadow.enabled = false;
  const light::SceneFrame f = view.Input(grey);
  light::ScenePipeline pipeline(o);
  const auto& r = pipeline.Process(f);
  ASSERT_TRUE(r.up.valid);
  EXPECT_LT(AngleDeg(r.up.up, view.up_camera), 0.5);
  // The same fit by hand: the transfer, then EstimateLight with the prior about that up.
  light::TransferComputer computer(o.transfer);
  light::TransferResult t;
  computer.Compute(view.View(), {}, nullptr, &t);
  light::EstimateOptions eo = o.estimate;
  eo.prior.up = r.up.up;
  const light::LightEstimate e = light::EstimateLight(t, grey, eo);
  EXPECT_EQ(r.light.coefficients, e.coefficients);
  eo.prior.weight = 0;
  EXPECT_NE(light::EstimateLight(t, grey, eo).coefficients, e.coefficients);
}

TEST(ScenePipeline, ConfidenceIsTheCalibratedExpectedError) {
  // The default table: raw ascending, expected error non-increasing, so the published confidence
  // is in [0, 1] and monotone in the fit's.
  for (const auto source :
       {light::SceneGeometrySource::kGeometryBuffer, light::SceneGeometrySource::kDepthImage}) {
    const std::vector<double> knots = light::DefaultSceneConfidenceKnots(source);
    ASSERT_GE(knots.size(), 4u);
    ASSERT_EQ(knots.size() % 2, 0u);
    for (size_t k = 2; k < knots.size(); k += 2) {
      EXPECT_GT(knots[k], knots[k - 2]);
      EXPECT_LE(knots[k + 1], knots[k - 1]);
    }
  }
  const std::vector<double> knots =
      light::DefaultSceneConfidenceKnots(light::SceneGeometrySource::kGeometryBuffer);
  const light::ConfidenceCalibration table(knots);
  double previous = -1;
  for (int i = 0; i <= 100; ++i) {
    const double c = table.Apply(i / 100.0);
    EXPECT_GE(c, 0);
    EXPECT_LE(c, 1);
    EXPECT_GE(c, previous) << i;
    previous = c;
  }
  // The first knot's error below it, the last's above it.
  EXPECT_NEAR(light::ExpectedErrorFromConfidence(table.Apply(0)), knots[1], 1e-9);
  EXPECT_NEAR(light::ExpectedErrorFromConfidence(table.Apply(1)), knots.back(), 1e-9);

  // The pipeline publishes the table's confidence of its fit's; empty knots publish the fit's.
  const TiltedView view(30, 5);
  const std::vector<float> grey = view.Shaded();
  light::ScenePipelineOptions o;
  o.transfer.directions = 16;
  o.light_model = light::LightModel::kDistant;
  o.shadow.enabled = false;
  const light::SceneFrame f = view.Input(grey);
  light::ScenePipeline calibrated(o);
  const light::ScenePipelineResult& r = calibrated.Process(f);
  ASSERT_TRUE(r.light.valid);
  EXPECT_GT(r.evidence.fit_confidence, 0);
  EXPECT_FLOAT_EQ(r.light.confidence, static_cast<float>(table.Apply(r.evidence.fit_confidence)));
  // No shadow search, so no prior-free fit was made: no shift is reported (and none computed).
  EXPECT_EQ(r.evidence.prior_shift_deg, 0);
  o.confidence_knots.emplace();
  light::ScenePipeline raw(o);
  const light::ScenePipelineResult& q = raw.Process(f);
  EXPECT_EQ(q.light.confidence, q.evidence.fit_confidence);

  o.confidence_knots = std::vector<double>{0.5, 20, 0.2, 30};
  EXPECT_EQ(ThrownMessage<light::LightError>([&] { light::ScenePipeline bad(o); }),
            "light::ScenePipeline: confidence_knots: confidence calibration: knot 1 needs a raw "
            "confidence in [0, 1] above the previous one and an error > 0");
}

}  // namespace
