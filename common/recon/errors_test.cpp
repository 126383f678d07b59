// Bad inputs at the boundary give one-line ReconErrors: wrong depth encoding, empty frames, NaN
// intrinsics, mismatched sizes, invalid options.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <vector>

#include "probeless/recon/msgs_io.h"
#include "probeless/recon/pipeline.h"
#include "test_scene.h"

namespace probeless::recon {
namespace {

template <class Fn>
std::string ErrorOf(Fn fn) {
  try {
    fn();
  } catch (const ReconError& e) {
    return e.what();
  }
  return "(no error)";
}

TEST(Errors, WrongDepthEncoding) {
  msgs::Image image;
  image.Init(4, 2, msgs::Encoding::kRgb8);
  std::vector<std::byte> payload(image.PayloadBytes());
  DepthImage out;
  EXPECT_EQ(ErrorOf([&] { DepthFromImage(image, payload, 0.001, 0.3f, 4.0f, out); }),
            "depth: expected encoding depth16 or float32, got rgb8");
}

TEST(Errors, EmptyFrames) {
  msgs::Image image;
  image.Init(0, 0, msgs::Encoding::kDepth16);
  DepthImage out;
  EXPECT_EQ(ErrorOf([&] { DepthFromImage(image, {}, 0.001, 0.3f, 4.0f, out); }),
            "depth: empty image (0x0)");
  FusionOptions options;
  options.merge_enabled = false;
  FusionPipeline pipeline(options);
  const Intrinsics k = testing::TestIntrinsics();
  DepthImage empty;
  EXPECT_EQ(ErrorOf([&] { pipeline.Process(empty, k, nullptr); }), "fusion: empty depth image");
  EXPECT_EQ(ErrorOf([&] { pipeline.ProcessDepth16(nullptr, 0, 0, 0, 0.001, k, nullptr); }),
            "depth: empty image (0x0)");
}

TEST(Errors, NanIntrinsics) {
  msgs::CameraInfo info;
  info.width = 640;
  info.height = 480;
  info.fx = std::numeric_limits<double>::quiet_NaN();
  info.fy = 525;
  info.cx = 320;
  info.cy = 240;
  EXPECT_EQ(ErrorOf([&] { IntrinsicsFromCameraInfo(info); }),
            "camera_info: intrinsics must be finite (fx, fy, cx, cy)");
  FusionOptions options;
  FusionPipeline pipeline(options);
  Intrinsics k = testing::TestIntrinsics();
  k.cx = std::nanf("");
  DepthImage depth;
  depth.Resize(k.width, k.height);
  EXPECT_EQ(ErrorOf([&] { pipeline.Process(depth, k, nullptr); }),
            "fusion: intrinsics must be finite (fx, fy, cx, cy)");
}

TEST(Errors, MismatchedSizesAndOptions) {
  FusionOptions options;
  FusionPipeline pipeline(options);
  const Intrinsics k = testing::TestIntrinsics();
  DepthImage depth;
  depth.Resize(100, 100);
  EXPECT_EQ(ErrorOf([&] { pipeline.Process(depth, k, nullptr); }),
            "fusion: depth is 100x100 but the intrinsics are for 320x240");
  VolumeOptions v;
  v.resolution = 100;
  EXPECT_EQ(ErrorOf([&] { TsdfVolume volume(v); }),
            "volume: resolution must be a multiple of 8 in [8, 1024], got 100");
  FusionOptions bad;
  bad.threads = 0;
  EXPECT_EQ(ErrorOf([&] { FusionPipeline p(bad); }), "fusion: threads must be >= 1");
  FusionOptions bad_block;
  bad_block.volume_normal_block = 0;
  EXPECT_EQ(ErrorOf([&] { FusionPipeline p(bad_block); }),
            "fusion: volume_normal_block must be 1..4");
  FusionOptions bad_step;
  bad_step.volume_normal_step_voxels = 0;
  EXPECT_EQ(ErrorOf([&] { FusionPipeline p(bad_step); }),
            "fusion: volume_normal_step_voxels must be in (0, 4]");
  msgs::CameraInfo info;
  info.width = 640;
  info.height = 480;
  info.fx = info.fy = 525;
  info.distortion_model = msgs::DistortionModel::kPlumbBob;
  info.distortion_count = 5;
  info.distortion[0] = 0.1;
  EXPECT_EQ(ErrorOf([&] { IntrinsicsFromCameraInfo(info); }),
            "camera_info: lens distortion (plumb_bob) is not supported: run the rectify node in "
            "front and feed its depth_rect, image_rect and camera_info_rect (docs/rectify.md)");
}

TEST(Errors, GeometryBufferRoundTrip) {
  DepthImage depth;
  depth.Resize(4, 2);
  depth.At(1, 1) = 1.5f;
  Vec3Image normals;
  normals.Resize(4, 2);
  normals.At(1, 1) = {0, 0, -1};
  msgs::Image rgb;
  rgb.Init(4, 2, msgs::Encoding::kBgr8);
  std::vector<std::byte> rgb_payload(rgb.PayloadBytes(), std::byte{0});
  rgb_payload[(1 * 4 + 1) * 3 + 0] = std::byte{30};  // B
  rgb_payload[(1 * 4 + 1) * 3 + 2] = std::byte{10};  // R
  msgs::GeometryBuffer g;
  std::vector<std::byte> payload(msgs::GeometryBuffer::StandardPayloadBytes(4, 2));
  WriteGeometryBuffer(depth, normals, &rgb, rgb_payload, g, payload);
  const std::span<const std::byte> bytes(payload);
  EXPECT_FLOAT_EQ(msgs::DepthPlane(g, bytes)[5], 1.5f);
  EXPECT_FLOAT_EQ(msgs::NormalsPlane(g, bytes)[5 * 3 + 2], -1.0f);
  EXPECT_EQ(msgs::ColourPlane(g, bytes)[5 * 3 + 0], 10);
  EXPECT_EQ(msgs::ColourPlane(g, bytes)[5 * 3 + 2], 30);
}

}  // namespace
}  // namespace probeless::recon
