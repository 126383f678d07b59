// The face pipeline's library calls (tracker -> sampler -> estimator -> head-pose rotation) on
// renders of the procedural head (data/scenarios/face_orbit.yaml), against the simulator's light
// at the face origin in the camera frame (sim::SimFrame::face_light). Regression for the demo's
// ~80 deg error: the demo compared with /groundtruth/light (the light seen from the camera, which
// for the orbiting point light 0.78 m from the head is ~45 deg off the light the face sees) and
// fed sRGB-encoded pixel values to a model trained on the roughly linear Yale B pixels
// (docs/face_light.md, "Frames and units on synthetic renders").
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "probeless/face_light/estimator.h"
#include "probeless/face_light/model.h"
#include "probeless/face_track/face_tracker.h"
#include "probeless/face_track/head_model.h"
#include "probeless/face_track/light_output.h"
#include "probeless/face_track/sampling.h"
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

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? NAN : v[v.size() / 2];
}

struct Errors {
  std::vector<double> vs_face, vs_camera;
};

// Frames through the pipeline as face_tracker + face_light run it (back_prior 0.1, directional
// fit, no smoothing); camera-frame direction errors vs the light at the face and at the camera.
Errors RunFrames(const sim::Scenario& scenario, const std::vector<uint64_t>& frames, bool srgb) {
  sim::Simulator simulator(scenario, 2);
  ft::FaceTracker tracker;
  const fl::FaceLightModel model =
      fl::LoadModel(std::string(PROBELESS_SOURCE_DIR) + "/data/face_light/default_model.txt");
  ft::SamplerOptions so;
  so.srgb_input = srgb;
  const ft::FaceSampler sampler(model, so);
  fl::EstimatorOptions eo;
  eo.back_prior = 0.1;
  const fl::FaceLightEstimator estimator(model, eo);
  Errors out;
  for (uint64_t i : frames) {
    const sim::SimFrame f = simulator.Render(i);
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
    // Face frame -> camera frame, as nodes/face_light does.
    const std::array<float, 3> d = ft::RotateVector(t.pose.rotation, e.dominant_direction);
    out.vs_face.push_back(AngleDeg(d, f.face_light.dominant_direction));
    out.vs_camera.push_back(AngleDeg(d, f.light.dominant_direction));
    std::printf("frame %3d: estimate %6.3f %6.3f %6.3f, error vs face light %5.1f, vs camera %5.1f\n",
                static_cast<int>(i), d[0], d[1], d[2], out.vs_face.back(), out.vs_camera.back());
  }
  return out;
}

sim::Scenario FaceOrbit() {
  return sim::LoadScenario(std::string(PROBELESS_SOURCE_DIR) + "/data/scenarios/face_orbit.yaml");
}

// The first 28 frames (the tracker loses the face from ~frame 28 on, when the light is at the side)
// and the last ones, where it is found again.
const std::vector<uint64_t> kFrames{0, 3, 6, 9, 12, 15, 18, 21, 24, 27, 110, 113, 116, 119};

TEST(FaceSyntheticLight, FaceGroundTruthIsTheLightSeenFromTheHead) {
  sim::Simulator simulator(FaceOrbit(), 1);
  const sim::SimFrame f = simulator.Render(0);
  // Frame 0: the point light is at world (0, 1.95, -0.7), the head at (0, 1.6, 0), the camera at
  // (0, 1.62, -0.6) looking along +z (camera x = world -x, y = world -y).
  const raytrace::Vec3 from_head = raytrace::Normalize(raytrace::Vec3{0, -0.35f, -0.7f});
  EXPECT_LT(AngleDeg({f.face_light.dominant_direction.x, f.face_light.dominant_direction.y,
                      f.face_light.dominant_direction.z},
                     from_head),
            2.5);  // the camera pitch (~2 deg)
  // Seen from the camera the same light is ~70 deg up: a different direction.
  EXPECT_GT(AngleDeg({f.light.dominant_direction.x, f.light.dominant_direction.y,
                      f.light.dominant_direction.z},
                     from_head),
            40);
}

TEST(FaceSyntheticLight, OrbitCameraFrameDirectionAgainstTheLightAtTheFace) {
  const Errors linear_units = RunFrames(FaceOrbit(), kFrames, /*srgb=*/false);
  const Errors decoded = RunFrames(FaceOrbit(), kFrames, /*srgb=*/true);
  ASSERT_GE(decoded.vs_face.size(), 10u) << "the procedural head was not found";
  const double raw = Median(linear_units.vs_face), fixed = Median(decoded.vs_face);
  const double camera = Median(decoded.vs_camera);
  std::printf("median error vs the light at the face: sRGB values %.1f deg, decoded %.1f deg; "
              "decoded vs the light at the camera %.1f deg\n",
              raw, fixed, camera);
  // Measured: decoded 16.2 deg, sRGB values as they are 26.8 deg, vs the camera-position light
  // 60 deg (the demo's symptom: ~80 deg with the sRGB values).
  EXPECT_LT(fixed, 20.0);
  EXPECT_LT(fixed, raw - 6);
  EXPECT_GT(camera, 50.0);
}

}  // namespace
