// probeless_eval: insertion.yaml / truth.json / rgb.txt readers and their one-line errors, and the
// metrics against hand-computed values.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <string>

#include "probeless/eval/metrics.h"
#include "probeless/eval/scene_folder.h"
#include "probeless/testing/expect.h"
#include "probeless/testing/testing.h"

namespace probeless::eval {
namespace {

std::string Write(const testing::TempDir& dir, const std::string& name, const std::string& text) {
  const std::string path = dir.path() + "/" + name;
  std::ofstream(path) << text;
  return path;
}

TEST(InsertionTest, ReadsSpheresAndBoxes) {
  testing::TempDir dir("eval");
  const std::string path = Write(dir, "insertion.yaml",
                                 "objects:\n"
                                 "  - shape: sphere\n"
                                 "    radius: 0.09\n"
                                 "    albedo: [0.7, 0.6, 0.5]\n"
                                 "    position: [0.1, 0.8, 0.9]\n"
                                 "    note: ignored\n"
                                 "  - {shape: box, size: [0.2, 0.12, 0.15], position: [0, 0, 1],\n"
                                 "     rotation: [0, 0, 2, 2]}\n");
  const std::vector<InsertedObject> objects = LoadInsertion(path, "s/insertion.yaml");
  ASSERT_EQ(objects.size(), 2u);
  EXPECT_EQ(objects[0].shape, Shape::kSphere);
  EXPECT_EQ(objects[0].radius, 0.09);
  EXPECT_EQ(objects[0].albedo[2], 0.5);
  EXPECT_EQ(objects[0].position[1], 0.8);
  EXPECT_EQ(objects[1].shape, Shape::kBox);
  EXPECT_EQ(objects[1].size[1], 0.12);
  EXPECT_EQ(objects[1].albedo[0], 0.75);  // default
  EXPECT_NEAR(objects[1].rotation[2], std::sqrt(0.5), 1e-12);
  EXPECT_NEAR(objects[1].BoundingRadius(), 0.5 * std::sqrt(0.04 + 0.0144 + 0.0225), 1e-12);
}

TEST(InsertionTest, ErrorsNameFileLineAndField) {
  testing::TempDir dir("eval");
  auto error = [&](const std::string& text) {
    const std::string path = Write(dir, "insertion.yaml", text);
    return probeless::testing::ThrownMessage<EvalError>(
        [&] { LoadInsertion(path, "scene/insertion.yaml"); });
  };
  EXPECT_EQ(error("objects:\n  - shape: sphere\n    position: [0, 0, 1]\n    radius: abc\n"),
            "scene/insertion.yaml:4: objects[0].radius: expected a positive number, got 'abc'");
  EXPECT_EQ(error("objects:\n  - shape: cone\n    position: [0, 0, 1]\n"),
            "scene/insertion.yaml:2: objects[0].shape: expected sphere or box, got 'cone'");
  EXPECT_EQ(error("objects:\n  - shape: sphere\n    radius: 0.1\n"),
            "scene/insertion.yaml:2: objects[0].position: missing");
  EXPECT_EQ(error("objects:\n  - shape: box\n    size: [1, 2]\n    position: [0, 0, 1]\n"),
            "scene/insertion.yaml:3: objects[0].size: expected 3 positive numbers [x, y, z] m, "
            "got 2 values");
  EXPECT_EQ(error("objects: []\n"),
            "scene/insertion.yaml:1: objects: expected a non-empty list of objects, got 'a list'");
  EXPECT_EQ(error("objects:\n  - shape: sphere\n    radius: 0.1\n    position: [0, 0, 1]\n"
                  "    albedo: [0.5, 2, 0.5]\n"),
            "scene/insertion.yaml:5: objects[0].albedo: expected 3 numbers [r, g, b] in [0, 1], "
            "got '2' at index 1");
  PROBELESS_EXPECT_THROWS_MESSAGE(LoadInsertion(dir.path() + "/none.yaml", "x/insertion.yaml"),
                                  EvalError, "x/insertion.yaml: cannot open");
}

TEST(TruthTest, ReadsFramesAndFindsThemByStamp) {
  testing::TempDir dir("eval");
  std::string sh = "[";
  for (int k = 0; k < 9; ++k)
    sh += std::string(k ? ", " : "") + "[" + std::to_string(k) + ", 0, 1]";
  sh += "]";
  const std::string path =
      Write(dir, "truth.json",
            "{\"light_type\": \"directional\", \"extra\": 1,\n \"frames\": [\n"
            "  {\"timestamp\": \"1305031102.175304\", \"direction_camera\": [0, -1, 0],\n"
            "   \"direct_to_ambient\": 2.5, \"sh_camera\": " +
                sh +
                "},\n"
                "  {\"timestamp\": \"1305031102.2\", \"direction_camera\": null,\n"
                "   \"direct_to_ambient\": 0}]}\n");
  const Truth truth = LoadTruth(path, "s/truth.json");
  EXPECT_EQ(truth.light_type, "directional");
  ASSERT_EQ(truth.frames.size(), 2u);
  EXPECT_EQ((*truth.frames[0].direction_camera)[1], -1);
  EXPECT_EQ(truth.frames[0].direct_to_ambient, 2.5);
  EXPECT_EQ((*truth.frames[0].sh_camera)[8][0], 8);
  EXPECT_FALSE(truth.frames[1].direction_camera);
  EXPECT_FALSE(truth.frames[1].sh_camera);
  EXPECT_EQ(truth.Find(1'305'031'102'200'000'000), &truth.frames[1]);
  EXPECT_EQ(truth.Find(1'305'031'102'175'304'000), &truth.frames[0]);
  EXPECT_EQ(truth.Find(1), nullptr);

  const std::string bad = Write(dir, "bad.json",
                                "{\"frames\": [\n {\"timestamp\": \"1.0\",\n"
                                "  \"sh_camera\": [[1, 2, 3]]}]}\n");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      LoadTruth(bad, "s/truth.json"), EvalError,
      "s/truth.json:3: frames[0].sh_camera: expected 9 [r, g, b] coefficients, got 1");
}

TEST(RgbListTest, SortsAndConvertsStampsExactly) {
  testing::TempDir dir("eval");
  const std::string path = Write(dir, "rgb.txt",
                                 "# color images\n1305031102.211214 rgb/b.png\n"
                                 "1305031102.175304 rgb/a.png\n");
  const std::vector<RgbEntry> e = LoadRgbList(path, "s/rgb.txt");
  ASSERT_EQ(e.size(), 2u);
  EXPECT_EQ(e[0].file, "rgb/a.png");
  EXPECT_EQ(e[0].stamp_ns, 1'305'031'102'175'304'000);
  EXPECT_EQ(e[1].timestamp, "1305031102.211214");
  EXPECT_EQ(ParseStampNs("12"), 12'000'000'000);
  EXPECT_FALSE(ParseStampNs("1.2.3"));
  // Seconds whose nanosecond count does not fit in int64 are malformed, not an overflow.
  EXPECT_EQ(ParseStampNs("9223372035.999999999"), 9'223'372'035'999'999'999);
  EXPECT_FALSE(ParseStampNs("13000000000"));
  EXPECT_FALSE(ParseStampNs("99999999999999999999999"));
  Write(dir, "rgb.txt", "1.0 rgb/a.png extra\n");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      LoadRgbList(path, "s/rgb.txt"), EvalError,
      "s/rgb.txt:1: expected 'timestamp filename', got '1.0 rgb/a.png extra'");
}

LinearImage Constant(int w, int h, float v) {
  LinearImage image;
  image.width = w;
  image.height = h;
  image.rgb.assign(static_cast<size_t>(w) * h * 3, v);
  return image;
}

TEST(MetricsTest, ObjectRmseScaleInvariantRmseAndEffectRatio) {
  EXPECT_EQ(SrgbToLinear(0), 0);
  EXPECT_EQ(SrgbToLinear(255), 1);
  EXPECT_NEAR(SrgbToLinear(188), 0.5, 0.003);

  const LinearImage truth = Constant(4, 1, 0.4f);
  LinearImage estimate = Constant(4, 1, 0.2f);
  const std::vector<uint8_t> mask = {255, 255, 0, 0};
  const MaskedSums s = ObjectSums(estimate, truth, mask);
  EXPECT_EQ(s.count, 6u);
  EXPECT_NEAR(std::sqrt(s.sum_sq / s.count), 0.2, 1e-6);
  EXPECT_NEAR(s.scale, 2.0, 1e-6);  // twice too dark: the right shading, scaled
  EXPECT_NEAR(s.si_sum_sq, 0, 1e-10);
  PooledRmse pooled;
  pooled.Add(s);
  EXPECT_NEAR(*pooled.Rmse(), 0.2, 1e-6);
  EXPECT_NEAR(*pooled.SiRmse(), 0, 1e-6);
  EXPECT_FALSE(PooledRmse().Rmse());

  // Effect: truth darkens by half, the estimate does nothing: ratio error 0.5.
  const LinearImage original = Constant(4, 1, 0.4f);
  const LinearImage shadowed = Constant(4, 1, 0.2f);
  const MaskedSums e = EffectSums(original, original, shadowed, mask);
  EXPECT_EQ(e.count, 6u);
  EXPECT_NEAR(std::sqrt(e.sum_sq / e.count), 0.5, 1e-6);

  EXPECT_NEAR(MeanSquaredError(truth, estimate), 0.04, 1e-7);
  EXPECT_NEAR(PsnrDb(0.01), 20, 1e-9);
  EXPECT_EQ(PsnrDb(0), 100);
}

TEST(MetricsTest, MedianPercentileAngle) {
  EXPECT_EQ(*Median({3, 1, 2}), 2);
  EXPECT_EQ(*Median({4, 1, 2, 3}), 2.5);
  EXPECT_NEAR(*Percentile({1, 2, 3, 4, 5, 6, 7, 8, 9, 10}, 0.9), 9.1, 1e-12);
  EXPECT_FALSE(Median({}));
  const float a[3] = {1, 0, 0};
  const double b[3] = {0, 2, 0};
  EXPECT_NEAR(*AngleDeg(a, b), 90, 1e-9);
  const double zero[3] = {0, 0, 0};
  EXPECT_FALSE(AngleDeg(a, zero));
}

}  // namespace
}  // namespace probeless::eval
