// composite_eval end to end (docs/evaluation.md, "composite_eval"): tiny scene folders written here
// with the simulator library (a table under a sun, rendered once without and once with a grey
// sphere on it: rgb/ and rgb_inserted/, the masks from the object ids and the image difference,
// truth.json from the simulator's light at the camera), then the tool on them:
// - the oracle light ranks ahead of the baseline (scale-invariant RMSE on the object);
// - a negative control: insertion.yaml's sphere moved by 10 cm raises ours' object error;
// - a box turned by its quaternion fits its rendering better than unturned;
// - an object outside every view is warned about and its scene still evaluated;
// - a malformed insertion.yaml, a missing rgb_inserted frame and an unknown option exit 2 with
//   one-line messages.
#include <gtest/gtest.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "probeless/sim/scenario.h"
#include "probeless/sim/simulator.h"
#include "probeless/testing/testing.h"

namespace probeless::composite {
namespace {

namespace fs = std::filesystem;
using testing::CommandResult;
using testing::RunCommand;

constexpr int kFrames = 5;
// The inserted sphere: on the table top (y = 0.775), in the scenario's world frame.
constexpr double kRadius = 0.09;
constexpr double kSphere[3] = {0.25, 0.775 + kRadius, 0.85};

// The inserted sphere as a scenario object (id 99).
std::string SphereObject() {
  char sphere[256];
  std::snprintf(sphere, sizeof sphere,
                "  - {name: inserted, id: 99, shape: sphere, radius: %.3f, position: [%.3f, %.3f, "
                "%.3f], color: [0.75, 0.75, 0.75]}\n",
                kRadius, kSphere[0], kSphere[1], kSphere[2]);
  return sphere;
}

// A box turned 30 degrees about the vertical, on the table left of the sphere's place (id 99),
// and the same in insertion.yaml (quaternion about y; `rotated` false: the control without it).
const std::string kBoxObject =
    "  - {name: inserted, id: 99, shape: box, size: [0.16, 0.1, 0.12], position: [0.0, 0.825, "
    "0.75], rotation_deg: [0, 30, 0], color: [0.7, 0.5, 0.4]}\n";
std::string BoxInsertion(bool rotated) {
  return std::string(
             "objects:\n  - shape: box\n    size: [0.16, 0.1, 0.12]\n"
             "    albedo: [0.7, 0.5, 0.4]\n    position: [0.0, 0.825, 0.75]\n") +
         (rotated ? "    rotation: [0, 0.25881904510252074, 0, 0.9659258262890683]\n" : "");
}

// The scenario: a table on a floor before a wall, under a sun and a sky; `inserted` adds the
// inserted object as real geometry.
std::string Scenario(const std::string& inserted) {
  return std::string(
             "name: composite_tiny\nseed: 3\nfps: 30\nframes: 5\n"
             "camera:\n  width: 640\n  height: 480\n  fx: 525\n  fy: 525\n"
             "  path:\n"
             "    - {t: 0, position: [-0.5, 1.45, -0.9], look_at: [0.2, 0.8, 0.9]}\n"
             "    - {t: 0.2, position: [-0.35, 1.47, -0.95], look_at: [0.22, 0.8, 0.9]}\n"
             "render:\n  shadows: true\n  diffuse_bounce: false\n"
             "sensor:\n  depth_min: 0.3\n  depth_max: 8\n  exposure: 1.0\n"
             "environment:\n  sky: [0.12, 0.12, 0.13]\n  ground: [0.05, 0.05, 0.05]\n"
             "objects:\n"
             "  - {name: floor, shape: plane, size: [5, 1, 5], position: [0, 0, 0.5], color: "
             "[0.45, 0.4, 0.35]}\n"
             "  - {name: wall, shape: plane, size: [5, 1, 3], position: [0, 1.5, 2.5], "
             "rotation_deg: [-90, 0, 0], color: [0.7, 0.68, 0.6]}\n"
             "  - {name: table_top, shape: box, size: [1.4, 0.05, 0.8], position: [0.3, 0.75, "
             "0.9], color: [0.6, 0.45, 0.3]}\n"
             "  - {name: box, shape: box, size: [0.2, 0.2, 0.2], position: [0.65, 0.875, 1.0], "
             "color: [0.3, 0.5, 0.7]}\n") +
         inserted +
         "lights:\n"
         "  - {name: sun, type: directional, direction: [-0.5, 1.0, -0.45], color: [1, 0.97, "
         "0.92], intensity: 2.2}\n";
}

void WriteText(const fs::path& path, const std::string& text) {
  fs::create_directories(path.parent_path());
  std::ofstream(path) << text;
}

void WriteRgb(const fs::path& path, const std::vector<uint8_t>& rgb, int w, int h) {
  cv::Mat image(h, w, CV_8UC3, const_cast<uint8_t*>(rgb.data()));
  cv::Mat bgr;
  cv::cvtColor(image, bgr, cv::COLOR_RGB2BGR);
  ASSERT_TRUE(cv::imwrite(path.string(), bgr)) << path;
}

std::string Insertion(double dx, double z_offset = 0) {
  char text[256];
  std::snprintf(text, sizeof text,
                "objects:\n  - shape: sphere\n    radius: %.3f\n    albedo: [0.75, 0.75, 0.75]\n"
                "    position: [%.4f, %.4f, %.4f]\n",
                kRadius, kSphere[0] + dx, kSphere[1], kSphere[2] + z_offset);
  return text;
}

// Writes the scene folder `dir` in the composite_eval format.
// `inserted`: the scenario object standing for the inserted one (rgb_inserted/, the masks).
void MakeScene(const fs::path& dir, const std::string& insertion,
               const std::string& inserted = SphereObject()) {
  const sim::Scenario plain = sim::ParseScenario(Scenario(""), "tiny.yaml", ".");
  const sim::Scenario with = sim::ParseScenario(Scenario(inserted), "tiny_inserted.yaml", ".");
  sim::Simulator plain_sim(plain, 2), with_sim(with, 2);
  for (const char* sub : {"rgb", "depth", "rgb_inserted", "mask_object", "mask_effect"}) {
    fs::create_directories(dir / sub);
  }
  std::string rgb_txt = "# color images\n", depth_txt = "# depth maps\n";
  std::string gt = "# timestamp tx ty tz qx qy qz qw\n";
  std::string truth = "{\"light_type\": \"directional\", \"frames\": [\n";
  for (int i = 0; i < kFrames; ++i) {
    const sim::SimFrame a = plain_sim.Render(i), b = with_sim.Render(i);
    const int w = a.camera.width, h = a.camera.height;
    char stamp[32];
    std::snprintf(stamp, sizeof stamp, "%.6f", 1000.0 + i / 30.0);
    const std::string name = std::string(stamp) + ".png";
    rgb_txt += std::string(stamp) + " rgb/" + name + "\n";
    depth_txt += std::string(stamp) + " depth/" + name + "\n";
    WriteRgb(dir / "rgb" / name, a.rgb, w, h);
    WriteRgb(dir / "rgb_inserted" / name, b.rgb, w, h);
    cv::Mat depth(h, w, CV_16UC1), object(h, w, CV_8UC1), effect(h, w, CV_8UC1);
    for (int p = 0; p < w * h; ++p) {
      const double z = a.render.depth_m[p];
      depth.at<uint16_t>(p / w, p % w) =
          static_cast<uint16_t>(std::min(65535.0, std::round(z * 5000.0)));
      const bool on_object = b.render.object_ids[p] == 99;
      int diff = 0;
      for (int c = 0; c < 3; ++c)
        diff = std::max(diff, std::abs(a.rgb[p * 3 + c] - b.rgb[p * 3 + c]));
      object.at<uint8_t>(p / w, p % w) = on_object ? 255 : 0;
      effect.at<uint8_t>(p / w, p % w) = !on_object && diff >= 2 ? 255 : 0;
    }
    ASSERT_TRUE(cv::imwrite((dir / "depth" / name).string(), depth));
    ASSERT_TRUE(cv::imwrite((dir / "mask_object" / name).string(), object));
    ASSERT_TRUE(cv::imwrite((dir / "mask_effect" / name).string(), effect));
    const auto q = a.camera.camera_to_world.rotation.ToQuaternion();  // w, x, y, z
    const auto& t = a.camera.camera_to_world.translation;
    char line[256];
    std::snprintf(line, sizeof line, "%s %.6f %.6f %.6f %.9f %.9f %.9f %.9f\n", stamp, t[0], t[1],
                  t[2], q[1], q[2], q[3], q[0]);
    gt += line;
    std::string sh = "[";
    for (int k = 0; k < 9; ++k) {
      char c[96];
      std::snprintf(c, sizeof c, "%s[%.6f, %.6f, %.6f]", k ? ", " : "", a.light.sh[k].x,
                    a.light.sh[k].y, a.light.sh[k].z);
      sh += c;
    }
    sh += "]";
    const auto& d = a.light.dominant_direction;
    char frame[1024];
    std::snprintf(frame, sizeof frame,
                  "  {\"timestamp\": \"%s\", \"direction_camera\": [%.6f, %.6f, %.6f], "
                  "\"direct_to_ambient\": 3.0, \"sh_camera\": %s}%s\n",
                  stamp, d.x, d.y, d.z, sh.c_str(), i + 1 < kFrames ? "," : "");
    truth += frame;
  }
  truth += "]}\n";
  WriteText(dir / "rgb.txt", rgb_txt);
  WriteText(dir / "depth.txt", depth_txt);
  WriteText(dir / "groundtruth.txt", gt);
  WriteText(dir / "truth.json", truth);
  WriteText(dir / "insertion.yaml", insertion);
  WriteText(dir / "camera_info.yaml",
            "image_width: 640\nimage_height: 480\ncamera_name: tiny\n"
            "camera_matrix: {rows: 3, cols: 3, data: [525, 0, 319.5, 0, 525, 239.5, 0, 0, 1]}\n"
            "distortion_model: plumb_bob\n"
            "distortion_coefficients: {rows: 1, cols: 5, data: [0, 0, 0, 0, 0]}\n");
}

class CompositeEval : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    root_ = new testing::TempDir("composite_eval");
    const fs::path scenes = fs::path(root_->path()) / "scenes";
    MakeScene(scenes / "good", Insertion(0));
    fs::copy(scenes / "good", scenes / "moved", fs::copy_options::recursive);
    WriteText(scenes / "moved" / "insertion.yaml", Insertion(0.10));
    fs::copy(scenes / "good", scenes / "outside", fs::copy_options::recursive);
    // 5 m behind the first camera: in no view. rgb_inserted stays as rendered (the sphere's
    // pixels only count where the masks say).
    WriteText(scenes / "outside" / "insertion.yaml", Insertion(0, -6.0));
    MakeScene(scenes / "box", BoxInsertion(true), kBoxObject);
    fs::copy(scenes / "box", scenes / "box_unrotated", fs::copy_options::recursive);
    WriteText(scenes / "box_unrotated" / "insertion.yaml", BoxInsertion(false));
    run_ = new CommandResult(RunCommand(
        std::string(PROBELESS_BIN_DIR) + "/composite_eval --scenes " + scenes.string() +
            " --json " + root_->path() + "/out.json --sheets " + root_->path() + "/sheets",
        root_->path()));
    if (run_->code == 0) json_ = new YAML::Node(YAML::LoadFile(root_->path() + "/out.json"));
  }
  static void TearDownTestSuite() {
    // COMPOSITE_TEST_KEEP=DIR keeps the scenes, the JSON and the sheets for a look.
    if (const char* keep = std::getenv("COMPOSITE_TEST_KEEP")) {
      fs::remove_all(keep);
      fs::copy(root_->path(), keep, fs::copy_options::recursive);
    }
    delete json_;
    delete run_;
    delete root_;
  }
  static YAML::Node SceneJson(const std::string& name) {
    for (const YAML::Node& s : (*json_)["scenes"]) {
      if (s["name"].as<std::string>() == name) return s;
    }
    ADD_FAILURE() << "no scene " << name;
    return YAML::Node();
  }
  static void ExpectRan() {
    ASSERT_EQ(run_->code, 0) << run_->err;
    ASSERT_NE(json_, nullptr);
  }
  static inline testing::TempDir* root_ = nullptr;
  static inline CommandResult* run_ = nullptr;
  static inline YAML::Node* json_ = nullptr;
};

TEST_F(CompositeEval, OracleRanksAheadOfBaselineAndEveryKeyIsThere) {
  ExpectRan();
  const YAML::Node good = SceneJson("good");
  EXPECT_EQ(good["frames"].as<int>(), kFrames);
  const double oracle = good["oracle_si_rmse_object"].as<double>();
  const double baseline = good["baseline_si_rmse_object"].as<double>();
  std::cerr << "good: ours si " << good["ours_si_rmse_object"].as<std::string>() << ", oracle si "
            << oracle << ", baseline si " << baseline << ", ours rmse "
            << good["ours_rmse_object"].as<std::string>() << ", ours effect "
            << good["ours_rmse_effect"].as<std::string>() << ", baseline effect "
            << good["baseline_rmse_effect"].as<std::string>() << ", direction median "
            << good["direction_error_deg_median"].as<std::string>() << ", took " << run_->seconds
            << " s\n";
  EXPECT_LT(oracle, baseline);
  for (const char* key :
       {"ours_rmse_object", "ours_si_rmse_object", "baseline_si_rmse_object",
        "oracle_si_rmse_object", "ours_rmse_effect", "baseline_rmse_effect", "ours_psnr_db",
        "direction_error_deg_median", "direction_error_deg_p90", "frames_with_estimate"}) {
    EXPECT_TRUE(good[key].IsScalar()) << key;
    EXPECT_TRUE((*json_)["summary"][key]["median"]) << key;
    EXPECT_TRUE((*json_)["summary"][key]["p90"]) << key;
  }
  EXPECT_EQ((*json_)["summary"]["scene_count"].as<int>(), 5);
  EXPECT_GT(good["frames_with_estimate"].as<int>(), 0);
  EXPECT_TRUE(fs::is_regular_file(root_->path() + "/sheets/good.png"));
  EXPECT_NE(run_->err.find("scene 3/5 'good'"), std::string::npos) << run_->err;
}

TEST_F(CompositeEval, MovingTheObjectBy10CmRaisesOursError) {
  ExpectRan();
  const YAML::Node good = SceneJson("good"), moved = SceneJson("moved");
  EXPECT_GT(moved["ours_rmse_object"].as<double>(), good["ours_rmse_object"].as<double>());
  EXPECT_GT(moved["ours_si_rmse_object"].as<double>(), good["ours_si_rmse_object"].as<double>());
}

TEST_F(CompositeEval, ABoxIsPlacedAndTurnedByItsQuaternion) {
  ExpectRan();
  const YAML::Node box = SceneJson("box"), unrotated = SceneJson("box_unrotated");
  std::cerr << "box: oracle rmse " << box["oracle_rmse_object"].as<double>() << " (unrotated "
            << unrotated["oracle_rmse_object"].as<double>() << "), oracle si "
            << box["oracle_si_rmse_object"].as<double>() << ", baseline si "
            << box["baseline_si_rmse_object"].as<double>() << "\n";
  EXPECT_LT(box["oracle_si_rmse_object"].as<double>(), box["baseline_si_rmse_object"].as<double>());
  // The turn matters: without it the silhouette misses part of the mask.
  EXPECT_LT(box["oracle_rmse_object"].as<double>(), unrotated["oracle_rmse_object"].as<double>());
}

TEST_F(CompositeEval, AnObjectOutsideEveryViewIsWarnedAboutAndTheSceneStillEvaluated) {
  ExpectRan();
  EXPECT_NE(run_->err.find("composite_eval: warning: objects[0] (sphere) of scene 'outside' is "
                           "outside every view"),
            std::string::npos)
      << run_->err;
  EXPECT_EQ(SceneJson("outside")["frames"].as<int>(), kFrames);
  EXPECT_EQ(run_->err.find("of scene 'good' is outside"), std::string::npos);
}

// A scene copied from the suite's good one, changed by `edit`, evaluated alone.
CommandResult RunOnCopy(const std::string& name, const std::function<void(const fs::path&)>& edit,
                        const testing::TempDir& scratch) {
  const fs::path scenes = fs::path(scratch.path()) / "scenes";
  MakeScene(scenes / name, Insertion(0));
  edit(scenes / name);
  return RunCommand(std::string(PROBELESS_BIN_DIR) + "/composite_eval --scenes " + scenes.string() +
                        " --json " + scratch.path() + "/out.json",
                    scratch.path());
}

TEST(CompositeEvalErrors, MalformedInsertionYamlNamesFileLineAndField) {
  testing::TempDir scratch("composite_bad");
  const CommandResult r = RunOnCopy(
      "scene",
      [](const fs::path& dir) {
        WriteText(dir / "insertion.yaml",
                  "objects:\n  - shape: sphere\n    position: [0, 0, 1]\n    radius: abc\n");
      },
      scratch);
  EXPECT_EQ(r.code, 2);
  EXPECT_EQ(r.err,
            "composite_eval: scene/insertion.yaml:4: objects[0].radius: expected a positive "
            "number, got 'abc'\n");
}

TEST(CompositeEvalErrors, AMissingRgbInsertedFrameIsOneClearLine) {
  testing::TempDir scratch("composite_missing");
  std::string missing;
  const CommandResult r = RunOnCopy(
      "scene",
      [&](const fs::path& dir) {
        std::vector<fs::path> files;
        for (const auto& e : fs::directory_iterator(dir / "rgb_inserted"))
          files.push_back(e.path());
        std::sort(files.begin(), files.end());
        missing = files[2].filename().string();
        fs::remove(files[2]);
      },
      scratch);
  EXPECT_EQ(r.code, 2);
  EXPECT_EQ(r.err, "composite_eval: scene/rgb_inserted/" + missing +
                       ": missing (expected the frame rendered with the objects as real "
                       "geometry, one per rgb.txt entry: rgb/" +
                       missing + ")\n");
}

TEST(CompositeEvalErrors, UnknownOptionPrintsUsage) {
  testing::TempDir scratch("composite_usage");
  const CommandResult r = RunCommand(
      std::string(PROBELESS_BIN_DIR) + "/composite_eval --scenes x --json y --frobnicate",
      scratch.path());
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("composite_eval: unknown option '--frobnicate'"), std::string::npos);
  EXPECT_NE(r.err.find("usage: composite_eval --scenes DIR"), std::string::npos);
}

}  // namespace
}  // namespace probeless::composite
