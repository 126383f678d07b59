// Unit tests of the scene pipeline (pipeline.h) on an analytic frame: a floor, a back wall and a
// sphere seen by a pinhole camera. The pipeline's result must equal the direct composition of the
// library calls it stands for (what the node and the evaluation did before), its state must carry
// over between frames (warm start, temporal history with the pose, the indirect term's light) and
// reset when stamps go backwards, and bad options / input must throw with a precise message.
#include "probeless/light/pipeline.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <string>
#include <vector>

#include "probeless/testing/testing.h"

namespace {

using namespace probeless;
using probeless::testing::ThrownMessage;

constexpr double kPi = std::numbers::pi;
constexpr double kY0 = 0.28209479177387814;

// A 160 x 120 camera (x right, y down, z forward) looking at a floor (y = 1), a back wall (z = 4)
// and a sphere (centre (0.3, 0.5, 2.5), radius 0.4); albedos floor 0.4, wall 0.7, sphere 0.5 with
// distinct colours. Shading without cast shadows (the shadow search then finds none to use, which
// is as deterministic a path as any).
struct Frame {
  int w = 160, h = 120;
  light::Intrinsics k{150, 150, 79.5, 59.5};
  std::vector<float> depth, normals, albedo, grey;
  std::vector<uint8_t> colour;
  // second_sphere: another sphere (centre (-0.7, 0.6, 3.2), radius 0.4, the same material).
  explicit Frame(bool second_sphere = false) {
    depth.assign(w * h, 0);
    normals.assign(3 * w * h, 0);
    albedo.assign(w * h, 0);
    colour.assign(3 * w * h, 0);
    const double c[3] = {0.3, 0.5, 2.5}, radius = 0.4;
    const double c2[3] = {-0.7, 0.6, 3.2};
    for (int v = 0; v < h; ++v) {
      for (int u = 0; u < w; ++u) {
        const double d[3] = {(u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0};  // ray with z = 1
        double t = INFINITY, n[3] = {0, 0, 0}, a = 0;
        uint8_t rgb[3] = {0, 0, 0};
        if (d[1] > 0 && 1.0 / d[1] < t) {
          t = 1.0 / d[1], n[1] = -1, a = 0.4;
          rgb[0] = 150, rgb[1] = 110, rgb[2] = 70;
        }
        if (4.0 < t) {
          t = 4.0, n[0] = 0, n[1] = 0, n[2] = -1, a = 0.7;
          rgb[0] = rgb[1] = rgb[2] = 200;
        }
        const double dd = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        for (const double* sc : {c, second_sphere ? c2 : nullptr}) {
          if (sc == nullptr) continue;
          const double dc = d[0] * sc[0] + d[1] * sc[1] + d[2] * sc[2];
          const double cc = sc[0] * sc[0] + sc[1] * sc[1] + sc[2] * sc[2];
          const double disc = dc * dc - dd * (cc - radius * radius);
          if (disc > 0) {
            const double ts = (dc - std::sqrt(disc)) / dd;
            if (ts > 0 && ts < t) {
              t = ts, a = 0.5;
              for (int i = 0; i < 3; ++i) n[i] = (t * d[i] - sc[i]) / radius;
              rgb[0] = 60, rgb[1] = 90, rgb[2] = 200;
            }
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
  // I = albedo (E max(0, n.l) / pi + ambient Y_0): a distant light towards `l` (unit).
  void LitByDistant(const double* l, double irradiance, double ambient) {
    grey.resize(w * h);
    for (size_t p = 0; p < grey.size(); ++p) {
      const double cosine =
          normals[3 * p] * l[0] + normals[3 * p + 1] * l[1] + normals[3 * p + 2] * l[2];
      grey[p] = static_cast<float>(albedo[p] *
                                   (irradiance * std::max(0.0, cosine) / kPi + ambient * kY0));
    }
  }
  // I = albedo (P max(0, n.(q - x)) / (pi |q - x|^3) + ambient Y_0): a point lamp at `q`.
  void LitByLamp(const double* q, double power, double ambient) {
    grey.resize(w * h);
    for (size_t p = 0; p < grey.size(); ++p) {
      const int u = static_cast<int>(p % w), v = static_cast<int>(p / w);
      const double x[3] = {(u - k.cx) * depth[p] / k.fx, (v - k.cy) * depth[p] / k.fy, depth[p]};
      const double d[3] = {q[0] - x[0], q[1] - x[1], q[2] - x[2]};
      const double r2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
      const double cosine =
          (normals[3 * p] * d[0] + normals[3 * p + 1] * d[1] + normals[3 * p + 2] * d[2]) /
          std::sqrt(r2);
      grey[p] = static_cast<float>(albedo[p] *
                                   (power * std::max(0.0, cosine) / (kPi * r2) + ambient * kY0));
    }
  }
  // LitByDistant with the light towards `near_l` within `near_m` metres of `centre` (camera
  // frame) and towards `far_l` elsewhere: an indoor light that varies across the view.
  void LitByRegions(const double* centre, double near_m, const double* near_l, const double* far_l,
                    double irradiance, double ambient) {
    grey.resize(w * h);
    for (size_t p = 0; p < grey.size(); ++p) {
      const int u = static_cast<int>(p % w), v = static_cast<int>(p / w);
      const double x[3] = {(u - k.cx) * depth[p] / k.fx, (v - k.cy) * depth[p] / k.fy, depth[p]};
      const double d2 = (x[0] - centre[0]) * (x[0] - centre[0]) +
                        (x[1] - centre[1]) * (x[1] - centre[1]) +
                        (x[2] - centre[2]) * (x[2] - centre[2]);
      const double* l = d2 < near_m * near_m ? near_l : far_l;
      const double cosine =
          normals[3 * p] * l[0] + normals[3 * p + 1] * l[1] + normals[3 * p + 2] * l[2];
      grey[p] = static_cast<float>(albedo[p] *
                                   (irradiance * std::max(0.0, cosine) / kPi + ambient * kY0));
    }
  }
  light::GeometryView View() const { return {w, h, k, depth, normals, {}}; }
  // The pipeline's input for a G-buffer source (or, with `depth_image`, a depth source).
  light::SceneFrame Input(int64_t stamp, bool gbuffer = true) const {
    light::SceneFrame f;
    f.stamp_ns = stamp;
    f.width = w;
    f.height = h;
    f.intrinsics = k;
    f.grey = grey;
    f.colour = colour;
    if (gbuffer) {
      f.gbuffer_depth = depth;
      f.gbuffer_normals = normals;
    }
    return f;
  }
};

const double kSun[3] = {0.36, -0.80, -0.48};  // towards the light (unit), camera frame

light::ScenePipelineOptions SmallOptions() {
  light::ScenePipelineOptions o;
  o.transfer.directions = 16;  // fast enough for a unit test
  o.transfer.threads = 2;
  o.shadow.threads = 2;
  // The compositions below call EstimateLight without the per-frame up direction: no prior here
  // (its composition is tested in up_prior_test.cpp).
  o.estimate.prior.weight = 0;
  // ... and the fit's own confidence, as the direct calls publish it (the calibration:
  // up_prior_test.cpp).
  o.confidence_knots.emplace();
  return o;
}

void ExpectSameLight(const light::LightEstimate& a, const light::LightEstimate& b) {
  EXPECT_EQ(a.valid, b.valid);
  EXPECT_EQ(a.coefficients, b.coefficients);
  EXPECT_EQ(a.dominant_direction, b.dominant_direction);
  EXPECT_EQ(a.intensity, b.intensity);
  EXPECT_EQ(a.confidence, b.confidence);
}

TEST(ScenePipeline, DistantEqualsDirectComposition) {
  Frame s;
  s.LitByDistant(kSun, 3.0, 0.3);
  light::ScenePipelineOptions o = SmallOptions();
  o.light_model = light::LightModel::kDistant;
  light::ScenePipeline pipeline(o);
  const light::ScenePipelineResult& r = pipeline.Process(s.Input(1));
  ASSERT_TRUE(r.light.valid);

  light::TransferComputer computer(o.transfer);
  light::TransferResult t;
  computer.Compute(s.View(), {}, nullptr, &t);
  EXPECT_EQ(r.transfer->transfer, t.transfer);
  light::LightEstimate e = light::EstimateLight(t, s.grey, o.estimate, s.colour);
  ExpectSameLight(r.distant, e);
  const light::ShadowEstimate shadow =
      light::RefineLightWithShadows(s.View(), s.grey, o.shadow, s.colour, &e);
  ExpectSameLight(r.light, e);
  EXPECT_TRUE(r.shadow_ran);
  EXPECT_FALSE(r.shadow_on_depth_image);
  EXPECT_EQ(r.shadow.valid, shadow.valid);
  EXPECT_EQ(r.shadow.direction, shadow.direction);
  EXPECT_EQ(r.used, light::LightModel::kDistant);
  EXPECT_FALSE(r.has_indirect);
  EXPECT_GT(r.timings.cpu_ms_transfer, 0);
  // The light is the sun's to within the fit's accuracy on exact data.
  const auto& d = r.light.dominant_direction;
  EXPECT_GT(d[0] * kSun[0] + d[1] * kSun[1] + d[2] * kSun[2], std::cos(10 * kPi / 180));
}

TEST(ScenePipeline, DepthSourceEqualsDirectComposition) {
  Frame s;
  s.LitByDistant(kSun, 3.0, 0.3);
  light::ScenePipelineOptions o = SmallOptions();
  o.source = light::SceneGeometrySource::kDepthImage;
  o.light_model = light::LightModel::kDistant;
  o.normal_filter = true;
  o.reliability_weights = true;
  light::ScenePipeline pipeline(o);
  light::SceneFrame in = s.Input(1, false);
  in.depth_image = s.depth;
  const light::ScenePipelineResult& r = pipeline.Process(in);
  ASSERT_TRUE(r.light.valid);

  std::vector<float> depth = s.depth, normals, reliability;
  const float noise =
      light::DepthGeometry(depth, s.w, s.h, s.k, o.depth_geometry, &normals, &reliability);
  light::FilterNormals(depth, s.w, s.h, s.k, o.filter, normals);
  const light::GeometryView g{s.w, s.h, s.k, depth, normals, {}};
  light::TransferComputer computer(o.transfer);
  light::TransferResult t;
  computer.Compute(g, {}, nullptr, &t);
  light::LightEstimate e = light::EstimateLight(t, s.grey, o.estimate, s.colour, reliability);
  light::RefineLightWithShadows(g, s.grey, light::RawDepthShadowOptions(o.shadow), s.colour, &e);
  ExpectSameLight(r.light, e);
  EXPECT_EQ(std::vector<float>(r.geometry.normals.begin(), r.geometry.normals.end()), normals);
  EXPECT_TRUE(r.shadow_on_depth_image);
  EXPECT_TRUE(r.shadow_options.image_cues);  // depth_image_cues
  EXPECT_TRUE(std::isnan(noise) ? std::isnan(r.measured_noise_quadratic)
                                : r.measured_noise_quadratic == noise);
}

TEST(ScenePipeline, GBufferWithTheFramesDepthImageForShadows) {
  Frame s;
  s.LitByDistant(kSun, 3.0, 0.3);
  light::ScenePipelineOptions o = SmallOptions();
  o.light_model = light::LightModel::kDistant;
  o.gbuffer_normals = light::GBufferNormals::kCentral;
  light::ScenePipeline pipeline(o);
  light::SceneFrame in = s.Input(1);
  in.depth_image = s.depth;
  const light::ScenePipelineResult& r = pipeline.Process(in);
  ASSERT_TRUE(r.light.valid);

  // The fit on G_r with normals recomputed max(2, w / 160) apart; the search on the depth image.
  std::vector<float> gr_normals, depth = s.depth, normals;
  light::NormalsFromDepth(s.depth, s.w, s.h, s.k, &gr_normals, 0.05f, 2);
  const light::GeometryView g{s.w, s.h, s.k, s.depth, gr_normals, {}};
  light::TransferComputer computer(o.transfer);
  light::TransferResult t;
  computer.Compute(g, {}, nullptr, &t);
  light::LightEstimate e = light::EstimateLight(t, s.grey, o.estimate, s.colour);
  light::DepthGeometry(depth, s.w, s.h, s.k, o.depth_geometry, &normals);
  const light::GeometryView raw{s.w, s.h, s.k, depth, normals, {}};
  light::RefineLightWithShadows(raw, s.grey, light::RawDepthShadowOptions(o.shadow), s.colour, &e);
  ExpectSameLight(r.light, e);
  EXPECT_TRUE(r.shadow_on_depth_image);

  // shadow_geometry kGeometryBuffer: the search on G_r without the cues, whatever is given.
  o.shadow_geometry = light::ShadowGeometry::kGeometryBuffer;
  light::ScenePipeline on_gr(o);
  const light::ScenePipelineResult& r2 = on_gr.Process(in);
  EXPECT_FALSE(r2.shadow_on_depth_image);
  EXPECT_FALSE(r2.shadow_options.image_cues);
}

TEST(ScenePipeline, PointModelWarmStartsAndResetsWhenStampsGoBack) {
  Frame s;
  const double lamp[3] = {-0.4, -0.2, 1.8};
  s.LitByLamp(lamp, 4.0, 0.2);
  light::ScenePipelineOptions o = SmallOptions();
  o.light_model = light::LightModel::kPoint;
  light::ScenePipeline pipeline(o);

  // The direct composition: EstimateSceneLight with one tracker over the stream (shadows only
  // for a distant light, which kPoint with a valid point fit never is).
  light::TransferComputer computer(o.transfer);
  light::TransferResult t;
  computer.Compute(s.View(), {}, nullptr, &t);
  light::SceneLightOptions so;
  so.model = o.light_model;
  so.distant = o.estimate;
  so.point = o.point;
  // One albedo model for both fits, as the pipeline composes them.
  so.point.albedo = o.estimate.albedo;
  so.point.albedo_groups = o.estimate.albedo_groups;
  so.point.albedo_invariant = o.estimate.albedo_invariant;
  so.shadow.enabled = false;
  light::PointLightTracker tracker;

  for (const int64_t stamp : {10, 20, 5}) {
    const light::ScenePipelineResult& r = pipeline.Process(s.Input(stamp));
    if (stamp == 5) tracker.Reset();  // stamps went backwards: a new stream, cold again
    const light::SceneLightResult direct =
        light::EstimateSceneLight(s.View(), t, s.grey, so, s.colour, &tracker);
    ASSERT_EQ(r.used, light::LightModel::kPoint) << stamp;
    ExpectSameLight(r.light, direct.light);
    EXPECT_EQ(r.point.warm_started, direct.point.warm_started) << stamp;
    EXPECT_EQ(r.point.warm_started, stamp == 20) << stamp;
    EXPECT_FALSE(r.shadow_ran);
    EXPECT_FALSE(std::isnan(r.timings.cpu_ms_point));
  }

  // Without warm starts every frame is cold.
  o.point_warm_start = false;
  light::ScenePipeline cold(o);
  cold.Process(s.Input(1));
  EXPECT_FALSE(cold.Process(s.Input(2)).point.warm_started);
}

TEST(ScenePipeline, IndirectFromThePreviousFramesLight) {
  Frame s;
  s.LitByDistant(kSun, 3.0, 0.3);
  light::ScenePipelineOptions o = SmallOptions();
  o.light_model = light::LightModel::kDistant;
  o.indirect = true;
  light::ScenePipeline pipeline(o);
  const light::LightEstimate first = pipeline.Process(s.Input(1)).light;
  EXPECT_FALSE(pipeline.Process(s.Input(0)).has_indirect);  // backwards: no previous light
  const light::LightEstimate second = pipeline.Process(s.Input(2)).light;
  ASSERT_TRUE(second.valid);
  const light::ScenePipelineResult& r = pipeline.Process(s.Input(3));
  ASSERT_TRUE(r.has_indirect);

  light::TransferComputer computer(o.transfer);
  light::TransferResult t;
  const light::DominantLight previous{second.dominant_direction, second.intensity};
  computer.Compute(s.View(), {}, &previous, &t);
  EXPECT_EQ(r.transfer->indirect, t.indirect);
  EXPECT_EQ(r.transfer->transfer, t.transfer);
  EXPECT_TRUE(first.valid);
}

TEST(ScenePipeline, TemporalRotatesTheHistoryByThePose) {
  Frame s;
  s.LitByDistant(kSun, 3.0, 0.3);
  light::ScenePipelineOptions o = SmallOptions();
  o.light_model = light::LightModel::kDistant;
  o.temporal.frames = 3;
  light::ScenePipeline pipeline(o);
  light::TemporalLightEstimator direct(o.temporal);
  light::TransferComputer computer(o.transfer);
  light::TransferResult t;
  computer.Compute(s.View(), {}, nullptr, &t);

  // Camera-to-world rotations about y by 0, 2 and 5 degrees (the same image: only the history's
  // rotation differs, which is what is tested).
  const double angles[3] = {0, 2, 5};
  std::array<double, 9> previous{};
  for (int i = 0; i < 3; ++i) {
    const double a = angles[i] * kPi / 180;
    const std::array<double, 9> c2w{std::cos(a),  0, std::sin(a), 0, 1, 0,
                                    -std::sin(a), 0, std::cos(a)};
    light::SceneFrame in = s.Input(i);
    in.camera_to_world_rotation = c2w;
    const light::ScenePipelineResult& r = pipeline.Process(in);
    float rotation[9];
    for (int p = 0; p < 3; ++p) {
      for (int q = 0; q < 3; ++q) {
        double x = 0;
        for (int c = 0; c < 3; ++c) x += c2w[c * 3 + p] * previous[c * 3 + q];  // R_now^T R_prev
        rotation[p * 3 + q] = static_cast<float>(x);
      }
    }
    const light::LightEstimate e =
        direct.Estimate(t, s.grey, o.estimate, s.colour, i > 0 ? rotation : nullptr);
    ExpectSameLight(r.light, e);
    EXPECT_FALSE(r.shadow_ran);  // no shadow refinement with the temporal fit
    previous = c2w;
  }
}

TEST(ScenePipeline, FocusFollowsTheLightAtTheInsertedObject) {
  // Two spheres on the floor; the second and the floor within 0.8 m of it under a light of its
  // own, the rest under kSun: with the focus on a sphere the fit follows that sphere's light,
  // without it the two mix.
  Frame s(/*second_sphere=*/true);
  const double c1[3] = {0.3, 0.5, 2.5}, c2[3] = {-0.7, 0.6, 3.2};
  const double other[3] = {-0.70, -0.60, 0.387};  // unit, 82 degrees from kSun
  s.LitByRegions(c2, 0.8, other, kSun, 3.0, 0.3);
  light::ScenePipelineOptions o = SmallOptions();
  o.light_model = light::LightModel::kDistant;
  o.shadow.enabled = false;
  auto angle = [](const light::LightEstimate& e, const double* l) {
    const auto& d = e.dominant_direction;
    return std::acos(std::clamp(d[0] * l[0] + d[1] * l[1] + d[2] * l[2], -1.0, 1.0)) * 180 / kPi;
  };
  light::ScenePipeline plain(o);
  const light::LightEstimate without = plain.Process(s.Input(1)).light;
  ASSERT_TRUE(without.valid);
  light::SceneFrame in = s.Input(1);
  in.focus = std::array<float, 3>{-0.7f, 0.6f, 3.2f};
  // Radius 0: the focus is ignored, bit for bit.
  o.focus.radius_m = 0;
  light::ScenePipeline off(o);
  ExpectSameLight(off.Process(in).light, without);
  o.focus = {.radius_m = 0.3f, .floor = 0.02f};
  for (const double* focus : {c1, c2}) {
    in.focus = std::array<float, 3>{static_cast<float>(focus[0]), static_cast<float>(focus[1]),
                                    static_cast<float>(focus[2])};
    const double* l = focus == c2 ? other : kSun;
    light::ScenePipeline focused(o);
    const light::LightEstimate with = focused.Process(in).light;
    ASSERT_TRUE(with.valid);
    // (The residual of the farther, smaller second sphere: the SSDO transfer sees the contact
    // occlusion that this shading leaves out.)
    EXPECT_LT(angle(with, l), focus == c2 ? 20.0 : 5.0) << (focus == c2 ? "second" : "first");
    EXPECT_GT(angle(without, l), angle(with, l) + 5.0) << (focus == c2 ? "second" : "first");
  }
}

TEST(ScenePipeline, UncertaintyBlurSoftensByTheExpectedError) {
  Frame s;
  s.LitByDistant(kSun, 3.0, 0.3);
  light::ScenePipelineOptions o = SmallOptions();
  o.light_model = light::LightModel::kDistant;
  o.shadow.enabled = false;
  o.confidence_knots = std::vector<double>{0.0, 45.0, 1.0, 45.0};  // every frame: 45 degrees
  light::ScenePipeline sharp(o);
  const light::LightEstimate a = sharp.Process(s.Input(1)).light;
  o.uncertainty_blur = 1;
  light::ScenePipeline soft(o);
  const light::LightEstimate b = soft.Process(s.Input(1)).light;
  ASSERT_TRUE(a.valid && b.valid);
  EXPECT_EQ(a.dominant_direction, b.dominant_direction);
  EXPECT_EQ(a.confidence, b.confidence);
  const double sigma = 45 * kPi / 180 / std::sqrt(2 * std::log(2.0));
  ASSERT_EQ(a.coefficients.size(), b.coefficients.size());
  EXPECT_EQ(a.coefficients[0], b.coefficients[0]);
  for (size_t k = 1; k < a.coefficients.size(); ++k) {
    const int l = k < 4 ? 1 : k < 9 ? 2 : 3;
    EXPECT_NEAR(b.coefficients[k], a.coefficients[k] * std::exp(-0.5 * l * (l + 1) * sigma * sigma),
                1e-9 + 1e-6 * std::abs(a.coefficients[k]))
        << "coefficient " << k;
  }
  // Band 1 of a 45-degree guess keeps 64 % of its length, band 3 7 %.
  EXPECT_NEAR(std::exp(-sigma * sigma), 0.64, 0.01);
  EXPECT_NEAR(std::exp(-6 * sigma * sigma), 0.07, 0.01);
  // Raw confidence (no calibration): nothing to blur by.
  o.confidence_knots.emplace();
  light::ScenePipeline raw(o);
  const light::LightEstimate c = raw.Process(s.Input(1)).light;
  light::ScenePipelineOptions o_raw = o;
  o_raw.uncertainty_blur = 0;
  light::ScenePipeline raw_sharp(o_raw);
  ExpectSameLight(c, raw_sharp.Process(s.Input(1)).light);
}

TEST(ScenePipeline, FollowsALampSwitchedOffMovedAndOnWithinThreeFrames) {
  // A stream of frames whose lamp switches (on at A, moved to B, off, on at A again): by the
  // third frame after each switch the stream's light equals a fresh pipeline's on that frame (no
  // state held back: warm starts, the previous light), and with the lamp off its power is gone.
  light::ScenePipelineOptions o = SmallOptions();  // light_model auto
  o.shadow.enabled = false;
  const double a[3] = {-0.4, -0.2, 1.8}, b[3] = {0.6, -0.3, 1.5};
  struct Phase {
    const double* lamp;
    double power;
  };
  const Phase phases[] = {{a, 4.0}, {b, 4.0}, {a, 0.0}, {a, 4.0}};
  light::ScenePipeline stream(o);
  Frame s;
  int64_t stamp = 0;
  float on_intensity = 0;
  for (const Phase& phase : phases) {
    s.LitByLamp(phase.lamp, phase.power, 0.2);
    light::ScenePipeline fresh(o);
    const light::LightEstimate reference = fresh.Process(s.Input(1)).light;
    for (int k = 0; k < 3; ++k) {
      const light::LightEstimate e = stream.Process(s.Input(++stamp)).light;
      ASSERT_TRUE(e.valid && reference.valid) << "frame " << stamp;
      if (k < 2) continue;  // followed by the third frame at the latest
      if (phase.power > 0) {
        const auto& d = e.dominant_direction;
        const auto& r = reference.dominant_direction;
        EXPECT_GT(d[0] * r[0] + d[1] * r[1] + d[2] * r[2], std::cos(3 * kPi / 180))
            << "frame " << stamp;
        EXPECT_NEAR(e.intensity, reference.intensity, 0.05 * reference.intensity)
            << "frame " << stamp;
        on_intensity = std::max(on_intensity, e.intensity);
      } else {
        // The ambient's own directional part (the room's occlusion of it) is what remains.
        EXPECT_NEAR(e.intensity, reference.intensity, 0.02f * on_intensity) << "frame " << stamp;
        EXPECT_LT(e.intensity, 0.25f * on_intensity) << "frame " << stamp << ": the lamp is off";
      }
    }
  }
}

TEST(ScenePipeline, BadOptionsAndInput) {
  auto error = [](auto&& edit) {
    light::ScenePipelineOptions o = SmallOptions();
    edit(o);
    return ThrownMessage<light::LightError>([&] { light::ScenePipeline p(o); });
  };
  EXPECT_EQ(error([](auto& o) { o.temporal.frames = 2; }),
            "light::ScenePipeline: temporal.frames > 1 needs light_model distant, got auto");
  EXPECT_EQ(error([](auto& o) {
              o.reliability_weights = true;
              o.light_model = light::LightModel::kPoint;
            }),
            "light::ScenePipeline: reliability_weights needs light_model distant, got point");
  EXPECT_EQ(error([](auto& o) { o.point.max_lamps = 3; }),
            "light::ScenePipeline: point.max_lamps must be 1 or 2, got 3");
  EXPECT_EQ(error([](auto& o) { o.shadow.stride = 0; }),
            "light::ScenePipeline: shadow.stride and shadow.coarse_stride must be >= 1, got 0 and "
            "16");
  EXPECT_EQ(error([](auto& o) { o.gbuffer_normal_step = 0; }),
            "light::ScenePipeline: gbuffer_normal_step must be -1 (max(2, width / 160)) or >= 1, "
            "got 0");
  EXPECT_EQ(error([](auto& o) { o.depth_geometry.step = -2; }),
            "light::ScenePipeline: depth_geometry.step must be -1 (by the noise) or >= 1, got -2");
  EXPECT_EQ(error([](auto& o) { o.focus.floor = 1.5f; }),
            "light::ScenePipeline: focus.radius_m must be >= 0 and focus.floor in [0, 1], got "
            "0.500000 and 1.500000");
  EXPECT_EQ(error([](auto& o) { o.uncertainty_blur = -1; }),
            "light::ScenePipeline: uncertainty_blur must be >= 0, got -1.000000");
  EXPECT_EQ(error([](auto& o) { o.temporal.forgetting = 2; }).rfind("light::", 0), 0u);

  Frame s;
  s.LitByDistant(kSun, 3.0, 0.3);
  light::ScenePipeline pipeline(SmallOptions());
  light::SceneFrame in = s.Input(1, false);
  EXPECT_EQ(ThrownMessage<light::LightError>([&] { pipeline.Process(in); }),
            "light::ScenePipeline::Process: source geometry buffer, but the frame has no G-buffer "
            "depth");
  in = s.Input(1);
  in.grey = std::span<const float>(s.grey).first(100);
  EXPECT_EQ(ThrownMessage<light::LightError>([&] { pipeline.Process(in); }),
            "light::ScenePipeline::Process: grey has 100 values, expected 160x120");
  in = s.Input(1);
  in.gbuffer_normals = {};
  EXPECT_EQ(ThrownMessage<light::LightError>([&] { pipeline.Process(in); }),
            "light::ScenePipeline::Process: missing normals");
  light::ScenePipelineOptions depth_source = SmallOptions();
  depth_source.source = light::SceneGeometrySource::kDepthImage;
  light::ScenePipeline from_depth(depth_source);
  EXPECT_EQ(ThrownMessage<light::LightError>([&] { from_depth.Process(s.Input(1)); }),
            "light::ScenePipeline::Process: source depth image, but the frame has none");
}

}  // namespace
