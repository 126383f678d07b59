// Unit tests of light::SceneFrameBuilder (messages.h): a frame's messages (a G_r or a depth image,
// the camera image, the camera info, the raw depth for the shadow search) -> SceneFrame, on small
// random messages (fixed seeds): sizes, intrinsics, stamps, which planes are borrowed, depth in
// metres, grey and RGB bytes, and the one-line errors of a size or encoding mismatch.
#include <gtest/gtest.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <random>
#include <span>
#include <vector>

#include "probeless/light/messages.h"
#include "probeless/light/pipeline.h"
#include "probeless/light/transfer.h"
#include "probeless/testing/testing.h"

namespace {

using namespace probeless;
using probeless::testing::ThrownMessage;

constexpr uint32_t kW = 16, kH = 12;

msgs::CameraInfo Info(uint32_t w = kW, uint32_t h = kH, double depth_scale = 0) {
  msgs::CameraInfo info;
  info.width = w;
  info.height = h;
  info.fx = 20;
  info.fy = 21;
  info.cx = 7.5;
  info.cy = 5.5;
  info.depth_scale = depth_scale;
  return info;
}

// An image message with its payload (random bytes of seed `seed`, step packed).
struct ImageMessage {
  msgs::Image image;
  std::vector<std::byte> payload;
  ImageMessage(uint32_t w, uint32_t h, msgs::Encoding encoding, unsigned seed) {
    image.Init(w, h, encoding);
    payload.resize(image.PayloadBytes());
    std::mt19937 rng(seed);
    for (std::byte& b : payload) b = static_cast<std::byte>(rng() & 0xff);
  }
  template <class T>
  std::span<T> Row(uint32_t y) {
    return msgs::ImageRow<T>(image, std::span<std::byte>(payload), y);
  }
};

// A G_r of kW x kH: random depth in [0.5, 4) m, normals (0, 0, -1), random colour; stamp 1000.
struct GeometryMessage {
  msgs::GeometryBuffer g;
  std::vector<std::byte> payload;
  GeometryMessage() {
    g.Init(kW, kH);
    g.header.stamp_ns = 1000;
    g.header.sequence = 7;
    payload.resize(msgs::GeometryBuffer::StandardPayloadBytes(kW, kH));
    const std::span<std::byte> p(payload);
    std::mt19937 rng(11);
    std::uniform_real_distribution<float> depth(0.5f, 4.0f);
    for (float& d : msgs::DepthPlane(g, p)) d = depth(rng);
    const auto normals = msgs::NormalsPlane(g, p);
    for (size_t i = 0; i < normals.size(); i += 3) normals[i + 2] = -1;
    for (uint8_t& c : msgs::ColourPlane(g, p)) c = static_cast<uint8_t>(rng() & 0xff);
  }
};

TEST(SceneFrameBuilder, GeometryBufferFrameBorrowsItsPlanesAndTakesTheImagesColour) {
  GeometryMessage m;
  light::SceneFrameBuilder builder;
  light::SceneFrame frame = builder.FromGeometryBuffer(m.g, m.payload, Info());
  EXPECT_EQ(frame.stamp_ns, 1000);
  EXPECT_EQ(frame.width, 16);
  EXPECT_EQ(frame.height, 12);
  EXPECT_EQ(frame.intrinsics.fx, 20);
  EXPECT_EQ(frame.intrinsics.fy, 21);
  EXPECT_EQ(frame.intrinsics.cx, 7.5);
  EXPECT_EQ(frame.intrinsics.cy, 5.5);
  // Borrowed from the message's payload, not copied.
  const std::span<const std::byte> p(m.payload);
  EXPECT_EQ(frame.gbuffer_depth.data(), msgs::DepthPlane(m.g, p).data());
  EXPECT_EQ(frame.gbuffer_depth.size(), kW * kH);
  EXPECT_EQ(frame.gbuffer_normals.data(), msgs::NormalsPlane(m.g, p).data());
  EXPECT_EQ(frame.gbuffer_colour.data(), msgs::ColourPlane(m.g, p).data());
  // Nothing the caller or the other methods own.
  EXPECT_TRUE(frame.depth_image.empty());
  EXPECT_TRUE(frame.grey.empty());
  EXPECT_EQ(frame.aux, nullptr);
  EXPECT_FALSE(frame.focus.has_value());
  EXPECT_FALSE(frame.camera_to_world_rotation.has_value());

  // I_c from a bgr8 image: linear grey, the sRGB bytes in R, G, B order.
  ImageMessage bgr(kW, kH, msgs::Encoding::kBgr8, 3);
  builder.AddImage(bgr.image, bgr.payload, &frame);
  ASSERT_EQ(frame.grey.size(), kW * kH);
  ASSERT_EQ(frame.colour.size(), 3u * kW * kH);
  for (uint32_t y = 0; y < kH; ++y) {
    const auto row = bgr.Row<uint8_t>(y);
    for (uint32_t x = 0; x < kW; ++x) {
      const size_t p = y * kW + x;
      EXPECT_EQ(frame.colour[3 * p], row[3 * x + 2]);
      EXPECT_EQ(frame.colour[3 * p + 1], row[3 * x + 1]);
      EXPECT_EQ(frame.colour[3 * p + 2], row[3 * x]);
      const float grey = (light::SrgbToLinear(row[3 * x]) + light::SrgbToLinear(row[3 * x + 1]) +
                          light::SrgbToLinear(row[3 * x + 2])) /
                         3;
      EXPECT_NEAR(frame.grey[p], grey, 1e-6f);
    }
  }
  // mono8: grey only, no colour.
  ImageMessage mono(kW, kH, msgs::Encoding::kMono8, 4);
  builder.AddImage(mono.image, mono.payload, &frame);
  EXPECT_TRUE(frame.colour.empty());
  EXPECT_EQ(frame.grey[5], light::SrgbToLinear(mono.Row<uint8_t>(0)[5]));
}

TEST(SceneFrameBuilder, DepthImagesAreInMetres) {
  light::SceneFrameBuilder builder;
  // depth16 with the camera's depth_scale (0.5 mm a unit).
  ImageMessage raw(kW, kH, msgs::Encoding::kDepth16, 5);
  raw.image.header.stamp_ns = 2000;
  const light::SceneFrame frame =
      builder.FromDepthImage(raw.image, raw.payload, Info(kW, kH, 5e-4));
  EXPECT_EQ(frame.stamp_ns, 2000);
  EXPECT_EQ(frame.width, 16);
  EXPECT_EQ(frame.height, 12);
  EXPECT_EQ(frame.intrinsics.fy, 21);
  EXPECT_TRUE(frame.gbuffer_depth.empty());
  ASSERT_EQ(frame.depth_image.size(), kW * kH);
  const uint16_t first = raw.Row<uint16_t>(0)[0], last = raw.Row<uint16_t>(kH - 1)[kW - 1];
  EXPECT_FLOAT_EQ(frame.depth_image.front(), first * 5e-4f);
  EXPECT_FLOAT_EQ(frame.depth_image.back(), last * 5e-4f);
  // depth_scale unset: millimetres.
  const light::SceneFrame mm = builder.FromDepthImage(raw.image, raw.payload, Info());
  EXPECT_FLOAT_EQ(mm.depth_image.front(), first * 1e-3f);

  // The shadow search's depth on a G_r: float32 metres, non-finite and <= 0 -> 0 (no depth).
  GeometryMessage m;
  light::SceneFrame g = builder.FromGeometryBuffer(m.g, m.payload, Info());
  ImageMessage metres(kW, kH, msgs::Encoding::kFloat32, 6);
  for (uint32_t y = 0; y < kH; ++y) {
    for (uint32_t x = 0; x < kW; ++x) metres.Row<float>(y)[x] = 1.0f + 0.01f * (y * kW + x);
  }
  metres.Row<float>(0)[1] = std::nanf("");
  metres.Row<float>(0)[2] = -1.0f;
  builder.AddShadowDepth(metres.image, metres.payload, Info(), &g);
  ASSERT_EQ(g.depth_image.size(), kW * kH);
  EXPECT_EQ(g.depth_image[0], 1.0f);
  EXPECT_EQ(g.depth_image[1], 0.0f);
  EXPECT_EQ(g.depth_image[2], 0.0f);
  EXPECT_FLOAT_EQ(g.depth_image[kW * kH - 1], 1.0f + 0.01f * (kW * kH - 1));
  EXPECT_FALSE(g.gbuffer_depth.empty());  // the G_r stays the frame's geometry
}

TEST(SceneFrameBuilder, SizeAndEncodingMismatchesAreOneLineErrors) {
  light::SceneFrameBuilder builder;
  GeometryMessage m;
  light::SceneFrame frame = builder.FromGeometryBuffer(m.g, m.payload, Info());
  ImageMessage small(8, 6, msgs::Encoding::kRgb8, 7);
  EXPECT_EQ(ThrownMessage<light::LightError>(
                [&] { builder.AddImage(small.image, small.payload, &frame); }),
            "light::GreyFromImage: image is 8x6, geometry is 16x12");
  // An image without byte channels is refused by its rows' reader.
  ImageMessage floats(kW, kH, msgs::Encoding::kFloat32, 8);
  EXPECT_EQ(ThrownMessage<msgs::MessageError>(
                [&] { builder.AddImage(floats.image, floats.payload, &frame); }),
            "Image 16x12 float32 (step 64): encoding float32 has float32 channels, not uint8");
  ImageMessage small_depth(8, 6, msgs::Encoding::kDepth16, 9);
  EXPECT_EQ(ThrownMessage<light::LightError>([&] {
              builder.AddShadowDepth(small_depth.image, small_depth.payload, Info(), &frame);
            }),
            "light::SceneFrameBuilder::AddShadowDepth: depth image is 8x6, frame is 16x12");
  ImageMessage colour(kW, kH, msgs::Encoding::kRgb8, 10);
  EXPECT_EQ(ThrownMessage<light::LightError>(
                [&] { builder.AddShadowDepth(colour.image, colour.payload, Info(), &frame); }),
            "light::DepthFromImage: depth encoding rgb8 is not depth16 or float32");
  // The camera info of another size than the trigger.
  EXPECT_EQ(ThrownMessage<light::LightError>(
                [&] { builder.FromDepthImage(small_depth.image, small_depth.payload, Info()); }),
            "light::IntrinsicsFrom: camera info is 16x12, buffer is 8x6");
  EXPECT_EQ(ThrownMessage<light::LightError>(
                [&] { builder.FromGeometryBuffer(m.g, m.payload, Info(8, 6)); }),
            "light::IntrinsicsFrom: camera info is 8x6, buffer is 16x12");
}

}  // namespace
