// The auxiliary views' convention end to end (issues #7 / #8): a rendered table-top scene fused
// into a recon::TsdfVolume from known poses, its left / right / top / light views raycast by recon,
// written into a msgs::AuxiliaryViews message and read back as light::OrthographicView (the path
// of fusion -> scene_light) agree with the views the ray tracer renders of the same scene for the
// same camera (light::RenderAuxiliaryViews): same roles and ray directions, the same world points
// at the same depths within a couple of voxels, and view pixels mapped by p_camera = R p_view + t
// land on the surfaces the main camera sees.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <vector>

#include "probeless/light/messages.h"
#include "probeless/light/sim_buffers.h"
#include "probeless/msgs/auxiliary_views.h"
#include "probeless/recon/msgs_io.h"
#include "probeless/recon/tsdf_volume.h"
#include "probeless/sim/scenario.h"
#include "probeless/sim/simulator.h"

namespace {

using namespace probeless;

// light_sim_test's table-top scene without sensor effects, the camera pitched down ~25 degrees
// and moving sideways over 6 frames (so the volume sees the objects from several sides).
constexpr const char* kScenario = R"(
name: aux_table
fps: 5
frames: 6
camera:
  width: 160
  height: 120
  fx: 131.25
  fy: 131.25
  path:
    - {t: 0, position: [-0.5, 1.3, -1.6], look_at: [0, 0.2, 0.3]}
    - {t: 1, position: [0.5, 1.3, -1.6], look_at: [0, 0.2, 0.3]}
render: {shadows: false}
environment: {constant: [0.04, 0.04, 0.04]}
objects:
  - {name: floor, shape: plane, size: [6, 1, 6], position: [0, 0, 0], color: [0.6, 0.6, 0.6]}
  - {name: wall, shape: plane, size: [6, 1, 3], position: [0, 1.5, 1.5], rotation_deg: [-90, 0, 0], color: [0.7, 0.7, 0.65]}
  - {name: box, shape: box, size: [0.4, 0.4, 0.4], position: [-0.5, 0.2, 0.3], color: [0.5, 0.5, 0.6]}
  - {name: ball, shape: sphere, radius: 0.25, position: [0.4, 0.25, 0.1], color: [0.7, 0.6, 0.5]}
  - {name: pillar, shape: cylinder, radius: 0.12, height: 0.8, position: [0.0, 0, 0.8], color: [0.6, 0.6, 0.6]}
lights:
  - {name: sun, type: directional, direction: [0.5, 1.0, -0.4], color: [1, 1, 1], intensity: 2.5}
)";

recon::Pose PoseOf(const raytrace::Transform& t) {
  recon::Pose p;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) p.r[3 * r + c] = t.rotation.m[r][c];
    p.t[r] = t.translation[r];
  }
  return p;
}

struct Fused {
  std::unique_ptr<sim::Simulator> simulator;
  std::unique_ptr<recon::TsdfVolume> volume;
  sim::SimFrame frame;  // the last frame: the camera the views are made for
};

// 2.2 m cube at 176^3 (1.25 cm voxels) around the objects and the floor, 6 noise-free frames.
Fused FuseScene(parallel::ThreadPool* pool) {
  Fused f;
  f.simulator =
      std::make_unique<sim::Simulator>(sim::ParseScenario(kScenario, "aux_table.yaml", "."), 2);
  recon::VolumeOptions vo;
  vo.resolution = 176;
  vo.size_m = 2.2f;
  vo.origin = {-1.1f, -0.3f, -0.6f};
  vo.truncation_m = 0.04f;
  f.volume = std::make_unique<recon::TsdfVolume>(vo);
  for (uint64_t i = 0; i < 6; ++i) {
    f.frame = f.simulator->Render(i);
    const raytrace::Camera& c = f.frame.camera;
    recon::DepthImage depth;
    depth.Resize(c.width, c.height);
    depth.data = f.frame.render.depth_m;
    const recon::Intrinsics k{c.width,
                              c.height,
                              static_cast<float>(c.fx),
                              static_cast<float>(c.fy),
                              static_cast<float>(c.cx),
                              static_cast<float>(c.cy)};
    f.volume->Integrate(depth, k, PoseOf(c.camera_to_world), pool);
  }
  return f;
}

// A 64-byte aligned bus slot.
struct Slot {
  explicit Slot(size_t n) : bytes(n), data(static_cast<std::byte*>(std::aligned_alloc(64, n))) {
    std::fill(data, data + n, std::byte{0});
  }
  ~Slot() { std::free(data); }
  size_t bytes;
  std::byte* data;
};

struct Comparison {
  int compared = 0;              // recon pixels whose point falls on a traced pixel with a surface
  double median_error_m = 0;     // |traced depth - recon depth| along the same ray line
  double median_signed_m = 0;    // traced depth - recon depth: a bias of the convention
  double within_2_voxels = 0;    // fraction of compared pixels
  int camera_checked = 0;        // recon points that project into the camera with a depth there
  double camera_free_space = 0;  // fraction of those > 2 voxels in front of the camera's surface
  double camera_on_surface = 0;  // fraction of those within 2 voxels of the camera's surface
};

// Maps every recon pixel with a surface into the camera (p_camera = R p_view + t), then into the
// traced view of the same role and into the main camera's depth.
Comparison Compare(const light::OrthographicView& a, const light::OrthographicView& b,
                   const sim::SimFrame& frame, float voxel) {
  const raytrace::Camera& cam = frame.camera;
  std::vector<double> errors, signed_errors;
  int free_space = 0, on_surface = 0, checked = 0;
  for (int v = 0; v < a.height; ++v) {
    for (int u = 0; u < a.width; ++u) {
      const float d = a.depth[static_cast<size_t>(v) * a.width + u];
      if (!(d > 0)) continue;
      const float pv[3] = {(u - 0.5f * (a.width - 1)) * a.pixel_size_m,
                           (v - 0.5f * (a.height - 1)) * a.pixel_size_m, d};
      float pc[3];
      for (int r = 0; r < 3; ++r) {
        pc[r] = a.rotation[3 * r] * pv[0] + a.rotation[3 * r + 1] * pv[1] +
                a.rotation[3 * r + 2] * pv[2] + a.translation[r];
      }
      // Into the traced view: q = R_b^T (p_camera - t_b).
      float q[3];
      for (int c = 0; c < 3; ++c) {
        q[c] = b.rotation[c] * (pc[0] - b.translation[0]) +
               b.rotation[3 + c] * (pc[1] - b.translation[1]) +
               b.rotation[6 + c] * (pc[2] - b.translation[2]);
      }
      const int bu = static_cast<int>(std::lround(q[0] / b.pixel_size_m + 0.5f * (b.width - 1)));
      const int bv = static_cast<int>(std::lround(q[1] / b.pixel_size_m + 0.5f * (b.height - 1)));
      if (bu >= 1 && bv >= 1 && bu < b.width - 1 && bv < b.height - 1) {
        // Only where the traced view has a surface on the 3x3 neighbourhood (not a silhouette).
        bool interior = true;
        for (int dy = -1; dy <= 1; ++dy) {
          for (int dx = -1; dx <= 1; ++dx) {
            const float n = b.depth[static_cast<size_t>(bv + dy) * b.width + bu + dx];
            if (!(n > 0) || std::fabs(n - q[2]) > 0.1f) interior = false;
          }
        }
        const float db = b.depth[static_cast<size_t>(bv) * b.width + bu];
        if (interior) {
          errors.push_back(std::fabs(db - q[2]));
          signed_errors.push_back(db - q[2]);
        }
      }
      // Into the main camera: a recon surface point never lies in the free space the camera sees.
      if (pc[2] > 0.1f) {
        const double x = cam.fx * pc[0] / pc[2] + cam.cx, y = cam.fy * pc[1] / pc[2] + cam.cy;
        const int cu = static_cast<int>(std::lround(x)), cv = static_cast<int>(std::lround(y));
        if (cu >= 0 && cv >= 0 && cu < cam.width && cv < cam.height) {
          const float dc = frame.render.depth_m[static_cast<size_t>(cv) * cam.width + cu];
          if (dc > 0) {
            ++checked;
            if (pc[2] < dc - 2 * voxel) ++free_space;
            if (std::fabs(pc[2] - dc) <= 2 * voxel) ++on_surface;
          }
        }
      }
    }
  }
  Comparison c;
  c.compared = static_cast<int>(errors.size());
  if (!errors.empty()) {
    std::nth_element(errors.begin(), errors.begin() + errors.size() / 2, errors.end());
    c.median_error_m = errors[errors.size() / 2];
    std::nth_element(signed_errors.begin(), signed_errors.begin() + signed_errors.size() / 2,
                     signed_errors.end());
    c.median_signed_m = signed_errors[signed_errors.size() / 2];
    c.within_2_voxels =
        static_cast<double>(
            std::count_if(errors.begin(), errors.end(), [&](double e) { return e <= 2 * voxel; })) /
        errors.size();
  }
  c.camera_checked = checked;
  if (checked > 0) {
    c.camera_free_space = static_cast<double>(free_space) / checked;
    c.camera_on_surface = static_cast<double>(on_surface) / checked;
  }
  return c;
}

TEST(AuxiliaryConvention, ReconViewsThroughTheMessageMatchRayTracedViews) {
  parallel::ThreadPool pool(2);
  const Fused f = FuseScene(&pool);
  const raytrace::Camera& cam = f.frame.camera;
  const recon::Pose c2w = PoseOf(cam.camera_to_world);
  // The sun's direction (towards the light) in the camera frame and in the world.
  const raytrace::Vec3 sun_c = f.frame.light.dominant_direction;
  const raytrace::Vec3 sun_w = cam.camera_to_world.ApplyDirection(sun_c);
  const recon::Vec3f sun_world{sun_w.x, sun_w.y, sun_w.z};

  // recon -> message -> light, as fusion and scene_light do.
  const std::vector<recon::AuxiliaryRaycast> raycast =
      recon::RaycastAuxiliaryViews(*f.volume, c2w, 128, &sun_world, &pool);
  ASSERT_EQ(raycast.size(), 4u);
  Slot slot(msgs::AuxiliaryViews::MessageBytesFor(4, 128, 128));
  auto out = msgs::WriteMessage<msgs::AuxiliaryViews>(std::span<std::byte>(slot.data, slot.bytes));
  recon::WriteAuxiliaryViews(c2w, raycast, *out, out.payload);
  const auto in =
      msgs::ReadMessage<msgs::AuxiliaryViews>(std::span<const std::byte>(slot.data, slot.bytes));
  const light::AuxiliaryBuffers from_recon = light::AuxiliaryFromMessage(*in, in.payload);
  ASSERT_EQ(from_recon.views.size(), 4u);

  light::AuxiliaryViewOptions ao;
  ao.resolution = 256;  // the reference finer than recon's views
  ao.top_along_camera_y = true;
  ao.light_view = true;
  ao.light_direction = {sun_c.x, sun_c.y, sun_c.z};
  const light::AuxiliaryStorage traced = light::RenderAuxiliaryViews(f.simulator->scene(), cam, ao);
  ASSERT_EQ(traced.buffers.views.size(), 4u);

  const float voxel = f.volume->voxel_size();
  const char* names[4] = {"left", "right", "top", "light"};
  for (size_t k = 0; k < 4; ++k) {
    const light::OrthographicView& a = from_recon.views[k];
    const light::OrthographicView& b = traced.buffers.views[k];
    EXPECT_EQ(a.role, b.role) << names[k];
    // Same ray direction (the view's z axis in the camera frame: column 2 of the rotation).
    const double dot = a.rotation[2] * b.rotation[2] + a.rotation[5] * b.rotation[5] +
                       a.rotation[8] * b.rotation[8];
    EXPECT_GT(dot, 0.9999) << names[k];
    const Comparison c = Compare(a, b, f.frame, voxel);
    std::printf(
        "%-5s: %d px compared, median |depth error| %.4f m (signed %+.4f; voxel %.4f), %.1f %% "
        "within 2 voxels; camera: %d px, %.1f %% on its surface, %.2f %% in its free space\n",
        names[k], c.compared, c.median_error_m, c.median_signed_m, voxel, 100 * c.within_2_voxels,
        c.camera_checked, 100 * c.camera_on_surface, 100 * c.camera_free_space);
    // Measured (voxel 1.25 cm): median 4 / 10 / 2.5 / 3 mm (left / right / top / light; signed
    // within +-1 mm: the right view's spread is symmetric, inclined surfaces at 3 cm pixels), 89-99
    // % within 2 voxels (the side views graze the floor, where a voxel of TSDF error is a long way
    // along the ray); 1-3 % of the points in the camera's free space (fusion artefacts where the
    // side rays enter observed space behind an object), 42-85 % on the camera's surface (the
    // rest is hidden from the camera, which is allowed).
    EXPECT_GT(c.compared, 150) << names[k];
    EXPECT_LT(c.median_error_m, voxel) << names[k];
    EXPECT_LT(std::fabs(c.median_signed_m), 0.3 * voxel) << names[k];  // no offset along the rays
    EXPECT_GT(c.within_2_voxels, 0.85) << names[k];
    EXPECT_GT(c.camera_checked, 200) << names[k];
    EXPECT_LT(c.camera_free_space, 0.05) << names[k];
    EXPECT_GT(c.camera_on_surface, 0.35) << names[k];
  }

  // The check can fail: the inverse transform (view = R^T (camera - t), a plausible mix-up)
  // puts the left view's points elsewhere.
  light::OrthographicView wrong = from_recon.views[0];
  std::array<float, 9> rt;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) rt[3 * r + c] = wrong.rotation[3 * c + r];
  const light::Vec3f t = wrong.translation;
  wrong.rotation = rt;
  for (int r = 0; r < 3; ++r) {
    wrong.translation[r] = -(rt[3 * r] * t[0] + rt[3 * r + 1] * t[1] + rt[3 * r + 2] * t[2]);
  }
  const Comparison bad = Compare(wrong, traced.buffers.views[0], f.frame, voxel);
  std::printf(
      "left with the inverse transform: %d px compared, %.1f %% within 2 voxels, %.1f %% "
      "in the camera's free space\n",
      bad.compared, 100 * bad.within_2_voxels, 100 * bad.camera_free_space);
  EXPECT_TRUE(bad.within_2_voxels < 0.5 || bad.camera_free_space > 0.1);
}

TEST(AuxiliaryConvention, BadInputsGiveOneLineErrors) {
  recon::VolumeOptions vo;
  vo.resolution = 16;
  vo.size_m = 1;
  vo.truncation_m = 0.1f;
  const recon::TsdfVolume volume(vo);
  try {
    recon::RaycastAuxiliaryViews(volume, {}, 5000, nullptr, nullptr);
    ADD_FAILURE() << "no error";
  } catch (const recon::ReconError& e) {
    EXPECT_STREQ(e.what(), "auxiliary views: pixels must be in 1..4096, got 5000");
  }
  std::vector<recon::AuxiliaryRaycast> views =
      recon::RaycastAuxiliaryViews(volume, {}, 8, nullptr, nullptr);
  views[1].depth.Resize(4, 4);
  msgs::AuxiliaryViews m;
  std::vector<std::byte> payload(4096);
  try {
    recon::WriteAuxiliaryViews({}, views, m, payload);
    ADD_FAILURE() << "no error";
  } catch (const recon::ReconError& e) {
    EXPECT_STREQ(e.what(), "auxiliary views: view 1 is 8x8 but its depth 4x4");
  }
  views[1].depth.Resize(8, 8);
  recon::WriteAuxiliaryViews({}, views, m, payload);
  // A message claiming more payload than it has -> msgs::MessageError from the light side.
  try {
    light::AuxiliaryFromMessage(m, std::span<const std::byte>(payload).first(300));
    ADD_FAILURE() << "no error";
  } catch (const msgs::MessageError& e) {
    EXPECT_STREQ(e.what(),
                 "probeless_msgs/AuxiliaryViews view 1 (right 8x8): depth plane (offset 256, 256 "
                 "bytes) exceeds the payload of 300 bytes");
  }
  const light::AuxiliaryBuffers ok = light::AuxiliaryFromMessage(m, payload);
  ASSERT_EQ(ok.views.size(), 3u);
  EXPECT_EQ(ok.views[2].role, light::AuxiliaryRole::kTop);
}

}  // namespace
