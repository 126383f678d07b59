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
#include <cstdlib>
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

// The model under test: $PROBELESS_FACE_LIGHT_MODEL if set (to compare a candidate model, e.g. an
// `rtf_train --align tracker` one), else the shipped data/face_light/default_model.txt.
std::string ModelPath() {
  const char* path = std::getenv("PROBELESS_FACE_LIGHT_MODEL");
  if (path && *path) return path;
  return std::string(PROBELESS_SOURCE_DIR) + "/data/face_light/default_model.txt";
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
  const fl::FaceLightModel model = fl::LoadModel(ModelPath());
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
    std::printf(
        "frame %3d: estimate %6.3f %6.3f %6.3f, error vs face light %5.1f, vs camera %5.1f\n",
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

// Eye-to-mouth drop and eye-to-nose-tip drop over the inter-ocular distance of the four
// CanonicalLandmarks points (right eye, left eye, nose tip, mouth), measured perpendicular to the
// eye line (roll-invariant).
std::array<double, 2> Proportions(const std::array<fl::Point2, 4>& k) {
  const double ex = k[1].x - k[0].x, ey = k[1].y - k[0].y;
  const double iod = std::hypot(ex, ey);
  const double mx = (k[0].x + k[1].x) / 2, my = (k[0].y + k[1].y) / 2;
  const auto drop = [&](const fl::Point2& p) { return ((p.y - my) * ex - (p.x - mx) * ey) / iod; };
  return {drop(k[3]) / iod, drop(k[2]) / iod};
}

// The similarity-aligned sampler assumes a face proportioned like the Yale B faces the model was
// trained on (kTrackerCanonical: eye-mouth / inter-ocular 1.02, eye-nose tip 0.47); a longer face
// puts the samples elsewhere (docs/face_light.md). The procedural head's ground-truth landmarks
// must have those proportions, and so must the tracker's landmarks on it while the light is near
// the camera (face_orbit frames 0-9; with the light at the side, frames 12-27, the tracked eyes
// drift a few pixels up and the tracked eye-mouth ratio rises to ~1.1).
TEST(FaceSyntheticLight, ProceduralHeadHasYaleBProportions) {
  const std::array<double, 2> yaleb = Proportions(ft::kTrackerCanonical);
  sim::Simulator simulator(FaceOrbit(), 2);
  ft::FaceTracker tracker;
  std::vector<double> mouth, nose, truth_mouth, truth_nose;
  for (uint64_t i : {0, 3, 6, 9}) {
    const sim::SimFrame f = simulator.Render(i);
    const ft::ImageView view{f.rgb.data(), f.camera.width, f.camera.height,
                             static_cast<size_t>(f.camera.width) * 3, ft::PixelFormat::kRgb};
    const ft::FaceTrack t =
        tracker.Track(view, {f.camera.fx, f.camera.fy, f.camera.cx, f.camera.cy});
    ASSERT_EQ(f.face.landmarks.size(), 68u);
    std::vector<ft::Point2f> truth;
    for (const auto& l : f.face.landmarks) truth.push_back({l[0], l[1]});
    const std::array<double, 2> g = Proportions(ft::CanonicalLandmarks(truth));
    truth_mouth.push_back(g[0]);
    truth_nose.push_back(g[1]);
    ASSERT_TRUE(t.found) << "the procedural head was not found in frame " << i;
    const std::array<double, 2> p = Proportions(ft::CanonicalLandmarks(t.landmarks));
    mouth.push_back(p[0]);
    nose.push_back(p[1]);
  }
  std::printf(
      "eye-mouth / inter-ocular: Yale B %.3f, tracked %.3f, ground truth %.3f; eye-nose "
      "tip: Yale B %.3f, tracked %.3f, ground truth %.3f\n",
      yaleb[0], Median(mouth), Median(truth_mouth), yaleb[1], Median(nose), Median(truth_nose));
  // Measured: tracked 1.061 / 0.475, ground truth 1.006 / 0.497 (the head before issue #6: ground
  // truth 1.26 / 0.76, tracked over frames 0-27 1.11 / 0.74).
  EXPECT_NEAR(Median(truth_mouth), yaleb[0], 0.04);
  EXPECT_NEAR(Median(truth_nose), yaleb[1], 0.05);
  EXPECT_NEAR(Median(mouth), yaleb[0], 0.05);
  EXPECT_NEAR(Median(nose), yaleb[1], 0.06);
}

TEST(FaceSyntheticLight, OrbitCameraFrameDirectionAgainstTheLightAtTheFace) {
  const Errors linear_units = RunFrames(FaceOrbit(), kFrames, /*srgb=*/false);
  const Errors decoded = RunFrames(FaceOrbit(), kFrames, /*srgb=*/true);
  ASSERT_GE(decoded.vs_face.size(), 10u) << "the procedural head was not found";
  const double raw = Median(linear_units.vs_face), fixed = Median(decoded.vs_face);
  const double camera = Median(decoded.vs_camera);
  std::printf(
      "median error vs the light at the face: sRGB values %.1f deg, decoded %.1f deg; "
      "decoded vs the light at the camera %.1f deg\n",
      raw, fixed, camera);
  // Measured with the shipped (landmark-aligned) model on the human-proportioned head (issue #6):
  // decoded 5.6 deg, sRGB values as they are 15.1 deg, vs the camera-position light 52.4 deg (the
  // crop-sampled model: 4.5 / 13.7 / 51.3 deg; before issue #6, on the long-faced head, it measured
  // 16.2 / 26.8 / 60 deg and the aligned model 24.1 deg decoded). The demo's symptom: ~80 deg with
  // the sRGB values vs the camera-position light.
  EXPECT_LT(fixed, 20.0);
  EXPECT_LT(fixed, raw - 6);
  EXPECT_GT(camera, 50.0);
}

// Per-segment figures of one pass over the face_orbit stream.
struct SegmentErrors {
  std::array<std::vector<double>, 3> errors, intensity;  // front, side, behind
  std::array<int, 3> frames{};
};

const char* const kSegmentNames[3] = {"front", "side", "behind"};

// The whole face_orbit stream in order through one tracker (or, with `truth`, the simulator's
// landmarks and head pose instead: what the sampler and the estimator give with perfect
// tracking), the sRGB values decoded, back prior 0.1: the camera-frame direction error vs the
// light at the face (/groundtruth/face_light). Segment by the angle between that light and the
// face's forward direction (ground-truth head pose): front (< 60 deg), side (60-120 deg),
// behind (> 120 deg).
SegmentErrors RunSegments(bool truth) {
  const sim::Scenario scenario = FaceOrbit();
  sim::Simulator simulator(scenario, 2);
  ft::FaceTracker tracker;
  const fl::FaceLightModel model = fl::LoadModel(ModelPath());
  ft::SamplerOptions so;
  so.srgb_input = true;
  const ft::FaceSampler sampler(model, so);
  fl::EstimatorOptions eo;
  eo.back_prior = 0.1;
  const fl::FaceLightEstimator estimator(model, eo);
  SegmentErrors out;
  for (uint64_t i = 0; i < static_cast<uint64_t>(scenario.frames); ++i) {
    const sim::SimFrame f = simulator.Render(i);
    const ft::ImageView view{f.rgb.data(), f.camera.width, f.camera.height,
                             static_cast<size_t>(f.camera.width) * 3, ft::PixelFormat::kRgb};
    ft::FaceTrack t = tracker.Track(view, {f.camera.fx, f.camera.fy, f.camera.cx, f.camera.cy});
    if (truth) {
      EXPECT_EQ(f.face.landmarks.size(), 68u);
      t = ft::FaceTrack{};
      t.found = t.detected = true;
      for (int j = 0; j < ft::kLandmarkCount; ++j) {
        t.landmarks[j] = {f.face.landmarks[j][0], f.face.landmarks[j][1]};
      }
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) t.pose.rotation[r * 3 + c] = f.face.head_pose.rotation.m[r][c];
      }
      t.pose.translation = f.face.head_pose.translation;
      t.pose.valid = true;
    }
    // The face's forward direction (face frame -z, out of the face) in the camera frame.
    const raytrace::Vec3 forward = f.face.head_pose.rotation * raytrace::Vec3{0, 0, -1};
    const double light_angle =
        AngleDeg({forward.x, forward.y, forward.z}, f.face_light.dominant_direction);
    const int segment = light_angle < 60 ? 0 : light_angle <= 120 ? 1 : 2;
    ++out.frames[segment];
    if (!t.found || !t.pose.valid) continue;
    const ft::FaceSamples s = sampler.Sample(view, t);
    std::vector<uint64_t> bits((s.count + 63) / 64, 0);
    for (int j = 0; j < s.count; ++j) {
      if (!s.flags[j]) bits[j / 64] |= uint64_t{1} << (j % 64);
    }
    const fl::LightEstimate e = estimator.EstimateRgb(s.rgb, bits);
    if (e.channels == 0) continue;
    const std::array<float, 3> d = ft::RotateVector(t.pose.rotation, e.dominant_direction);
    out.errors[segment].push_back(AngleDeg(d, f.face_light.dominant_direction));
    out.intensity[segment].push_back(e.intensity);
    std::printf(
        "%s frame %3d: light %5.1f deg from the face forward (%s), %s, error %5.1f deg, "
        "intensity %.3f\n",
        truth ? "truth" : "tracked", static_cast<int>(i), light_angle, kSegmentNames[segment],
        t.detected ? "detected"
        : t.flow   ? "flow"
                   : "tracked",
        out.errors[segment].back(), e.intensity);
  }
  for (int k = 0; k < 3; ++k) {
    std::vector<double> v = out.errors[k];
    std::sort(v.begin(), v.end());
    const double p90 = v.empty() ? NAN : v[std::min(v.size() - 1, v.size() * 9 / 10)];
    std::printf(
        "%s landmarks and pose, %s: %d frames, %zu estimates, median %.1f deg, p90 %.1f deg, "
        "median intensity %.3f\n",
        truth ? "ground-truth" : "tracked", kSegmentNames[k], out.frames[k], v.size(), Median(v),
        p90, Median(out.intensity[k]));
  }
  return out;
}

// The demo's side-lit and back-lit frames (face_orbit ~19-101), which the tracker keeps with flow
// tracking + CLAHE: how good is the light there.
TEST(FaceSyntheticLight, OrbitErrorPerSegmentFrontSideBehind) {
  const SegmentErrors tracked = RunSegments(false);
  const SegmentErrors truth = RunSegments(true);
  for (int k = 0; k < 3; ++k) {
    EXPECT_GE(tracked.errors[k].size() + 3, static_cast<size_t>(tracked.frames[k]))
        << kSegmentNames[k] << ": the tracker lost the face";
  }
  // Measured (shipped model): front median 4.1 / p90 6.2 deg, side 10.6 / 26.3 deg (19-41:
  // median 20.4, 79-101: 9.0), behind 134.9 / 145.3 deg: a light behind the head does not light
  // the face; the estimate points forward, but its intensity falls to ~0.08 (front ~0.37).
  EXPECT_LT(Median(tracked.errors[0]), 10.0);
  EXPECT_LT(Median(tracked.errors[1]), 20.0);
  EXPECT_LT(Median(tracked.intensity[2]), 0.4 * Median(tracked.intensity[0]));
  EXPECT_LT(Median(truth.errors[0]), 10.0);
}

}  // namespace
