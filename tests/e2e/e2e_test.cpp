// End-to-end tests of the whole graph (issue #10): recorded streams (the simulator's face_orbit and
// courtyard_sun scenarios, recorded with `sim --fast --frames N --out`) replayed through
// launch/replay.yaml with every processing node (face_tracker, face_light, fusion, scene_light,
// light_fusion, renderer) and a recorder, headless:
// - EndToEnd.*: the player in lock-step. Every node runs until the player ends the graph and then
//   exits 0; no drops (each output counted against the inputs that must produce it, see
//   CheckCounts); light errors against /groundtruth/* within the bounds of the pipelines' own
//   tests; composites non-empty and matching the golden PNGs in tests/e2e/golden/ (golden.h); no
//   /dev/shm segment of the test's bus domain left. A node that fails at start ends the graph.
// - Chaos.*: scene_light (respawn on) is SIGKILLed mid-run; it comes back and its output resumes,
//   the graph finishes, and the recording of everything upstream of it (/camera/*, /scene/gbuffer,
//   /scene/pose) has every played frame with contiguous sequence numbers.
// - GoldenCompare.*: the comparison passes float noise and fails a missing object or a wrong light.
// PROBELESS_UPDATE_GOLDEN=1 rewrites the golden PNGs from the run instead of comparing
// (docs/replay.md, "End-to-end tests").
#include <gtest/gtest.h>
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <regex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "golden.h"
#include "probeless/bus/bus.h"
#include "probeless/log/mcap_reader.h"
#include "probeless/log/ros2.h"
#include "probeless/msgs/msgs.h"
#include "probeless/testing/testing.h"

namespace probeless::e2e {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using testing::CommandResult;
using testing::RunCommand;

const std::string kBin = PROBELESS_BIN_DIR;
const std::string kSource = PROBELESS_SOURCE_DIR;
constexpr int kFrames = 12;  // frames recorded per scenario (keeps the suite well under a minute)

// A bus domain of its own for each test (children inherit it through the environment).
std::string UseFreshDomain() {
  static int counter = 0;
  const std::string domain = "e2e_" + std::to_string(getpid()) + "_" + std::to_string(counter++);
  setenv("PROBELESS_DOMAIN", domain.c_str(), 1);
  return domain;
}

// Segments of `domain` in /dev/shm (bus naming: probeless.<uid>.<domain>.*).
std::vector<std::string> ShmSegments(const std::string& domain) {
  const std::string prefix = "probeless." + std::to_string(getuid()) + "." + domain + ".";
  std::vector<std::string> found;
  for (const auto& entry : fs::directory_iterator("/dev/shm")) {
    const std::string name = entry.path().filename().string();
    if (name.starts_with(prefix)) found.push_back(name);
  }
  return found;
}

// Asserts that nothing of `domain` is left, then removes whatever is (so a failure does not leak).
void ExpectNoShmLeftovers(const std::string& domain) {
  const std::vector<std::string> left = ShmSegments(domain);
  std::string names;
  for (const auto& n : left) names += " " + n;
  EXPECT_TRUE(left.empty()) << "left in /dev/shm:" << names;
  std::system((kBin + "/probeless clean > /dev/null 2>&1").c_str());
}

// The scenario recordings, made once per test program.
class Recordings {
 public:
  static const std::string& Get(const std::string& scenario) {
    static Recordings instance;
    auto it = instance.files_.find(scenario);
    if (it != instance.files_.end()) return it->second;
    const std::string out = (instance.dir_ / (scenario + ".mcap")).string();
    const CommandResult r =
        RunCommand(kBin + "/sim " + kSource + "/data/scenarios/" + scenario +
                       ".yaml --fast --frames " + std::to_string(kFrames) + " --out " + out,
                   instance.dir_);
    EXPECT_EQ(r.code, 0) << "sim failed: " << r.err;
    return instance.files_[scenario] = out;
  }
  ~Recordings() { fs::remove_all(dir_); }

 private:
  Recordings() : dir_(fs::temp_directory_path() / ("probeless_e2e_" + std::to_string(getpid()))) {
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  fs::path dir_;
  std::map<std::string, std::string> files_;
};

// One recorded message, decoded into its probeless layout.
struct Recorded {
  uint32_t sequence = 0;         // the bus sequence of the publisher (MCAP Message record)
  uint64_t publish_time_ns = 0;  // when it was published (bus publish wall time)
  log::MessageBuffer message;
  const msgs::Header& header() const {
    return *reinterpret_cast<const msgs::Header*>(message.bytes().data());
  }
};

// Every message of the recording, per topic, in log-time order.
std::map<std::string, std::vector<Recorded>> ReadRecording(const std::string& path) {
  std::map<std::string, std::vector<Recorded>> topics;
  const log::McapReader reader(path);
  log::MessageCursor cursor = reader.Messages();
  log::MessageView view;
  while (cursor.Next(view)) {
    const auto* converter = log::FindRos2ConverterByRos2Type(view.schema ? view.schema->name : "");
    if (converter == nullptr) continue;
    topics[view.channel->topic].push_back(
        {view.sequence, view.publish_time_ns,
         log::DecodeRos2(*converter, view.data, view.channel->metadata)});
  }
  return topics;
}

cv::Mat ImageToBgr(const log::MessageBuffer& buffer) {
  const auto m = msgs::ReadMessage<msgs::Image>(buffer.bytes());
  if (m->encoding != msgs::Encoding::kRgb8) return {};
  cv::Mat rgb(static_cast<int>(m->height), static_cast<int>(m->width), CV_8UC3,
              const_cast<std::byte*>(m.payload.data()), m->step);
  cv::Mat bgr;
  cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
  return bgr;
}

double AngleDeg(const float a[3], const float b[3]) {
  const double na = std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
  const double nb = std::sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2]);
  const double c = (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) / (na * nb);
  return std::acos(std::clamp(c, -1.0, 1.0)) * 180 / M_PI;
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? NAN : v[v.size() / 2];
}

// Median dominant-direction error of `estimates` against the truth of the same frame (stamp).
double MedianErrorDeg(const std::vector<Recorded>& estimates, const std::vector<Recorded>& truths,
                      const std::string& what) {
  std::map<int64_t, const msgs::ShLight*> truth;
  for (const auto& t : truths) {
    truth[t.header().stamp_ns] = reinterpret_cast<const msgs::ShLight*>(t.message.bytes().data());
  }
  std::vector<double> errors;
  for (const auto& e : estimates) {
    const auto* light = reinterpret_cast<const msgs::ShLight*>(e.message.bytes().data());
    const auto it = truth.find(e.header().stamp_ns);
    EXPECT_NE(it, truth.end()) << what << ": no ground truth for stamp " << e.header().stamp_ns;
    if (it == truth.end()) continue;
    errors.push_back(AngleDeg(light->dominant_direction, it->second->dominant_direction));
  }
  const double median = Median(errors);
  std::printf("%s: %zu estimates, median dominant-direction error %.1f deg; per frame:",
              what.c_str(), errors.size(), median);
  for (double e : errors) std::printf(" %.1f", e);
  std::printf("\n");
  return median;
}

// The player's per-topic counts from its summary line ("...; /camera/image 12; ...").
std::map<std::string, uint64_t> PlayerCounts(const std::string& out) {
  std::map<std::string, uint64_t> counts;
  const auto line_start = out.find("player: published ");
  EXPECT_NE(line_start, std::string::npos) << "no player summary in:\n" << out;
  if (line_start == std::string::npos) return counts;
  const std::string line = out.substr(line_start, out.find('\n', line_start) - line_start);
  static const std::regex kCount("; (/[^ ;]+) ([0-9]+)");
  for (auto it = std::sregex_iterator(line.begin(), line.end(), kCount);
       it != std::sregex_iterator(); ++it) {
    counts[(*it)[1]] = std::stoull((*it)[2]);
  }
  return counts;
}

// Checks the supervisor's account of the run: each node started once (or, with `respawned`, that
// one twice), nothing ended before the player finished, and after it every node exited 0.
void CheckNodesAliveUntilTheEnd(const std::string& err, const std::vector<std::string>& nodes,
                                const std::string& respawned = "") {
  const auto stopping = err.find("[probeless] required node player finished; stopping");
  ASSERT_NE(stopping, std::string::npos) << err;
  const std::string before = err.substr(0, stopping);
  const std::string after = err.substr(stopping);
  for (const std::string& node : nodes) {
    const std::regex started("\\[probeless\\] started " + node + " \\(pid [0-9]+\\)");
    const auto starts = std::distance(std::sregex_iterator(err.begin(), err.end(), started),
                                      std::sregex_iterator());
    EXPECT_EQ(starts, node == respawned ? 2 : 1) << node << " starts in:\n" << err;
    const std::string exit_line = "[probeless] " + node + " ";
    if (node == "player") continue;
    // Before the stop only the respawned node may have ended (killed, then respawned).
    const bool ended_early = before.find(exit_line + "exited") != std::string::npos ||
                             before.find(exit_line + "was killed") != std::string::npos;
    EXPECT_EQ(ended_early, node == respawned) << node << " ended early:\n" << err;
    EXPECT_NE(after.find(exit_line + "exited with code 0"), std::string::npos)
        << node << " did not exit 0 at the end:\n"
        << err;
  }
  EXPECT_NE(before.find("[probeless] player exited with code 0"), std::string::npos) << err;
}

// Sequence numbers 1..n without gaps.
void ExpectContiguous(const std::vector<Recorded>& messages, uint64_t expected,
                      const std::string& topic) {
  EXPECT_EQ(messages.size(), expected) << topic;
  for (size_t i = 0; i < messages.size(); ++i) {
    if (messages[i].sequence != i + 1) {
      ADD_FAILURE() << topic << ": message " << i << " has sequence " << messages[i].sequence;
      return;
    }
  }
}

struct GraphRun {
  std::string followed_light;  // the light the renderer follows
  CommandResult launch;
  std::map<std::string, std::vector<Recorded>> recording;
  std::map<std::string, uint64_t> played;
  std::vector<fs::path> pngs;
};

// Runs launch/replay.yaml with the whole graph in lock-step on `source`, recording into `dir`.
GraphRun RunGraph(const std::string& source, const std::string& dir, const std::string& light,
                  const std::string& args) {
  GraphRun run;
  run.followed_light = light;
  const std::string png_dir = dir + "/png";
  // The renderer creates its publisher at its first composite; a subscriber created now makes the
  // topic known to the recorder's discovery before that (docs/replay.md, "Known limits").
  bus::Subscriber composite_topic("/render/composite", msgs::TopicTypeOf<msgs::Image>(),
                                  {.queue_depth = 1});
  run.launch =
      RunCommand(kBin + "/probeless launch " + kSource + "/launch/replay.yaml source:=" + source +
                     " face:=true scene:=true fuse:=true render:=true lockstep:=true"
                     " record:=true out:=" +
                     dir + " png_dir:=" + png_dir + " light:=" + light + " " + args,
                 dir);
  if (fs::exists(dir + "/replay.mcap")) run.recording = ReadRecording(dir + "/replay.mcap");
  run.played = PlayerCounts(run.launch.out);
  if (fs::is_directory(png_dir)) {
    for (const auto& e : fs::directory_iterator(png_dir)) run.pngs.push_back(e.path());
    std::sort(run.pngs.begin(), run.pngs.end());
  }
  return run;
}

// No drops: every output counted against the inputs that must produce it (lock-step).
void CheckCounts(GraphRun& run) {
  auto& rec = run.recording;
  const uint64_t images = run.played["/camera/image"];
  ASSERT_EQ(images, static_cast<uint64_t>(kFrames)) << run.launch.out;
  // Everything played was recorded, in order.
  for (const auto& [topic, count] : run.played) {
    if (topic.starts_with("/camera/") || topic.starts_with("/groundtruth/")) {
      ExpectContiguous(rec[topic], count, topic + " (recorded vs played)");
    }
  }
  // face_tracker: one observation per image.
  ASSERT_EQ(rec["/face/observation"].size(), images);
  size_t faces = 0;
  for (const auto& o : rec["/face/observation"]) {
    faces +=
        reinterpret_cast<const msgs::FaceObservation*>(o.message.bytes().data())->face_detected;
  }
  // face_light: one light per observation with a face (all have enough valid samples here).
  EXPECT_EQ(rec["/face/light"].size(), faces);
  // fusion: one G_r per depth image (the camera_info of a frame comes before its depth).
  EXPECT_EQ(rec["/scene/gbuffer"].size(), run.played["/camera/depth"]);
  // scene_light: one light per G_r, or per depth image in depth mode (every frame gives a valid
  // estimate here).
  EXPECT_EQ(rec["/scene/light"].size(), rec["/scene/gbuffer"].size());
  // light_fusion (defaults max_age_s 0.5, min_confidence 0.05): one /light after each input light
  // when the latest face or scene light, not older than 0.5 s than the newest, is confident enough.
  std::vector<std::pair<const Recorded*, int>> inputs;  // in arrival order; 0 face, 1 scene
  for (const auto& l : rec["/face/light"]) inputs.push_back({&l, 0});
  for (const auto& l : rec["/scene/light"]) inputs.push_back({&l, 1});
  std::sort(inputs.begin(), inputs.end(), [](const auto& a, const auto& b) {
    return a.first->publish_time_ns < b.first->publish_time_ns;
  });
  const msgs::ShLight* latest[2] = {nullptr, nullptr};
  size_t expected_fused = 0;
  for (const auto& [recorded, which] : inputs) {
    latest[which] = reinterpret_cast<const msgs::ShLight*>(recorded->message.bytes().data());
    int64_t newest = 0;
    for (const auto* l : latest) {
      if (l != nullptr) newest = std::max(newest, l->header.stamp_ns);
    }
    bool usable = false;
    for (const auto* l : latest) {
      usable |=
          l != nullptr && newest - l->header.stamp_ns <= 500'000'000 && l->confidence >= 0.05f;
    }
    expected_fused += usable;
  }
  EXPECT_GT(expected_fused, 0u);
  EXPECT_EQ(rec["/light"].size(), expected_fused);
  // renderer (trigger image): one composite per camera image played after the first light it
  // follows (lit by the latest light, the previous frame's in lock-step), each also a PNG.
  const auto& followed = rec[run.followed_light];
  ASSERT_FALSE(followed.empty()) << run.followed_light;
  size_t expected_composites = 0;
  for (const auto& image : rec["/camera/image"]) {
    expected_composites += image.publish_time_ns > followed.front().publish_time_ns;
  }
  EXPECT_EQ(rec["/render/composite"].size(), expected_composites);
  EXPECT_EQ(run.pngs.size(), rec["/render/composite"].size());
  for (const auto& png : run.pngs) EXPECT_GT(fs::file_size(png), 1000u) << png;
  std::printf(
      "frames %llu, faces %zu, /face/light %zu, /scene/light %zu, /light %zu, "
      "composites %zu\n",
      static_cast<unsigned long long>(images), faces, rec["/face/light"].size(),
      rec["/scene/light"].size(), rec["/light"].size(), rec["/render/composite"].size());
}

// The camera image of the composite's frame (same stamp).
cv::Mat CameraImageFor(GraphRun& run, const Recorded& composite) {
  for (const auto& image : run.recording["/camera/image"]) {
    if (image.header().stamp_ns == composite.header().stamp_ns) return ImageToBgr(image.message);
  }
  return {};
}

// Composites `indices` against tests/e2e/golden/<name>_<index>.png (or rewrites them), plus the
// negative controls on the real frame: the bare camera image (a renderer that draws nothing) and
// the composite with the virtual objects' pixels 20 % darker (a wrong light) must not match.
void CheckGoldens(GraphRun& run, const std::string& name, const std::vector<size_t>& indices) {
  const auto& composites = run.recording["/render/composite"];
  const bool update = std::getenv("PROBELESS_UPDATE_GOLDEN") != nullptr &&
                      std::string(std::getenv("PROBELESS_UPDATE_GOLDEN")) == "1";
  for (size_t index : indices) {
    ASSERT_LT(index, composites.size());
    const cv::Mat composite = ImageToBgr(composites[index].message);
    ASSERT_FALSE(composite.empty());
    const cv::Mat camera = CameraImageFor(run, composites[index]);
    ASSERT_EQ(camera.size(), composite.size());
    // Non-empty: the virtual objects changed a visible part of the picture.
    cv::Mat changed;
    cv::absdiff(composite, camera, changed);
    cv::cvtColor(changed, changed, cv::COLOR_BGR2GRAY);
    const cv::Mat object_mask = changed > 8;
    const int object_pixels = cv::countNonZero(object_mask);
    EXPECT_GT(object_pixels, 200) << name << " composite " << index << " shows no virtual object";
    // The PNG written by the renderer is the same picture.
    ASSERT_LT(index, run.pngs.size());
    const cv::Mat png = cv::imread(run.pngs[index].string(), cv::IMREAD_COLOR);
    ASSERT_EQ(png.size(), composite.size());
    EXPECT_EQ(cv::norm(png, composite, cv::NORM_INF), 0) << run.pngs[index];

    const std::string golden_path =
        kSource + "/tests/e2e/golden/" + name + "_" + std::to_string(index) + ".png";
    const cv::Mat small = ToGoldenSize(composite);
    if (update) {
      fs::create_directories(fs::path(golden_path).parent_path());
      ASSERT_TRUE(cv::imwrite(golden_path, small));
      std::printf("updated %s\n", golden_path.c_str());
      continue;
    }
    const cv::Mat golden = cv::imread(golden_path, cv::IMREAD_COLOR);
    ASSERT_FALSE(golden.empty()) << "missing " << golden_path
                                 << " (PROBELESS_UPDATE_GOLDEN=1 writes it)";
    const ImageDiff d = Compare(small, golden);
    std::printf("%s composite %zu vs golden: mean %.3f, max block %.2f (limits %.1f, %.1f)\n",
                name.c_str(), index, d.mean_abs, d.max_block_mean, kMaxMeanAbsDiff,
                kMaxBlockMeanAbsDiff);
    EXPECT_TRUE(d.Matches()) << golden_path;
    // Negative controls.
    const ImageDiff bare = Compare(ToGoldenSize(camera), golden);
    std::printf("  bare camera image: mean %.3f, max block %.2f\n", bare.mean_abs,
                bare.max_block_mean);
    EXPECT_FALSE(bare.Matches()) << "the comparison cannot tell a missing object";
    cv::Mat darker = composite.clone();
    cv::Mat scaled;
    composite.convertTo(scaled, CV_8UC3, 0.8);
    scaled.copyTo(darker, object_mask);
    const ImageDiff wrong = Compare(ToGoldenSize(darker), golden);
    std::printf("  objects 20%% darker: mean %.3f, max block %.2f\n", wrong.mean_abs,
                wrong.max_block_mean);
    EXPECT_FALSE(wrong.Matches()) << "the comparison cannot tell a 20 % wrong light";
  }
}

class EndToEnd : public ::testing::Test {
 protected:
  void SetUp() override { domain_ = UseFreshDomain(); }
  void TearDown() override { ExpectNoShmLeftovers(domain_); }
  std::string domain_;
};

// face_orbit: the synthetic head under an orbiting point light; renderer in face mode (nose and
// glasses) lit by the fused /light.
TEST_F(EndToEnd, FaceOrbitThroughTheWholeGraphInLockStep) {
  const std::string& source = Recordings::Get("face_orbit");
  ASSERT_TRUE(fs::exists(source));
  testing::TempDir dir("e2e_face");
  // The renderer follows /face/light (as launch/demo.yaml), so its composites depend on the face
  // pipeline only; light_fusion still fuses both lights into /light.
  GraphRun run = RunGraph(source, dir.path(), "/face/light", "smoothing:=false");
  ASSERT_EQ(run.launch.code, 0) << run.launch.err;
  CheckNodesAliveUntilTheEnd(run.launch.err, {"recorder", "face_tracker", "face_light", "fusion",
                                              "scene_light", "light_fusion", "renderer", "player"});
  CheckCounts(run);
  auto& rec = run.recording;
  // The face is found in every frame of the first 0.4 s of the orbit.
  EXPECT_GE(rec["/face/light"].size(), static_cast<size_t>(kFrames - 1));
  // Against the light at the face: 4.6 deg median measured here with the shipped (landmark-
  // aligned) model on the human-proportioned procedural head; bound: issue #6's 8.5 deg target.
  EXPECT_LT(MedianErrorDeg(rec["/face/light"], rec["/groundtruth/face_light"], "face_light"), 8.5);
  CheckGoldens(run, "face_orbit", {2, 9});
}

// courtyard_sun: a scene under a moving sun; renderer in scene mode (a red sphere on the table)
// lit by the fused /light.
TEST_F(EndToEnd, CourtyardSunThroughTheWholeGraphInLockStep) {
  const std::string& source = Recordings::Get("courtyard_sun");
  ASSERT_TRUE(fs::exists(source));
  testing::TempDir dir("e2e_scene");
  // fusion sized for the courtyard (as launch/demo_scene.yaml); scene_light on the sensor depth
  // with the cast-shadow search of a clear sun (see the bound below); the renderer's sphere on the
  // table lit by /scene/light.
  GraphRun run = RunGraph(source, dir.path(), "/scene/light",
                          "volume_size:=6.0 'volume_origin:=[-3.0, -3.0, 0.3]' truncation:=0.08 "
                          "depth_max:=6.0 scene_light_mode:=depth shadows:=true mode:=scene "
                          "'objects:=[nose]' object_scale:=5.0 "
                          "'object_position:=[0.151, 0.107, 3.178]'");
  ASSERT_EQ(run.launch.code, 0) << run.launch.err;
  CheckNodesAliveUntilTheEnd(run.launch.err, {"recorder", "face_tracker", "face_light", "fusion",
                                              "scene_light", "light_fusion", "renderer", "player"});
  CheckCounts(run);
  auto& rec = run.recording;
  EXPECT_EQ(rec["/scene/light"].size(), static_cast<size_t>(kFrames));
  // docs/light.md "Cast shadows": on the raw sensor depth the shadow search with the image cues
  // corrects the direction the quantised normals get wrong; these 12 consecutive frames: 6.7 deg
  // median measured here (22.5 deg without the search, 43.6 deg with it but without the cues);
  // bound 10 deg.
  EXPECT_LT(MedianErrorDeg(rec["/scene/light"], rec["/groundtruth/light"], "scene_light"), 10.0);
  CheckGoldens(run, "courtyard_sun", {3, 10});
}

// A node that fails for good (here scene_light with a bad mode) ends the graph with exit code 1
// instead of leaving the lock-step player waiting for it (every node of replay.yaml is required).
TEST_F(EndToEnd, ANodeThatFailsEndsTheGraphInsteadOfStallingIt) {
  const std::string& source = Recordings::Get("courtyard_sun");
  testing::TempDir dir("e2e_fail");
  const CommandResult r =
      RunCommand(kBin + "/probeless launch " + kSource + "/launch/replay.yaml source:=" + source +
                     " face:=false scene:=true scene_light_mode:=lidar",
                 dir.path());
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_NE(r.err.find("[scene_light] [error] [scene_light] node '/scene_light': parameter 'mode' "
                       "= \"lidar\" (from -p) is not one of gbuffer|depth"),
            std::string::npos)
      << r.err;
  EXPECT_NE(r.err.find("[probeless] required node scene_light finished; stopping"),
            std::string::npos)
      << r.err;
}

// scene_light (respawn on) is SIGKILLed after its third estimate; lock-step does not wait for it
// while it is gone and waits for it again once it is back.
// Counts the messages of a topic on a thread (stopped and joined when destroyed, also when an
// assertion leaves the test early).
class TopicCounter {
 public:
  TopicCounter(const std::string& topic, const bus::TopicType& type)
      : subscriber_(topic, type, {.queue_depth = 64}), thread_([this] {
          while (!stop_) {
            if (subscriber_.Take(10ms)) ++count_;
          }
        }) {}
  ~TopicCounter() {
    stop_ = true;
    thread_.join();
  }
  int count() const { return count_; }

 private:
  bus::Subscriber subscriber_;
  std::atomic<bool> stop_{false};
  std::atomic<int> count_{0};
  std::thread thread_;
};

class Chaos : public EndToEnd {};

TEST_F(Chaos, KilledSceneLightRespawnsAndNothingUpstreamIsLost) {
  const std::string& source = Recordings::Get("courtyard_sun");
  ASSERT_TRUE(fs::exists(source));
  testing::TempDir dir("e2e_chaos");
  {
    TopicCounter lights("/scene/light", msgs::TopicTypeOf<msgs::ShLight>());
    // Destroyed (SIGKILL to the supervisor, whose watchdog kills the nodes) before the /dev/shm
    // check of TearDown if an assertion ends the test early.
    testing::Process launch(
        "probeless", {"launch", kSource + "/launch/replay.yaml", "source:=" + source, "face:=false",
                      "scene:=true", "fuse:=false", "render:=false", "lockstep:=true",
                      "record:=true", "out:=" + dir.path(), "respawn:=true", "volume_size:=6.0",
                      "volume_origin:=[-3.0, -3.0, 0.3]", "truncation:=0.08", "depth_max:=6.0"});
    // Kill scene_light once it has published three lights.
    const auto deadline = std::chrono::steady_clock::now() + 60s;
    while (lights.count() < 3 && std::chrono::steady_clock::now() < deadline) {
      std::this_thread::sleep_for(5ms);
    }
    ASSERT_GE(lights.count(), 3) << launch.Err();
    std::smatch m;
    const std::string err = launch.Err();
    ASSERT_TRUE(std::regex_search(err, m, std::regex("started scene_light \\(pid ([0-9]+)\\)")))
        << err;
    const pid_t victim = std::stoi(m[1]);
    const int killed_after = lights.count();
    ASSERT_EQ(kill(victim, SIGKILL), 0);
    const int code = launch.Wait(120s);
    const std::string final_err = launch.Err();
    const std::string final_out = launch.Out();
    EXPECT_EQ(code, 0) << final_err;
    EXPECT_NE(
        final_err.find("[probeless] scene_light was killed by signal SIGKILL (9); respawning"),
        std::string::npos)
        << final_err;
    CheckNodesAliveUntilTheEnd(final_err, {"recorder", "fusion", "scene_light", "player"},
                               "scene_light");
    // Whether the player saw the node gone depends on when its respawn subscribed again (the
    // replay_test unit test covers that path deterministically).
    const bool noticed =
        final_err.find("lock-step: /scene_light has left the bus") != std::string::npos;

    const auto rec = ReadRecording(dir.path() + "/replay.mcap");
    const auto played = PlayerCounts(final_out);
    ASSERT_EQ(played.at("/camera/image"), static_cast<uint64_t>(kFrames));
    // Upstream of the killed node: every played frame recorded, in order; fusion saw every depth.
    for (const auto& [topic, count] : played) {
      if (topic.starts_with("/camera/")) ExpectContiguous(rec.at(topic), count, topic);
    }
    ExpectContiguous(rec.at("/scene/gbuffer"), played.at("/camera/depth"), "/scene/gbuffer");
    ExpectContiguous(rec.at("/scene/pose"), played.at("/camera/depth"), "/scene/pose");
    // The node came back: lights for frames after the kill, the last frame's among them.
    const auto& scene = rec.at("/scene/light");
    ASSERT_GT(static_cast<int>(scene.size()), killed_after) << "no light after the respawn";
    EXPECT_EQ(scene.back().header().stamp_ns, rec.at("/camera/depth").back().header().stamp_ns)
        << "the respawned node did not process the last frame";
    std::printf("chaos: killed after %d lights; %zu of %d frames got a light; the player %s\n",
                killed_after, scene.size(), kFrames,
                noticed ? "saw it leave and come back" : "did not see it gone");
  }
}

// The comparison itself: noise of a level passes; a missing object and a wrong light do not.
TEST(GoldenCompare, PassesNoiseAndFailsAMissingObjectOrAWrongLight) {
  cv::Mat background(480, 640, CV_8UC3);
  cv::RNG rng(12345);
  rng.fill(background, cv::RNG::UNIFORM, 40, 200);
  cv::GaussianBlur(background, background, cv::Size(9, 9), 3);
  cv::Mat composite = background.clone();
  cv::circle(composite, {320, 240}, 18, cv::Scalar(40, 40, 210), cv::FILLED);  // a "nose"
  const cv::Mat golden = ToGoldenSize(composite);
  EXPECT_EQ(Compare(golden, golden).mean_abs, 0);
  cv::Mat noisy = composite.clone();
  cv::Mat noise(composite.size(), CV_8SC3);
  rng.fill(noise, cv::RNG::UNIFORM, -1, 2);  // +-1 level everywhere
  cv::add(noisy, noise, noisy, cv::noArray(), CV_8UC3);
  EXPECT_TRUE(Compare(ToGoldenSize(noisy), golden).Matches());
  EXPECT_FALSE(Compare(ToGoldenSize(background), golden).Matches()) << "missing object";
  cv::Mat wrong_light = background.clone();
  cv::circle(wrong_light, {320, 240}, 18, cv::Scalar(32, 32, 168), cv::FILLED);  // 20 % darker
  EXPECT_FALSE(Compare(ToGoldenSize(wrong_light), golden).Matches()) << "wrong light";
  EXPECT_THROW(Compare(golden, ToGoldenSize(composite(cv::Rect(0, 0, 320, 480)))),
               std::invalid_argument);
}

}  // namespace
}  // namespace probeless::e2e
