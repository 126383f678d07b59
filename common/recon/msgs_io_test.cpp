// The fusion node's message conversions: a depth frame from depth image and camera_info, a colour
// frame from an image, scene/light's dominant direction and the TrackingStatus of a frame result.
#include "probeless/recon/msgs_io.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "probeless/testing/expect.h"

namespace probeless::recon {
namespace {

msgs::CameraInfo TestInfo(uint32_t w, uint32_t h) {
  msgs::CameraInfo info;
  info.width = w;
  info.height = h;
  info.fx = info.fy = 100;
  info.cx = w / 2.0;
  info.cy = h / 2.0;
  return info;
}

TEST(MsgsIo, DepthFrameFromMessages) {
  msgs::Image image;
  image.Init(4, 2, msgs::Encoding::kDepth16);
  image.header.stamp_ns = 1234;
  image.header.sequence = 7;
  std::vector<std::byte> payload(image.PayloadBytes());
  std::vector<uint16_t> units = {0, 500, 1000, 2000, 5000, 250, 3999, 4001};
  std::memcpy(payload.data(), units.data(), payload.size());
  msgs::CameraInfo info = TestInfo(4, 2);
  info.depth_scale = 0.002;  // 2 mm per unit
  const DepthFrame d = DepthFrameFromMessages(image, payload, info, 0.3f, 8.0f);
  EXPECT_EQ(d.header.stamp_ns, 1234);
  EXPECT_EQ(d.header.sequence, 7u);
  EXPECT_EQ(d.intrinsics.width, 4);
  EXPECT_FLOAT_EQ(d.intrinsics.fx, 100.0f);
  EXPECT_FLOAT_EQ(d.intrinsics.cx, 2.0f);
  ASSERT_EQ(d.depth.width, 4);
  ASSERT_EQ(d.depth.height, 2);
  EXPECT_EQ(d.depth.At(0, 0), 0.0f);        // no measurement
  EXPECT_FLOAT_EQ(d.depth.At(1, 0), 1.0f);  // 500 x 2 mm
  EXPECT_EQ(d.depth.At(0, 1), 0.0f);        // 10 m: beyond max_m
  EXPECT_FLOAT_EQ(d.depth.At(2, 1), 7.998f);
  EXPECT_FLOAT_EQ(d.depth.At(1, 1), 0.5f);  // 250 x 2 mm
  EXPECT_EQ(d.depth.At(3, 1), 0.0f);        // 8.002 m: beyond max_m
  // The camera_info is checked first, then the image.
  msgs::CameraInfo nan_info = info;
  nan_info.fx = std::numeric_limits<double>::quiet_NaN();
  msgs::Image rgb;
  rgb.Init(4, 2, msgs::Encoding::kRgb8);
  std::vector<std::byte> rgb_payload(rgb.PayloadBytes());
  PROBELESS_EXPECT_THROWS_MESSAGE(DepthFrameFromMessages(rgb, rgb_payload, nan_info, 0.3f, 8.0f),
                                  ReconError,
                                  "camera_info: intrinsics must be finite (fx, fy, cx, cy)");
  PROBELESS_EXPECT_THROWS_MESSAGE(DepthFrameFromMessages(rgb, rgb_payload, info, 0.3f, 8.0f),
                                  ReconError,
                                  "depth: expected encoding depth16 or float32, got rgb8");
}

TEST(MsgsIo, ColourFrameFromMessage) {
  msgs::Image image;
  image.Init(3, 2, msgs::Encoding::kRgb8);
  image.header.stamp_ns = 99;
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> byte(0, 255);
  // A payload longer than the image: only PayloadBytes() are kept.
  std::vector<std::byte> payload(image.PayloadBytes() + 16);
  for (std::byte& b : payload) b = std::byte(byte(rng));
  const ColourFrame c = ColourFrameFromMessage(image, payload);
  EXPECT_EQ(c.image.header.stamp_ns, 99);
  EXPECT_EQ(c.image.encoding, msgs::Encoding::kRgb8);
  ASSERT_EQ(c.payload.size(), image.PayloadBytes());
  EXPECT_TRUE(std::equal(c.payload.begin(), c.payload.end(), payload.begin()));
  ASSERT_EQ(c.grey.width, 3);
  ASSERT_EQ(c.grey.height, 2);
  GreyImage expected;
  GreyFromImage(image, payload, expected);
  EXPECT_EQ(c.grey.data, expected.data);
  const auto* p = reinterpret_cast<const uint8_t*>(payload.data());
  EXPECT_EQ(c.grey.At(1, 0), static_cast<uint8_t>((77 * p[3] + 150 * p[4] + 29 * p[5]) >> 8));

  msgs::Image depth;
  depth.Init(3, 2, msgs::Encoding::kDepth16);
  std::vector<std::byte> depth_payload(depth.PayloadBytes());
  PROBELESS_EXPECT_THROWS_MESSAGE(ColourFrameFromMessage(depth, depth_payload), ReconError,
                                  "image: expected encoding rgb8, bgr8 or mono8, got depth16");
  std::vector<std::byte> short_payload(image.PayloadBytes() - 1);
  EXPECT_THROW(ColourFrameFromMessage(image, short_payload), ReconError);
}

TEST(MsgsIo, DominantDirection) {
  msgs::ShLight light;
  EXPECT_FALSE(DominantDirection(light).has_value());  // zero: none
  light.dominant_direction[0] = 1e-4f;                 // squared length 1e-8
  EXPECT_FALSE(DominantDirection(light).has_value());
  light.dominant_direction[0] = std::numeric_limits<float>::quiet_NaN();
  EXPECT_FALSE(DominantDirection(light).has_value());
  light.dominant_direction[0] = std::numeric_limits<float>::infinity();
  EXPECT_FALSE(DominantDirection(light).has_value());
  // Returned as it is, not normalised (the caller rotates, then normalises).
  light.dominant_direction[0] = 0.0f;
  light.dominant_direction[1] = -2.0f;
  light.dominant_direction[2] = 0.5f;
  const std::optional<Vec3f> d = DominantDirection(light);
  ASSERT_TRUE(d.has_value());
  EXPECT_EQ(d->x, 0.0f);
  EXPECT_EQ(d->y, -2.0f);
  EXPECT_EQ(d->z, 0.5f);
}

TEST(MsgsIo, FillTrackingStatus) {
  FrameResult r;
  r.state = TrackingState::kUncertain;
  r.integrated = false;
  r.relocalised = true;
  r.icp.rms_m = 0.004f;
  r.icp.inlier_fraction = 0.6f;
  r.quality.score = 0.3f;
  r.quality.reasons = msgs::kTrackingReasonMotion | msgs::kTrackingReasonInliers;
  r.quality.residual_ratio = 1.5f;
  r.quality.inlier_ratio = 0.7f;
  r.quality.motion_translation_m = 0.02f;
  r.quality.motion_rotation_deg = 3.0f;
  r.quality.observability = 0.9f;
  r.quality.text = std::string(300, 'x');  // longer than the message holds
  msgs::TrackingStatus t;
  t.header.stamp_ns = 42;
  FillTrackingStatus(
      r, {.frames = 5, .tracked = 2, .uncertain = 2, .lost = 1, .relocalisations = 1}, &t);
  EXPECT_EQ(t.header.stamp_ns, 42);  // left alone
  EXPECT_EQ(t.state, msgs::TrackingStatusState::kUncertain);
  EXPECT_FLOAT_EQ(t.score, 0.3f);
  EXPECT_EQ(t.reasons, msgs::kTrackingReasonMotion | msgs::kTrackingReasonInliers);
  EXPECT_EQ(t.integrated, 0);
  EXPECT_EQ(t.relocalised, 1);
  EXPECT_FLOAT_EQ(t.rms_m, 0.004f);
  EXPECT_FLOAT_EQ(t.inlier_fraction, 0.6f);
  EXPECT_FLOAT_EQ(t.residual_ratio, 1.5f);
  EXPECT_FLOAT_EQ(t.inlier_ratio, 0.7f);
  EXPECT_FLOAT_EQ(t.motion_translation_m, 0.02f);
  EXPECT_FLOAT_EQ(t.motion_rotation_deg, 3.0f);
  EXPECT_FLOAT_EQ(t.observability, 0.9f);
  EXPECT_EQ(t.frames, 5u);
  EXPECT_EQ(t.tracked_frames, 2u);
  EXPECT_EQ(t.uncertain_frames, 2u);
  EXPECT_EQ(t.lost_frames, 1u);
  EXPECT_EQ(t.relocalisations, 1u);
  EXPECT_EQ(t.ReasonText(), std::string(msgs::kTrackingReasonCapacity - 1, 'x'));
  EXPECT_NO_THROW(t.Validate());

  r.state = TrackingState::kLost;
  FillTrackingStatus(r, {}, &t);
  EXPECT_EQ(t.state, msgs::TrackingStatusState::kLost);
  EXPECT_EQ(t.frames, 0u);
  r.state = TrackingState::kEmpty;  // the message has no "empty": tracked
  r.integrated = true;
  r.quality.text.clear();
  FillTrackingStatus(r, {}, &t);
  EXPECT_EQ(t.state, msgs::TrackingStatusState::kTracked);
  EXPECT_EQ(t.integrated, 1);
  EXPECT_EQ(t.ReasonText(), "");
}

}  // namespace
}  // namespace probeless::recon
