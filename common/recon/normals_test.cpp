// G_r normals from the TSDF gradient (FusionOptions::normal_source = kVolume) against the
// normals of the merged depth, on an analytic sphere seen through Kinect-like depth quantisation.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "probeless/recon/pipeline.h"
#include "test_scene.h"

namespace probeless::recon {
namespace {

using testing::PoseFrom;
using testing::Scene;
using testing::TestIntrinsics;
using testing::TestVolumeOptions;

constexpr float kRadToDeg = 57.29578f;

// Kinect-like depth: quantised in disparity (step 0.0029 z^2 metres, 6.5 mm at 1.5 m) after
// Gaussian noise of 0.0012 z^2 metres (fixed seed).
DepthImage Quantised(const DepthImage& exact, std::mt19937& rng) {
  constexpr float kDisparityPerMetre = 1.0f / 0.0029f;  // z step = z^2 / kDisparityPerMetre
  std::normal_distribution<float> noise(0.0f, 1.0f);
  DepthImage out = exact;
  for (float& z : out.data) {
    if (!(z > 0)) continue;
    const float noisy = z + 0.0012f * z * z * noise(rng);
    z = kDisparityPerMetre / std::round(kDisparityPerMetre / noisy);
  }
  return out;
}

struct NormalErrors {
  float median_deg = 0;
  float p90_deg = 0;
  int pixels = 0;
};

// Angles between G_r's normals and the analytic sphere normals on the pixels whose exact depth
// lies on the sphere and at least 3 pixels inside its silhouette (the rim is the background's).
NormalErrors SphereErrors(const FusionPipeline& pipeline, const DepthImage& exact,
                          const Intrinsics& k, const Pose& camera_to_world, Vec3f centre_world,
                          float radius) {
  const Pose world_to_camera = camera_to_world.Inverse();
  const Vec3f centre = world_to_camera.Apply(centre_world);
  std::vector<float> errors;
  const Vec3Image& normals = pipeline.merged_normals();
  for (int y = 3; y + 3 < k.height; ++y) {
    for (int x = 3; x + 3 < k.width; ++x) {
      bool inside = true;
      for (int dy = -3; dy <= 3 && inside; ++dy) {
        for (int dx = -3; dx <= 3 && inside; ++dx) {
          const float z = exact.At(x + dx, y + dy);
          const Vec3f p{(x + dx - k.cx) / k.fx * z, (y + dy - k.cy) / k.fy * z, z};
          inside = z > 0 && std::fabs(Norm(p - centre) - radius) < 1e-3f;
        }
      }
      if (!inside) continue;
      const float z = exact.At(x, y);
      const Vec3f p{(x - k.cx) / k.fx * z, (y - k.cy) / k.fy * z, z};
      const Vec3f truth = Normalized(p - centre);
      const Vec3f n = normals.At(x, y);
      const float c = Norm(n) > 0.5f ? std::clamp(Dot(n, truth), -1.0f, 1.0f) : -1.0f;
      errors.push_back(std::acos(c) * kRadToDeg);  // a missing normal counts as 180 degrees
    }
  }
  NormalErrors e;
  e.pixels = static_cast<int>(errors.size());
  if (errors.empty()) return e;
  std::sort(errors.begin(), errors.end());
  e.median_deg = errors[errors.size() / 2];
  e.p90_deg = errors[errors.size() * 9 / 10];
  return e;
}

// A 12 cm ball in front of a wall at 1.6 m, seen by a camera sliding sideways over 20 frames
// (known poses), quantised depth; the last frame's G_r normals on the ball.
NormalErrors RunBall(NormalSource source) {
  Scene scene;
  scene.planes.push_back({Normalized({0, 0, -1}), -1.6f});
  const Vec3f centre{0.02f, 0.0f, 1.25f};
  constexpr float kRadius = 0.12f;
  scene.spheres.push_back({centre, kRadius});
  const Intrinsics k = TestIntrinsics(320, 240);
  FusionOptions options;
  options.volume = TestVolumeOptions();  // 2 m, 256^3: 7.8 mm voxels
  options.threads = 2;
  options.normal_source = source;
  FusionPipeline pipeline(options);
  std::mt19937 rng(7);
  Pose pose;
  DepthImage exact;
  for (int f = 0; f < 20; ++f) {
    pose = PoseFrom(0, 0.004 * f, 0, 0.006 * f - 0.06, 0.002 * f, 0);
    exact = scene.Render(pose, k);
    pipeline.Process(Quantised(exact, rng), k, nullptr, &pose);
  }
  return SphereErrors(pipeline, exact, k, pose, centre, kRadius);
}

TEST(VolumeNormals, BallUnderQuantisationBeatsDepthNormals) {
  const NormalErrors depth = RunBall(NormalSource::kDepth);
  const NormalErrors volume = RunBall(NormalSource::kVolume);
  std::printf(
      "ball normals vs analytic, median / p90 deg: depth %.2f / %.2f, volume %.2f / %.2f "
      "(%d pixels)\n",
      depth.median_deg, depth.p90_deg, volume.median_deg, volume.p90_deg, volume.pixels);
  ASSERT_GT(volume.pixels, 500);
  EXPECT_EQ(volume.pixels, depth.pixels);
  EXPECT_LT(volume.median_deg, 4.0f);
  EXPECT_LT(volume.p90_deg, 10.0f);
  EXPECT_LT(volume.median_deg, 0.6f * depth.median_deg);
  EXPECT_LT(volume.p90_deg, depth.p90_deg);
}

TEST(VolumeNormals, NormalAtOnAPlaneAndOutside) {
  Scene scene;
  const Vec3f n_true = Normalized({0.3f, -0.2f, -1.0f});  // towards a camera at the origin
  scene.planes.push_back({n_true, Dot(n_true, Vec3f{0, 0, 1.3f})});
  const Intrinsics k = TestIntrinsics(320, 240);
  TsdfVolume volume(TestVolumeOptions());
  const Pose identity;
  volume.Integrate(scene.Render(identity, k), k, identity, nullptr);
  Vec3f n;
  ASSERT_TRUE(volume.NormalAt({0.05f, 0.02f, 1.3f}, 1.0f, &n));
  EXPECT_GT(Dot(n, n_true), std::cos(1.0f / kRadToDeg));
  const Vec3f untouched{9, 9, 9};
  n = untouched;
  EXPECT_FALSE(volume.NormalAt({5.0f, 0.0f, 1.3f}, 1.0f, &n));  // outside the cube
  EXPECT_FALSE(volume.NormalAt({0.0f, 0.0f, 0.4f}, 1.0f, &n));  // never observed
  EXPECT_EQ(n.x, untouched.x);
}

}  // namespace
}  // namespace probeless::recon
