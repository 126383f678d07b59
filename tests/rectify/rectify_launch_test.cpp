// Rectification in the graph: a TUM-layout Freiburg 1 folder (simulator frames seen through the
// Freiburg 1 lens) played through launch/replay.yaml reaches fusion and scene_light through the
// rectify node, with poses and lights published; a calibration written by tools/calibrate from
// distorted checkerboard views reads back, through every reader, to the same maps; malformed or
// inconsistent camera_info stops the node with one line naming the topic.
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <thread>
#include <vector>

#include "probeless/bus/bus.h"
#include "probeless/calib/calibration.h"
#include "probeless/dataset/datasets.h"
#include "probeless/log/mcap_reader.h"
#include "probeless/log/ros2.h"
#include "probeless/msgs/msgs.h"
#include "probeless/rectify/rectify.h"
#include "probeless/sim/scenario.h"
#include "probeless/sim/simulator.h"
#include "probeless/testing/testing.h"
#include "test_scenes.h"

namespace probeless {
namespace {

namespace fs = std::filesystem;
using testing::Process;
using testing::RunCommand;
using testing::TempDir;

const std::string kBin = PROBELESS_BIN_DIR;

// Writes a TUM RGB-D folder `dir` (rgb/, depth/, rgb.txt, depth.txt, groundtruth.txt) of `frames`
// courtyard frames as the Freiburg 1 camera would have seen them: colour (bilinear) and depth
// (nearest) through its lens, depth in TUM's 5000 units per metre.
void WriteFreiburg1Folder(const fs::path& dir, int frames) {
  fs::create_directories(dir / "rgb");
  fs::create_directories(dir / "depth");
  sim::Scenario scenario =
      sim::LoadScenario(std::string(PROBELESS_SOURCE_DIR) + "/data/scenarios/courtyard_grey.yaml");
  sim::Simulator simulator(scenario, 2);
  const msgs::CameraInfo fr1 = rectify::test::Freiburg1Info();
  std::FILE* rgb_txt = std::fopen((dir / "rgb.txt").c_str(), "w");
  std::FILE* depth_txt = std::fopen((dir / "depth.txt").c_str(), "w");
  std::FILE* truth_txt = std::fopen((dir / "groundtruth.txt").c_str(), "w");
  ASSERT_TRUE(rgb_txt && depth_txt && truth_txt);
  cv::Mat map_x, map_y;
  for (int i = 0; i < frames; ++i) {
    const sim::SimFrame f = simulator.Render(static_cast<uint64_t>(i));
    if (i == 0) {
      const cv::Matx33d k(f.camera.fx, 0, f.camera.cx, 0, f.camera.fy, f.camera.cy, 0, 0, 1);
      rectify::test::DistortionMaps(fr1, map_x, map_y, &k);
    }
    const cv::Mat rgb(480, 640, CV_8UC3, const_cast<uint8_t*>(f.rgb.data()));
    const cv::Mat mm(480, 640, CV_16UC1, const_cast<uint16_t*>(f.depth_mm.data()));
    cv::Mat rgb_lens, mm_lens, bgr, tum;
    cv::remap(rgb, rgb_lens, map_x, map_y, cv::INTER_LINEAR, cv::BORDER_CONSTANT, 0);
    cv::remap(mm, mm_lens, map_x, map_y, cv::INTER_NEAREST, cv::BORDER_CONSTANT, 0);
    cv::cvtColor(rgb_lens, bgr, cv::COLOR_RGB2BGR);
    mm_lens.convertTo(tum, CV_16UC1, 5.0);
    char stamp[32];
    std::snprintf(stamp, sizeof(stamp), "%.6f", 1305031102.0 + i / 30.0);
    cv::imwrite((dir / "rgb" / (std::string(stamp) + ".png")).string(), bgr);
    cv::imwrite((dir / "depth" / (std::string(stamp) + ".png")).string(), tum);
    std::fprintf(rgb_txt, "%s rgb/%s.png\n", stamp, stamp);
    std::fprintf(depth_txt, "%s depth/%s.png\n", stamp, stamp);
    const auto& t = f.camera.camera_to_world;
    const cv::Matx33d r(t.rotation.m[0][0], t.rotation.m[0][1], t.rotation.m[0][2],
                        t.rotation.m[1][0], t.rotation.m[1][1], t.rotation.m[1][2],
                        t.rotation.m[2][0], t.rotation.m[2][1], t.rotation.m[2][2]);
    // Rotation matrix -> quaternion (trace is > -1 for this smooth camera path's rotations).
    const double w = std::sqrt(std::max(0.0, 1 + r(0, 0) + r(1, 1) + r(2, 2))) / 2;
    const double x = std::copysign(std::sqrt(std::max(0.0, 1 + r(0, 0) - r(1, 1) - r(2, 2))) / 2,
                                   r(2, 1) - r(1, 2));
    const double y = std::copysign(std::sqrt(std::max(0.0, 1 - r(0, 0) + r(1, 1) - r(2, 2))) / 2,
                                   r(0, 2) - r(2, 0));
    const double z = std::copysign(std::sqrt(std::max(0.0, 1 - r(0, 0) - r(1, 1) + r(2, 2))) / 2,
                                   r(1, 0) - r(0, 1));
    std::fprintf(truth_txt, "%s %.6f %.6f %.6f %.9f %.9f %.9f %.9f\n", stamp, t.translation[0],
                 t.translation[1], t.translation[2], x, y, z, w);
  }
  std::fclose(rgb_txt);
  std::fclose(depth_txt);
  std::fclose(truth_txt);
}

cv::Matx44d Matrix(const msgs::RigidTransform& t) {
  const double w = t.rotation.w, x = t.rotation.x, y = t.rotation.y, z = t.rotation.z;
  return {1 - 2 * (y * y + z * z),
          2 * (x * y - w * z),
          2 * (x * z + w * y),
          t.translation.x,
          2 * (x * y + w * z),
          1 - 2 * (x * x + z * z),
          2 * (y * z - w * x),
          t.translation.y,
          2 * (x * z - w * y),
          2 * (y * z + w * x),
          1 - 2 * (x * x + y * y),
          t.translation.z,
          0,
          0,
          0,
          1};
}

TEST(RectifyLaunch, Freiburg1FolderPlaysThroughFusionAndSceneLight) {
  TempDir dir("rectify_launch");
  const fs::path folder = fs::path(dir.path()) / "rgbd_dataset_freiburg1_courtyard";
  constexpr int kFrames = 12;
  WriteFreiburg1Folder(folder, kFrames);
  const fs::path out = fs::path(dir.path()) / "out";
  fs::create_directories(out);
  const testing::CommandResult run = RunCommand(
      kBin + "/probeless launch " + PROBELESS_SOURCE_DIR + "/launch/replay.yaml source:=" +
          folder.string() + " face:=false record:=true out:=" + out.string() +
          " volume_size:=6.0 'volume_origin:=[-3.0, -3.0, 0.3]' truncation:=0.08 depth_max:=6.0",
      dir.path());
  std::system((kBin + "/probeless clean > /dev/null 2>&1").c_str());
  const std::string log = run.out + run.err;
  ASSERT_EQ(run.code, 0) << log;
  EXPECT_EQ(log.find("lens distortion"), std::string::npos) << log;
  EXPECT_NE(log.find("plumb_bob: maps in"), std::string::npos) << log;
  EXPECT_NE(log.find("rectified 12 images and 12 depth images"), std::string::npos) << log;

  std::map<std::string, int> counts;
  std::map<int64_t, cv::Matx44d> estimate, truth;  // by stamp, camera -> world
  const log::McapReader reader((out / "replay.mcap").string());
  log::MessageCursor cursor = reader.Messages();
  log::MessageView view;
  while (cursor.Next(view)) {
    const std::string& topic = view.channel->topic;
    ++counts[topic];
    if (topic != "/scene/pose" && topic != "/groundtruth/pose") continue;
    const log::MessageBuffer m =
        log::DecodeRos2(log::Ros2ConverterFor<msgs::Pose>(), view.data, view.channel->metadata);
    const msgs::Pose& pose = *msgs::ReadMessage<msgs::Pose>(m.bytes());
    (topic == "/scene/pose" ? estimate : truth)[pose.header.stamp_ns] = Matrix(pose.transform);
  }
  // The tracked poses follow the truth (ATE after aligning the first tracked pose).
  ASSERT_FALSE(estimate.empty());
  const int64_t first = estimate.begin()->first;
  ASSERT_TRUE(truth.count(first));
  const cv::Matx44d align = truth.at(first) * estimate.begin()->second.inv();
  double sum2 = 0;
  for (const auto& [stamp, e] : estimate) {
    ASSERT_TRUE(truth.count(stamp)) << stamp;
    const cv::Matx44d a = align * e, t = truth.at(stamp);
    sum2 += std::pow(a(0, 3) - t(0, 3), 2) + std::pow(a(1, 3) - t(1, 3), 2) +
            std::pow(a(2, 3) - t(2, 3), 2);
  }
  const double ate = std::sqrt(sum2 / static_cast<double>(estimate.size()));
  std::printf("Freiburg 1 folder through replay.yaml: %zu poses, ATE %.4f m\n", estimate.size(),
              ate);
  EXPECT_LT(ate, 0.05);
  EXPECT_EQ(counts["/camera/camera_info"], kFrames);
  // Every frame but the first (it initialises the map) is tracked; scene_light lights them.
  EXPECT_GE(counts["/scene/pose"], kFrames - 1) << log;
  EXPECT_GE(counts["/scene/light"], kFrames - 2) << log;
  EXPECT_EQ(counts["/camera/image_rect"], 0) << "rectified frames are not recorded by default";
}

// Views of a 10 x 7 board (9 x 6 inner corners, 40 mm squares) through the Freiburg 1 lens, tilted
// and moved around the image so that calibrateCamera sees the whole lens.
std::vector<cv::Mat> BoardViews() {
  const msgs::CameraInfo fr1 = rectify::test::Freiburg1Info();
  std::vector<cv::Mat> views;
  const double s = 0.04;
  const cv::Vec3d poses[][2] = {
      {{0.0, 0.0, 0.0}, {-0.2, -0.14, 0.55}},     {{0.35, 0.0, 0.0}, {-0.2, -0.14, 0.6}},
      {{-0.35, 0.0, 0.0}, {-0.2, -0.14, 0.6}},    {{0.0, 0.4, 0.0}, {-0.2, -0.14, 0.6}},
      {{0.0, -0.4, 0.0}, {-0.2, -0.14, 0.6}},     {{0.2, 0.25, 0.1}, {-0.32, -0.22, 0.6}},
      {{-0.2, 0.25, -0.1}, {-0.08, -0.22, 0.62}}, {{0.2, -0.25, 0.1}, {-0.32, -0.05, 0.62}},
      {{-0.2, -0.25, 0.0}, {-0.08, -0.05, 0.6}},  {{0.1, 0.1, 0.3}, {-0.18, -0.16, 0.5}},
  };
  for (const auto& p : poses) {
    views.push_back(rectify::test::RenderBoard(fr1, {10, 7}, s, p[0], p[1], true));
  }
  return views;
}

TEST(RectifyLaunch, CalibrateOutputReadsBackToTheSameMapsThroughEveryReader) {
  TempDir dir("rectify_calibrate");
  const std::vector<cv::Mat> views = BoardViews();
  const std::string topic = "/rectify_test/image";
  const std::string file = dir.File("fr1.yaml");
  bus::Publisher publisher(
      topic, msgs::TopicTypeOf<msgs::Image>(),
      {.max_message_bytes = msgs::Image::MessageBytesFor(640, 480, msgs::Encoding::kMono8)});
  Process calibrate("calibrate",
                    {"--size", "9x6", "--square", "0.04", "--frames", std::to_string(views.size()),
                     "--min-interval", "0", "--topic", topic, "--out", file, "--name", "fr1"});
  // Each view a few times (a queue of 1 drops some while the board is searched), until it exits.
  std::atomic<bool> stop{false};
  std::thread feeder([&] {
    for (size_t n = 0; !stop; ++n) {
      const cv::Mat& v = views[(n / 3) % views.size()];
      bus::Loan loan =
          publisher.Borrow(msgs::Image::MessageBytesFor(640, 480, msgs::Encoding::kMono8));
      auto out = msgs::WriteMessage<msgs::Image>(loan.data());
      out->Init(640, 480, msgs::Encoding::kMono8);
      out->header.stamp_ns = static_cast<int64_t>(n);
      std::memcpy(out.payload.data(), v.data, 640 * 480);
      publisher.Publish(std::move(loan));
      std::this_thread::sleep_for(std::chrono::milliseconds(60));
    }
  });
  const int code = calibrate.Wait(std::chrono::seconds(120));
  stop = true;
  feeder.join();
  ASSERT_EQ(code, 0) << calibrate.Err();
  ASSERT_TRUE(fs::exists(file)) << calibrate.Out() << calibrate.Err();

  // Reader 1: calib::ReadCalibrationFile (capture nodes' camera_info_url, dataset
  // camera_info_path).
  msgs::CameraInfo from_file;
  calib::FillCameraInfo(calib::ReadCalibrationFile(file), 0.001, from_file);
  // Reader 2: the TUM source's camera_info.yaml in the sequence folder, as the player publishes it.
  const fs::path folder = fs::path(dir.path()) / "rgbd_dataset_freiburg1_calibrated";
  fs::create_directories(folder / "rgb");
  fs::create_directories(folder / "depth");
  cv::Mat bgr;
  cv::cvtColor(views[0], bgr, cv::COLOR_GRAY2BGR);
  cv::imwrite((folder / "rgb" / "1.000000.png").string(), bgr);
  cv::imwrite((folder / "depth" / "1.000000.png").string(), cv::Mat(480, 640, CV_16UC1, 5000));
  testing::WriteText(folder / "rgb.txt", "1.000000 rgb/1.000000.png\n");
  testing::WriteText(folder / "depth.txt", "1.000000 depth/1.000000.png\n");
  fs::copy_file(file, folder / "camera_info.yaml");
  const std::unique_ptr<dataset::Source> source = dataset::OpenDataset(folder.string());
  std::optional<msgs::CameraInfo> from_player;
  while (auto m = source->Next()) {
    if (source->topics()[m->topic_index].topic == "/camera/camera_info") {
      from_player = *msgs::ReadMessage<msgs::CameraInfo>(m->message.bytes());
      break;
    }
  }
  ASSERT_TRUE(from_player);

  const rectify::Rectifier a(from_file, {}, file), b(*from_player, {}, "player");
  const rectify::Rectifier truth(rectify::test::Freiburg1Info());
  EXPECT_TRUE(a.Matches(*from_player));
  double worst_readers = 0, worst_truth = 0;
  for (uint32_t y = 0; y < 480; y += 4) {
    for (uint32_t x = 0; x < 640; x += 4) {
      const auto pa = a.SourcePixel(x, y), pb = b.SourcePixel(x, y), pt = truth.SourcePixel(x, y);
      worst_readers = std::max(worst_readers, double(std::hypot(pa[0] - pb[0], pa[1] - pb[1])));
      // The calibration itself against the true lens, where the board was seen (the centre 80 %):
      // K and the coefficients are estimates (measured 0.81 px, RMS reprojection 0.11 px).
      if (x > 64 && x < 576 && y > 48 && y < 432) {
        worst_truth = std::max(worst_truth, double(std::hypot(pa[0] - pt[0], pa[1] - pt[1])));
      }
    }
  }
  EXPECT_EQ(worst_readers, 0.0);
  EXPECT_LT(worst_truth, 1.0) << calibrate.Out();
  std::printf("%smaps vs the true lens: worst %.3f px (centre 80 %%)\n", calibrate.Out().c_str(),
              worst_truth);
}

// The node's Spin rule for bad input: the sample is rejected with one line naming the topic and
// the problem, and the node runs on (here until SIGINT: exit 0, with the count at exit).
TEST(RectifyLaunch, MalformedCameraInfoIsRejectedWithOneLineNamingTheTopicAndTheNodeRunsOn) {
  const std::string kInfoLine =
      "[error] [/rect_err/rectify] rejected a sample of /rect_err/camera_info: distortion "
      "coefficient 1 (k2) is NaN\n";
  const std::string kImageLine =
      "[error] [/rect_err/rectify] rejected a sample of /rect_err/image: image 320x240 does not "
      "match the calibration (640x480 from /rect_err/camera_info)\n";
  auto run = [](const std::function<void(bus::Publisher&, bus::Publisher&)>& feed,
                const std::string& expected) {
    Process node("rectify", {"--ros-args", "-r", "__ns:=/rect_err", "-r", "image:=/rect_err/image",
                             "-r", "camera_info:=/rect_err/camera_info"});
    bus::Publisher info("/rect_err/camera_info", msgs::TopicTypeOf<msgs::CameraInfo>(),
                        {.max_message_bytes = sizeof(msgs::CameraInfo)});
    bus::Publisher image(
        "/rect_err/image", msgs::TopicTypeOf<msgs::Image>(),
        {.max_message_bytes = msgs::Image::MessageBytesFor(640, 480, msgs::Encoding::kRgb8)});
    // Until the node has subscribed.
    for (int i = 0; i < 400 && (info.SubscriberCount() == 0 || image.SubscriberCount() == 0); ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    feed(info, image);
    for (int i = 0; i < 500 && node.Err().find(expected) == std::string::npos; ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(200));  // still running after it
    node.Signal(SIGINT);
    const int code = node.Wait(std::chrono::seconds(10));
    return std::make_pair(code, node.Err());
  };
  {
    const auto [code, err] = run(
        [](bus::Publisher& info, bus::Publisher&) {
          msgs::CameraInfo m = rectify::test::Freiburg1Info();
          m.distortion[1] = std::nan("");
          info.PublishCopy(std::as_bytes(std::span(&m, 1)));
        },
        kInfoLine);
    EXPECT_EQ(code, 0) << err;
    EXPECT_NE(err.find(kInfoLine), std::string::npos) << err;
    EXPECT_NE(err.find("[warn] [/rect_err/rectify] /rect_err/camera_info: rejected 1 of 1 "
                       "samples\n"),
              std::string::npos)
        << err;
  }
  {
    const auto [code, err] = run(
        [](bus::Publisher& info, bus::Publisher& image) {
          const msgs::CameraInfo m = rectify::test::Freiburg1Info();
          info.PublishCopy(std::as_bytes(std::span(&m, 1)));
          std::this_thread::sleep_for(std::chrono::milliseconds(200));
          bus::Loan loan =
              image.Borrow(msgs::Image::MessageBytesFor(320, 240, msgs::Encoding::kRgb8));
          auto out = msgs::WriteMessage<msgs::Image>(loan.data());
          out->Init(320, 240, msgs::Encoding::kRgb8);
          image.Publish(std::move(loan));
        },
        kImageLine);
    EXPECT_EQ(code, 0) << err;
    EXPECT_NE(err.find(kImageLine), std::string::npos) << err;
  }
  std::system((kBin + "/probeless clean > /dev/null 2>&1").c_str());
}

// A stream without camera_info: the first 30 frames wait for one, then frames pass through
// unrectified (a log recorded without camera_info must not stall the face tracker behind rectify).
TEST(RectifyLaunch, FramesPassThroughWhenNoCameraInfoEverComes) {
  Process node("rectify", {"--ros-args", "-r", "image:=/rect_none/image", "-r",
                           "image_rect:=/rect_none/image_rect", "-r", "__node:=rectify_none"});
  bus::Publisher image(
      "/rect_none/image", msgs::TopicTypeOf<msgs::Image>(),
      {.max_message_bytes = msgs::Image::MessageBytesFor(64, 48, msgs::Encoding::kMono8)});
  bus::Subscriber rect("/rect_none/image_rect", msgs::TopicTypeOf<msgs::Image>(),
                       {.queue_depth = 64});
  for (int i = 0; i < 400 && image.SubscriberCount() == 0; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  for (int i = 0; i < 40; ++i) {
    bus::Loan loan = image.Borrow(msgs::Image::MessageBytesFor(64, 48, msgs::Encoding::kMono8));
    auto out = msgs::WriteMessage<msgs::Image>(loan.data());
    out->Init(64, 48, msgs::Encoding::kMono8);
    out->header.stamp_ns = i;
    std::memset(out.payload.data(), i, 64 * 48);
    image.Publish(std::move(loan));
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  std::vector<int64_t> stamps;
  for (int tries = 0; tries < 100 && stamps.size() < 10; ++tries) {
    while (auto sample = rect.Take(std::chrono::milliseconds(20))) {
      const auto m = msgs::ReadMessage<msgs::Image>(sample->data());
      EXPECT_EQ(static_cast<int>(m.payload[0]), static_cast<int>(m->header.stamp_ns));
      stamps.push_back(m->header.stamp_ns);
    }
  }
  node.Signal(SIGINT);
  EXPECT_EQ(node.Wait(), 0) << node.Err();
  EXPECT_EQ(stamps, (std::vector<int64_t>{30, 31, 32, 33, 34, 35, 36, 37, 38, 39})) << node.Err();
  EXPECT_NE(node.Err().find("no /camera_info after 30 frames: passing frames through unrectified"),
            std::string::npos)
      << node.Err();
}

}  // namespace
}  // namespace probeless
