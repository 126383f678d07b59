// The evaluation-world generator: split seeds, determinism (same seed, same bytes), variety of
// the drawn scenes, the folder contract and the consistency of the insertion masks with depth.
#include "probeless/sim/generate.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <set>
#include <sstream>

#include "probeless/raytrace/pathtrace.h"

namespace probeless::sim {
namespace {

namespace fs = std::filesystem;

GenerateOptions Tiny() {
  GenerateOptions o;
  o.frames = 2;
  o.width = 80;
  o.height = 60;
  o.samples_per_pixel = 2;
  o.bounces = 1;
  o.probe_directions = 128;
  o.ratio_samples = 1;
  return o;
}

std::string ReadFile(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// Every file under `dir`, relative path -> bytes.
std::map<std::string, std::string> Tree(const fs::path& dir) {
  std::map<std::string, std::string> out;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (e.is_regular_file()) out[fs::relative(e.path(), dir).string()] = ReadFile(e.path());
  }
  return out;
}

fs::path TempDir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("probeless_generate_test_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

TEST(Generate, SplitsAreDisjointSeedRanges) {
  EXPECT_EQ(SplitSeedBase(Split::kTrain), 0u);
  EXPECT_EQ(SplitSeedBase(Split::kValidation), kSplitSeedStride);
  EXPECT_EQ(SplitSeedBase(Split::kTest), 2 * kSplitSeedStride);
  EXPECT_EQ(ParseSplit("validation"), Split::kValidation);
  try {
    ParseSplit("dev");
    FAIL() << "no error";
  } catch (const ScenarioError& e) {
    EXPECT_STREQ(e.what(), "--split: expected train, validation or test, got 'dev'");
  }
  const GeneratedScene s = GenerateScene(2 * kSplitSeedStride + 7, Split::kTest, Tiny());
  EXPECT_EQ(s.name, "test_2000007");
}

TEST(Generate, OptionsAreValidated) {
  GenerateOptions o = Tiny();
  o.samples_per_pixel = 0;
  try {
    o.Validate();
    FAIL() << "no error";
  } catch (const ScenarioError& e) {
    EXPECT_STREQ(e.what(), "--spp: expected 1..65536, got 0");
  }
}

TEST(Generate, ScenesAreDeterministicAndVaried) {
  std::set<std::string> light_types, rooms;
  int two_insertions = 0, on_floor = 0;
  for (uint64_t seed = 0; seed < 60; ++seed) {
    const GeneratedScene a = GenerateScene(seed, Split::kTrain, Tiny());
    const GeneratedScene b = GenerateScene(seed, Split::kTrain, Tiny());
    ASSERT_EQ(a.objects.size(), b.objects.size());
    ASSERT_EQ(a.insertions.size(), b.insertions.size());
    EXPECT_EQ(a.insertions[0].position.x, b.insertions[0].position.x);
    EXPECT_EQ(a.camera_path.back().translation, b.camera_path.back().translation);
    light_types.insert(a.light_type);
    rooms.insert(a.room);
    two_insertions += a.insertions.size() == 2;
    on_floor += a.support_point.y == 0;
    // Every insertion rests on the support surface.
    for (const InsertionObject& o : a.insertions) {
      const float bottom =
          o.shape == "sphere" ? o.position.y - o.radius : o.position.y - o.size.y / 2;
      EXPECT_NEAR(bottom, a.support_point.y, 1e-5) << a.name;
    }
    // The lights and the camera are inside the room, the camera 1-3 m from the insertions.
    for (const raytrace::PointLight& l : a.point_lights) {
      EXPECT_GT(l.position.y, 0) << a.name;
      EXPECT_LT(l.position.y, a.room_size.y) << a.name;
    }
    const raytrace::Vec3 eye{static_cast<float>(a.camera_path[0].translation[0]),
                             static_cast<float>(a.camera_path[0].translation[1]),
                             static_cast<float>(a.camera_path[0].translation[2])};
    const float distance = raytrace::Length(eye - a.insertions[0].position);
    EXPECT_GT(distance, 0.6f) << a.name;
    EXPECT_LT(distance, 3.2f) << a.name;
    // Nothing stands between the first camera and an insertion resting on the table.
    if (a.support_point.y > 0) {
      raytrace::Scene scene;
      BuildScene(a, false, &scene);
      std::vector<raytrace::Ray> rays;
      for (const InsertionObject& o : a.insertions) rays.push_back({eye, o.position - eye, 0, 1});
      std::vector<raytrace::Hit> hits(rays.size());
      scene.Intersect(rays, hits);
      for (const raytrace::Hit& h : hits) EXPECT_EQ(h.object, -1) << a.name;
    }
  }
  EXPECT_EQ(light_types, (std::set<std::string>{"area", "directional", "mixed", "point"}));
  EXPECT_EQ(rooms, (std::set<std::string>{"courtyard", "room"}));
  EXPECT_GT(two_insertions, 5);
  EXPECT_GT(on_floor, 3);
}

TEST(Generate, FolderIsByteIdenticalAndMasksMatchDepth) {
  const GenerateOptions options = Tiny();
  // A seed whose insertion is seen (checked below) and that has a dominant light.
  const GeneratedScene scene = GenerateScene(3, Split::kTrain, options);
  const fs::path a = TempDir("a");
  const fs::path b = TempDir("b");
  const GeneratedSceneSummary sa = WriteGeneratedScene(scene, options, a.string());
  WriteGeneratedScene(scene, options, b.string());
  const auto tree_a = Tree(a);
  const auto tree_b = Tree(b);
  EXPECT_EQ(tree_a, tree_b);
  const std::string root = scene.name + "/";
  for (const char* f : {"rgb.txt", "depth.txt", "groundtruth.txt", "camera_info.yaml",
                        "insertion.yaml", "truth.json", "scene.json"}) {
    EXPECT_TRUE(tree_a.count(root + f)) << f;
  }
  EXPECT_EQ(sa.frames, 2);
  EXPECT_GT(sa.exposure, 0);
  const std::string truth = tree_a.at(root + "truth.json");
  EXPECT_NE(truth.find("\"light_type\": \"" + scene.light_type + "\""), std::string::npos);
  EXPECT_NE(truth.find("\"timestamp\": \"1.000000\""), std::string::npos);
  EXPECT_NE(truth.find("\"timestamp\": \"1.033333\""), std::string::npos);
  EXPECT_NE(truth.find("\"sh_camera\": [["), std::string::npos);
  EXPECT_NE(tree_a.at(root + "rgb.txt").find("1.033333 rgb/1.033333.png"), std::string::npos);

  // mask_object is exactly where the inserted render's first surface is an insertion, i.e. where
  // the depth of the scene with the objects is nearer than without them.
  raytrace::Scene plain, inserted;
  BuildScene(scene, false, &plain);
  BuildScene(scene, true, &inserted);
  raytrace::PathTraceOptions pt;
  pt.samples_per_pixel = 1;
  pt.max_bounces = 0;
  int object_pixels = 0;
  for (int i = 0; i < options.frames; ++i) {
    raytrace::Camera camera = scene.camera;
    camera.camera_to_world = scene.camera_path[i];
    const raytrace::Frame fa = raytrace::PathTrace(plain, camera, pt);
    const raytrace::Frame fb = raytrace::PathTrace(inserted, camera, pt);
    const std::string stamp = i == 0 ? "1.000000" : "1.033333";
    const cv::Mat mask = cv::imread((a / scene.name / "mask_object" / (stamp + ".png")).string(),
                                    cv::IMREAD_UNCHANGED);
    const cv::Mat effect = cv::imread((a / scene.name / "mask_effect" / (stamp + ".png")).string(),
                                      cv::IMREAD_UNCHANGED);
    ASSERT_EQ(mask.type(), CV_8UC1);
    ASSERT_EQ(mask.cols, options.width);
    for (int p = 0; p < options.width * options.height; ++p) {
      const bool nearer =
          fb.depth_m[p] > 0 && (fa.depth_m[p] <= 0 || fb.depth_m[p] < fa.depth_m[p] - 1e-4f);
      ASSERT_EQ(mask.data[p] == 255, nearer) << "frame " << i << " pixel " << p;
      ASSERT_TRUE(mask.data[p] == 0 || mask.data[p] == 255);
      ASSERT_FALSE(mask.data[p] && effect.data[p]) << "object and effect overlap at " << p;
      object_pixels += mask.data[p] == 255;
    }
  }
  EXPECT_GT(object_pixels, 20);
  fs::remove_all(a);
  fs::remove_all(b);
}

}  // namespace
}  // namespace probeless::sim
