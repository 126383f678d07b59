// Projective point-to-plane ICP recovers a known rigid motion against a raycast model; a frame
// that does not overlap the model fails the tracking-quality test.
#include "probeless/recon/icp.h"

#include <gtest/gtest.h>

#include <cmath>

#include "probeless/recon/pipeline.h"
#include "test_scene.h"

namespace probeless::recon {
namespace {

using testing::CornerScene;
using testing::PoseFrom;
using testing::TestIntrinsics;

double TranslationError(const Pose& a, const Pose& b) {
  const double dx = a.t[0] - b.t[0], dy = a.t[1] - b.t[1], dz = a.t[2] - b.t[2];
  return std::sqrt(dx * dx + dy * dy + dz * dz);
}
double RotationErrorDeg(const Pose& a, const Pose& b) {
  return (a.Inverse() * b).RotationAngle() * 180.0 / M_PI;
}

TEST(Icp, RecoversAKnownRigidMotion) {
  const testing::Scene scene = CornerScene();
  const Intrinsics k = TestIntrinsics();
  ThreadPool pool(2);
  TsdfVolume volume(testing::TestVolumeOptions());
  const Pose model_pose;
  volume.Integrate(scene.Render(model_pose, k), k, model_pose, &pool);
  GeometryView view;
  volume.Raycast(model_pose, k, view, &pool);
  ModelPyramid model;
  BuildModelPyramid(view, model_pose, k, 3, model);

  const Pose truth = PoseFrom(0.02, -0.03, 0.01, 0.03, -0.02, 0.04);  // 2.1 deg, 5.4 cm
  FramePyramid frame;
  Preprocess(scene.Render(truth, k), k, PreprocessOptions{}, frame, &pool);
  const IcpResult r = TrackIcp(frame, model, model_pose, IcpOptions{}, &pool);
  ASSERT_TRUE(r.ok) << r.failure;
  EXPECT_LT(TranslationError(r.camera_to_world, truth), 0.003);
  EXPECT_LT(RotationErrorDeg(r.camera_to_world, truth), 0.2);
  EXPECT_GT(r.inlier_fraction, 0.8f);
  EXPECT_LT(r.rms_m, 0.003f);
}

TEST(Icp, SameResultWithOneOrTwoThreads) {
  const testing::Scene scene = CornerScene();
  const Intrinsics k = TestIntrinsics();
  ThreadPool pool(2);
  TsdfVolume volume(testing::TestVolumeOptions());
  volume.Integrate(scene.Render(Pose{}, k), k, Pose{}, nullptr);
  GeometryView view;
  volume.Raycast(Pose{}, k, view, nullptr);
  ModelPyramid model;
  BuildModelPyramid(view, Pose{}, k, 3, model);
  FramePyramid frame;
  Preprocess(scene.Render(PoseFrom(0, 0.01, 0, 0.01, 0, 0), k), k, PreprocessOptions{}, frame,
             nullptr);
  const IcpResult a = TrackIcp(frame, model, Pose{}, IcpOptions{}, nullptr);
  const IcpResult b = TrackIcp(frame, model, Pose{}, IcpOptions{}, &pool);
  for (int i = 0; i < 9; ++i) EXPECT_EQ(a.camera_to_world.r[i], b.camera_to_world.r[i]);
  for (int i = 0; i < 3; ++i) EXPECT_EQ(a.camera_to_world.t[i], b.camera_to_world.t[i]);
}

TEST(Icp, PipelineReportsLossStopsIntegratingAndRelocalises) {
  const testing::Scene scene = CornerScene();
  const Intrinsics k = TestIntrinsics();
  FusionOptions options;
  options.merge_enabled = false;
  options.volume = testing::TestVolumeOptions();
  FusionPipeline pipeline(options);
  const FrameResult first = pipeline.Process(scene.Render(Pose{}, k), k, nullptr);
  EXPECT_EQ(first.state, TrackingState::kTracking);
  const FrameResult second =
      pipeline.Process(scene.Render(PoseFrom(0, 0.01, 0, 0.01, 0, 0), k), k, nullptr);
  EXPECT_EQ(second.state, TrackingState::kTracking);
  // A frame of a plane 30 cm away that the model does not contain: lost, not integrated.
  testing::Scene other;
  other.planes.push_back({{0, 0, -1}, -0.5f});
  const int bricks = pipeline.volume().ObservedBricks();
  const FrameResult lost = pipeline.Process(other.Render(Pose{}, k), k, nullptr);
  EXPECT_EQ(lost.state, TrackingState::kLost);
  EXPECT_FALSE(lost.integrated);
  EXPECT_FALSE(lost.icp.failure.empty());
  EXPECT_EQ(pipeline.volume().ObservedBricks(), bricks);
  // The scene again near the last good pose: relocalised.
  const FrameResult back =
      pipeline.Process(scene.Render(PoseFrom(0, 0.015, 0, 0.012, 0, 0), k), k, nullptr);
  EXPECT_EQ(back.state, TrackingState::kTracking);
  EXPECT_TRUE(back.relocalised);
  // Reset starts a new map at the initial pose.
  pipeline.Reset();
  EXPECT_EQ(pipeline.state(), TrackingState::kEmpty);
  EXPECT_EQ(pipeline.volume().ObservedBricks(), 0);
}

}  // namespace
}  // namespace probeless::recon
