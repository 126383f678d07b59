// The private SIMD kernels against their scalar references on random inputs (fixed seeds): the
// transfer's occlusion test (8 directions per step) and the shadow search's ray (8 points); and
// the run-time choice between them (probeless/simd/simd.h).
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "occlusion_kernel.h"
#include "probeless/simd/simd.h"
#include "shadow_kernel.h"

namespace probeless::light::internal {
namespace {

TEST(SimdDispatch, KernelsFollowTheActiveLevel) {
  {
    simd::ScopedLevel portable(simd::Level::kPortable);
    EXPECT_EQ(OcclusionKernel(), &OcclusionScalar);
    EXPECT_EQ(ShadowRay8Kernel(), &ShadowRay8Scalar);
  }
  if (simd::Supported() != simd::Level::kAvx2Fma) GTEST_SKIP() << "no AVX2/FMA on this CPU";
  simd::ScopedLevel avx2(simd::Level::kAvx2Fma);
  EXPECT_EQ(OcclusionKernel(), &OcclusionAvx2);
  EXPECT_EQ(ShadowRay8Kernel(), &ShadowRay8Avx2);
}

TEST(OcclusionKernel, SimdMatchesScalar) {
  if (simd::Supported() != simd::Level::kAvx2Fma) GTEST_SKIP() << "no AVX2/FMA on this CPU";
  constexpr int kW = 96, kH = 72;
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> uni(0.0f, 1.0f);
  // A bumpy surface 1-3 m away with holes (depth 0), so that every branch is taken.
  std::vector<float> depth(kW * kH);
  for (int v = 0; v < kH; ++v) {
    for (int u = 0; u < kW; ++u) {
      const float z = 2.0f + 0.6f * std::sin(0.2f * u) * std::cos(0.15f * v) + 0.05f * uni(rng);
      depth[v * kW + u] = uni(rng) < 0.05f ? 0.0f : z;
    }
  }
  for (int n_dir : {8, 13, 32, 61}) {
    SCOPED_TRACE("directions " + std::to_string(n_dir));
    const int n_pad = (n_dir + 7) / 8 * 8;
    std::vector<float> dx(n_pad, 0.0f), dy(n_pad, 0.0f), dz(n_pad, 0.0f), off(n_pad, 0.0f);
    for (int j = 0; j < n_dir; ++j) {
      const float z = 2 * uni(rng) - 1, a = 6.2831853f * uni(rng), r = std::sqrt(1 - z * z);
      dx[j] = r * std::cos(a), dy[j] = r * std::sin(a), dz[j] = z;
      off[j] = 0.1f + 0.9f * uni(rng);
    }
    OcclusionParams p;
    p.depth = depth.data();
    p.width = kW, p.height = kH;
    p.fx = p.fy = 80, p.cx = 47.5f, p.cy = 35.5f, p.ifx = p.ify = 1.0f / 80;
    p.radius = 0.4f, p.max_occ2 = 0.6f * 0.6f, p.bias = 0.01f, p.bias_rel = 0.005f;
    p.chi = 0.3f, p.inv_chi = 1 / 0.3f;
    p.n_padded = n_pad;
    p.dir_x = dx.data(), p.dir_y = dy.data(), p.dir_z = dz.data();
    int occluded = 0, compared = 0;
    for (int i = 0; i < 400; ++i) {
      const int u = static_cast<int>(uni(rng) * kW) % kW, v = static_cast<int>(uni(rng) * kH) % kH;
      const float d = depth[v * kW + u] > 0 ? depth[v * kW + u] : 2.0f;
      const float x[3] = {d * (u - p.cx) * p.ifx, d * (v - p.cy) * p.ify, d};
      float n[3] = {uni(rng) - 0.5f, uni(rng) - 0.5f, -1.0f};
      const float len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
      for (float& c : n) c /= len;
      PixelOcclusion a, b;
      OcclusionScalar(p, off.data(), x, n, &a);
      OcclusionAvx2(p, off.data(), x, n, &b);
      for (int j = 0; j < n_dir; ++j) {
        ASSERT_NEAR(a.cosn[j], b.cosn[j], 1e-6f) << "pixel " << i << " direction " << j;
        // A sample within rounding of a threshold (image border, depth bias, range) may go
        // either way; those are rare: count them and compare the rest exactly.
        if (a.occluder[j] != b.occluder[j]) continue;
        ASSERT_NEAR(a.k[j], b.k[j], 1e-4f) << "pixel " << i << " direction " << j;
        occluded += a.occluder[j] >= 0;
        ++compared;
      }
    }
    EXPECT_GT(compared, 400 * n_dir * 99 / 100) << "threshold disagreements above 1 %";
    EXPECT_GT(occluded, compared / 20) << "too few occluded samples to test the kernel";
  }
}

// The shadow ray: a bumpy depth image with holes and a box standing in front of it, random points
// on the surface and random directions; every outcome (lit, occluded, unknown) must occur.
TEST(ShadowRayKernel, EightPointsMatchTheScalarRay) {
  if (simd::Supported() != simd::Level::kAvx2Fma) GTEST_SKIP() << "no AVX2/FMA on this CPU";
  constexpr int kW = 120, kH = 90;
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> uni(0.0f, 1.0f);
  std::vector<float> depth(kW * kH);
  for (int v = 0; v < kH; ++v) {
    for (int u = 0; u < kW; ++u) {
      float z = 3.0f + 0.3f * std::sin(0.1f * u) + 0.02f * uni(rng);
      if (u > 40 && u < 70 && v > 30 && v < 60) z = 2.0f;  // a box 1 m in front
      depth[v * kW + u] = uni(rng) < 0.03f ? 0.0f : z;
    }
  }
  std::vector<float> steps, thickness;
  for (float t = 0.04f; t < 3.0f; t *= 1.15f) {
    steps.push_back(t);
    thickness.push_back(std::max(0.4f, 1.5f * 0.15f * t));
  }
  ShadowRayParams r;
  r.depth = depth.data();
  r.width = kW, r.height = kH;
  r.fx = r.fy = 100, r.cx = 59.5f, r.cy = 44.5f;
  r.steps = steps.data(), r.thickness = thickness.data();
  r.step_count = static_cast<int>(steps.size());
  r.bias = 0.005f, r.bias_rel = 0.002f;
  int outcome[3] = {0, 0, 0}, compared = 0, differ = 0;
  for (bool unknown_behind : {true, false}) {
    r.unknown_behind = unknown_behind;
    for (int trial = 0; trial < 300; ++trial) {
      const float a = 6.2831853f * uni(rng), zc = -0.2f - 0.8f * uni(rng);
      const float s = std::sqrt(1 - zc * zc);
      const std::array<float, 3> l = {s * std::cos(a), s * std::sin(a), zc};  // towards the camera
      float x[8], y[8], z[8], out[8];
      for (int k = 0; k < 8; ++k) {
        const int u = static_cast<int>(uni(rng) * kW) % kW,
                  v = static_cast<int>(uni(rng) * kH) % kH;
        z[k] = depth[v * kW + u] > 0 ? depth[v * kW + u] : 3.0f;
        x[k] = (u - r.cx) * z[k] / r.fx, y[k] = (v - r.cy) * z[k] / r.fy;
      }
      if (trial % 10 == 0) z[7] = 0;  // padding lanes: lit
      ShadowRay8Avx2(r, x, y, z, l, out);
      for (int k = 0; k < 8; ++k) {
        const float ref = z[k] > 0 ? ShadowRayScalar(r, x[k], y[k], z[k], l) : 1.0f;
        ++compared;
        // A sample within rounding of a pixel border or the bias may go either way: rare.
        if (out[k] != ref) {
          ++differ;
          continue;
        }
        ++outcome[static_cast<int>(ref) + 1];
      }
    }
  }
  EXPECT_LT(differ, compared / 100) << differ << " of " << compared << " rays differ";
  EXPECT_GT(outcome[0], 20) << "unknown";
  EXPECT_GT(outcome[1], 100) << "occluded";
  EXPECT_GT(outcome[2], 100) << "lit";
}

}  // namespace
}  // namespace probeless::light::internal
