// Bad inputs at the boundary give one-line ReconErrors: wrong depth encoding, empty frames, NaN
// intrinsics, mismatched sizes, invalid options.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <vector>

#include "probeless/recon/msgs_io.h"
#include "probeless/recon/pipeline.h"
#include "probeless/testing/expect.h"
#include "test_scene.h"

namespace probeless::recon {
namespace {

TEST(Errors, WrongDepthEncoding) {
  msgs::Image image;
  image.Init(4, 2, msgs::Encoding::kRgb8);
  std::vector<std::byte> payload(image.PayloadBytes());
  DepthImage out;
  PROBELESS_EXPECT_THROWS_MESSAGE(DepthFromImage(image, payload, 0.001, 0.3f, 4.0f, out),
                                  ReconError,
                                  "depth: expected encoding depth16 or float32, got rgb8");
}

TEST(Errors, EmptyFrames) {
  msgs::Image image;
  image.Init(0, 0, msgs::Encoding::kDepth16);
  DepthImage out;
  PROBELESS_EXPECT_THROWS_MESSAGE(DepthFromImage(image, {}, 0.001, 0.3f, 4.0f, out), ReconError,
                                  "depth: empty image (0x0)");
  FusionOptions options;
  options.merge_enabled = false;
  FusionPipeline pipeline(options);
  const Intrinsics k = testing::TestIntrinsics();
  DepthImage empty;
  PROBELESS_EXPECT_THROWS_MESSAGE(pipeline.Process(empty, k, nullptr), ReconError,
                                  "fusion: empty depth image");
  PROBELESS_EXPECT_THROWS_MESSAGE(pipeline.ProcessDepth16(nullptr, 0, 0, 0, 0.001, k, nullptr),
                                  ReconError, "depth: empty image (0x0)");
}

TEST(Errors, NanIntrinsics) {
  msgs::CameraInfo info;
  info.width = 640;
  info.height = 480;
  info.fx = std::numeric_limits<double>::quiet_NaN();
  info.fy = 525;
  info.cx = 320;
  info.cy = 240;
  PROBELESS_EXPECT_THROWS_MESSAGE(IntrinsicsFromCameraInfo(info), ReconError,
                                  "camera_info: intrinsics must be finite (fx, fy, cx, cy)");
  FusionOptions options;
  FusionPipeline pipeline(options);
  Intrinsics k = testing::TestIntrinsics();
  k.cx = std::nanf("");
  DepthImage depth;
  depth.Resize(k.width, k.height);
  PROBELESS_EXPECT_THROWS_MESSAGE(pipeline.Process(depth, k, nullptr), ReconError,
                                  "fusion: intrinsics must be finite (fx, fy, cx, cy)");
}

TEST(Errors, MismatchedSizesAndOptions) {
  FusionOptions options;
  FusionPipeline pipeline(options);
  const Intrinsics k = testing::TestIntrinsics();
  DepthImage depth;
  depth.Resize(100, 100);
  PROBELESS_EXPECT_THROWS_MESSAGE(pipeline.Process(depth, k, nullptr), ReconError,
                                  "fusion: depth is 100x100 but the intrinsics are for 320x240");
  VolumeOptions v;
  v.resolution = 100;
  PROBELESS_EXPECT_THROWS_MESSAGE(
      TsdfVolume volume(v), ReconError,
      "volume: resolution must be a multiple of 8 in [8, 1024], got 100");
  FusionOptions bad;
  bad.threads = 0;
  PROBELESS_EXPECT_THROWS_MESSAGE(FusionPipeline p(bad), ReconError,
                                  "fusion: threads must be >= 1");
  FusionOptions bad_block;
  bad_block.volume_normal_block = 0;
  PROBELESS_EXPECT_THROWS_MESSAGE(FusionPipeline p(bad_block), ReconError,
                                  "fusion: volume_normal_block must be 1..4");
  FusionOptions bad_step;
  bad_step.volume_normal_step_voxels = 0;
  PROBELESS_EXPECT_THROWS_MESSAGE(FusionPipeline p(bad_step), ReconError,
                                  "fusion: volume_normal_step_voxels must be in (0, 4]");
  msgs::CameraInfo info;
  info.width = 640;
  info.height = 480;
  info.fx = info.fy = 525;
  info.distortion_model = msgs::DistortionModel::kPlumbBob;
  info.distortion_count = 5;
  info.distortion[0] = 0.1;
  PROBELESS_EXPECT_THROWS_MESSAGE(
      IntrinsicsFromCameraInfo(info), ReconError,
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
