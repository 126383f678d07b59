// Mesh loaders (OBJ, PLY), their error messages, primitives and the procedural head.
#include "probeless/raytrace/mesh.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "probeless/testing/expect.h"

namespace probeless::raytrace {
namespace {

namespace fs = std::filesystem;

class MeshFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("raytrace_mesh_test_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Write(const std::string& name, const std::string& text) {
    const std::string path = (dir_ / name).string();
    std::ofstream(path, std::ios::binary) << text;
    return path;
  }
  fs::path dir_;
};

TEST_F(MeshFiles, ObjQuadWithUvsAndNormals) {
  const std::string path = Write("quad.obj",
                                 "# a quad\n"
                                 "o quad\n"
                                 "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
                                 "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                                 "vn 0 0 1\n"
                                 "f 1/1/1 2/2/1 3/3/1 4/4/1\n");
  const Mesh m = LoadObj(path);
  EXPECT_EQ(m.positions.size(), 4u);
  EXPECT_EQ(m.triangles.size(), 2u);
  EXPECT_EQ(m.uvs.size(), 4u);
  EXPECT_TRUE(m.colors.empty());
  EXPECT_FLOAT_EQ(m.normals[0].z, 1);
  const Mesh neg = LoadObj(Write("neg.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0 1 0 0\nf -3 -2 -1\n"));
  EXPECT_EQ(neg.triangles.size(), 1u);
  ASSERT_EQ(neg.colors.size(), 3u);
  EXPECT_FLOAT_EQ(neg.colors[2].y, 0);
  EXPECT_NEAR(neg.normals[0].z, 1, 1e-6f);  // computed
}

TEST_F(MeshFiles, ObjErrorsNameFileAndLine) {
  const std::string bad_number = Write("a.obj", "v 0 0 0\nv 1 x 0\n");
  PROBELESS_EXPECT_THROWS_MESSAGE(LoadObj(bad_number), RaytraceError,
                                  bad_number + ":2: expected a number, got 'x'");
  const std::string bad_index = Write("b.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n");
  PROBELESS_EXPECT_THROWS_MESSAGE(LoadObj(bad_index), RaytraceError,
                                  bad_index + ":4: vertex index 4 out of range (3 defined so far)");
  // A relative index one before the first vertex (mesh_fuzz: it was taken as "no index" and
  // read v[-1]).
  const std::string before_first = Write("r.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -4 -2 -1\n");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      LoadObj(before_first), RaytraceError,
      before_first + ":4: vertex index -4 out of range (3 defined so far)");
  const std::string uv_before_first =
      Write("s.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/-2 2/1 3/1\n");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      LoadObj(uv_before_first), RaytraceError,
      uv_before_first + ":5: texture coordinate index -2 out of range (1 defined so far)");
  const std::string short_face = Write("c.obj", "v 0 0 0\nv 1 0 0\nf 1 2\n");
  PROBELESS_EXPECT_THROWS_MESSAGE(LoadObj(short_face), RaytraceError,
                                  short_face + ":3: face 'f' expects at least 3 vertices, got 2");
  const std::string unknown = Write("d.obj", "v 0 0 0\nbogus 1\n");
  PROBELESS_EXPECT_THROWS_MESSAGE(LoadObj(unknown), RaytraceError,
                                  unknown + ":2: unknown OBJ statement 'bogus'");
  const std::string empty = Write("e.obj", "v 0 0 0\n");
  PROBELESS_EXPECT_THROWS_MESSAGE(LoadObj(empty), RaytraceError, empty + ": OBJ file has no faces");
  PROBELESS_EXPECT_THROWS_MESSAGE(LoadObj((dir_ / "missing.obj").string()), RaytraceError,
                                  (dir_ / "missing.obj").string() + ": cannot open OBJ file");
  PROBELESS_EXPECT_THROWS_MESSAGE(LoadMesh("x.stl"), RaytraceError,
                                  "x.stl: unknown mesh format (expected a .obj or .ply file)");
}

TEST_F(MeshFiles, PlyAsciiAndBinary) {
  const std::string ascii = Write("t.ply",
                                  "ply\nformat ascii 1.0\ncomment hi\n"
                                  "element vertex 4\nproperty float x\nproperty float y\n"
                                  "property float z\nproperty uchar red\nproperty uchar green\n"
                                  "property uchar blue\n"
                                  "element face 1\nproperty list uchar int vertex_indices\n"
                                  "end_header\n"
                                  "0 0 0 255 0 0\n1 0 0 255 255 255\n1 1 0 0 0 0\n0 1 0 10 10 10\n"
                                  "4 0 1 2 3\n");
  const Mesh a = LoadPly(ascii);
  EXPECT_EQ(a.positions.size(), 4u);
  EXPECT_EQ(a.triangles.size(), 2u);
  ASSERT_EQ(a.colors.size(), 4u);
  EXPECT_FLOAT_EQ(a.colors[0].x, 1);
  EXPECT_FLOAT_EQ(a.colors[0].y, 0);

  std::string binary =
      "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
      "property float y\nproperty float z\nelement face 1\n"
      "property list uchar uint vertex_indices\nend_header\n";
  const float v[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  binary.append(reinterpret_cast<const char*>(v), sizeof(v));
  binary.push_back(3);
  const uint32_t idx[3] = {0, 1, 2};
  binary.append(reinterpret_cast<const char*>(idx), sizeof(idx));
  const Mesh b = LoadPly(Write("b.ply", binary));
  EXPECT_EQ(b.triangles.size(), 1u);
  EXPECT_FLOAT_EQ(b.positions[1].x, 1);
}

TEST_F(MeshFiles, PlyErrors) {
  const std::string not_ply = Write("a.ply", "hello\n");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      LoadPly(not_ply), RaytraceError,
      not_ply + ":1: not a PLY file (expected 'ply' on the first line)");
  const std::string bad_format = Write("b.ply", "ply\nformat weird 1.0\nend_header\n");
  PROBELESS_EXPECT_THROWS_MESSAGE(LoadPly(bad_format), RaytraceError,
                                  bad_format + ":2: unknown PLY format 'weird'");
  const std::string bad_index = Write("c.ply",
                                      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                                      "property float y\nproperty float z\nelement face 1\n"
                                      "property list uchar int vertex_indices\nend_header\n"
                                      "0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n");
  PROBELESS_EXPECT_THROWS_MESSAGE(LoadPly(bad_index), RaytraceError,
                                  bad_index + ": element face: face 0 uses vertex 5 of 3");
  // Face indices must be integers (a float or a NaN was cast), counts must fit the file.
  const std::string float_index =
      Write("f.ply",
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
            "property float y\nproperty float z\nelement face 1\n"
            "property list uchar float vertex_indices\nend_header\n"
            "0 0 0\n1 0 0\n0 1 0\n3 0 1 1.5\n");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      LoadPly(float_index), RaytraceError,
      float_index +
          ": element face: face 0 vertex index must be a non-negative integer, got "
          "1.5");
  const std::string negative_count =
      Write("g.ply",
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
            "property float y\nproperty float z\nelement face 1\n"
            "property list int int vertex_indices\nend_header\n"
            "0 0 0\n1 0 0\n0 1 0\n-3 0 1 2\n");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      LoadPly(negative_count), RaytraceError,
      negative_count +
          ": element face: face 0 vertex count must be a non-negative integer, "
          "got -3");
  const std::string huge =
      Write("h.ply",
            "ply\nformat binary_little_endian 1.0\nelement vertex 1099511627776\n"
            "property float x\nproperty float y\nproperty float z\nend_header\n"
            "0123456789ab");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      LoadPly(huge), RaytraceError,
      huge +
          ": element vertex has 1099511627776 entries of at least 12 bytes, but the file "
          "has 12 bytes after the header (truncated or a wrong count)");
  const std::string empty_element = Write("i.ply",
                                          "ply\nformat binary_little_endian 1.0\nelement junk "
                                          "4611686018427387904\nend_header\n");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      LoadPly(empty_element), RaytraceError,
      empty_element + ": element junk has 4611686018427387904 entries but no properties");
  const std::string nan_vertex = Write("j.ply",
                                       "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"
                                       "property float y\nproperty float z\nend_header\nnan 0 0\n");
  PROBELESS_EXPECT_THROWS_MESSAGE(LoadPly(nan_vertex), RaytraceError,
                                  nan_vertex + ": element vertex: expected a number, got 'nan'");
  const std::string truncated = Write("d.ply",
                                      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                                      "property float y\nproperty float z\nend_header\n0 0 0\n1 0");
  PROBELESS_EXPECT_THROWS_MESSAGE(LoadPly(truncated), RaytraceError,
                                  truncated + ": element vertex: unexpected end of file");
  const std::string no_z = Write("e.ply",
                                 "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"
                                 "property float y\nend_header\n0 0\n");
  PROBELESS_EXPECT_THROWS_MESSAGE(LoadPly(no_z), RaytraceError,
                                  no_z + ": element vertex has no property 'z'");
}

TEST(Primitives, ClosedAndOutwardFacing) {
  for (const Mesh& m : {MakeBox({1, 2, 3}), MakeSphere(1, 32), MakeCylinder(0.5f, 2, 24)}) {
    m.Validate("primitive");
    double volume = 0;
    for (const auto& t : m.triangles) {
      volume += Dot(m.positions[t[0]], Cross(m.positions[t[1]], m.positions[t[2]])) / 6;
    }
    EXPECT_GT(volume, 0);
  }
  const Mesh box = MakeBox({1, 2, 3});
  double volume = 0;
  for (const auto& t : box.triangles) {
    volume += Dot(box.positions[t[0]], Cross(box.positions[t[1]], box.positions[t[2]])) / 6;
  }
  EXPECT_NEAR(volume, 6, 1e-5);
}

TEST(Primitives, HeadHasFaceFeaturesAndLandmarks) {
  const HeadModel head = MakeHead();
  head.mesh.Validate("head");
  ASSERT_EQ(head.landmarks.size(), 68u);
  const Vec3 bridge = head.landmarks[27];
  const Vec3 tip = head.landmarks[30];
  EXPECT_NEAR(bridge.x, 0, 1e-6f);
  EXPECT_LT(tip.z, bridge.z - 0.01f);                     // the nose sticks out (face looks to -z)
  EXPECT_NEAR(bridge.z, 0, 0.02f);                        // origin near the nose bridge
  EXPECT_LT(head.landmarks[36].x, head.landmarks[45].x);  // subject's right eye at -x
  EXPECT_GT(head.landmarks[8].y, head.landmarks[57].y);   // chin below the lower lip
  const auto bounds = head.mesh.Bounds();
  EXPECT_NEAR(bounds[1].x - bounds[0].x, 0.42f, 0.05f);  // shoulders
}

}  // namespace
}  // namespace probeless::raytrace
