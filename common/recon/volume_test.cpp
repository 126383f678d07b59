// TSDF integration + raycast of analytic scenes reproduce their depth within a voxel; auxiliary
// orthographic and light views see the surfaces; marching-cubes mesh lies on the surface.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "probeless/recon/tsdf_volume.h"
#include "test_scene.h"

namespace probeless::recon {
namespace {

using testing::CornerScene;
using testing::PoseFrom;
using testing::Scene;
using testing::TestIntrinsics;

// Fraction of pixels where both are valid, and the largest |difference| among them.
struct Compare {
  double both = 0;     // fraction of the reference's valid pixels the raycast also has
  double max_err = 0;  // 95th percentile of |difference| (silhouettes and corners excepted)
  double median_err = 0;
};
Compare CompareDepth(const DepthImage& a, const DepthImage& b) {
  std::vector<double> errs;
  int both = 0, a_valid = 0;
  for (size_t i = 0; i < a.data.size(); ++i) {
    if (a.data[i] > 0) ++a_valid;
    if (a.data[i] > 0 && b.data[i] > 0) {
      ++both;
      errs.push_back(std::fabs(a.data[i] - b.data[i]));
    }
  }
  Compare c;
  c.both = a_valid > 0 ? static_cast<double>(both) / a_valid : 0;
  if (!errs.empty()) {
    std::sort(errs.begin(), errs.end());
    c.max_err = errs[errs.size() * 95 / 100];
    c.median_err = errs[errs.size() / 2];
  }
  return c;
}

TEST(TsdfVolume, PlaneIntegrateRaycastWithinAVoxel) {
  Scene scene;
  scene.planes.push_back({Normalized({0.2f, 0, -1}), -1.0f});
  const Intrinsics k = TestIntrinsics();
  TsdfVolume volume(testing::TestVolumeOptions());
  ThreadPool pool(2);
  const Pose pose;
  const DepthImage depth = scene.Render(pose, k);
  for (int i = 0; i < 3; ++i) volume.Integrate(depth, k, pose, &pool);
  GeometryView view;
  volume.Raycast(pose, k, view, &pool);
  const Compare c = CompareDepth(depth, view.depth);
  EXPECT_GT(c.both, 0.97);
  EXPECT_LT(c.max_err, volume.voxel_size());
  // Normals face the camera and match the plane's.
  const Vec3f n = view.normals.At(k.width / 2, k.height / 2);
  const Vec3f expected = Normalized({0.2f, 0, -1});
  EXPECT_GT(Dot(n, expected), 0.99f);
}

TEST(TsdfVolume, SphereFromSeveralViewsWithinAVoxel) {
  const Scene scene = CornerScene();
  const Intrinsics k = TestIntrinsics();
  TsdfVolume volume(testing::TestVolumeOptions());
  ThreadPool pool(2);
  const Pose poses[3] = {Pose{}, PoseFrom(0, 0.05, 0, -0.05, 0, 0),
                         PoseFrom(0.03, -0.04, 0, 0.04, -0.02, 0.05)};
  for (const Pose& p : poses) volume.Integrate(scene.Render(p, k), k, p, &pool);
  for (const Pose& p : poses) {
    GeometryView view;
    volume.Raycast(p, k, view, &pool);
    const Compare c = CompareDepth(scene.Render(p, k), view.depth);
    EXPECT_GT(c.both, 0.95);
    EXPECT_LT(c.max_err, volume.voxel_size());
    EXPECT_LT(c.median_err, 0.3 * volume.voxel_size());
  }
  // The TSDF is ~0 on the sphere surface and positive in front of it.
  EXPECT_NEAR(volume.TsdfAt({-0.15f, 0.05f, 1.0f}), 0.0f, 0.3f);
  EXPECT_GT(volume.TsdfAt({-0.15f, 0.05f, 0.985f}), 0.3f);
  EXPECT_TRUE(std::isnan(volume.TsdfAt({5, 5, 5})));
}

// Rays that pass a small near object traverse empty bricks and coarse cells (4^3 bricks) up to the
// far wall behind it: skipping must neither stop early nor jump over the wall; the resolution (200,
// i.e. 25 bricks per side) leaves a partial coarse cell at the volume's far faces.
TEST(TsdfVolume, EmptySpaceSkippingReachesSurfacesBehindEmptyCells) {
  Scene scene;
  scene.planes.push_back({Normalized({0, 0, -1}), -2.1f});  // far wall z = 2.1
  scene.spheres.push_back({{0.02f, -0.03f, 0.6f}, 0.06f});  // small and near
  const Intrinsics k = TestIntrinsics();
  VolumeOptions options;
  options.resolution = 200;
  options.size_m = 3.0f;  // 1.5 cm voxels; the whole view of the wall lies inside
  options.origin = {-1.5f, -1.5f, 0.2f};
  TsdfVolume volume(options);
  ThreadPool pool(2);
  const Pose pose = PoseFrom(0, 0.03, 0, -0.06, 0, 0);
  const DepthImage reference = scene.Render(pose, k);
  for (int i = 0; i < 2; ++i) volume.Integrate(reference, k, pose, &pool);
  GeometryView view;
  volume.Raycast(pose, k, view, &pool);
  const Compare c = CompareDepth(reference, view.depth);
  EXPECT_GT(c.both, 0.97);
  EXPECT_LT(c.max_err, volume.voxel_size());
  // The wall around the sphere (the same 8 x 8 range-image tiles, so these rays start in front of
  // the sphere and cross the empty space behind it), away from the silhouette's voxel-sized
  // fringe, is found at its depth.
  auto sphere_within = [&](int x, int y, int r) {
    for (int yy = std::max(0, y - r); yy <= std::min(k.height - 1, y + r); ++yy)
      for (int xx = std::max(0, x - r); xx <= std::min(k.width - 1, x + r); ++xx)
        if (reference.At(xx, yy) > 0 && reference.At(xx, yy) < 1.0f) return true;
    return false;
  };
  int checked = 0;
  for (int y = 0; y < k.height; ++y)
    for (int x = 0; x < k.width; ++x) {
      if (reference.At(x, y) < 2.0f || !sphere_within(x, y, 16) || sphere_within(x, y, 8)) continue;
      ++checked;
      ASSERT_NEAR(view.depth.At(x, y), reference.At(x, y), volume.voxel_size())
          << "pixel " << x << "," << y;
    }
  EXPECT_GT(checked, 500);
}

TEST(TsdfVolume, IntegrationIsDeterministicAcrossThreadCounts) {
  const Scene scene = CornerScene();
  const Intrinsics k = TestIntrinsics();
  TsdfVolume a(testing::TestVolumeOptions()), b(testing::TestVolumeOptions());
  ThreadPool pool(2);
  const Pose p = PoseFrom(0, 0.05, 0, -0.05, 0, 0);
  a.Integrate(scene.Render(p, k), k, p, nullptr);
  b.Integrate(scene.Render(p, k), k, p, &pool);
  GeometryView va, vb;
  a.Raycast(p, k, va, nullptr);
  b.Raycast(p, k, vb, &pool);
  EXPECT_EQ(va.depth.data, vb.depth.data);
}

TEST(TsdfVolume, ResetForgetsEverything) {
  const Scene scene = CornerScene();
  const Intrinsics k = TestIntrinsics();
  TsdfVolume volume(testing::TestVolumeOptions());
  volume.Integrate(scene.Render(Pose{}, k), k, Pose{}, nullptr);
  EXPECT_GT(volume.ObservedBricks(), 0);
  volume.Reset();
  EXPECT_EQ(volume.ObservedBricks(), 0);
  GeometryView view;
  volume.Raycast(Pose{}, k, view, nullptr);
  for (float d : view.depth.data) ASSERT_EQ(d, 0.0f);
}

TEST(TsdfVolume, AuxiliaryAndLightViewsSeeTheSurfaces) {
  // The corner scene seen from the front; the orthographic views must find the right wall
  // (x = 0.6) and the floor (y = 0.45) where the analytic scene puts them.
  const Scene scene = CornerScene();
  const Intrinsics k = TestIntrinsics();
  TsdfVolume volume(testing::TestVolumeOptions());
  ThreadPool pool(2);
  const Pose poses[3] = {Pose{}, PoseFrom(0, 0.05, 0, -0.05, 0, 0),
                         PoseFrom(0.03, -0.04, 0, 0.04, -0.02, 0.05)};
  for (const Pose& p : poses) volume.Integrate(scene.Render(p, k), k, p, &pool);
  const AuxiliaryViews aux = volume.AuxiliaryViewsFor(Pose{}, 256);
  struct Case {
    const char* name;
    OrthographicView view;
    Vec3f surface_point;  // world point the view's ray must hit
    bool front_facing;    // the view sees the observed side of the surface
  };
  const Vec3f wall{0.6f, 0.35f, 1.4f}, floor{0.3f, 0.45f, 1.3f};
  const Case cases[4] = {{"left", aux.left, wall, true},
                         {"right", aux.right, wall, false},
                         {"top", aux.top, floor, true},
                         {"light", volume.LightView({0, -1, 0}, 256), floor, true}};
  for (const Case& c : cases) {
    GeometryView g;
    volume.RaycastOrthographic(c.view, g, &pool);
    const Vec3f pv = c.view.view_to_world.Inverse().Apply(c.surface_point);
    const int x =
        static_cast<int>(std::lround(pv.x / c.view.pixel_size_m + (c.view.width - 1) * 0.5f));
    const int y =
        static_cast<int>(std::lround(pv.y / c.view.pixel_size_m + (c.view.height - 1) * 0.5f));
    ASSERT_GE(x, 0) << c.name;
    ASSERT_LT(x, c.view.width) << c.name;
    ASSERT_GE(y, 0) << c.name;
    ASSERT_LT(y, c.view.height) << c.name;
    // Seen from behind (the unobserved side) the hit lies within the negative band.
    const float tolerance =
        c.front_facing ? 2 * volume.voxel_size() : volume.options().truncation_m;
    EXPECT_NEAR(g.depth.At(x, y), pv.z, tolerance) << c.name;
    if (c.front_facing) {
      EXPECT_LT(g.normals.At(x, y).z, -0.9f) << c.name;  // towards the viewer
    }
  }
}

TEST(TsdfVolume, MeshLiesOnTheSurfaceAndWritesPly) {
  Scene scene;
  scene.spheres.push_back({{0, 0, 1.2f}, 0.3f});
  const Intrinsics k = TestIntrinsics();
  TsdfVolume volume(testing::TestVolumeOptions());
  volume.Integrate(scene.Render(Pose{}, k), k, Pose{}, nullptr);
  const Mesh mesh = volume.ExtractMesh(nullptr);
  ASSERT_GT(mesh.indices.size(), 300u);
  for (const Vec3f& v : mesh.vertices) {
    ASSERT_NEAR(Norm(v - Vec3f{0, 0, 1.2f}), 0.3f, 1.5f * volume.voxel_size());
  }
  const std::string path =
      (std::filesystem::temp_directory_path() / "probeless_recon_mesh_test.ply").string();
  WritePly(mesh, path);
  std::ifstream in(path, std::ios::binary);
  std::string line;
  std::getline(in, line);
  EXPECT_EQ(line, "ply");
  EXPECT_EQ(std::filesystem::file_size(path) > mesh.vertices.size() * 24, true);
  std::filesystem::remove(path);
  EXPECT_THROW(WritePly(mesh, "/nonexistent-dir/x.ply"), ReconError);
}

}  // namespace
}  // namespace probeless::recon
