// The face light as face_light publishes it (tracker -> sampler -> estimator -> linear conversion
// -> calibrated confidence -> head-pose rotation -> hold) over the whole face_orbit stream (the
// demo: a point light orbiting the head, in front, at the side, behind), against the simulator's
// linear light at the face (/groundtruth/face_light): direction error, confidence, held frames
// and how bright the virtual object's camera-facing side is lit relative to the truth, per segment
// (docs/face_light.md, "Linear light").
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "probeless/face_light/estimator.h"
#include "probeless/face_light/linear_light.h"
#include "probeless/face_light/model.h"
#include "probeless/face_track/face_tracker.h"
#include "probeless/face_track/light_output.h"
#include "probeless/face_track/sampling.h"
#include "probeless/light/fusion.h"
#include "probeless/sh/sh.h"
#include "probeless/sim/scenario.h"
#include "probeless/sim/simulator.h"

namespace {
using namespace probeless;
namespace ft = probeless::face_track;
namespace fl = probeless::face_light;

double AngleDeg(const std::array<float, 3>& a, const raytrace::Vec3& b) {
  const double d = a[0] * b.x + a[1] * b.y + a[2] * b.z;
  const double n = std::sqrt((a[0] * a[0] + a[1] * a[1] + a[2] * a[2]) * raytrace::Dot(b, b));
  return std::acos(std::clamp(d / n, -1.0, 1.0)) * 180 / M_PI;
}

double Quantile(std::vector<double> v, double q) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(q * v.size()))];
}

// Lambertian irradiance / pi (what a white surface reads) of the channel-mean light at normal n.
double Reading(const std::array<double, 9>& c, const sh::Vec3& n) {
  const auto y = sh::Basis9(n);
  double e = 0;
  for (int k = 0; k < 9; ++k) {
    e += sh::ClampedCosineCoefficient(k == 0 ? 0 : k < 4 ? 1 : 2) * y[k] * c[k];
  }
  return e / M_PI;
}

struct Segment {
  std::vector<double> error, raw_error, confidence, ratio, raw_ratio, own_ratio;
  int frames = 0, held = 0;
};

TEST(FaceLinearOrbit, PublishedLightPerSegment) {
  const sim::Scenario scenario =
      sim::LoadScenario(std::string(PROBELESS_SOURCE_DIR) + "/data/scenarios/face_orbit.yaml");
  sim::Simulator simulator(scenario, 2);
  ft::FaceTracker tracker;
  const fl::FaceLightModel model =
      fl::LoadModel(std::string(PROBELESS_SOURCE_DIR) + "/data/face_light/default_model.txt");
  ft::SamplerOptions so;
  so.srgb_input = true;  // the simulator's images are sRGB (face_tracker image_transfer: srgb)
  const ft::FaceSampler sampler(model, so);
  fl::EstimatorOptions eo;
  eo.back_prior = 0.1;
  const fl::FaceLightEstimator estimator(model, eo);
  const fl::LinearLightConverter converter(model);
  // The same with the procedural head's own skin albedo (raytrace::MakeHead's default): the
  // absolute scale when the albedo is known.
  fl::LinearLightOptions own_options;
  own_options.skin_albedo = {0.62, 0.42, 0.33};
  const fl::LinearLightConverter own(model, own_options);
  ft::LightHold hold;
  std::array<Segment, 3> segments;
  const char* const names[3] = {"front", "side", "behind"};
  const sh::Vec3 towards_camera{0, 0, -1};  // the virtual object's camera-facing normal
  for (uint64_t i = 0; i < static_cast<uint64_t>(scenario.frames); ++i) {
    const sim::SimFrame f = simulator.Render(i);
    const raytrace::Vec3 forward = f.face.head_pose.rotation * raytrace::Vec3{0, 0, -1};
    const double light_angle =
        AngleDeg({forward.x, forward.y, forward.z}, f.face_light.dominant_direction);
    Segment& seg = segments[light_angle < 60 ? 0 : light_angle <= 120 ? 1 : 2];
    ++seg.frames;
    const ft::ImageView view{f.rgb.data(), f.camera.width, f.camera.height,
                             static_cast<size_t>(f.camera.width) * 3, ft::PixelFormat::kRgb};
    const ft::FaceTrack t =
        tracker.Track(view, {f.camera.fx, f.camera.fy, f.camera.cx, f.camera.cy});
    if (!t.found || !t.pose.valid) continue;
    const ft::FaceSamples s = sampler.Sample(view, t);
    std::vector<uint64_t> bits((s.count + 63) / 64, 0);
    for (int j = 0; j < s.count; ++j) {
      if (!s.flags[j]) bits[j / 64] |= uint64_t{1} << (j % 64);
    }
    const fl::LightEstimate e = estimator.EstimateRgb(s.rgb, bits);
    if (e.channels == 0) continue;
    const fl::LinearLight linear = converter.Convert(s.rgb, bits, e);
    if (!linear.valid) continue;
    const float confidence = static_cast<float>(
        light::ConfidenceFromExpectedError(fl::FaceLightExpectedErrorDeg(linear)));
    const ft::Sh9Rgb camera = ft::RotateSh9(linear.coefficients, t.pose.rotation);
    const std::array<float, 3> direction = ft::RotateVector(t.pose.rotation, linear.direction);
    const ft::LightHold::Output out = hold.Update(camera, direction, linear.intensity, confidence,
                                                  static_cast<int64_t>(f.time_s * 1e9));
    std::array<double, 9> published{}, raw{}, truth{};
    for (int n = 0; n < 9; ++n) {
      published[n] = (out.coefficients[n][0] + out.coefficients[n][1] + out.coefficients[n][2]) / 3;
      raw[n] = (camera[n][0] + camera[n][1] + camera[n][2]) / 3;
      truth[n] = (f.face_light.sh[n].x + f.face_light.sh[n].y + f.face_light.sh[n].z) / 3;
    }
    const double true_reading = Reading(truth, towards_camera);
    const fl::LinearLight own_light = own.Convert(s.rgb, bits, e);
    const ft::Sh9Rgb own_camera = ft::RotateSh9(own_light.coefficients, t.pose.rotation);
    std::array<double, 9> own_mean{};
    for (int n = 0; n < 9; ++n) {
      own_mean[n] = (own_camera[n][0] + own_camera[n][1] + own_camera[n][2]) / 3;
    }
    seg.own_ratio.push_back(Reading(own_mean, towards_camera) / true_reading);
    seg.confidence.push_back(confidence);
    seg.held += out.held;
    seg.ratio.push_back(Reading(published, towards_camera) / true_reading);
    seg.raw_ratio.push_back(Reading(raw, towards_camera) / true_reading);
    seg.raw_error.push_back(AngleDeg(direction, f.face_light.dominant_direction));
    if (out.direction != std::array<float, 3>{0, 0, 0}) {
      seg.error.push_back(AngleDeg(out.direction, f.face_light.dominant_direction));
    }
    std::printf(
        "frame %3d %-6s light %5.1f deg: confidence %.3f%s, error %5.1f, camera-facing "
        "reading %.3f (raw %.3f, truth %.3f)\n",
        static_cast<int>(i), names[&seg - segments.data()], light_angle, confidence,
        out.held ? " held" : "", seg.error.empty() ? NAN : seg.error.back(),
        Reading(published, towards_camera), Reading(raw, towards_camera), true_reading);
  }
  std::vector<double> all, all_raw;
  for (int k = 0; k < 3; ++k) {
    const Segment& s = segments[k];
    all.insert(all.end(), s.error.begin(), s.error.end());
    all_raw.insert(all_raw.end(), s.raw_error.begin(), s.raw_error.end());
    std::printf(
        "%s: %d frames, %zu estimates, %d held; direction error median %.1f p90 %.1f deg "
        "(unheld %.1f / %.1f); confidence median %.3f; camera-facing reading / truth "
        "median %.2f p90 %.2f (unheld %.2f / %.2f)\n",
        names[k], s.frames, s.confidence.size(), s.held, Quantile(s.error, 0.5),
        Quantile(s.error, 0.9), Quantile(s.raw_error, 0.5), Quantile(s.raw_error, 0.9),
        Quantile(s.confidence, 0.5), Quantile(s.ratio, 0.5), Quantile(s.ratio, 0.9),
        Quantile(s.raw_ratio, 0.5), Quantile(s.raw_ratio, 0.9));
  }
  std::printf("all frames: direction error p90 %.1f deg (unheld %.1f)\n", Quantile(all, 0.9),
              Quantile(all_raw, 0.9));
  std::printf("front, the head's own albedo: reading / truth median %.2f p10 %.2f p90 %.2f\n",
              Quantile(segments[0].own_ratio, 0.5), Quantile(segments[0].own_ratio, 0.1),
              Quantile(segments[0].own_ratio, 0.9));
  // Measured: front 37 estimates, 0 held, median 4.1 deg, reading / truth 1.20 (the linear
  // scale with the default skin albedo, 0.47 / 0.62 of the head's: 1.20 x 0.76 = 0.91); side 0
  // held, 10.6 deg; behind 31 of 37 held, median 33.9 / p90 66.0 deg (unheld 134.9 / 145.3),
  // reading / truth 1.02 (unheld 1.25, p90 2.15); all frames p90 48.2 deg (unheld 141.3: the
  // issue's 141).
  const Segment& front = segments[0];
  const Segment& behind = segments[2];
  EXPECT_GE(front.confidence.size() + 3, static_cast<size_t>(front.frames));
  EXPECT_LT(Quantile(front.error, 0.5), 10.0);
  EXPECT_EQ(front.held, 0);
  EXPECT_LT(Quantile(front.ratio, 0.5), 1.5);  // linear, within 50 % of the true reading
  EXPECT_GT(Quantile(front.ratio, 0.5), 0.67);
  // With the head's own albedo (0.62, 0.42, 0.33), measured 0.91 (p10-p90 0.85-0.93).
  EXPECT_NEAR(Quantile(front.own_ratio, 0.5), 1.0, 0.15);
  EXPECT_GE(behind.held, 0.7 * behind.confidence.size());
  EXPECT_LT(Quantile(behind.confidence, 0.5), 0.05);  // below light_fusion's min_confidence
  EXPECT_LT(Quantile(behind.error, 0.5), 60.0);
  EXPECT_GT(Quantile(behind.raw_error, 0.5), 100.0);
  // The backlit face does not brighten the virtual object: its camera-facing side reads no
  // more than the truth's +30 % (median) and less than without the hold.
  EXPECT_LT(Quantile(behind.ratio, 0.5), 1.3);
  EXPECT_LT(Quantile(behind.ratio, 0.9), Quantile(behind.raw_ratio, 0.9));
  EXPECT_LT(Quantile(all, 0.9), 90.0);
}

}  // namespace
