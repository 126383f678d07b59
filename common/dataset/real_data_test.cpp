// Tests on the shared real data (7-Scenes RedKitchen excerpt, Extended Yale B), found at
// $PROBELESS_DATA or <source>/../shared/data; skipped with a message when it is absent.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>

#include "internal.h"
#include "probeless/dataset/datasets.h"
#include "probeless/dataset/yaleb.h"
#include "testing_util.h"

namespace probeless::dataset {
namespace {

using testing::Drain;
using testing::View;

std::string DataDir() {
  if (const char* env = std::getenv("PROBELESS_DATA"); env != nullptr && *env != '\0') return env;
  return std::string(PROBELESS_SOURCE_DIR) + "/../shared/data";
}

#define REQUIRE_DATA(sub)                                                                     \
  const std::string data_path = DataDir() + "/" + (sub);                                      \
  if (!std::filesystem::is_directory(data_path)) {                                            \
    GTEST_SKIP() << "shared data '" << data_path                                              \
                 << "' is absent (set PROBELESS_DATA to the folder holding " << (sub) << ")"; \
  }

TEST(RealDataTest, SevenScenesRedKitchen) {
  REQUIRE_DATA("7scenes-redkitchen");
  EXPECT_EQ(DetectDatasetKind(data_path), "7scenes");
  const std::unique_ptr<Source> source = OpenDataset(data_path);
  const std::vector<TopicInfo>& topics = source->topics();
  ASSERT_EQ(topics.size(), 4u);
  for (const TopicInfo& topic : topics) EXPECT_EQ(topic.message_count, 300u) << topic.topic;
  EXPECT_EQ(topics[1].max_message_bytes,
            msgs::Image::MessageBytesFor(640, 480, msgs::Encoding::kRgb8));
  EXPECT_EQ(topics[2].max_message_bytes,
            msgs::Image::MessageBytesFor(640, 480, msgs::Encoding::kDepth16));
  EXPECT_EQ(source->time_range()->second, internal::FrameTimeNs(299, 30));

  const std::vector<StreamMessage> messages = Drain(*source);
  ASSERT_EQ(messages.size(), 1200u);
  uint64_t previous = 0;
  for (const StreamMessage& message : messages) {
    EXPECT_GE(message.log_time_ns, previous);
    previous = message.log_time_ns;
    EXPECT_LE(message.message.size(), topics[message.topic_index].max_message_bytes);
  }
  const auto info = View<msgs::CameraInfo>(messages[0]);
  EXPECT_EQ(info->fx, 585);
  EXPECT_EQ(info->fy, 585);
  EXPECT_EQ(info->cx, 320);
  EXPECT_EQ(info->cy, 240);
  EXPECT_EQ(info->depth_scale, 0.001);
  const auto image = View<msgs::Image>(messages[1]);
  EXPECT_EQ(image->Describe(), "640x480 rgb8 (step 1920)");
  for (size_t f = 0; f < 300; f += 37) {
    const auto depth = View<msgs::Image>(messages[f * 4 + 2]);
    EXPECT_EQ(depth->Describe(), "640x480 depth16 (step 1280)");
    const auto values = msgs::ImageChannels<uint16_t>(*depth, depth.payload);
    EXPECT_EQ(std::count(values.begin(), values.end(), uint16_t{65535}), 0) << f;
    // Kinect v1 range: valid depths between 0.4 and 10 m.
    const auto valid = std::count_if(values.begin(), values.end(),
                                     [](uint16_t v) { return v >= 400 && v <= 10000; });
    const auto invalid = std::count(values.begin(), values.end(), uint16_t{0});
    EXPECT_EQ(static_cast<size_t>(valid + invalid), values.size()) << f;
    EXPECT_GT(valid, static_cast<long>(values.size() / 2)) << f;
  }
  // frame-000000.pose.txt: the camera-to-world matrix, rotation columns = camera axes in world.
  const auto pose = View<msgs::Pose>(messages[3]);
  EXPECT_NEAR(pose->transform.translation.x, -3.404563400000000239e-01, 1e-12);
  EXPECT_NEAR(pose->transform.translation.y, 1.646981800000000065e-02, 1e-12);
  EXPECT_NEAR(pose->transform.translation.z, 2.965691699999999931e-01, 1e-12);
  const msgs::RigidTransform rotation_only{{0, 0, 0}, pose->transform.rotation};
  const msgs::Vector3 x_axis = rotation_only.Apply({1, 0, 0});
  const msgs::Vector3 z_axis = rotation_only.Apply({0, 0, 1});
  EXPECT_NEAR(x_axis.x, 9.093128999999999795e-01, 1e-4);
  EXPECT_NEAR(x_axis.y, -2.724861800000000223e-01, 1e-4);
  EXPECT_NEAR(x_axis.z, 3.143392500000000145e-01, 1e-4);
  EXPECT_NEAR(z_axis.x, -3.142243299999999961e-01, 1e-4);
  EXPECT_NEAR(z_axis.y, 4.527962600000000337e-02, 1e-4);
  EXPECT_NEAR(z_axis.z, 9.482093499999999509e-01, 1e-4);
}

// Mean colour gradient (grey, central differences) at the depth discontinuities (> 5 % jump to
// the right or below) of frames 0, 50, 100, 150 of `source` (camera_info, image, depth, pose).
double ColourGradientAtDepthEdges(Source& source) {
  const std::vector<StreamMessage> messages = Drain(source);
  double sum = 0;
  long n = 0;
  for (size_t f = 0; f * 4 + 2 < messages.size(); f += 50) {
    const auto image = View<msgs::Image>(messages[f * 4 + 1]);
    const auto depth = View<msgs::Image>(messages[f * 4 + 2]);
    const auto rgb = msgs::ImageChannels<uint8_t>(*image, image.payload);
    const auto z = msgs::ImageChannels<uint16_t>(*depth, depth.payload);
    const int w = static_cast<int>(depth->width), h = static_cast<int>(depth->height);
    auto grey = [&](int u, int v) {
      const size_t i = 3 * (static_cast<size_t>(v) * w + u);
      return (rgb[i] + rgb[i + 1] + rgb[i + 2]) / 3.0;
    };
    for (int v = 1; v + 1 < h; ++v) {
      for (int u = 1; u + 1 < w; ++u) {
        const double c = z[v * w + u], r = z[v * w + u + 1], d = z[(v + 1) * w + u];
        const bool edge = c > 0 && ((r > 0 && std::abs(r - c) > 0.05 * c) ||
                                    (d > 0 && std::abs(d - c) > 0.05 * c));
        if (!edge) continue;
        sum +=
            std::abs(grey(u + 1, v) - grey(u - 1, v)) + std::abs(grey(u, v + 1) - grey(u, v - 1));
        ++n;
      }
    }
  }
  return n > 0 ? sum / n : 0;
}

TEST(RealDataTest, SevenScenesColourIsRegisteredToDepth) {
  REQUIRE_DATA("7scenes-redkitchen");
  DatasetOptions options;
  options.max_frames = 151;
  const std::unique_ptr<Source> registered = OpenDataset(data_path, options);
  options.register_colour = false;
  const std::unique_ptr<Source> raw = OpenDataset(data_path, options);
  const double with = ColourGradientAtDepthEdges(*registered);
  const double without = ColourGradientAtDepthEdges(*raw);
  std::printf("colour gradient at depth edges: registered %.1f, as recorded %.1f\n", with, without);
  // Colour edges coincide with depth edges only when the images are registered.
  EXPECT_GT(with, 1.8 * without);
}

TEST(RealDataTest, YaleBSubject01) {
  REQUIRE_DATA("yaleb");
  EXPECT_EQ(DetectDatasetKind(data_path), "yaleb");
  EXPECT_EQ(DetectDatasetKind(data_path + "/yaleB01"), "yaleb");
  DatasetOptions options;
  options.yaleb_subjects = {1};
  const std::unique_ptr<Source> source = OpenDataset(data_path, options);
  ASSERT_EQ(source->topics().size(), 3u);
  for (const TopicInfo& topic : source->topics()) EXPECT_EQ(topic.message_count, 64u);
  const std::vector<StreamMessage> messages = Drain(*source);
  ASSERT_EQ(messages.size(), 192u);
  int frontal = 0;
  for (size_t f = 0; f < 64; ++f) {
    const auto image = View<msgs::Image>(messages[f * 3 + 1]);
    EXPECT_EQ(image->Describe(), "168x192 mono8 (step 168)");
    const auto light = View<msgs::ShLight>(messages[f * 3 + 2]);
    const float* d = light->dominant_direction;
    EXPECT_NEAR(d[0] * d[0] + d[1] * d[1] + d[2] * d[2], 1, 1e-6);
    if (d[2] < -0.999f) ++frontal;  // A+000E+00 only
  }
  EXPECT_EQ(frontal, 1);
  // First the lowest azimuth: yaleB01_P00A-130E+20 (light from the subject's left, image right,
  // behind the face and above).
  const auto first = View<msgs::ShLight>(messages[2]);
  const std::array<double, 3> expected = YaleBLightDirection(-130, 20);
  for (int k = 0; k < 3; ++k) EXPECT_FLOAT_EQ(first->dominant_direction[k], expected[k]);
  EXPECT_GT(first->dominant_direction[0], 0.7f);   // image right
  EXPECT_LT(first->dominant_direction[1], -0.3f);  // above
  EXPECT_GT(first->dominant_direction[2], 0.6f);   // behind the face
  // Every subject of the folder (27, a few images missing in some).
  EXPECT_GT(OpenDataset(data_path)->message_count(), 27u * 58u * 3u);
}

}  // namespace
}  // namespace probeless::dataset
