// Unit tests of the dataset sources on synthetic folders written by the tests.
#include "probeless/dataset/datasets.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include "internal.h"
#include "probeless/dataset/yaleb.h"
#include "probeless/testing/expect.h"
#include "testing_util.h"
#include "text_io.h"

namespace probeless::dataset {
namespace {

using probeless::testing::ThrownMessage;
using testing::Drain;
using testing::TempDir;
using testing::View;
using testing::WriteText;

constexpr double kPi = std::numbers::pi;

// A BGR image whose pixel (x, y) is (b, g, r) = (x + seed, y + 2 * seed, 3 * seed) (mod 256).
cv::Mat PatternBgr(int width, int height, int seed) {
  cv::Mat image(height, width, CV_8UC3);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      image.at<cv::Vec3b>(y, x) =
          cv::Vec3b(static_cast<uint8_t>(x + seed), static_cast<uint8_t>(y + 2 * seed),
                    static_cast<uint8_t>(3 * seed));
    }
  }
  return image;
}

void WritePng(const std::string& path, const cv::Mat& image) {
  ASSERT_TRUE(cv::imwrite(path, image)) << path;
}

// Rz(angle) as a row-major 4x4 camera-to-world matrix with translation t.
std::string PoseText(double angle, double tx, double ty, double tz) {
  const double c = std::cos(angle);
  const double s = std::sin(angle);
  char text[512];
  std::snprintf(text, sizeof(text),
                "%.17g %.17g 0 %.17g\n%.17g %.17g 0 %.17g\n0 0 1 %.17g\n0 0 0 1\n", c, -s, tx, s, c,
                ty, tz);
  return text;
}

// ---------------------------------------------------------------------------------------------
// 7-Scenes

struct SevenScenesFolder {
  explicit SevenScenesFolder(const TempDir& dir, int frames = 3) : path(dir.File("seq-01")) {
    std::filesystem::create_directories(path);
    WriteText(path + "/camera-intrinsics.txt", "500 0 31.5\n0 510 23.5\n0 0 1\n");
    for (int i = 0; i < frames; ++i) {
      char stem[64];
      std::snprintf(stem, sizeof(stem), "/frame-%06d", i);
      WritePng(path + stem + ".color.png", PatternBgr(64, 48, i + 1));
      cv::Mat depth(48, 64, CV_16UC1, cv::Scalar(1000 + i));
      depth.at<uint16_t>(0, 0) = 65535;  // invalid in 7-Scenes
      depth.at<uint16_t>(1, 0) = 0;      // invalid too
      depth.at<uint16_t>(2, 0) = 65534;  // valid, kept
      WritePng(path + stem + ".depth.png", depth);
      WriteText(path + stem + ".pose.txt", PoseText(kPi / 2 * i, 0.1 * i, -0.2, 1.5));
    }
  }
  std::string path;
};

TEST(SevenScenesTest, TopicsAreExactAndKnownUpFront) {
  TempDir dir;
  SevenScenesFolder folder(dir);
  const std::unique_ptr<Source> source = OpenDataset(folder.path);
  EXPECT_EQ(source->kind(), "7scenes");
  EXPECT_EQ(source->path(), folder.path);
  const std::vector<TopicInfo>& topics = source->topics();
  ASSERT_EQ(topics.size(), 4u);
  EXPECT_EQ(topics[0].topic, "/camera/camera_info");
  EXPECT_EQ(topics[0].type_name, "probeless_msgs/CameraInfo");
  EXPECT_EQ(topics[0].layout_hash, msgs::CameraInfo::kLayoutHash);
  EXPECT_EQ(topics[0].max_message_bytes, sizeof(msgs::CameraInfo));
  EXPECT_EQ(topics[1].topic, "/camera/image");
  EXPECT_EQ(topics[1].type_name, "probeless_msgs/Image");
  EXPECT_EQ(topics[1].max_message_bytes,
            msgs::Image::MessageBytesFor(64, 48, msgs::Encoding::kRgb8));
  EXPECT_EQ(topics[2].topic, "/camera/depth");
  EXPECT_EQ(topics[2].max_message_bytes,
            msgs::Image::MessageBytesFor(64, 48, msgs::Encoding::kDepth16));
  EXPECT_EQ(topics[3].topic, "/groundtruth/pose");
  EXPECT_EQ(topics[3].type_name, "probeless_msgs/Pose");
  EXPECT_EQ(topics[3].layout_hash, msgs::Pose::kLayoutHash);
  for (const TopicInfo& topic : topics) EXPECT_EQ(topic.message_count, 3u) << topic.topic;
  EXPECT_EQ(source->message_count(), 12u);
  ASSERT_TRUE(source->time_range().has_value());
  EXPECT_EQ(source->time_range()->first, 0u);
  EXPECT_EQ(source->time_range()->second, 66'666'667u);
}

TEST(SevenScenesTest, FramesInOrderWithTimingValuesAndFrames) {
  TempDir dir;
  SevenScenesFolder folder(dir);
  const std::unique_ptr<Source> source = OpenDataset("7scenes:" + folder.path);
  const std::vector<StreamMessage> messages = Drain(*source);
  ASSERT_EQ(messages.size(), 12u);
  const uint64_t times[] = {0, 33'333'333, 66'666'667};
  for (size_t i = 0; i < messages.size(); ++i) {
    EXPECT_EQ(messages[i].topic_index, i % 4) << i;
    EXPECT_EQ(messages[i].log_time_ns, times[i / 4]) << i;
    EXPECT_EQ(messages[i].message.size(), source->topics()[i % 4].max_message_bytes) << i;
  }
  for (int f = 0; f < 3; ++f) {
    const auto info = View<msgs::CameraInfo>(messages[f * 4 + 0]);
    EXPECT_NO_THROW(info->Validate());
    EXPECT_EQ(info->header.FrameId(), "camera");
    EXPECT_EQ(info->header.stamp_ns, static_cast<int64_t>(times[f]));
    EXPECT_EQ(info->header.sequence, static_cast<uint64_t>(f + 1));
    EXPECT_EQ(info->width, 64u);
    EXPECT_EQ(info->height, 48u);
    EXPECT_EQ(info->fx, 500);
    EXPECT_EQ(info->fy, 510);
    EXPECT_EQ(info->cx, 31.5);
    EXPECT_EQ(info->cy, 23.5);
    EXPECT_EQ(info->distortion_model, msgs::DistortionModel::kPlumbBob);  // as ROS: five zeros
    EXPECT_EQ(info->distortion_count, 5u);
    for (uint32_t i = 0; i < 5; ++i) EXPECT_EQ(info->distortion[i], 0.0);
    EXPECT_EQ(info->depth_scale, 0.001);

    const auto image = View<msgs::Image>(messages[f * 4 + 1]);
    EXPECT_EQ(image->Describe(), "64x48 rgb8 (step 192)");
    EXPECT_EQ(image->header.FrameId(), "camera");
    EXPECT_EQ(image->header.sequence, static_cast<uint64_t>(f + 1));
    const auto row = msgs::ImageRow<uint8_t>(*image, image.payload, 5);
    // Pixel (7, 5): R = 3 * seed, G = 5 + 2 * seed, B = 7 + seed (written as BGR).
    const int seed = f + 1;
    EXPECT_EQ(row[7 * 3 + 0], 3 * seed);
    EXPECT_EQ(row[7 * 3 + 1], 5 + 2 * seed);
    EXPECT_EQ(row[7 * 3 + 2], 7 + seed);

    const auto depth = View<msgs::Image>(messages[f * 4 + 2]);
    EXPECT_EQ(depth->Describe(), "64x48 depth16 (step 128)");
    EXPECT_EQ(msgs::ImageRow<uint16_t>(*depth, depth.payload, 0)[0], 0);  // 65535 -> 0
    EXPECT_EQ(msgs::ImageRow<uint16_t>(*depth, depth.payload, 1)[0], 0);
    EXPECT_EQ(msgs::ImageRow<uint16_t>(*depth, depth.payload, 2)[0], 65534);
    EXPECT_EQ(msgs::ImageRow<uint16_t>(*depth, depth.payload, 3)[4], 1000 + f);

    const auto pose = View<msgs::Pose>(messages[f * 4 + 3]);
    EXPECT_EQ(pose->ParentFrameId(), "world");
    EXPECT_EQ(pose->header.FrameId(), "world");
    EXPECT_EQ(pose->ChildFrameId(), "camera");
    EXPECT_EQ(pose->header.stamp_ns, static_cast<int64_t>(times[f]));
    EXPECT_NEAR(pose->transform.translation.x, 0.1 * f, 1e-12);
    EXPECT_NEAR(pose->transform.translation.y, -0.2, 1e-12);
    EXPECT_NEAR(pose->transform.translation.z, 1.5, 1e-12);
    // Rz(f * 90 deg): q = (cos(f * 45 deg), 0, 0, sin(f * 45 deg)).
    EXPECT_NEAR(pose->transform.rotation.w, std::cos(kPi / 4 * f), 1e-12);
    EXPECT_NEAR(pose->transform.rotation.x, 0, 1e-12);
    EXPECT_NEAR(pose->transform.rotation.y, 0, 1e-12);
    EXPECT_NEAR(pose->transform.rotation.z, std::sin(kPi / 4 * f), 1e-12);
    // The camera's x axis maps to the world's Rz(f * 90 deg) x axis.
    const msgs::Vector3 p = pose->transform.Apply({1, 0, 0});
    EXPECT_NEAR(p.x, std::cos(kPi / 2 * f) + 0.1 * f, 1e-12);
    EXPECT_NEAR(p.y, std::sin(kPi / 2 * f) - 0.2, 1e-12);
  }
}

TEST(SevenScenesTest, RewindMaxFramesFpsAndPrefixes) {
  TempDir dir;
  SevenScenesFolder folder(dir);
  DatasetOptions options;
  options.max_frames = 2;
  options.fps = 10;
  options.topic_prefix = "/kinect/rgbd";
  options.ground_truth_prefix = "/gt";
  options.camera_frame_id = "kinect_optical";
  options.world_frame_id = "map";
  const std::unique_ptr<Source> source = OpenDataset(folder.path, options);
  EXPECT_EQ(source->topics()[1].topic, "/kinect/rgbd/image");
  EXPECT_EQ(source->topics()[3].topic, "/gt/pose");
  EXPECT_EQ(source->message_count(), 8u);
  std::vector<StreamMessage> first = Drain(*source);
  ASSERT_EQ(first.size(), 8u);
  EXPECT_EQ(first[4].log_time_ns, 100'000'000u);
  EXPECT_FALSE(source->Next().has_value());
  source->Rewind();
  std::vector<StreamMessage> second = Drain(*source);
  ASSERT_EQ(second.size(), 8u);
  for (size_t i = 0; i < first.size(); ++i) {
    ASSERT_EQ(first[i].message.size(), second[i].message.size());
    EXPECT_TRUE(std::equal(first[i].message.bytes().begin(), first[i].message.bytes().end(),
                           second[i].message.bytes().begin()))
        << i;
  }
  const auto pose = View<msgs::Pose>(first[3]);
  EXPECT_EQ(pose->ParentFrameId(), "map");
  EXPECT_EQ(pose->ChildFrameId(), "kinect_optical");
}

TEST(SevenScenesTest, JpegColourWithoutDepthPoseOrIntrinsics) {
  TempDir dir;
  const std::string path = dir.File("scene");
  std::filesystem::create_directories(path);
  for (int i = 0; i < 2; ++i) {
    ASSERT_TRUE(cv::imwrite(path + "/frame-00000" + std::to_string(i) + ".color.jpg",
                            PatternBgr(32, 24, 40)));
  }
  const std::unique_ptr<Source> source = OpenDataset(path);
  ASSERT_EQ(source->topics().size(), 2u);
  const std::vector<StreamMessage> messages = Drain(*source);
  ASSERT_EQ(messages.size(), 4u);
  const auto info = View<msgs::CameraInfo>(messages[0]);
  // The published 7-Scenes intrinsics when camera-intrinsics.txt is absent.
  EXPECT_EQ(info->fx, 585);
  EXPECT_EQ(info->cx, 320);
  EXPECT_EQ(info->depth_scale, 0);
  const auto image = View<msgs::Image>(messages[1]);
  EXPECT_EQ(image->Describe(), "32x24 rgb8 (step 96)");
  // JPEG is lossy: R = 120, G = 80 + y, B = 40 + x roughly.
  EXPECT_NEAR(msgs::ImageRow<uint8_t>(*image, image.payload, 10)[5 * 3 + 0], 120, 6);
}

TEST(SevenScenesTest, BadFilesNameTheFileAndTheExpectation) {
  TempDir dir;
  SevenScenesFolder folder(dir);
  const std::string pose1 = folder.path + "/frame-000001.pose.txt";
  WriteText(pose1, "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0\n");
  const std::unique_ptr<Source> source = OpenDataset(folder.path);
  for (int i = 0; i < 4; ++i) ASSERT_TRUE(source->Next().has_value());
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { source->Next(); }),
            "malformed pose file '" + pose1 +
                "': expected 16 numbers (a 4x4 camera-to-world matrix), found 15 numbers");
  // The pass continues with the next frame, and Rewind starts again.
  const std::optional<StreamMessage> next = source->Next();
  ASSERT_TRUE(next.has_value());
  EXPECT_EQ(next->log_time_ns, 66'666'667u);
  source->Rewind();
  EXPECT_EQ(source->Next()->log_time_ns, 0u);

  WriteText(pose1, "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 x\n");
  source->Rewind();
  for (int i = 0; i < 4; ++i) source->Next();
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { source->Next(); }),
            "malformed pose file '" + pose1 +
                "': expected 16 numbers (a 4x4 camera-to-world matrix), found 'x'");
  WriteText(pose1, "2 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n");
  source->Rewind();
  for (int i = 0; i < 4; ++i) source->Next();
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { source->Next(); }),
            "malformed pose file '" + pose1 +
                "': expected a rotation (orthonormal, determinant +1) in the upper-left 3x3");
  WriteText(pose1, "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 1 1\n");
  source->Rewind();
  for (int i = 0; i < 4; ++i) source->Next();
  EXPECT_EQ(
      ThrownMessage<DatasetError>([&] { source->Next(); }),
      "malformed pose file '" + pose1 + "': expected the last row 0 0 0 1 of a rigid transform");

  // An undecodable colour image.
  WriteText(pose1, PoseText(0, 0, 0, 0));
  const std::string colour2 = folder.path + "/frame-000002.color.png";
  WriteText(colour2, "not a png");
  source->Rewind();
  for (int i = 0; i < 8; ++i) source->Next();
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { source->Next(); }),
            "cannot decode colour image '" + colour2 + "': expected an 8-bit colour JPEG or PNG");
  // A depth image of the wrong type.
  WritePng(colour2, PatternBgr(64, 48, 3));
  const std::string depth2 = folder.path + "/frame-000002.depth.png";
  WritePng(depth2, PatternBgr(64, 48, 3));
  source->Rewind();
  for (int i = 0; i < 8; ++i) source->Next();
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { source->Next(); }),
            "depth image '" + depth2 +
                "' is 64x48 8-bit 3-channel: expected a 16-bit single-channel 64x48 PNG like the "
                "first frame");
}

TEST(SevenScenesTest, BadFolderErrorsAtOpen) {
  TempDir dir;
  SevenScenesFolder folder(dir);
  const std::string intrinsics = folder.path + "/camera-intrinsics.txt";
  WriteText(intrinsics, "500 0 31.5 0 510 23.5 0 0\n");
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset(folder.path); }),
            "malformed camera intrinsics '" + intrinsics +
                "': expected 9 numbers (a 3x3 camera matrix), found 8 numbers");
  WriteText(intrinsics, "500 0 31.5 0 510 23.5 0 0 2\n");
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset(folder.path); }),
            "malformed camera intrinsics '" + intrinsics +
                "': expected a camera matrix [fx 0 cx; 0 fy cy; 0 0 1] with fx, fy > 0");
  std::filesystem::remove(intrinsics);
  std::filesystem::remove(folder.path + "/frame-000001.depth.png");
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset(folder.path); }),
            "missing depth image '" + folder.path +
                "/frame-000001.depth.png' (the other frames of '" + folder.path + "' have one)");
  std::filesystem::remove(folder.path + "/frame-000001.color.png");
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset(folder.path); }),
            "7-Scenes folder '" + folder.path + "': '" + folder.path +
                "/frame-000001.pose.txt' has no colour image frame-XXXXXX.color.jpg|png beside it");
  TempDir empty;
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset("7scenes:" + empty.path()); }),
            "7-Scenes folder '" + empty.path() + "' has no frame-XXXXXX.color.jpg|png files");
}

// ---------------------------------------------------------------------------------------------
// TUM RGB-D

// rgb at t0, t0 + 10 ms, t0 + 100 ms; depth at t0 + 6 ms (closer to the second rgb: greedy
// association gives it to the second), t0 + 130 ms (too far from the third: none).
struct TumFolder {
  explicit TumFolder(const TempDir& dir, const std::string& name = "rgbd_dataset_test")
      : path(dir.File(name)) {
    std::filesystem::create_directories(path + "/rgb");
    std::filesystem::create_directories(path + "/depth");
    WriteText(path + "/rgb.txt",
              "# color images\n# file: 'test.bag'\n# timestamp filename\n"
              "1305031102.100000 rgb/a.png\n"
              "1305031102.110000 rgb/b.png\n"
              "1305031102.200000 rgb/c.png\n");
    WriteText(path + "/depth.txt",
              "# depth maps\n# timestamp filename\n"
              "1305031102.106000 depth/a.png\n"
              "1305031102.230000 depth/b.png\n");
    WriteText(path + "/groundtruth.txt",
              "# ground truth trajectory\n# timestamp tx ty tz qx qy qz qw\n"
              "1305031102.0900 1.0 2.0 3.0 0 0 0 1\n"
              "1305031102.1200 1.3 2.0 3.0 0 0 0.7071067811865476 0.7071067811865476\n"
              "1305031102.3000 0 0 0 0 0 0 1\n");
    for (const char* name : {"a", "b", "c"}) {
      WritePng(path + "/rgb/" + name + ".png", PatternBgr(40, 30, name[0] - 'a'));
    }
    cv::Mat depth(30, 40, CV_16UC1, cv::Scalar(5000));  // 1 m
    depth.at<uint16_t>(0, 1) = 12;                      // 2.4 mm -> 2
    depth.at<uint16_t>(0, 2) = 13;                      // 2.6 mm -> 3
    depth.at<uint16_t>(0, 3) = 0;                       // invalid
    depth.at<uint16_t>(0, 4) = 65535;                   // 13107 mm
    WritePng(path + "/depth/a.png", depth);
    WritePng(path + "/depth/b.png", depth);
  }
  std::string path;
};

TEST(TumTest, AssociatesDepthConvertsMillimetresAndInterpolatesGroundTruth) {
  TempDir dir;
  TumFolder folder(dir);
  EXPECT_EQ(DetectDatasetKind(folder.path), "tum");
  const std::unique_ptr<Source> source = OpenDataset(folder.path);
  EXPECT_EQ(source->kind(), "tum");
  const std::vector<TopicInfo>& topics = source->topics();
  ASSERT_EQ(topics.size(), 4u);
  EXPECT_EQ(topics[0].topic, "/camera/camera_info");
  EXPECT_EQ(topics[0].message_count, 3u);
  EXPECT_EQ(topics[1].topic, "/camera/image");
  EXPECT_EQ(topics[1].message_count, 3u);
  EXPECT_EQ(topics[2].topic, "/camera/depth");
  EXPECT_EQ(topics[2].message_count, 1u);
  EXPECT_EQ(topics[2].max_message_bytes,
            msgs::Image::MessageBytesFor(40, 30, msgs::Encoding::kDepth16));
  EXPECT_EQ(topics[3].topic, "/groundtruth/pose");
  EXPECT_EQ(topics[3].message_count, 2u);  // the third rgb is 100 ms from any ground truth
  EXPECT_EQ(source->time_range()->first, 1'305'031'102'100'000'000u);
  EXPECT_EQ(source->time_range()->second, 1'305'031'102'200'000'000u);

  const std::vector<StreamMessage> messages = Drain(*source);
  // Frame 1: info, image, pose. Frame 2: info, image, depth, pose. Frame 3: info, image.
  ASSERT_EQ(messages.size(), 9u);
  const size_t expected_topics[] = {0, 1, 3, 0, 1, 2, 3, 0, 1};
  const uint64_t expected_times[] = {1'305'031'102'100'000'000u, 1'305'031'102'110'000'000u,
                                     1'305'031'102'200'000'000u};
  const size_t expected_frame[] = {0, 0, 0, 1, 1, 1, 1, 2, 2};
  for (size_t i = 0; i < messages.size(); ++i) {
    EXPECT_EQ(messages[i].topic_index, expected_topics[i]) << i;
    EXPECT_EQ(messages[i].log_time_ns, expected_times[expected_frame[i]]) << i;
  }
  const auto info = View<msgs::CameraInfo>(messages[0]);
  // ROS default intrinsics for a folder without freiburg1|2|3 in its name.
  EXPECT_EQ(info->fx, 525);
  EXPECT_EQ(info->fy, 525);
  EXPECT_EQ(info->cx, 319.5);
  EXPECT_EQ(info->cy, 239.5);
  EXPECT_EQ(info->depth_scale, 0.001);
  EXPECT_EQ(info->header.stamp_ns, 1'305'031'102'100'000'000);

  const auto depth = View<msgs::Image>(messages[5]);
  EXPECT_EQ(depth->encoding, msgs::Encoding::kDepth16);
  EXPECT_EQ(depth->header.stamp_ns, 1'305'031'102'110'000'000);  // the rgb image's stamp
  const auto row0 = msgs::ImageRow<uint16_t>(*depth, depth.payload, 0);
  EXPECT_EQ(row0[0], 1000);
  EXPECT_EQ(row0[1], 2);
  EXPECT_EQ(row0[2], 3);
  EXPECT_EQ(row0[3], 0);
  EXPECT_EQ(row0[4], 13107);

  // t = 100 ms lies 1/3 of the way from the 90 ms to the 120 ms sample.
  const auto pose0 = View<msgs::Pose>(messages[2]);
  EXPECT_EQ(pose0->ParentFrameId(), "world");
  EXPECT_EQ(pose0->ChildFrameId(), "camera");
  EXPECT_NEAR(pose0->transform.translation.x, 1.1, 1e-12);
  EXPECT_NEAR(pose0->transform.translation.y, 2.0, 1e-12);
  EXPECT_NEAR(pose0->transform.rotation.w, std::cos(kPi / 4 / 3), 1e-9);
  EXPECT_NEAR(pose0->transform.rotation.z, std::sin(kPi / 4 / 3), 1e-9);
  const auto pose1 = View<msgs::Pose>(messages[6]);
  EXPECT_NEAR(pose1->transform.translation.x, 1.2, 1e-12);
  EXPECT_NEAR(pose1->transform.rotation.w, std::cos(kPi / 4 * 2 / 3), 1e-9);
}

TEST(TumTest, FreiburgIntrinsicsAndCameraInfoOverrides) {
  TempDir dir;
  TumFolder fr1(dir, "rgbd_dataset_freiburg1_xyz");
  {
    const std::unique_ptr<Source> source = OpenDataset(fr1.path);
    const auto info = View<msgs::CameraInfo>(*source->Next());
    EXPECT_EQ(info->fx, 517.3);
    EXPECT_EQ(info->fy, 516.5);
    EXPECT_EQ(info->cx, 318.6);
    EXPECT_EQ(info->cy, 255.3);
    EXPECT_EQ(info->distortion_model, msgs::DistortionModel::kPlumbBob);
    EXPECT_EQ(info->distortion[0], 0.2624);
    EXPECT_EQ(info->distortion[4], 1.1633);
  }
  TumFolder fr3(dir, "rgbd_dataset_freiburg3_long_office_household/");
  {
    const std::unique_ptr<Source> source = OpenDataset(fr3.path);
    const auto info = View<msgs::CameraInfo>(*source->Next());
    EXPECT_EQ(info->fx, 535.4);
    // No distortion is published as ROS writes it: plumb_bob with five zeros.
    EXPECT_EQ(info->distortion_model, msgs::DistortionModel::kPlumbBob);
    EXPECT_EQ(info->distortion_count, 5u);
    EXPECT_EQ(info->distortion[0], 0.0);
  }

  // ROS camera_info YAML.
  const std::string ros = dir.File("ros.yaml");
  WriteText(ros,
            "image_width: 40\nimage_height: 30\ncamera_name: test\n"
            "camera_matrix:\n  rows: 3\n  cols: 3\n  data: [100, 0, 19.5, 0, 101, 14.5, 0, 0, 1]\n"
            "distortion_model: plumb_bob\n"
            "distortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [0.1, -0.2, 0.001, 0.002, 0]\n"
            "rectification_matrix:\n  rows: 3\n  cols: 3\n  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]\n");
  DatasetOptions options;
  options.camera_info_path = ros;
  {
    const std::unique_ptr<Source> source = OpenDataset(fr1.path, options);
    const auto info = View<msgs::CameraInfo>(*source->Next());
    EXPECT_EQ(info->fx, 100);
    EXPECT_EQ(info->fy, 101);
    EXPECT_EQ(info->cx, 19.5);
    EXPECT_EQ(info->cy, 14.5);
    EXPECT_EQ(info->distortion_model, msgs::DistortionModel::kPlumbBob);
    EXPECT_EQ(info->distortion_count, 5u);
    EXPECT_EQ(info->distortion[1], -0.2);
    EXPECT_EQ(info->depth_scale, 0.001);
  }
  // OpenCV FileStorage, YAML and XML.
  for (const std::string name : {"cv.yaml", "cv.xml"}) {
    const std::string file = dir.File(name);
    {
      cv::FileStorage storage(file, cv::FileStorage::WRITE);
      storage << "image_width" << 40 << "image_height" << 30;
      storage << "camera_matrix" << (cv::Mat_<double>(3, 3) << 200, 0, 20, 0, 201, 15, 0, 0, 1);
      storage << "distortion_coefficients"
              << (cv::Mat_<double>(1, 8) << 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8);
    }
    options.camera_info_path = file;
    const std::unique_ptr<Source> source = OpenDataset(fr1.path, options);
    const auto info = View<msgs::CameraInfo>(*source->Next());
    EXPECT_EQ(info->fx, 200) << name;
    EXPECT_EQ(info->cy, 15) << name;
    EXPECT_EQ(info->distortion_model, msgs::DistortionModel::kRationalPolynomial) << name;
    EXPECT_EQ(info->distortion[7], 0.8) << name;
  }
  // Errors.
  WriteText(ros,
            "image_width: 640\nimage_height: 480\n"
            "camera_matrix: {rows: 3, cols: 3, data: [1, 0, 2, 0, 1, 2, 0, 0, 1]}\n");
  options.camera_info_path = ros;
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset(fr1.path, options); }),
            "calibration file '" + ros + "' is for 640x480 images, the dataset's are 40x30");
  WriteText(ros, "image_width: 40\n");
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset(fr1.path, options); }),
            "calibration file '" + ros +
                "': missing camera_matrix (expected a ROS camera_info YAML file)");
  WriteText(ros, "camera_matrix: {rows: 3, cols: 3, data: [1, 0, 2, 0, 1, 2, 0, 0]}\n");
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset(fr1.path, options); }),
            "calibration file '" + ros + "': camera matrix has 8 entries, expected 9 (3x3)");
  WriteText(ros,
            "camera_matrix: {rows: 3, cols: 3, data: [1, 0, 2, 0, 1, 2, 0, 0, 1]}\n"
            "distortion_model: equidistant\n");
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset(fr1.path, options); }),
            "calibration file '" + ros +
                "': distortion_model 'equidistant' is not supported (expected plumb_bob or "
                "rational_polynomial)");
  options.camera_info_path = dir.File("absent.yaml");
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset(fr1.path, options); }),
            "cannot read calibration file '" + options.camera_info_path + "'");
}

TEST(TumTest, CameraInfoYamlInTheFolderIsReadAndTheOptionWins) {
  TempDir dir;
  TumFolder fr1(dir, "rgbd_dataset_freiburg1_xyz");
  WriteText(fr1.path + "/camera_info.yaml",
            "image_width: 40\nimage_height: 30\ncamera_name: folder\n"
            "camera_matrix:\n  rows: 3\n  cols: 3\n  data: [90, 0, 19.5, 0, 91, 14.5, 0, 0, 1]\n"
            "distortion_model: plumb_bob\n"
            "distortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [0, 0, 0, 0, 0]\n");
  {
    // The folder's file replaces the freiburg1 table.
    const std::unique_ptr<Source> source = OpenDataset(fr1.path);
    const auto info = View<msgs::CameraInfo>(*source->Next());
    EXPECT_EQ(info->fx, 90);
    EXPECT_EQ(info->fy, 91);
    EXPECT_EQ(info->cx, 19.5);
    EXPECT_EQ(info->depth_scale, 0.001);
  }
  const std::string option_file = dir.File("option.yaml");
  WriteText(option_file,
            "camera_matrix: {rows: 3, cols: 3, data: [70, 0, 19.5, 0, 71, 14.5, 0, 0, 1]}\n");
  DatasetOptions options;
  options.camera_info_path = option_file;
  {
    const std::unique_ptr<Source> source = OpenDataset(fr1.path, options);
    EXPECT_EQ(View<msgs::CameraInfo>(*source->Next())->fx, 70);
  }
  // A malformed folder file is an error naming it.
  WriteText(fr1.path + "/camera_info.yaml", "image_width: 40\n");
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset(fr1.path); }),
            "calibration file '" + fr1.path +
                "/camera_info.yaml': missing camera_matrix (expected a ROS camera_info YAML file)");
}

TEST(TumTest, MalformedListsAndMissingFiles) {
  TempDir dir;
  TumFolder folder(dir);
  const std::string rgb = folder.path + "/rgb.txt";
  WriteText(rgb, "# comment\n1305031102.100000 rgb/a.png extra\n");
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset(folder.path); }),
            "malformed line 2 of '" + rgb + "': expected 'timestamp filename'");
  WriteText(rgb, "1305031102,1 rgb/a.png\n");
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset(folder.path); }),
            "malformed line 1 of '" + rgb + "': '1305031102,1' is not a timestamp in seconds");
  WriteText(rgb, "1305031102.1 rgb/missing.png\n");
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset(folder.path); }),
            "missing rgb image '" + folder.path + "/rgb/missing.png' (line 1 of '" + rgb + "')");
  WriteText(rgb, "# nothing\n");
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset(folder.path); }),
            "TUM list '" + rgb + "' lists no images (expected 'timestamp filename' lines)");
  WriteText(rgb, "1305031102.100000 rgb/a.png\n");
  const std::string gt = folder.path + "/groundtruth.txt";
  WriteText(gt, "1305031102.09 1 2 3 0 0 0\n");
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset(folder.path); }),
            "malformed line 1 of '" + gt + "': expected 'timestamp tx ty tz qx qy qz qw'");
  WriteText(gt, "1305031102.09 1 2 3 0 0 0 2\n");
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset(folder.path); }),
            "malformed line 1 of '" + gt + "': qx qy qz qw is not a unit quaternion");
  WriteText(gt, "1305031102.09 1 2 nan 0 0 0 1\n");
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset(folder.path); }),
            "malformed line 1 of '" + gt + "': 'nan' is not a number");
  std::filesystem::remove(folder.path + "/depth.txt");
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset("tum:" + folder.path); }),
            "cannot read TUM list '" + folder.path + "/depth.txt'");
}

TEST(TumTest, TimestampsAreExact) {
  uint64_t ns = 0;
  ASSERT_TRUE(internal::ParseSecondsToNs("1305031102.175304", ns));
  EXPECT_EQ(ns, 1'305'031'102'175'304'000u);
  ASSERT_TRUE(internal::ParseSecondsToNs("12", ns));
  EXPECT_EQ(ns, 12'000'000'000u);
  ASSERT_TRUE(internal::ParseSecondsToNs("0.0000000015", ns));
  EXPECT_EQ(ns, 2u);
  EXPECT_FALSE(internal::ParseSecondsToNs("-1.0", ns));
  EXPECT_FALSE(internal::ParseSecondsToNs("1.", ns));
  EXPECT_FALSE(internal::ParseSecondsToNs("1e9", ns));
}

// ---------------------------------------------------------------------------------------------
// Extended Yale B

std::string YaleName(int subject, int azimuth, int elevation) {
  char name[64];
  std::snprintf(name, sizeof(name), "yaleB%02d_P00A%+04dE%+03d.pgm", subject, azimuth, elevation);
  return name;
}

// Parent folder with yaleB02 and yaleB01 subject folders.
struct YaleFolder {
  explicit YaleFolder(const TempDir& dir) : path(dir.File("yale")) {
    const int lights[][2] = {{0, 0}, {90, 0}, {-90, 0}, {0, 90}, {0, -35}, {45, 20}, {-130, 20}};
    for (int subject : {2, 1}) {
      const std::string folder = path + "/" + YaleName(subject, 0, 0).substr(0, 7);
      std::filesystem::create_directories(folder);
      for (const auto& light : lights) {
        cv::Mat face(192, 168, CV_8UC1, cv::Scalar(subject * 10 + (light[0] + 130) / 10));
        WritePng(folder + "/" + YaleName(subject, light[0], light[1]), face);
      }
      WritePng(folder + "/" + folder.substr(folder.size() - 7) + "_P00_Ambient.pgm",
               cv::Mat(480, 640, CV_8UC1, cv::Scalar(0)));
      WriteText(folder + "/" + folder.substr(folder.size() - 7) + "_P00.info", "list\n");
    }
  }
  std::string path;
};

TEST(YaleBTest, FileNames) {
  const auto name = ParseYaleBName("yaleB07_P00A-035E+65.pgm");
  ASSERT_TRUE(name.has_value());
  EXPECT_EQ(name->subject, 7);
  EXPECT_EQ(name->azimuth_deg, -35);
  EXPECT_EQ(name->elevation_deg, 65);
  EXPECT_FALSE(ParseYaleBName("yaleB07_P00_Ambient.pgm").has_value());
  EXPECT_FALSE(ParseYaleBName("yaleB07_P00A-035E+65.pgm.bad").has_value());
  EXPECT_FALSE(ParseYaleBName("yaleB07_P00A035E+65.pgm").has_value());
  EXPECT_EQ(YaleName(3, -5, 0), "yaleB03_P00A-005E+00.pgm");
}

TEST(YaleBTest, LightDirectionsFollowTheCameraFrame) {
  auto expect_direction = [](double a, double e, double x, double y, double z) {
    const std::array<double, 3> d = YaleBLightDirection(a, e);
    EXPECT_NEAR(d[0], x, 1e-12) << a << " " << e;
    EXPECT_NEAR(d[1], y, 1e-12) << a << " " << e;
    EXPECT_NEAR(d[2], z, 1e-12) << a << " " << e;
  };
  expect_direction(0, 0, 0, 0, -1);   // frontal: from the face back towards the camera
  expect_direction(90, 0, -1, 0, 0);  // subject's right = image left = -x
  expect_direction(-90, 0, 1, 0, 0);  // subject's left = image right = +x
  expect_direction(0, 90, 0, -1, 0);  // above = -y (y points down)
  expect_direction(0, -35, 0, std::sin(35 * kPi / 180), -std::cos(35 * kPi / 180));  // below
  expect_direction(45, 20, -std::sin(kPi / 4) * std::cos(kPi / 9), -std::sin(kPi / 9),
                   -std::cos(kPi / 4) * std::cos(kPi / 9));
}

TEST(YaleBTest, SubjectsThenAzimuthThenElevationWithLights) {
  TempDir dir;
  YaleFolder folder(dir);
  EXPECT_EQ(DetectDatasetKind(folder.path), "yaleb");
  const std::unique_ptr<Source> source = OpenDataset(folder.path);
  EXPECT_EQ(source->kind(), "yaleb");
  const std::vector<TopicInfo>& topics = source->topics();
  ASSERT_EQ(topics.size(), 3u);
  EXPECT_EQ(topics[0].topic, "/camera/camera_info");
  EXPECT_EQ(topics[1].topic, "/camera/image");
  EXPECT_EQ(topics[1].max_message_bytes,
            msgs::Image::MessageBytesFor(168, 192, msgs::Encoding::kMono8));
  EXPECT_EQ(topics[2].topic, "/groundtruth/light");
  EXPECT_EQ(topics[2].type_name, "probeless_msgs/ShLight");
  EXPECT_EQ(topics[2].layout_hash, msgs::ShLight::kLayoutHash);
  EXPECT_EQ(source->message_count(), 42u);  // 2 subjects x 7 lights x 3 (ambient skipped)

  const std::vector<StreamMessage> messages = Drain(*source);
  ASSERT_EQ(messages.size(), 42u);
  const int order[][2] = {{-130, 20}, {-90, 0}, {0, -35}, {0, 0}, {0, 90}, {45, 20}, {90, 0}};
  for (size_t frame = 0; frame < 14; ++frame) {
    const int subject = frame < 7 ? 1 : 2;
    const int a = order[frame % 7][0];
    const int e = order[frame % 7][1];
    EXPECT_EQ(messages[frame * 3].log_time_ns, internal::FrameTimeNs(frame, 30));
    const auto image = View<msgs::Image>(messages[frame * 3 + 1]);
    EXPECT_EQ(image->Describe(), "168x192 mono8 (step 168)");
    EXPECT_EQ(msgs::ImageRow<uint8_t>(*image, image.payload, 100)[80],
              subject * 10 + (a + 130) / 10)
        << frame;
    const auto light = View<msgs::ShLight>(messages[frame * 3 + 2]);
    EXPECT_NO_THROW(light->Validate());
    EXPECT_EQ(light->header.FrameId(), "camera");
    EXPECT_EQ(light->bands, 3u);
    EXPECT_EQ(light->intensity, 1.0f);
    EXPECT_EQ(light->confidence, 1.0f);
    const std::array<double, 3> d = YaleBLightDirection(a, e);
    for (int k = 0; k < 3; ++k) EXPECT_FLOAT_EQ(light->dominant_direction[k], d[k]) << frame;
    const double k1 = std::sqrt(3 / (4 * kPi));
    for (int c = 0; c < 3; ++c) {
      EXPECT_FLOAT_EQ(light->coefficients[0][c], 0.5 / std::sqrt(kPi));
      EXPECT_NEAR(light->coefficients[1][c], -k1 * d[1], 1e-6);
      EXPECT_NEAR(light->coefficients[2][c], k1 * d[2], 1e-6);
      EXPECT_NEAR(light->coefficients[3][c], -k1 * d[0], 1e-6);
      EXPECT_EQ(light->coefficients[9][c], 0.0f);
    }
  }
  // Frame 4 of subject 1 is A+000E+90: light straight above, -y.
  const auto above = View<msgs::ShLight>(messages[4 * 3 + 2]);
  EXPECT_NEAR(above->dominant_direction[1], -1, 1e-7);
  const auto info = View<msgs::CameraInfo>(messages[0]);
  EXPECT_EQ(info->width, 168u);
  EXPECT_EQ(info->height, 192u);
  EXPECT_EQ(info->fx, 1050);
  EXPECT_EQ(info->cx, 83.5);
  EXPECT_EQ(info->cy, 95.5);
  EXPECT_EQ(info->depth_scale, 0);
}

TEST(YaleBTest, SubjectFolderSubjectFilterAndErrors) {
  TempDir dir;
  YaleFolder folder(dir);
  {
    const std::unique_ptr<Source> source = OpenDataset(folder.path + "/yaleB02");
    EXPECT_EQ(source->message_count(), 21u);
  }
  DatasetOptions options;
  options.yaleb_subjects = {2};
  {
    const std::unique_ptr<Source> source = OpenDataset(folder.path, options);
    EXPECT_EQ(source->message_count(), 21u);
    const auto image = View<msgs::Image>(*(source->Next(), source->Next()));
    EXPECT_EQ(msgs::ImageRow<uint8_t>(*image, image.payload, 0)[0], 20);
  }
  options.yaleb_subjects = {2, 14};
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset(folder.path, options); }),
            "Yale B folder '" + folder.path + "' has no images of subject yaleB14");
  EXPECT_EQ(ThrownMessage<DatasetError>(
                [&] { OpenDataset("images:" + folder.path + "/yaleB01", options); }),
            "dataset option yaleb_subjects applies to yaleb datasets only, not images");
  options.yaleb_subjects.clear();
  options.max_frames = 3;
  EXPECT_EQ(OpenDataset(folder.path, options)->message_count(), 9u);

  const std::string bad = folder.path + "/yaleB01/" + YaleName(1, 0, 0);
  WritePng(bad, cv::Mat(10, 10, CV_8UC1, cv::Scalar(0)));
  const std::unique_ptr<Source> source = OpenDataset(folder.path);
  for (int i = 0; i < 9; ++i) source->Next();
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { source->Next(); }),
            "Yale B image '" + bad +
                "' is 10x10 8-bit 1-channel: expected an 8-bit grey 168x192 PGM like the first "
                "image");
  TempDir empty;
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset("yaleb:" + empty.path()); }),
            "Yale B folder '" + empty.path() +
                "' has no yaleBxx_P00A±aaaE±ee.pgm images (nor yaleBxx/ folders with them)");
}

// ---------------------------------------------------------------------------------------------
// Image folders

TEST(ImagesTest, SortedByNameWithEncodingsAndDefaultCameraInfo) {
  TempDir dir;
  const std::string path = dir.File("shots");
  std::filesystem::create_directories(path);
  WritePng(path + "/b.png", PatternBgr(20, 10, 2));
  WritePng(path + "/a.png", PatternBgr(20, 10, 1));
  cv::Mat grey(10, 20, CV_8UC1, cv::Scalar(77));
  WritePng(path + "/c.pgm", grey);
  WriteText(path + "/notes.txt", "ignored\n");
  EXPECT_EQ(DetectDatasetKind(path), "images");
  DatasetOptions options;
  options.fps = 4;
  const std::unique_ptr<Source> source = OpenDataset(path, options);
  ASSERT_EQ(source->topics().size(), 2u);
  EXPECT_EQ(source->topics()[1].max_message_bytes,
            msgs::Image::MessageBytesFor(20, 10, msgs::Encoding::kRgb8));
  EXPECT_EQ(source->message_count(), 6u);
  EXPECT_EQ(source->time_range()->second, 500'000'000u);
  const std::vector<StreamMessage> messages = Drain(*source);
  ASSERT_EQ(messages.size(), 6u);
  EXPECT_EQ(messages[2].log_time_ns, 250'000'000u);
  const auto a = View<msgs::Image>(messages[1]);
  EXPECT_EQ(msgs::ImageRow<uint8_t>(*a, a.payload, 0)[0], 3);  // R = 3 * seed of a.png
  const auto b = View<msgs::Image>(messages[3]);
  EXPECT_EQ(msgs::ImageRow<uint8_t>(*b, b.payload, 0)[0], 6);
  const auto c = View<msgs::Image>(messages[5]);  // grey converted to the folder's rgb8
  EXPECT_EQ(c->encoding, msgs::Encoding::kRgb8);
  EXPECT_EQ(msgs::ImageRow<uint8_t>(*c, c.payload, 0)[1], 77);
  const auto info = View<msgs::CameraInfo>(messages[0]);
  EXPECT_NEAR(info->fx, 10 / std::tan(kPi / 6), 1e-12);  // 60 degree horizontal field of view
  EXPECT_EQ(info->fx, info->fy);
  EXPECT_EQ(info->cx, 9.5);
  EXPECT_EQ(info->cy, 4.5);
}

TEST(ImagesTest, GreyAnd16BitFolders) {
  TempDir dir;
  const std::string grey = dir.File("grey");
  std::filesystem::create_directories(grey);
  WritePng(grey + "/0.pgm", cv::Mat(4, 6, CV_8UC1, cv::Scalar(9)));
  EXPECT_EQ(View<msgs::Image>(Drain(*OpenDataset(grey))[1])->Describe(), "6x4 mono8 (step 6)");
  const std::string deep = dir.File("deep");
  std::filesystem::create_directories(deep);
  WritePng(deep + "/0.png", cv::Mat(4, 6, CV_16UC1, cv::Scalar(40000)));
  WritePng(deep + "/1.png", cv::Mat(4, 6, CV_8UC1, cv::Scalar(2)));
  const std::vector<StreamMessage> messages = Drain(*OpenDataset(deep));
  const auto first = View<msgs::Image>(messages[1]);
  EXPECT_EQ(first->Describe(), "6x4 mono16 (step 12)");
  EXPECT_EQ(msgs::ImageRow<uint16_t>(*first, first.payload, 3)[5], 40000);
  const auto second = View<msgs::Image>(messages[3]);
  EXPECT_EQ(msgs::ImageRow<uint16_t>(*second, second.payload, 0)[0], 2 * 257);
}

TEST(ImagesTest, Errors) {
  TempDir dir;
  const std::string path = dir.File("shots");
  std::filesystem::create_directories(path);
  WritePng(path + "/a.png", PatternBgr(20, 10, 1));
  WritePng(path + "/b.jpg", PatternBgr(21, 10, 1));
  WriteText(path + "/c.png", "garbage");
  const std::unique_ptr<Source> source = OpenDataset(path);
  EXPECT_EQ(source->message_count(), 6u);
  source->Next();
  source->Next();
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { source->Next(); }),
            "image '" + path +
                "/b.jpg' is 21x10 8-bit 3-channel: expected 20x10 like the first "
                "image of the folder");
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { source->Next(); }),
            "cannot decode image '" + path + "/c.png': expected a png, jpg, pgm, ppm or bmp image");
  EXPECT_FALSE(source->Next().has_value());
  DatasetOptions options;
  options.camera_info_path = dir.File("bad.xml");
  WriteText(options.camera_info_path,
            "<?xml version=\"1.0\"?>\n<opencv_storage>\n"
            "<image_width>20</image_width></opencv_storage>\n");
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset(path, options); }),
            "calibration file '" + options.camera_info_path +
                "': missing camera_matrix (or cameraMatrix, K) in OpenCV FileStorage file");
}

// ---------------------------------------------------------------------------------------------
// Video

TEST(VideoTest, MjpgAviFramesAtTheFileRate) {
  TempDir dir;
  const std::string path = dir.File("clip.avi");
  {
    cv::VideoWriter writer(path, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 10, cv::Size(64, 48));
    ASSERT_TRUE(writer.isOpened());
    for (int i = 0; i < 5; ++i) {
      writer.write(cv::Mat(48, 64, CV_8UC3, cv::Scalar(20 * i, 100, 200)));  // B G R
    }
  }
  EXPECT_EQ(DetectDatasetKind(path), "video");
  const std::unique_ptr<Source> source = OpenDataset(path);
  EXPECT_EQ(source->kind(), "video");
  ASSERT_EQ(source->topics().size(), 2u);
  EXPECT_EQ(source->topics()[1].topic, "/camera/image");
  EXPECT_EQ(source->topics()[1].max_message_bytes,
            msgs::Image::MessageBytesFor(64, 48, msgs::Encoding::kRgb8));
  EXPECT_EQ(source->message_count(), 0u);  // unknown
  std::vector<StreamMessage> messages = Drain(*source);
  ASSERT_EQ(messages.size(), 10u);
  for (size_t i = 0; i < 10; ++i) {
    EXPECT_EQ(messages[i].log_time_ns, (i / 2) * 100'000'000u) << i;
    EXPECT_EQ(messages[i].topic_index, i % 2);
  }
  for (int f = 0; f < 5; ++f) {
    const auto image = View<msgs::Image>(messages[f * 2 + 1]);
    EXPECT_EQ(image->header.sequence, static_cast<uint64_t>(f + 1));
    const auto row = msgs::ImageRow<uint8_t>(*image, image.payload, 20);
    EXPECT_NEAR(row[30 * 3 + 0], 200, 8) << f;     // R
    EXPECT_NEAR(row[30 * 3 + 1], 100, 8) << f;     // G
    EXPECT_NEAR(row[30 * 3 + 2], 20 * f, 8) << f;  // B
  }
  source->Rewind();
  EXPECT_EQ(Drain(*source).size(), 10u);
  DatasetOptions options;
  options.max_frames = 2;
  EXPECT_EQ(Drain(*OpenDataset("video:" + path, options)).size(), 4u);

  const std::string broken = dir.File("broken.mp4");
  WriteText(broken, "not a video");
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset(broken); }),
            "cannot open video '" + broken +
                "': expected a video file OpenCV can decode (e.g. MJPG .avi, H.264 .mp4)");
}

// ---------------------------------------------------------------------------------------------
// Detection, specs and options

TEST(DetectTest, KindsAndWhatWasLookedFor) {
  TempDir dir;
  SevenScenesFolder seven(dir);
  EXPECT_EQ(DetectDatasetKind(seven.path), "7scenes");
  EXPECT_EQ(DetectDatasetKind(seven.path + "/"), "7scenes");
  const std::string mcap = dir.File("log.MCAP");
  WriteText(mcap, "");
  EXPECT_EQ(DetectDatasetKind(mcap), "mcap");
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset(mcap); }),
            "'" + mcap + "' is an MCAP log: open it with the MCAP source, not as a dataset folder");
  const std::string text = dir.File("notes.txt");
  WriteText(text, "");
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { DetectDatasetKind(text); }),
            "no dataset kind for file '" + text +
                "': expected a folder (tum, 7scenes, yaleb, images), a video file (avi, mp4, mkv, "
                "mov, webm, m4v, mpg, mpeg, wmv) or an .mcap log");
  const std::string empty = dir.File("empty");
  std::filesystem::create_directories(empty);
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { DetectDatasetKind(empty); }),
            "no dataset found in folder '" + empty +
                "': looked for rgb.txt + depth.txt (tum), frame-XXXXXX.color.jpg|png (7scenes), "
                "yaleBxx_P00A±aaaE±ee.pgm files or yaleBxx/ folders of them (yaleb), "
                "png/jpg/jpeg/pgm/ppm/bmp files (images)");
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset(empty); }),
            ThrownMessage<DatasetError>([&] { DetectDatasetKind(empty); }));
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { DetectDatasetKind(dir.path() + "/absent"); }),
            "dataset path '" + dir.path() + "/absent' does not exist");
  // A 7-Scenes folder also holds images: the more specific kind wins, an explicit kind overrides.
  // (3 colour and 3 depth PNGs, 2 messages each).
  EXPECT_EQ(OpenDataset("images:" + seven.path)->message_count(), 12u);
  EXPECT_EQ((std::vector<std::string>{"tum", "7scenes", "yaleb", "images", "video"}),
            DatasetKinds());
}

TEST(DetectTest, SpecsAndOptions) {
  TempDir dir;
  SevenScenesFolder seven(dir, 1);
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset("bogus:" + seven.path); }),
            "unknown dataset kind 'bogus' in 'bogus:" + seven.path +
                "' (expected 7scenes, tum, yaleb, images or video)");
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset("tum:"); }),
            "dataset spec 'tum:' names no path");
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset("tum:" + seven.path); }),
            "cannot read TUM list '" + seven.path + "/rgb.txt'");
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset("video:" + seven.path); }),
            "video path '" + seven.path + "' is a folder: expected a video file");
  EXPECT_EQ(ThrownMessage<DatasetError>(
                [&] { OpenDataset("7scenes:" + seven.path + "/frame-000000.pose.txt"); }),
            "7scenes dataset path '" + seven.path + "/frame-000000.pose.txt' is not a folder");
  DatasetOptions options;
  options.fps = 0;
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset(seven.path, options); }),
            "dataset option fps 0.000000 must be a positive number of frames per second");
  options = {};
  options.topic_prefix = "camera/";
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset(seven.path, options); }),
            "dataset option topic_prefix 'camera/' is not an absolute topic prefix (expected e.g. "
            "/camera: letters, digits, '_' and single '/', no trailing '/')");
  options = {};
  options.camera_frame_id = std::string(32, 'c');
  EXPECT_EQ(ThrownMessage<DatasetError>([&] { OpenDataset(seven.path, options); }),
            "dataset option camera_frame_id '" + options.camera_frame_id +
                "' must have 1 to 31 characters");
}

}  // namespace
}  // namespace probeless::dataset
