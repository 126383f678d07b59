// Tests of the PRT bake (label render): the fast basis matches common/sh, the bake of an unoccluded
// sphere equals the analytic clamped-cosine projection A_l Y(n) / pi, a vertex under the proxy head
// receives less light from above, determinism, SH rotation, the file format and its errors.
#include "probeless/prt/prt.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <numbers>

#include "../src/sh_fast.h"
#include "probeless/prt/demo_objects.h"
#include "probeless/sh/sh.h"

namespace probeless::prt {
namespace {

using raytrace::Vec3;

std::string TempPath(const std::string& name) {
  return (std::filesystem::temp_directory_path() / ("prt_test_" + name)).string();
}

TEST(PrtTest, FastBasisMatchesShConvention) {
  for (const sh::Vec3& d : sh::FibonacciSphere(50)) {
    float fast[16], ref[16];
    internal::FastBasis(4, static_cast<float>(d[0]), static_cast<float>(d[1]),
                        static_cast<float>(d[2]), fast);
    sh::EvaluateBasis<float>(4, static_cast<float>(d[0]), static_cast<float>(d[1]),
                             static_cast<float>(d[2]), ref);
    for (int k = 0; k < 16; ++k) EXPECT_NEAR(fast[k], ref[k], 1e-5f) << "k " << k;
  }
}

TEST(PrtTest, SphereBakeEqualsAnalyticClampedCosine) {
  const raytrace::Mesh sphere = raytrace::MakeSphere(1.0f, 24);
  BakeOptions options;
  options.bands = 4;
  options.samples = 4096;
  BakeStats stats;
  const TransferMesh baked = Bake(sphere, {}, options, &stats);
  EXPECT_EQ(stats.shadow_rays, sphere.positions.size() * 4096u);
  double max_error = 0;
  for (size_t v = 0; v < sphere.positions.size(); ++v) {
    const std::vector<float> expected = UnshadowedTransfer(baked.mesh.normals[v], 4);
    const auto got = baked.VertexTransfer(v);
    for (int k = 0; k < 16; ++k)
      max_error = std::max(max_error, double(std::abs(got[k] - expected[k])));
  }
  // T_0 = 0.282; stratified 64x64 samples leave < 1 % of it; the faceted sphere's grazing rays
  // (re-entering neighbouring faces) cost a little more near the horizon.
  EXPECT_LT(max_error, 0.01);
  // Band 3 (odd, > 1) of the clamped cosine vanishes.
  EXPECT_NEAR(baked.VertexTransfer(5)[12], 0.0f, 0.01f);
}

TEST(PrtTest, VertexUnderProxyHeadReceivesLessLightFromAbove) {
  // Two small patches: one under the chin (below the head, y larger = down) and one far away.
  raytrace::Mesh patch = raytrace::MakeSphere(0.005f, 12);
  const auto bounds = ProxyHead().Bounds();
  raytrace::Mesh under = patch, free = patch;
  // Under the head: below the jaw (chin landmark 8 at y = 0.123), in front of the neck.
  under.TransformBy({raytrace::Mat3::Identity(), {0, 0.15, 0.02}});
  free.TransformBy({raytrace::Mat3::Identity(), {0.6, 0.15, 0.02}});
  const Occluder head{ProxyHead(), {}};
  BakeOptions options;
  options.samples = 1024;
  const TransferMesh a = Bake(under, {&head, 1}, options);
  const TransferMesh b = Bake(free, {&head, 1}, options);
  // Light from above = from -y (the face frame's y points to the chin).
  const std::vector<double> light = sh::DirectionalLight({0, -1, 0}, 1.0, 3);
  auto irradiance = [&](const TransferMesh& m) {
    double sum = 0;
    for (size_t v = 0; v < m.mesh.positions.size(); ++v) {
      for (int k = 0; k < 9; ++k) sum += m.VertexTransfer(v)[k] * light[k];
    }
    return sum / m.mesh.positions.size();
  };
  EXPECT_LT(irradiance(a), 0.5 * irradiance(b))
      << "head bounds y " << bounds[0].y << ".." << bounds[1].y;
  // The patch is outside the head: light from the front (-z) still reaches it.
  const std::vector<double> front = sh::DirectionalLight({0, 0, -1}, 1.0, 3);
  double lit = 0;
  for (size_t v = 0; v < a.mesh.positions.size(); ++v) {
    for (int k = 0; k < 9; ++k) lit += a.VertexTransfer(v)[k] * front[k];
  }
  EXPECT_GT(lit / a.mesh.positions.size(), 0.5 * irradiance(b));
}

TEST(PrtTest, BakeIsDeterministicAcrossThreadCounts) {
  const raytrace::Mesh mesh = MakeClownNose(16);
  const Occluder head{ProxyHead(32), {}};
  BakeOptions options;
  options.samples = 64;
  options.threads = 1;
  const TransferMesh a = Bake(mesh, {&head, 1}, options);
  options.threads = 2;
  const TransferMesh b = Bake(mesh, {&head, 1}, options);
  EXPECT_EQ(a.transfer, b.transfer);
}

TEST(PrtTest, InterreflectionAddsLightInConcavities) {
  const raytrace::Mesh mesh = MakeCap(24);
  BakeOptions options;
  options.samples = 64;
  const TransferMesh direct = Bake(mesh, {}, options);
  options.interreflection = true;
  BakeStats stats;
  const TransferMesh bounced = Bake(mesh, {}, options, &stats);
  EXPECT_GT(stats.bounce_rays, 0u);
  double d = 0, b = 0;
  for (size_t i = 0; i < direct.transfer.size(); i += 9)
    d += direct.transfer[i], b += bounced.transfer[i];
  EXPECT_GT(b, d);
}

TEST(PrtTest, ShRotationMatchesRotatedEvaluation) {
  const raytrace::Mat3 r = raytrace::Mat3::FromEulerZyx(0.3, -0.7, 1.1);
  const int bands = 3;
  const std::vector<double> m = ShRotationMatrix(r, bands);
  const std::vector<double> la = sh::DirectionalLight({0.3, -0.8, 0.52}, 2.0, bands);
  std::vector<double> lb(9, 0.0);
  for (int n = 0; n < 9; ++n)
    for (int k = 0; k < 9; ++k) lb[n] += m[n * 9 + k] * la[k];
  for (const sh::Vec3& d : sh::FibonacciSphere(20)) {
    const Vec3 rd = r * Vec3{float(d[0]), float(d[1]), float(d[2])};
    EXPECT_NEAR(sh::Evaluate(lb, d), sh::Evaluate(la, {rd.x, rd.y, rd.z}), 1e-5);
  }
  EXPECT_THROW(ShRotationMatrix(r, 6), PrtError);
}

TEST(PrtTest, FileRoundTripAndErrors) {
  BakeOptions options;
  options.samples = 16;
  const TransferMesh baked = Bake(MakeClownNose(12), {}, options);
  const std::string path = TempPath("nose.prt");
  SavePrt(baked, path);
  const TransferMesh loaded = LoadPrt(path);
  EXPECT_EQ(loaded.bands, 3);
  EXPECT_EQ(loaded.transfer, baked.transfer);
  EXPECT_EQ(loaded.mesh.colors.size(), baked.mesh.colors.size());

  try {
    LoadPrt(TempPath("missing.prt"));
    FAIL();
  } catch (const PrtError& e) {
    EXPECT_EQ(std::string(e.what()), TempPath("missing.prt") + ": cannot open");
  }
  const std::string bad = TempPath("bad.prt");
  std::ofstream(bad) << "ply\nformat ascii 1.0\n";
  try {
    LoadPrt(bad);
    FAIL();
  } catch (const PrtError& e) {
    EXPECT_EQ(std::string(e.what()), bad + ": not a PRT file (expected magic PBLPRT01)");
  }
  // Truncated: cut the file in the middle of the triangles.
  const auto size = std::filesystem::file_size(path);
  std::filesystem::resize_file(path, size - baked.transfer.size() * 4 - 10);
  try {
    LoadPrt(path);
    FAIL();
  } catch (const PrtError& e) {
    EXPECT_EQ(std::string(e.what()), path + ": truncated triangles");
  }
  // A header asking for 2^28 vertices in a file of 44 bytes: refused from the file size, before
  // any allocation.
  {
    std::string header(44, '\0');
    std::memcpy(header.data(), "PBLPRT01", 8);
    const uint32_t fields[4] = {3, 1u << 28, 1u << 28, 0};
    std::memcpy(header.data() + 8, fields, sizeof(fields));
    const std::string huge = TempPath("huge.prt");
    std::ofstream(huge, std::ios::binary) << header;
    try {
      LoadPrt(huge);
      FAIL();
    } catch (const PrtError& e) {
      EXPECT_EQ(std::string(e.what()), huge + ": truncated positions");
    }
    // The baked file one byte longer than its header says: trailing bytes.
    std::filesystem::resize_file(path, size + 1);
    try {
      LoadPrt(path);
      FAIL();
    } catch (const PrtError& e) {
      EXPECT_EQ(std::string(e.what()), path + ": trailing bytes");
    }
  }
  EXPECT_THROW(Bake(raytrace::Mesh{}, {}, options), PrtError);
  options.bands = 6;
  EXPECT_THROW(Bake(MakeClownNose(12), {}, options), PrtError);
  EXPECT_THROW(MakeDemoObject("hat"), PrtError);
}

}  // namespace
}  // namespace probeless::prt
