// Unit tests of probeless_light on analytic G-buffers (planes, a concave corner) and synthetic
// least-squares systems: SH weights, visibility, estimation (exact, robust, non-negative),
// OursFast vs full, the indirect term and the boundary errors.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>
#include <string>

#include "probeless/light/estimate.h"
#include "probeless/light/messages.h"
#include "probeless/light/reliability.h"
#include "probeless/light/transfer.h"
#include "probeless/sh/sh.h"
#include "probeless/testing/testing.h"

namespace {

using namespace probeless;
using light::Vec3f;

using probeless::testing::ThrownMessage;

// An analytic scene seen by a 160x120 camera (fx = fy = 120): kPlane, a wall at z = 3 m facing
// the camera; kFloor, that wall and a floor 0.5 m below the camera (y = +0.5, normal -y); kValley,
// a concave V: z = 3 + x for x < 0 (normal (1, 0, -1)/sqrt 2) and z = 3 - x for x > 0.
enum class Shape { kPlane, kFloor, kValley };
struct Scene {
  int w = 160, h = 120;
  light::Intrinsics k{120, 120, 79.5, 59.5};
  std::vector<float> depth, normals;
  std::vector<uint8_t> colour;
  explicit Scene(Shape shape) {
    depth.assign(w * h, 0);
    normals.assign(3 * w * h, 0);
    colour.assign(3 * w * h, 200);
    const float r2 = std::sqrt(0.5f);
    for (int v = 0; v < h; ++v) {
      for (int u = 0; u < w; ++u) {
        const double dx = (u - k.cx) / k.fx, dy = (v - k.cy) / k.fy;
        double t = 3.0;
        Vec3f n{0, 0, -1};
        if (shape == Shape::kFloor && dy > 0 && 0.5 / dy < t) {
          t = 0.5 / dy;
          n = {0, -1, 0};
        }
        if (shape == Shape::kValley) {
          if (dx < 0) {  // t dx = 3 + t... z = t, x = t dx: t = 3 + t dx
            t = 3.0 / (1 - dx);
            n = {r2, 0, -r2};
          } else {
            t = 3.0 / (1 + dx);
            n = {-r2, 0, -r2};
          }
        }
        depth[v * w + u] = static_cast<float>(t);
        for (int c = 0; c < 3; ++c) normals[3 * (v * w + u) + c] = n[c];
      }
    }
  }
  light::GeometryView View() const { return {w, h, k, depth, normals, colour}; }
};

// Quadrature tolerance of the clamped cosine with 128 jittered directions: the kink of max(0, cos)
// makes bands 2-3 converge slowly (measured errors: <= 0.028 for bands 0-1, <= 0.055 for 2-3;
// the clamped-cosine coefficients are 0.28, 0.33, 0.16 and 0 for Y_00, Y_10, Y_20, Y_30).
double Tolerance(int k) { return sh::DegreeOf(k) <= 1 ? 0.035 : 0.07; }

TEST(Directions, OctahedronHullHasTwelveEdges) {
  const std::vector<Vec3f> octa{{1, 0, 0},  {-1, 0, 0}, {0, 1, 0},
                                {0, -1, 0}, {0, 0, 1},  {0, 0, -1}};
  // The octahedron's 4-point equators are coplanar, but the hull edges are still the 12 edges.
  EXPECT_EQ(light::SphericalDelaunayEdges(octa).size(), 12u);
}

TEST(Directions, DelaunayIsATriangulationAndChiFollowsEq9) {
  const light::DirectionSet set(64, 4, 7);
  // A triangulation of the sphere with V vertices has 3V - 6 edges (Euler).
  EXPECT_EQ(set.delaunay_edges().size(), 3u * 64 - 6);
  // Mean neighbour spacing of N uniform points ~ sqrt(4 pi / N) * 1.07 (hexagonal packing).
  const double spacing = std::sqrt(4 * std::numbers::pi / 64);
  EXPECT_GT(set.median_neighbour_angle(), 0.8 * spacing);
  EXPECT_LT(set.median_neighbour_angle(), 1.4 * spacing);
  EXPECT_DOUBLE_EQ(set.chi(), std::cos(set.median_neighbour_angle() / 2));
  // Deterministic.
  const light::DirectionSet again(64, 4, 7);
  EXPECT_EQ(again.directions(), set.directions());
}

TEST(Directions, WeightsIntegrateTheClampedCosine) {
  // sum_j max(0, w_j . n) W_jn ~ (A_l / pi) Y_n(n) (Ramamoorthi-Hanrahan), for several normals.
  const light::DirectionSet set(128, 4, 3);
  for (const Vec3f& n : std::vector<Vec3f>{{0, 0, 1}, {0, 0, -1}, {0.6f, -0.8f, 0}}) {
    std::vector<double> t(16, 0.0);
    for (int j = 0; j < set.count(); ++j) {
      const auto& d = set.directions()[j];
      const double c = std::max(0.0f, d[0] * n[0] + d[1] * n[1] + d[2] * n[2]);
      for (int k = 0; k < 16; ++k) t[k] += c * set.weights()[j * 16 + k];
    }
    const auto y = sh::Basis(4, {n[0], n[1], n[2]});
    for (int k = 0; k < 16; ++k) {
      const double expected =
          sh::ClampedCosineCoefficient(sh::DegreeOf(k)) / std::numbers::pi * y[k];
      EXPECT_NEAR(t[k], expected, Tolerance(k)) << "coefficient " << k;
    }
  }
}

TEST(Transfer, UnoccludedPlaneEqualsClampedCosineProjection) {
  // analytic_unoccluded (default): exact up to float rounding; eq. 6 as printed (quadrature over
  // N = 128 directions): within the quadrature error.
  for (bool analytic : {true, false}) {
    const Scene scene(Shape::kPlane);
    light::TransferOptions o;
    o.directions = 128;
    o.analytic_unoccluded = analytic;
    light::TransferComputer computer(o);
    light::TransferResult r;
    computer.Compute(scene.View(), {}, nullptr, &r);
    ASSERT_EQ(r.coefficient_count, 16);
    const auto y = sh::Basis(4, {0, 0, -1});
    for (int p : {60 * 160 + 80, 10 * 160 + 10, 100 * 160 + 150}) {
      EXPECT_TRUE(r.valid[p]);
      for (int k = 0; k < 16; ++k) {
        const double expected =
            sh::ClampedCosineCoefficient(sh::DegreeOf(k)) / std::numbers::pi * y[k];
        EXPECT_NEAR(r.transfer[p * 16 + k], expected, analytic ? 1e-5 : Tolerance(k))
            << "analytic " << analytic << " pixel " << p << " coefficient " << k;
      }
    }
    // Under a uniform white light of radiance 1 the plane reflects 1 (albedo 1): T_0 Y_0 ~ 1.
    EXPECT_NEAR(r.transfer[(60 * 160 + 80) * 16] * 2 * std::sqrt(std::numbers::pi), 1.0,
                analytic ? 1e-5 : 0.03);
  }
}

TEST(Transfer, AnalyticUnoccludedPartMatchesTheBasisForAnyNormal) {
  // A single-pixel view with a tilted normal and nothing around it: T = (A_l / pi) Y(n) exactly
  // (the per-pixel evaluator in transfer.cpp against sh::Basis, also bands 2-3 and m < 0).
  const std::vector<float> depth{2.0f};
  for (const auto& n : sh::FibonacciSphere(40)) {
    if (n[2] > -0.05) continue;  // facing the camera
    const std::vector<float> normals{static_cast<float>(n[0]), static_cast<float>(n[1]),
                                     static_cast<float>(n[2])};
    light::TransferComputer computer({});
    light::TransferResult r;
    computer.Compute({1, 1, {100, 100, 0, 0}, depth, normals, {}}, {}, nullptr, &r);
    const auto y = sh::Basis(4, n);
    for (int k = 0; k < 16; ++k) {
      EXPECT_NEAR(r.transfer[k],
                  sh::ClampedCosineCoefficient(sh::DegreeOf(k)) / std::numbers::pi * y[k], 2e-6)
          << "coefficient " << k;
    }
  }
}

TEST(Transfer, ConcaveCornerGetsLessTransferThanOpenPlane) {
  const Scene scene(Shape::kValley);
  light::TransferComputer computer({});
  light::TransferResult r;
  computer.Compute(scene.View(), {}, nullptr, &r);
  // The valley floor is the column u = cx; pixels 2 columns away are in the concave corner, pixels
  // 60 columns away (about 1 m along the slope) see the open plane.
  const int corner = 60 * 160 + 78, open = 60 * 160 + 20;
  ASSERT_GT(scene.depth[corner], 2.9f);
  EXPECT_LT(r.transfer[corner * 16], 0.9 * r.transfer[open * 16])
      << "corner " << r.transfer[corner * 16] << " open " << r.transfer[open * 16];
}

TEST(Transfer, FastAgreesWithFull) {
  const Scene scene(Shape::kValley);
  light::TransferOptions full_o, fast_o;
  fast_o.subsample = 4;
  light::TransferComputer full(full_o), fast(fast_o);
  light::TransferResult a, b;
  full.Compute(scene.View(), {}, nullptr, &a);
  fast.Compute(scene.View(), {}, nullptr, &b);
  double diff = 0, norm = 0;
  for (size_t p = 0; p < a.valid.size(); ++p) {
    ASSERT_EQ(a.valid[p], b.valid[p]);
    for (int k = 0; k < 4; ++k) {
      diff += std::abs(a.transfer[p * 16 + k] - b.transfer[p * 16 + k]);
      norm += std::abs(a.transfer[p * 16 + k]);
    }
  }
  EXPECT_LT(diff / norm, 0.06) << "mean relative difference of bands 0-1";
}

// The differential renderer's window: the same bits as the whole-image transfer at its pixels, for
// every step and with the indirect term; bad rects are refused.
TEST(Transfer, RegionEqualsTheFullTransferAtItsPixels) {
  const Scene scene(Shape::kValley);
  light::TransferOptions o;
  o.subsample = 4;  // ignored by ComputeRegion
  light::TransferOptions full_o;
  light::TransferComputer region(o), full(full_o);
  const float r2 = std::sqrt(0.5f);
  const light::DominantLight light{{r2, 0, -r2}, 3.0f};
  light::TransferResult a, b;
  full.Compute(scene.View(), {}, &light, &a);
  for (int step : {1, 3}) {
    const light::PixelRect rect{70, 40, 101, 77};
    region.ComputeRegion(scene.View(), {}, &light, rect, step, &b);
    ASSERT_EQ(b.width, (31 + step - 1) / step);
    ASSERT_EQ(b.height, (37 + step - 1) / step);
    for (int j = 0; j < b.height; ++j) {
      for (int i = 0; i < b.width; ++i) {
        const size_t p =
            static_cast<size_t>(40 + j * step + step / 2) * 160 + 70 + i * step + step / 2;
        const size_t q = static_cast<size_t>(j) * b.width + i;
        ASSERT_EQ(b.valid[q], a.valid[p]);
        for (int k = 0; k < 16; ++k) ASSERT_EQ(b.transfer[q * 16 + k], a.transfer[p * 16 + k]);
        for (int c = 0; c < 3; ++c) ASSERT_EQ(b.indirect[3 * q + c], a.indirect[3 * p + c]);
      }
    }
  }
  EXPECT_EQ(ThrownMessage<light::LightError>([&] {
              region.ComputeRegion(scene.View(), {}, nullptr, {150, 0, 161, 10}, 1, &b);
            }),
            "light::TransferComputer::ComputeRegion: rect [150, 161) x [0, 10) is empty or not "
            "inside 160x120");
  // A mask skips samples and leaves the others bit-identical.
  std::vector<uint8_t> mask(31 * 37, 1);
  mask[5] = 0;
  region.ComputeRegion(scene.View(), {}, nullptr, {70, 40, 101, 77}, 1, &b, mask);
  EXPECT_EQ(b.valid[5], 0);
  EXPECT_EQ(b.transfer[5 * 16], 0.0f);
  EXPECT_EQ(b.transfer[6 * 16], a.transfer[(40 * 160 + 76) * 16]);
  EXPECT_EQ(ThrownMessage<light::LightError>([&] {
              region.ComputeRegion(scene.View(), {}, nullptr, {70, 40, 101, 77}, 1, &b,
                                   std::span<const uint8_t>(mask).first(3));
            }),
            "light::TransferComputer::ComputeRegion: mask has 3 bytes, expected 31x37");
  EXPECT_EQ(ThrownMessage<light::LightError>([&] {
              region.ComputeRegion(scene.View(), {}, nullptr, {0, 0, 5, 5}, 0, &b);
            }),
            "light::TransferComputer::ComputeRegion: step must be >= 1, got 0");
}

TEST(Transfer, FastKeepsItsSparseSamples) {
  const Scene scene(Shape::kValley);
  light::TransferOptions o;
  o.subsample = 4;
  light::TransferComputer fast(o);
  light::TransferResult r;
  fast.Compute(scene.View(), {}, nullptr, &r);
  ASSERT_EQ(r.sample_step, 4);
  ASSERT_EQ(r.sample_width, 40);
  ASSERT_EQ(r.sample_height, 30);
  ASSERT_EQ(r.samples.size(), 40u * 30u * 16u);
  // Catmull-Rom interpolates: the upsampled T equals the sample at the sample's pixel.
  int checked = 0;
  for (int j = 0; j < 30; ++j) {
    for (int i = 0; i < 40; ++i) {
      const size_t s = static_cast<size_t>(j) * 40 + i;
      const size_t p = static_cast<size_t>(4 * j + 2) * 160 + (4 * i + 2);
      ASSERT_EQ(r.sample_valid[s], r.valid[p]);
      if (!r.valid[p]) continue;
      for (int k = 0; k < 16; ++k) {
        ASSERT_NEAR(r.samples[s * 16 + k], r.transfer[p * 16 + k], 1e-5);
      }
      ++checked;
    }
  }
  EXPECT_GT(checked, 1000);
  light::TransferComputer full({});
  full.Compute(scene.View(), {}, nullptr, &r);
  EXPECT_EQ(r.sample_step, 1);
  EXPECT_TRUE(r.samples.empty());
}

// OursFast's upsampling for every coefficient count (16 and 9 have unrolled paths, the others a
// generic one) and for the indirect channels: interpolating at a sample's own pixel returns it,
// and the full-resolution T stays within the samples' range elsewhere (Catmull-Rom overshoots a
// little, never far).
TEST(Transfer, FastUpsamplingForAllBandCountsAndIndirect) {
  const Scene scene(Shape::kValley);
  const float r2 = std::sqrt(0.5f);
  const light::DominantLight light{{r2, 0, -r2}, 3.0f};
  for (int bands : {2, 3, 4, 5}) {
    SCOPED_TRACE("bands " + std::to_string(bands));
    light::TransferOptions o;
    o.bands = bands;
    o.subsample = 4;
    light::TransferComputer fast(o);
    light::TransferResult r, sparse_indirect;
    fast.Compute(scene.View(), {}, &light, &r);
    const int cc = bands * bands;
    ASSERT_EQ(r.coefficient_count, cc);
    ASSERT_EQ(r.indirect.size(), 3u * 160 * 120);
    // The sparse grid's indirect term: the full variant at the sample pixels (same offsets).
    light::TransferComputer full({.bands = bands});
    full.Compute(scene.View(), {}, &light, &sparse_indirect);
    int checked = 0, bounced = 0;
    float t0_min = 1e9f, t0_max = -1e9f;
    for (int j = 0; j < 30; ++j) {
      for (int i = 0; i < 40; ++i) {
        const size_t s = static_cast<size_t>(j) * 40 + i;
        const size_t p = static_cast<size_t>(4 * j + 2) * 160 + (4 * i + 2);
        if (!r.sample_valid[s]) continue;
        for (int k = 0; k < cc; ++k) {
          ASSERT_NEAR(r.samples[s * cc + k], r.transfer[p * cc + k], 1e-5);
          ASSERT_NEAR(sparse_indirect.transfer[p * cc + k], r.transfer[p * cc + k], 1e-5);
        }
        for (int c = 0; c < 3; ++c) {
          ASSERT_NEAR(sparse_indirect.indirect[3 * p + c], r.indirect[3 * p + c], 1e-5);
        }
        bounced += r.indirect[3 * p] > 1e-3f;
        t0_min = std::min(t0_min, r.samples[s * cc]);
        t0_max = std::max(t0_max, r.samples[s * cc]);
        ++checked;
      }
    }
    EXPECT_GT(checked, 1000);
    EXPECT_GT(bounced, 10);
    const float margin = 0.1f * (t0_max - t0_min);
    for (size_t p = 0; p < r.valid.size(); ++p) {
      if (!r.valid[p]) continue;
      ASSERT_GE(r.transfer[p * cc], t0_min - margin) << "pixel " << p;
      ASSERT_LE(r.transfer[p * cc], t0_max + margin) << "pixel " << p;
      ASSERT_GE(r.indirect[3 * p], 0.0f);
    }
  }
}

TEST(Transfer, IndirectLightBouncesAcrossTheValley) {
  const Scene scene(Shape::kValley);
  light::TransferComputer computer({});
  light::TransferResult r;
  // The light faces the left slope (normal (1, 0, -1)/sqrt 2), which bounces it onto the right one.
  const float r2 = std::sqrt(0.5f);
  const light::DominantLight light{{r2, 0, -r2}, 3.0f};
  computer.Compute(scene.View(), {}, &light, &r);
  ASSERT_EQ(r.indirect.size(), 3u * 160 * 120);
  const int corner = 60 * 160 + 82, open = 60 * 160 + 140;
  EXPECT_GT(r.indirect[3 * corner], 1e-3);
  EXPECT_EQ(r.indirect[3 * open], 0.0f);

  // As the node publishes it: an rgb32f image with the same values, pixel-major R G B.
  const size_t bytes = msgs::Image::MessageBytesFor(160, 120, msgs::Encoding::kRgb32f);
  std::vector<std::byte> storage(bytes + 64);  // bus slots are 64-byte aligned
  const size_t pad = (64 - reinterpret_cast<uintptr_t>(storage.data()) % 64) % 64;
  auto out = msgs::WriteMessage<msgs::Image>(std::span(storage).subspan(pad, bytes));
  light::FillIndirectImage(r, out.message, out.payload);
  EXPECT_EQ(out->encoding, msgs::Encoding::kRgb32f);
  EXPECT_EQ(out->width, 160u);
  const auto row = msgs::ImageRow<float>(*out, out.payload, 60);
  EXPECT_EQ(row[3 * 82 + 1], r.indirect[3 * corner + 1]);
  EXPECT_EQ(ThrownMessage<light::LightError>(
                [&] { light::FillIndirectImage(r, out.message, out.payload.first(100)); }),
            "light::FillIndirectImage: payload of 100 bytes, need 230400");
  computer.Compute(scene.View(), {}, nullptr, &r);  // no dominant light: no indirect buffer
  EXPECT_EQ(ThrownMessage<light::LightError>(
                [&] { light::FillIndirectImage(r, out.message, out.payload); }),
            "light::FillIndirectImage: the transfer result has no indirect buffer (0 values for "
            "160x120 pixels; Compute needs a DominantLight)");
}

TEST(Transfer, AuxiliaryViewOccludes) {
  // An open plane; a top view (looking along camera +y = down) sees a slab 10 cm in front of it.
  const Scene scene(Shape::kPlane);
  std::vector<float> top(32 * 32, 0.0f);
  light::OrthographicView view;
  view.role = light::AuxiliaryRole::kTop;
  view.width = view.height = 32;
  view.pixel_size_m = 0.1f;
  // View frame: x = camera x, y = camera z (z_view = +y_camera), origin 1 m above (y = -1).
  view.rotation = {1, 0, 0, 0, 0, 1, 0, -1, 0};  // columns: x_v=(1,0,0), y_v=(0,0,-1), z_v=(0,1,0)
  view.translation = {0, -1, 2.9f};
  for (float& d : top) d = 0.9f;  // a horizontal slab 10 cm above the camera axis... at y = -0.1
  light::AuxiliaryBuffers aux;
  view.depth = top;
  aux.views.push_back(view);
  light::TransferComputer computer({});
  light::TransferResult open, covered;
  computer.Compute(scene.View(), {}, nullptr, &open);
  computer.Compute(scene.View(), aux, nullptr, &covered);
  const int p = 60 * 160 + 80;  // on the wall at y ~ 0, just below the slab
  EXPECT_LT(covered.transfer[p * 16], 0.95 * open.transfer[p * 16]);
}

TEST(Normals, FromDepthOfAPlane) {
  const Scene scene(Shape::kPlane);
  std::vector<float> n;
  light::NormalsFromDepth(scene.depth, scene.w, scene.h, scene.k, &n);
  const int p = 60 * 160 + 80;
  EXPECT_NEAR(n[3 * p + 2], -1.0f, 1e-5);
  EXPECT_NEAR(n[3 * p], 0.0f, 1e-5);
}

std::vector<double> RandomLight(int cc, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<double> l(cc);
  for (auto& v : l) v = static_cast<double>(rng() >> 11) / 9007199254740992.0 - 0.5;
  return l;
}

TEST(Estimate, RecoversAKnownLightExactly) {
  const int cc = 16, m = 600;
  std::mt19937_64 rng(5);
  std::vector<float> rows(m * cc), targets(m);
  const auto l = RandomLight(cc, 9);
  for (int i = 0; i < m; ++i) {
    double s = 0;
    for (int k = 0; k < cc; ++k) {
      rows[i * cc + k] =
          static_cast<float>(static_cast<double>(rng() >> 11) / 9007199254740992.0 - 0.5);
      s += rows[i * cc + k] * l[k];
    }
    targets[i] = static_cast<float>(s);
  }
  light::EstimateOptions o;
  o.robust = false;
  o.ridge = 0;
  o.smoothness = 0;  // no prior: exact data must be reproduced exactly
  auto e = light::SolveLight(rows, targets, cc, o);
  ASSERT_TRUE(e.valid);
  for (int k = 0; k < cc; ++k) EXPECT_NEAR(e.coefficients[k], l[k], 1e-5);
  EXPECT_GT(e.confidence, 0.99f);
  // Robust mode: 10 % gross outliers (specular highlights, wrong geometry) are ignored.
  for (int i = 0; i < m; i += 10) targets[i] += 3.0f;
  o.robust = true;
  e = light::SolveLight(rows, targets, cc, o);
  for (int k = 0; k < cc; ++k) EXPECT_NEAR(e.coefficients[k], l[k], 1e-4);
  o.robust = false;
  e = light::SolveLight(rows, targets, cc, o);
  double err = 0;
  for (int k = 0; k < cc; ++k) err = std::max(err, std::abs(e.coefficients[k] - l[k]));
  EXPECT_GT(err, 1e-2) << "plain least squares is hurt by the outliers";
}

TEST(Estimate, DominantDirectionAndNonNegativeModeOnPlaneTransfer) {
  // A directional light seen through the transfer of many orientations: I = T l, l = P Y(d).
  const light::DirectionSet set(64, 4, 1);
  const auto normals = sh::FibonacciSphere(300);
  const sh::Vec3 d{0.3, -0.8, -0.52};
  const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  const sh::Vec3 dn{d[0] / len, d[1] / len, d[2] / len};
  const auto l = sh::DirectionalLight(dn, 3.0, 4);
  std::vector<float> rows, targets;
  for (const auto& n : normals) {
    std::vector<double> t(16, 0);
    for (int j = 0; j < set.count(); ++j) {
      const auto& w = set.directions()[j];
      const double c = std::max(0.0, w[0] * n[0] + w[1] * n[1] + w[2] * n[2]);
      for (int k = 0; k < 16; ++k) t[k] += c * set.weights()[j * 16 + k];
    }
    double s = 0;
    for (int k = 0; k < 16; ++k) {
      rows.push_back(static_cast<float>(t[k]));
      s += t[k] * l[k];
    }
    targets.push_back(static_cast<float>(s));
  }
  light::EstimateOptions o;
  o.smoothness = 0;
  o.direction_bands = 0;  // the exact 16-coefficient model: direction from the full fit
  const auto e = light::SolveLight(rows, targets, 16, o);
  const double dot = e.dominant_direction[0] * dn[0] + e.dominant_direction[1] * dn[1] +
                     e.dominant_direction[2] * dn[2];
  EXPECT_GT(dot, std::cos(2.0 * std::numbers::pi / 180));
  o.non_negative = true;
  const auto nn = light::SolveLight(rows, targets, 16, o);
  double most_negative = 0;
  for (const auto& w : sh::FibonacciSphere(64)) {
    most_negative = std::min(most_negative, sh::Evaluate(nn.coefficients, w));
  }
  double plain_negative = 0;
  for (const auto& w : sh::FibonacciSphere(64)) {
    plain_negative = std::min(plain_negative, sh::Evaluate(e.coefficients, w));
  }
  EXPECT_GT(most_negative, 0.5 * plain_negative - 1e-9);
}

// Unoccluded transfer rows (A_l / pi) Y(n) of normals spread over the sphere facing the camera
// (z < 0), grouped by the sign of n.x, and the light d with irradiance 3 plus an ambient term.
struct GroupedScene {
  light::TransferResult transfer;
  std::vector<float> intensity;
  std::vector<uint8_t> colour;
  sh::Vec3 direction;
};
GroupedScene MakeGroupedScene(double albedo_left, double albedo_right) {
  GroupedScene g;
  const auto normals = sh::FibonacciSphere(4000);
  std::vector<sh::Vec3> facing;
  for (const auto& n : normals) {
    if (n[2] < -0.05) facing.push_back(n);
  }
  const int w = static_cast<int>(facing.size()), cc = 16;
  g.transfer.width = w;
  g.transfer.height = 1;
  g.transfer.coefficient_count = cc;
  g.transfer.transfer.resize(static_cast<size_t>(w) * cc);
  g.transfer.valid.assign(w, 1);
  g.direction = {0.45, -0.6, -0.66};
  const double len = std::sqrt(g.direction[0] * g.direction[0] + g.direction[1] * g.direction[1] +
                               g.direction[2] * g.direction[2]);
  for (auto& c : g.direction) c /= len;
  auto l = sh::DirectionalLight(g.direction, 3.0, 4);
  l[0] += 0.3;  // ambient
  for (int i = 0; i < w; ++i) {
    const auto y = sh::Basis(4, facing[i]);
    double shading = 0;
    for (int k = 0; k < cc; ++k) {
      const double t = sh::ClampedCosineCoefficient(sh::DegreeOf(k)) / std::numbers::pi * y[k];
      g.transfer.transfer[static_cast<size_t>(i) * cc + k] = static_cast<float>(t);
      shading += t * l[k];
    }
    const bool left = facing[i][0] < 0;
    g.intensity.push_back(static_cast<float>((left ? albedo_left : albedo_right) * shading));
    // Two materials of different chromaticity: reddish on the left, bluish on the right.
    const uint8_t rgb[2][3] = {{200, 120, 100}, {100, 120, 200}};
    g.colour.insert(g.colour.end(), rgb[left ? 0 : 1], rgb[left ? 0 : 1] + 3);
  }
  return g;
}

double DirectionErrorDeg(const light::LightEstimate& e, const sh::Vec3& d) {
  const double dot = e.dominant_direction[0] * d[0] + e.dominant_direction[1] * d[1] +
                     e.dominant_direction[2] * d[2];
  return std::acos(std::clamp(dot, -1.0, 1.0)) * 180 / std::numbers::pi;
}

TEST(Estimate, AlbedoGroupsRemoveTheBiasOfTwoMaterials) {
  // Left-facing surfaces have albedo 0.2, right-facing ones 0.7: a uniform-albedo fit reads the
  // difference as light from the right; with one albedo per chromaticity group it does not.
  const GroupedScene g = MakeGroupedScene(0.2, 0.7);
  light::EstimateOptions o;
  o.stride = 1;
  o.albedo_groups = 0;
  const auto uniform = light::EstimateLight(g.transfer, g.intensity, o, g.colour);
  o.albedo_groups = 32;
  const auto grouped = light::EstimateLight(g.transfer, g.intensity, o, g.colour);
  o.albedo_iterations = 12;  // the alternation run to convergence
  const auto converged = light::EstimateLight(g.transfer, g.intensity, o, g.colour);
  ASSERT_TRUE(uniform.valid);
  ASSERT_TRUE(grouped.valid);
  const double e_uniform = DirectionErrorDeg(uniform, g.direction);
  const double e_grouped = DirectionErrorDeg(grouped, g.direction);
  const double e_converged = DirectionErrorDeg(converged, g.direction);
  std::printf(
      "two materials: uniform albedo %.2f deg, albedo groups %.2f deg (3 alternations), "
      "%.2f deg (12)\n",
      e_uniform, e_grouped, e_converged);
  EXPECT_GT(e_uniform, 10.0);
  EXPECT_LT(e_grouped, 0.5 * e_uniform);
  EXPECT_LT(e_converged, 1.5);
  o.albedo_iterations = 3;
  // One material: with and without groups (no colour = one albedo) close to the truth (the
  // remaining ~1 deg is the smoothness prior and the bands 0-1 direction fit).
  const GroupedScene same = MakeGroupedScene(0.6, 0.6);
  EXPECT_LT(DirectionErrorDeg(light::EstimateLight(same.transfer, same.intensity, o, same.colour),
                              same.direction),
            2.0);
  EXPECT_LT(
      DirectionErrorDeg(light::EstimateLight(same.transfer, same.intensity, o), same.direction),
      2.0);
}

TEST(Estimate, ThinningTheBigBinsKeepsTheResult) {
  // 90 % of the rows share one orientation (a floor), the rest spread over the sphere.
  const GroupedScene g = MakeGroupedScene(0.6, 0.6);
  light::TransferResult t = g.transfer;
  std::vector<float> intensity = g.intensity;
  const int floor_rows = 9 * t.width;
  for (int i = 0; i < floor_rows; ++i) {
    t.transfer.insert(t.transfer.end(), g.transfer.transfer.begin(),
                      g.transfer.transfer.begin() + 16);
    intensity.push_back(g.intensity[0]);
  }
  t.width += floor_rows;
  t.valid.assign(t.width, 1);
  light::EstimateOptions o;
  o.stride = 1;
  o.max_rows_per_bin = 0;
  const auto all = light::EstimateLight(t, intensity, o);
  o.max_rows_per_bin = 20;
  const auto thin = light::EstimateLight(t, intensity, o);
  const double e_all = DirectionErrorDeg(all, g.direction);
  const double e_thin = DirectionErrorDeg(thin, g.direction);
  EXPECT_LT(e_all, 2.0);
  EXPECT_LT(e_thin, 2.0);
  EXPECT_LT(std::abs(e_all - e_thin), 0.5);
  EXPECT_EQ(thin.pixels, t.width);
}

TEST(Normals, FilterDropsCreasesAndGrazingSurfaces) {
  // Wall at 3 m over a floor 0.5 m below the camera: the crease row (the floor meets the wall at
  // v = cy + 0.5 * fy / 3 = 79.5) and the floor near the horizon (seen at > 75 degrees) lose their
  // normals, the middle of the wall and the near floor keep them.
  const Scene scene(Shape::kFloor);
  std::vector<float> n = scene.normals;
  light::NormalFilterOptions o;
  light::FilterNormals(scene.depth, scene.w, scene.h, scene.k, o, n);
  auto has_normal = [&](int u, int v) {
    const size_t p = static_cast<size_t>(v) * scene.w + u;
    return n[3 * p] != 0 || n[3 * p + 1] != 0 || n[3 * p + 2] != 0;
  };
  EXPECT_TRUE(has_normal(80, 40));   // wall
  EXPECT_TRUE(has_normal(80, 115));  // floor 1.1 m ahead, seen at ~66 degrees
  EXPECT_FALSE(has_normal(80, 80));  // the crease
  EXPECT_FALSE(has_normal(80, 84));  // floor ~3 m ahead, seen at ~80 degrees
  EXPECT_FALSE(has_normal(1, 40));   // the image border (no neighbour)
  // Depth stays; only the normals are dropped. Everything off = unchanged.
  std::vector<float> same = scene.normals;
  o.radius = 0;
  o.max_view_angle_deg = 90;
  light::FilterNormals(scene.depth, scene.w, scene.h, scene.k, o, same);
  EXPECT_EQ(same, scene.normals);
  EXPECT_EQ(
      ThrownMessage<light::LightError>(
          [&] { light::FilterNormals(scene.depth, scene.w, scene.h - 1, scene.k, o, same); }),
      "light::FilterNormals: depth has 19200 values and normals 57600, expected 160x119 (x3)");
}

TEST(Estimate, ShRotationMatrixRotatesADirectionalLight) {
  // A[k][n] = integral Y_k(d) Y_n(R d): the light of frame B (directions d_B = R d_A) maps back
  // to frame A's coefficients.
  const double a = 0.4;  // rotation about (0.6, 0, 0.8) by 0.4 rad (Rodrigues)
  const double ax[3] = {0.6, 0, 0.8};
  const double c = std::cos(a), s = std::sin(a);
  float r[9];
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      const double cross[3][3] = {{0, -ax[2], ax[1]}, {ax[2], 0, -ax[0]}, {-ax[1], ax[0], 0}};
      r[i * 3 + j] =
          static_cast<float>((i == j ? c : 0) + (1 - c) * ax[i] * ax[j] + s * cross[i][j]);
    }
  }
  const sh::Vec3 d{0.3, -0.8, -0.52};
  const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  const sh::Vec3 da{d[0] / len, d[1] / len, d[2] / len};
  const sh::Vec3 db{r[0] * da[0] + r[1] * da[1] + r[2] * da[2],
                    r[3] * da[0] + r[4] * da[1] + r[5] * da[2],
                    r[6] * da[0] + r[7] * da[1] + r[8] * da[2]};
  const auto la = sh::DirectionalLight(da, 2.0, 4), lb = sh::DirectionalLight(db, 2.0, 4);
  std::vector<double> m;
  light::ShRotationMatrix(r, 4, &m);
  double worst = 0;
  for (int k = 0; k < 16; ++k) {
    double v = 0;
    for (int n = 0; n < 16; ++n) v += m[k * 16 + n] * lb[n];
    worst = std::max(worst, std::abs(v - la[k]));
  }
  EXPECT_LT(worst, 2e-5);
  EXPECT_EQ(ThrownMessage<light::LightError>([&] { light::ShRotationMatrix(r, 6, &m); }),
            "light::ShRotationMatrix: bands must be 1..5, got 6");
}

// A sphere of radius `radius` centred 3 m ahead (on the optical axis) in front of a wall at 4 m,
// seen by the 160x120 camera of Scene: depth and exact normals.
Scene SphereScene(double radius) {
  Scene s(Shape::kPlane);
  for (int v = 0; v < s.h; ++v) {
    for (int u = 0; u < s.w; ++u) {
      const double dx = (u - s.k.cx) / s.k.fx, dy = (v - s.k.cy) / s.k.fy;
      const double len = std::sqrt(dx * dx + dy * dy + 1);
      const double d[3] = {dx / len, dy / len, 1 / len};
      // |t d - c|^2 = r^2, c = (0, 0, 3).
      const double b = d[2] * 3, disc = b * b - (9 - radius * radius);
      double z = 4, n[3] = {0, 0, -1};
      if (disc > 0) {
        const double t = b - std::sqrt(disc);
        const double p[3] = {t * d[0], t * d[1], t * d[2]};
        z = p[2];
        n[0] = p[0] / radius, n[1] = p[1] / radius, n[2] = (p[2] - 3) / radius;
      }
      const size_t q = static_cast<size_t>(v) * s.w + u;
      s.depth[q] = static_cast<float>(z);
      for (int c = 0; c < 3; ++c) s.normals[3 * q + c] = static_cast<float>(n[c]);
    }
  }
  return s;
}

double AngleDeg(const std::vector<float>& a, const std::vector<float>& b, size_t p) {
  const double dot =
      a[3 * p] * b[3 * p] + a[3 * p + 1] * b[3 * p + 1] + a[3 * p + 2] * b[3 * p + 2];
  return std::acos(std::clamp(dot, -1.0, 1.0)) * 180 / std::numbers::pi;
}

// The test camera is coarse (a pixel is 2.5 cm at 3 m): curvature radii below ~0.2 m are below
// its resolution, so the smooth-surface allowance is set to that (the default 2 cm suits 640 x 480
// at 525 px focal length: 4.8 mm pixels at 2.5 m).
constexpr float kTestMinRadius = 0.2f;

TEST(Reliability, LowAtDepthEdgesAndCreasesHighOnPlanesAndSpheres) {
  light::NormalReliabilityOptions o;
  o.window = 2;
  o.min_radius_m = kTestMinRadius;
  std::vector<float> r;
  // Wall over floor: the crease (row ~79.5) is unreliable, wall and near floor are not.
  const Scene floor(Shape::kFloor);
  light::NormalReliability(floor.depth, floor.w, floor.h, floor.k, floor.normals, o, &r);
  auto at = [&](int u, int v) { return r[static_cast<size_t>(v) * floor.w + u]; };
  EXPECT_GT(at(80, 40), 0.9f);   // wall
  EXPECT_GT(at(80, 110), 0.9f);  // floor 1.2 m ahead
  EXPECT_LT(at(80, 80), 0.1f);   // the crease
  EXPECT_LT(at(80, 79), 0.1f);
  // A concave V: its crease (u ~ 79.5) too.
  const Scene valley(Shape::kValley);
  light::NormalReliability(valley.depth, valley.w, valley.h, valley.k, valley.normals, o, &r);
  EXPECT_LT(at(80, 60), 0.1f);
  EXPECT_GT(at(40, 60), 0.9f);
  EXPECT_GT(at(120, 60), 0.9f);
  // A 0.6 m sphere 3 m ahead of a wall at 4 m: reliable on the sphere and the wall, not at the
  // silhouette (radius 0.6 / 3 * 120 = 24 px, at u = 79.5 + 24.5).
  const Scene sphere = SphereScene(0.6);
  light::NormalReliability(sphere.depth, sphere.w, sphere.h, sphere.k, sphere.normals, o, &r);
  EXPECT_GT(at(80, 60), 0.9f);   // sphere centre
  EXPECT_GT(at(95, 60), 0.9f);   // sphere, 38 degrees off the view axis
  EXPECT_GT(at(140, 60), 0.9f);  // wall
  int edge_low = 0;
  for (int u = 100; u <= 108; ++u) edge_low += at(u, 60) < 0.1f;
  EXPECT_GE(edge_low, 3);  // the silhouette and its window
  EXPECT_EQ(ThrownMessage<light::LightError>([&] {
              light::NormalReliability(sphere.depth, sphere.w, sphere.h - 1, sphere.k,
                                       sphere.normals, o, &r);
            }),
            "light::NormalReliability: depth has 19200 values and normals 57600, expected "
            "160x119 (x3)");
}

TEST(Reliability, EdgeAwareNormalsComeFromThePixelsOwnSurface) {
  // Next to a crease and a silhouette, central differences mix the two surfaces; the edge-aware
  // normals take the side that continues the pixel's surface and are exact there.
  light::DepthNormalOptions o;
  o.step = 2;
  o.min_radius_m = kTestMinRadius;
  std::vector<float> edge, central, r;
  const Scene floor(Shape::kFloor);
  light::NormalsWithReliability(floor.depth, floor.w, floor.h, floor.k, o, &edge, &r);
  light::NormalsFromDepth(floor.depth, floor.w, floor.h, floor.k, &central, 0.05f, 2);
  double worst_edge = 0, worst_central = 0;
  for (int v = 76; v <= 83; ++v) {  // the rows around the crease (79.5)
    const size_t p = static_cast<size_t>(v) * floor.w + 80;
    worst_edge = std::max(worst_edge, AngleDeg(edge, floor.normals, p));
    worst_central = std::max(worst_central, AngleDeg(central, floor.normals, p));
  }
  std::printf("crease: worst normal error %.2f deg edge-aware, %.2f deg central\n", worst_edge,
              worst_central);
  EXPECT_LT(worst_edge, 1.0);
  EXPECT_GT(worst_central, 10.0);
  const Scene sphere = SphereScene(0.6);
  light::NormalsWithReliability(sphere.depth, sphere.w, sphere.h, sphere.k, o, &edge, &r);
  // The wall right outside the silhouette (the sphere's depth is within 5 % * step of the wall's
  // only near the rim, so compare a wide band) and the sphere's interior.
  double worst_wall = 0, worst_sphere = 0;
  for (int u = 105; u <= 112; ++u) {
    worst_wall = std::max(worst_wall, AngleDeg(edge, sphere.normals, 60 * sphere.w + u));
  }
  for (int u = 60; u <= 98; ++u) {
    worst_sphere = std::max(worst_sphere, AngleDeg(edge, sphere.normals, 60 * sphere.w + u));
    EXPECT_GT(r[60 * sphere.w + u], 0.5f) << u;
  }
  EXPECT_LT(worst_wall, 1.0);
  EXPECT_LT(worst_sphere, 5.0);
  EXPECT_GT(r[60 * sphere.w + 140], 0.99f);  // plane
  // A one-pixel spike 10 cm in front of the wall: no side continues it, reliability ~0.
  Scene spike(Shape::kPlane);
  spike.depth[60 * spike.w + 80] = 2.9f;
  light::NormalsWithReliability(spike.depth, spike.w, spike.h, spike.k, o, &edge, &r);
  EXPECT_LT(r[60 * spike.w + 80], 0.01f);
  EXPECT_GT(r[60 * spike.w + 90], 0.99f);
  EXPECT_EQ(ThrownMessage<light::LightError>([&] {
              light::NormalsWithReliability(spike.depth, spike.w, spike.h - 1, spike.k, o, &edge,
                                            &r);
            }),
            "light::NormalsWithReliability: depth has 19200 values, expected 160x119");
}

TEST(Reliability, DepthNoiseTellsCleanFromQuantisedDepth) {
  // The wall at 3 m rounded to millimetres (a clean depth16 image) and quantised like a
  // Kinect-like disparity (steps of 0.00285 z^2, i.e. 2.6 cm at 3 m) with a slight slant so the
  // steps show: DepthGeometry's fine / smoothed regimes are told apart by the measured k.
  Scene clean(Shape::kPlane), coarse(Shape::kPlane);
  for (int v = 0; v < clean.h; ++v) {
    for (int u = 0; u < clean.w; ++u) {
      const size_t p = static_cast<size_t>(v) * clean.w + u;
      const double z = 3.0 / (1 - 0.3 * (u - clean.k.cx) / clean.k.fx);  // a slanted plane
      clean.depth[p] = static_cast<float>(std::round(z * 1000) / 1000);
      const double q = 0.00285 * z * z;
      coarse.depth[p] = static_cast<float>(std::round(z / q) * q);
    }
  }
  const float k_clean = light::DepthNoiseQuadratic(clean.depth, clean.w, clean.h);
  const float k_coarse = light::DepthNoiseQuadratic(coarse.depth, coarse.w, coarse.h);
  std::printf("measured noise k: mm depth %.2e, quantised %.2e\n", k_clean, k_coarse);
  const light::DepthGeometryOptions defaults;
  EXPECT_GT(k_clean, 0.0f);
  EXPECT_LT(k_clean, defaults.fine_noise_quadratic);
  EXPECT_GT(k_coarse, defaults.fine_noise_quadratic);

  // Too little depth beyond 1.5 m: not measured (NaN) rather than "clean"; DepthGeometry then
  // takes the noisy image's path and says so.
  Scene near(Shape::kPlane);
  for (float& d : near.depth) d = d > 0 ? 1.0f : 0.0f;
  EXPECT_TRUE(std::isnan(light::DepthNoiseQuadratic(near.depth, near.w, near.h)));
  std::vector<float> normals, reliability;
  EXPECT_TRUE(std::isnan(
      light::DepthGeometry(near.depth, near.w, near.h, near.k, defaults, &normals, &reliability)));
  ASSERT_EQ(normals.size(), 3u * near.w * near.h);
  const size_t centre = static_cast<size_t>(near.h / 2) * near.w + near.w / 2;
  EXPECT_NEAR(normals[3 * centre + 2], -1.0f, 1e-4);
  light::DepthGeometryOptions bad;
  bad.step = 0;
  EXPECT_EQ(ThrownMessage<light::LightError>(
                [&] { light::DepthGeometry(near.depth, near.w, near.h, near.k, bad, &normals); }),
            "light::DepthGeometry: step must be -1 (by the noise) or >= 1, got 0");
  EXPECT_EQ(ThrownMessage<light::LightError>([&] {
              light::DepthGeometry(near.depth, near.w, near.h, near.k, defaults, nullptr);
            }),
            "light::DepthGeometry: normals must not be null");
}

// A room-like frame: unoccluded transfer rows of three planes (floor, back and left wall: 3000,
// 3000 and 1500 rows) and of a ball (300 normals over the visible hemisphere) under the light of
// MakeGroupedScene (albedo 0.6). `corrupt_share` of the plane rows (fixed seed) get the transfer of
// their normal tilted by 57 degrees in a random direction while their intensity stays the plane's:
// the mixed normals of depth-image pixels whose stencil straddles a crease or a depth edge. Their
// reliability is 0.02, all others 1.
struct CorruptedFrame {
  light::TransferResult transfer;
  std::vector<float> intensity, reliability;
  sh::Vec3 direction;
  int corrupted = 0;
};
CorruptedFrame MakeCorruptedFrame(double corrupt_share, uint64_t seed) {
  CorruptedFrame f;
  f.direction = {0.45, -0.6, -0.66};
  const double dl = std::sqrt(0.45 * 0.45 + 0.6 * 0.6 + 0.66 * 0.66);
  for (auto& c : f.direction) c /= dl;
  auto l = sh::DirectionalLight(f.direction, 3.0, 4);
  l[0] += 0.3;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> uniform(0, 1);
  std::vector<sh::Vec3> normals;
  std::vector<bool> plane;
  const sh::Vec3 planes[3] = {{0, -1, 0}, {0, 0, -1}, {1, 0, 0}};
  const int counts[3] = {3000, 3000, 1500};
  for (int k = 0; k < 3; ++k) {
    for (int i = 0; i < counts[k]; ++i) normals.push_back(planes[k]), plane.push_back(true);
  }
  for (const auto& n : sh::FibonacciSphere(600)) {
    if (n[2] < -0.05) normals.push_back(n), plane.push_back(false);
  }
  const int w = static_cast<int>(normals.size()), cc = 16;
  f.transfer.width = w;
  f.transfer.height = 1;
  f.transfer.coefficient_count = cc;
  f.transfer.valid.assign(w, 1);
  f.reliability.assign(w, 1.0f);
  auto row_of = [&](const sh::Vec3& n, float* out) {
    const auto y = sh::Basis(4, n);
    double shading = 0;
    for (int k = 0; k < cc; ++k) {
      out[k] = static_cast<float>(sh::ClampedCosineCoefficient(sh::DegreeOf(k)) / std::numbers::pi *
                                  y[k]);
      shading += out[k] * l[k];
    }
    return shading;
  };
  f.transfer.transfer.resize(static_cast<size_t>(w) * cc);
  for (int i = 0; i < w; ++i) {
    float* row = &f.transfer.transfer[static_cast<size_t>(i) * cc];
    f.intensity.push_back(static_cast<float>(0.6 * row_of(normals[i], row)));
    if (plane[i] && uniform(rng) < corrupt_share) {
      // The plane normal tilted by 1 rad (57 degrees) towards a random direction.
      const sh::Vec3 n = normals[i];
      sh::Vec3 a{uniform(rng) - 0.5, uniform(rng) - 0.5, uniform(rng) - 0.5};
      const double d = a[0] * n[0] + a[1] * n[1] + a[2] * n[2];
      for (int c = 0; c < 3; ++c) a[c] -= d * n[c];
      const double la = std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
      sh::Vec3 m;
      for (int c = 0; c < 3; ++c) m[c] = n[c] * std::cos(1.0) + a[c] / la * std::sin(1.0);
      row_of(m, row);
      f.reliability[i] = 0.02f;
      ++f.corrupted;
    }
  }
  return f;
}

TEST(Estimate, ReliabilityWeightsIgnoreCorruptedNormals) {
  // Orientation balancing gives the orientations the corrupted rows land in (empty otherwise but
  // for the ball's few rows) a full bin's weight: measured 11.7 degrees off (0.4 clean); with
  // their reliability the estimate ignores them (0.1).
  const CorruptedFrame f = MakeCorruptedFrame(0.04, 17);
  const int w = f.transfer.width;
  light::EstimateOptions o;
  o.stride = 1;
  const auto plain = light::EstimateLight(f.transfer, f.intensity, o);
  const auto weighted = light::EstimateLight(f.transfer, f.intensity, o, {}, f.reliability);
  const std::vector<float> ones(w, 1.0f);
  const auto neutral = light::EstimateLight(f.transfer, f.intensity, o, {}, ones);
  const CorruptedFrame clean = MakeCorruptedFrame(0.0, 17);
  const auto reference = light::EstimateLight(clean.transfer, clean.intensity, o);
  ASSERT_TRUE(plain.valid);
  ASSERT_TRUE(weighted.valid);
  const double e_plain = DirectionErrorDeg(plain, f.direction);
  const double e_weighted = DirectionErrorDeg(weighted, f.direction);
  const double e_clean = DirectionErrorDeg(reference, f.direction);
  std::printf("%d of %d normals corrupted: %.2f deg unweighted, %.2f deg weighted (%.2f clean)\n",
              f.corrupted, w, e_plain, e_weighted, e_clean);
  EXPECT_GT(f.corrupted, w / 40);
  EXPECT_LT(f.corrupted, w / 20);
  EXPECT_GT(e_plain, 8.0);
  EXPECT_LT(e_weighted, e_clean + 1.0);
  EXPECT_LT(e_weighted, 2.0);
  // Weights of 1 change nothing.
  EXPECT_EQ(neutral.coefficients, plain.coefficients);
  // Sizes are checked.
  EXPECT_EQ(ThrownMessage<light::LightError>([&] {
              light::EstimateLight(f.transfer, f.intensity, o, {}, std::vector<float>(w - 1, 1.0f));
            }),
            "light::EstimateLight: reliability has " + std::to_string(w - 1) +
                " values, transfer is " + std::to_string(w) + "x1");
  EXPECT_EQ(ThrownMessage<light::LightError>([&] {
              light::SolveLight(std::vector<float>(32, 0.0f), std::vector<float>(2, 0.0f), 16, o,
                                std::vector<float>(3, 1.0f));
            }),
            "light::SolveLight: 3 row weights for 2 targets");
}

// One frame of a synthetic stream: the GroupedScene surfaces (one grey material, normals facing
// the camera) lit by a directional light `direction` (camera frame; power 0 = off) plus ambient,
// intensities with Gaussian noise of `noise` (seeded).
GroupedScene MakeNoisyFrame(const sh::Vec3& direction, double power, double noise, uint64_t seed) {
  GroupedScene g = MakeGroupedScene(0.6, 0.6);
  auto l = sh::DirectionalLight(direction, power, 4);
  l[0] += 0.3;
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> gauss(0, noise);
  const int cc = 16;
  for (int i = 0; i < g.transfer.width; ++i) {
    double shading = 0;
    for (int k = 0; k < cc; ++k) shading += g.transfer.transfer[i * cc + k] * l[k];
    g.intensity[i] = static_cast<float>(std::max(0.0, 0.6 * shading + gauss(rng)));
  }
  g.direction = direction;
  g.colour.assign(g.colour.size(), 150);
  return g;
}

TEST(Temporal, PoolsNoisyFramesAndFollowsASwitchWithinThreeFrames) {
  const sh::Vec3 a{0.45, -0.6, -0.66}, b{-0.62, -0.55, -0.56};
  auto unit = [](sh::Vec3 v) {
    const double n = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    return sh::Vec3{v[0] / n, v[1] / n, v[2] / n};
  };
  const sh::Vec3 da = unit(a), db = unit(b);
  light::EstimateOptions o;
  o.stride = 1;
  light::TemporalOptions t;
  t.frames = 4;
  t.forgetting = 0.5f;
  light::TemporalLightEstimator pooled(t);
  // Noisy frames under light a: the pooled error is below the single-frame one on average.
  double single = 0, accumulated = 0;
  const int frames = 8;
  for (int f = 0; f < frames; ++f) {
    const GroupedScene g = MakeNoisyFrame(da, 3.0, 0.25, 100 + f);
    single += DirectionErrorDeg(light::EstimateLight(g.transfer, g.intensity, o, g.colour), da);
    accumulated += DirectionErrorDeg(pooled.Estimate(g.transfer, g.intensity, o, g.colour), da);
  }
  std::printf("noisy frames: single %.2f deg, pooled over 4 frames %.2f deg (mean of %d)\n",
              single / frames, accumulated / frames, frames);
  EXPECT_LT(accumulated, 0.8 * single);
  // The light jumps from a to b (less noise, so that one frame can tell): within three frames
  // the estimate is at b.
  double after[3];
  for (int f = 0; f < 3; ++f) {
    const GroupedScene g = MakeNoisyFrame(db, 3.0, 0.05, 200 + f);
    after[f] = DirectionErrorDeg(pooled.Estimate(g.transfer, g.intensity, o, g.colour), db);
  }
  std::printf("after the switch a -> b: %.1f, %.1f, %.1f deg\n", after[0], after[1], after[2]);
  EXPECT_LT(after[2], 5.0);
  // Switched off: three frames of ambient only bring the directional power down to < 20 %.
  const GroupedScene on = MakeNoisyFrame(db, 3.0, 0.0, 300);
  const float power_on = pooled.Estimate(on.transfer, on.intensity, o, on.colour).intensity;
  float power_off = 0;
  for (int f = 0; f < 3; ++f) {
    const GroupedScene g = MakeNoisyFrame(db, 0.0, 0.0, 400 + f);
    power_off = pooled.Estimate(g.transfer, g.intensity, o, g.colour).intensity;
  }
  std::printf("directional power on %.3f, 3 frames after switching off %.3f\n", power_on,
              power_off);
  EXPECT_LT(power_off, 0.2f * power_on);
  // A rotating camera: with the rotation the pooled rows stay consistent, the error small.
  light::TemporalLightEstimator rotating(t);
  const double step = 0.08;  // rad per frame about the camera's y axis
  const float r[9] = {
      static_cast<float>(std::cos(step)),  0, static_cast<float>(std::sin(step)), 0, 1, 0,
      static_cast<float>(-std::sin(step)), 0, static_cast<float>(std::cos(step))};
  sh::Vec3 d = da;
  double last = 0;
  for (int f = 0; f < 6; ++f) {
    if (f > 0) {
      d = {r[0] * d[0] + r[1] * d[1] + r[2] * d[2], r[3] * d[0] + r[4] * d[1] + r[5] * d[2],
           r[6] * d[0] + r[7] * d[1] + r[8] * d[2]};
    }
    const GroupedScene g = MakeNoisyFrame(d, 3.0, 0.0, 500 + f);
    last = DirectionErrorDeg(
        rotating.Estimate(g.transfer, g.intensity, o, g.colour, f > 0 ? r : nullptr), d);
  }
  EXPECT_LT(last, 2.0);
  EXPECT_EQ(ThrownMessage<light::LightError>([] {
              light::TemporalLightEstimator bad({0, 0.5f});
            }),
            "light::TemporalLightEstimator: frames must be >= 1 and forgetting in [0, 1]");
}

TEST(Messages, GeometryBufferAndShLightRoundTrip) {
  // The node's gbuffer path: planes copied into a msgs::GeometryBuffer give the same transfer.
  const Scene scene(Shape::kValley);
  msgs::GeometryBuffer g;
  g.Init(160, 120);
  std::vector<std::byte> storage(msgs::GeometryBuffer::StandardPayloadBytes(160, 120) + 64);
  std::span<std::byte> payload(storage.data(),
                               msgs::GeometryBuffer::StandardPayloadBytes(160, 120));
  std::ranges::copy(scene.depth, msgs::DepthPlane(g, payload).begin());
  std::ranges::copy(scene.normals, msgs::NormalsPlane(g, payload).begin());
  std::ranges::copy(scene.colour, msgs::ColourPlane(g, payload).begin());
  msgs::CameraInfo info;
  info.width = 160;
  info.height = 120;
  info.fx = info.fy = 120;
  info.cx = 79.5;
  info.cy = 59.5;
  const light::GeometryView view = light::ViewOfGeometryBuffer(g, payload, info);
  light::TransferComputer computer({});
  light::TransferResult a, b;
  computer.Compute(view, {}, nullptr, &a);
  computer.Compute(scene.View(), {}, nullptr, &b);
  EXPECT_EQ(a.transfer, b.transfer);
  // Deterministic: the same input gives bit-identical output, whatever the thread count.
  light::TransferOptions one;
  one.threads = 1;
  light::TransferComputer single(one);
  light::TransferResult c;
  single.Compute(scene.View(), {}, nullptr, &c);
  EXPECT_EQ(b.transfer, c.transfer);
  light::LightEstimate e;
  e.bands = 2;
  e.coefficients = {1.0, -0.5, 0.25, 0.125};
  e.dominant_direction = {0, -1, 0};
  e.intensity = 2;
  e.confidence = 1.5f;
  msgs::ShLight out;
  light::FillShLight(e, &out);
  EXPECT_EQ(out.bands, 2u);
  EXPECT_EQ(out.coefficients[1][2], -0.5f);
  EXPECT_EQ(out.coefficients[4][0], 0.0f);
  EXPECT_EQ(out.confidence, 1.0f);
  out.Validate();
}

TEST(Messages, WorldPointInCamera) {
  // Camera at (1, 2, 3) turned 90 degrees about world z (camera x -> world y), quaternion not
  // normalised: the world point one metre along world y from it is one metre along camera x.
  msgs::RigidTransform pose;
  pose.translation = {1, 2, 3};
  const double h = std::sqrt(0.5) * 2;
  pose.rotation = {h, 0, 0, h};
  const std::array<float, 3> p = light::WorldPointInCamera(pose, {1, 3, 3});
  EXPECT_NEAR(p[0], 1, 1e-6);
  EXPECT_NEAR(p[1], 0, 1e-6);
  EXPECT_NEAR(p[2], 0, 1e-6);
  pose.rotation = {0, 0, 0, 0};
  EXPECT_EQ(ThrownMessage<light::LightError>([&] {
              light::WorldPointInCamera(pose, {0, 0, 0});
            }),
            "light::WorldPointInCamera: the camera's rotation quaternion has norm 0.000000, "
            "expected a finite non-zero norm");
}

TEST(Messages, CameraToWorldRotation) {
  // 90 degrees about world z, quaternion not normalised: camera x -> world y, y -> -x, z -> z.
  msgs::RigidTransform pose;
  const double h = std::sqrt(0.5) * 3;
  pose.rotation = {h, 0, 0, h};
  const std::array<double, 9> r = light::CameraToWorldRotation(pose);
  const std::array<double, 9> expected = {0, -1, 0, 1, 0, 0, 0, 0, 1};
  for (int i = 0; i < 9; ++i) EXPECT_NEAR(r[i], expected[i], 1e-12) << i;
  pose.rotation = {std::nan(""), 0, 0, 0};
  EXPECT_EQ(ThrownMessage<light::LightError>([&] { light::CameraToWorldRotation(pose); }),
            "light::CameraToWorldRotation: the camera's rotation quaternion has norm nan, "
            "expected a finite non-zero norm");
}

TEST(Errors, BadInputsGiveOneLineMessages) {
  Scene scene(Shape::kPlane);
  light::TransferComputer computer({});
  light::TransferResult r;
  auto view = scene.View();
  view.depth = std::span<const float>(scene.depth.data(), 100);
  EXPECT_EQ(ThrownMessage<light::LightError>([&] { computer.Compute(view, {}, nullptr, &r); }),
            "light::TransferComputer::Compute: depth has 100 values, expected 160x120");
  view = scene.View();
  view.normals = {};
  EXPECT_EQ(ThrownMessage<light::LightError>([&] { computer.Compute(view, {}, nullptr, &r); }),
            "light::TransferComputer::Compute: missing normals");
  view = scene.View();
  view.intrinsics.fx = std::nan("");
  EXPECT_EQ(ThrownMessage<light::LightError>([&] { computer.Compute(view, {}, nullptr, &r); }),
            "light::TransferComputer::Compute: non-finite intrinsics");
  light::TransferOptions bad;
  bad.directions = 4;
  EXPECT_EQ(ThrownMessage<light::LightError>([&] { light::TransferComputer c(bad); }),
            "light::DirectionSet: directions must be 8..256, got 4");
  computer.Compute(scene.View(), {}, nullptr, &r);
  std::vector<float> grey(10);
  EXPECT_EQ(ThrownMessage<light::LightError>([&] { light::EstimateLight(r, grey, {}); }),
            "light::EstimateLight: intensity has 10 values, transfer is 160x120");
  grey.assign(160 * 120, 0.1f);
  std::vector<uint8_t> colour(5);
  EXPECT_EQ(ThrownMessage<light::LightError>([&] { light::EstimateLight(r, grey, {}, colour); }),
            "light::EstimateLight: colour has 5 bytes, expected 3 x 160x120");
  // Message adapters.
  msgs::CameraInfo info;
  info.width = 160;
  info.height = 120;
  info.fx = std::nan("");
  info.fy = 120;
  EXPECT_EQ(ThrownMessage<light::LightError>([&] { light::IntrinsicsFrom(info, 160, 120); }),
            "light::IntrinsicsFrom: camera info has non-finite intrinsics");
  info.fx = 120;
  EXPECT_EQ(ThrownMessage<light::LightError>([&] { light::IntrinsicsFrom(info, 320, 240); }),
            "light::IntrinsicsFrom: camera info is 160x120, buffer is 320x240");
  msgs::GeometryBuffer g;
  g.Init(160, 120);
  std::vector<std::byte> payload(msgs::GeometryBuffer::StandardPayloadBytes(160, 120));
  auto depth = msgs::DepthPlane(g, std::span<std::byte>(payload));
  std::fill(depth.begin(), depth.end(), 2.0f);
  EXPECT_EQ(
      ThrownMessage<light::LightError>([&] { light::ViewOfGeometryBuffer(g, payload, info); }),
      "light::ViewOfGeometryBuffer: missing normals (all zero)");
}

}  // namespace
