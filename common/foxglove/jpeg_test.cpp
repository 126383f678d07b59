#include "probeless/foxglove/jpeg.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>

// jpeglib.h needs size_t and FILE declared first.
#include <jpeglib.h>

#include "probeless/foxglove/protocol.h"
#include "probeless/log/ros2.h"
#include "probeless/msgs/msgs.h"

namespace probeless::foxglove {
namespace {

namespace m = probeless::msgs;

// A whole bus Image message: a horizontal ramp in the first channel, 100 in the others.
log::MessageBuffer MakeImage(m::Encoding encoding, uint32_t width, uint32_t height) {
  log::MessageBuffer buffer(m::Image::MessageBytesFor(width, height, encoding));
  auto [image, payload] = m::WriteMessage<m::Image>(buffer.bytes());
  image->Init(width, height, encoding);
  image->header.stamp_ns = 1'700'000'000'123'456'789;
  image->header.SetFrameId("camera_optical");
  const uint32_t channels = m::BytesPerPixel(encoding);
  for (uint32_t y = 0; y < height; ++y) {
    for (uint32_t x = 0; x < width; ++x) {
      for (uint32_t c = 0; c < channels; ++c) {
        payload[y * image->step + x * channels + c] =
            std::byte(c == 0 ? static_cast<uint8_t>(x * 255 / (width - 1)) : 100);
      }
    }
  }
  return buffer;
}

struct Decoded {
  int width = 0, height = 0, components = 0;
  std::vector<uint8_t> pixels;
};

Decoded Decode(const std::vector<std::byte>& jpeg) {
  jpeg_decompress_struct info{};
  jpeg_error_mgr error{};
  info.err = jpeg_std_error(&error);
  jpeg_create_decompress(&info);
  jpeg_mem_src(&info, reinterpret_cast<const unsigned char*>(jpeg.data()), jpeg.size());
  jpeg_read_header(&info, TRUE);
  jpeg_start_decompress(&info);
  Decoded d{static_cast<int>(info.output_width),
            static_cast<int>(info.output_height),
            info.output_components,
            {}};
  d.pixels.resize(size_t(d.width) * d.height * d.components);
  while (info.output_scanline < info.output_height) {
    JSAMPROW row = d.pixels.data() + size_t(info.output_scanline) * d.width * d.components;
    jpeg_read_scanlines(&info, &row, 1);
  }
  jpeg_finish_decompress(&info);
  jpeg_destroy_decompress(&info);
  return d;
}

TEST(JpegTest, RgbBgrMonoDecodeBackClose) {
  for (m::Encoding e : {m::Encoding::kRgb8, m::Encoding::kBgr8, m::Encoding::kMono8}) {
    SCOPED_TRACE(std::string(m::EncodingName(e)));
    const log::MessageBuffer image = MakeImage(e, 64, 32);
    const std::vector<std::byte> jpeg = EncodeJpeg(image.bytes(), 90);
    ASSERT_GT(jpeg.size(), 4u);
    EXPECT_EQ(jpeg[0], std::byte{0xff});
    EXPECT_EQ(jpeg[1], std::byte{0xd8});
    const Decoded d = Decode(jpeg);
    EXPECT_EQ(d.width, 64);
    EXPECT_EQ(d.height, 32);
    EXPECT_EQ(d.components, e == m::Encoding::kMono8 ? 1 : 3);
    // The ramp is in the first bus channel: R for rgb8, B for bgr8 (decoded as RGB: index 2).
    const int ramp = e == m::Encoding::kBgr8 ? 2 : 0;
    const auto at = [&](int x, int c) {
      return int(d.pixels[(16 * d.width + x) * d.components + c]);
    };
    EXPECT_NEAR(at(0, ramp), 0, 6);
    EXPECT_NEAR(at(63, ramp), 255, 6);
    if (d.components == 3) {
      EXPECT_NEAR(at(32, 1), 100, 6);
    }
  }
}

TEST(JpegTest, CompressedImageCdrCarriesHeaderAndJpeg) {
  const log::MessageBuffer image = MakeImage(m::Encoding::kRgb8, 16, 8);
  log::CdrWriter out;
  EncodeCompressedImageCdr(image.bytes(), 80, out);
  log::CdrReader r(out.data(), "check");
  EXPECT_EQ(r.Read<int32_t>("sec"), 1'700'000'000);
  EXPECT_EQ(r.Read<uint32_t>("nanosec"), 123'456'789u);
  EXPECT_EQ(r.String("frame_id"), "camera_optical");
  EXPECT_EQ(r.String("format"), "jpeg");
  const auto data = r.SequenceBytes<uint8_t>("data");
  const std::vector<std::byte> jpeg(data.begin(), data.end());
  EXPECT_EQ(Decode(jpeg).width, 16);
  EXPECT_EQ(r.remaining(), 0u);
}

TEST(JpegTest, Errors) {
  auto error = [](std::span<const std::byte> message, int quality) {
    try {
      EncodeJpeg(message, quality);
    } catch (const FoxgloveError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  const log::MessageBuffer depth = MakeImage(m::Encoding::kDepth16, 4, 4);
  EXPECT_EQ(error(depth.bytes(), 80),
            "JPEG: image encoding depth16 cannot be compressed (expected rgb8, bgr8 or mono8)");
  const log::MessageBuffer rgb = MakeImage(m::Encoding::kRgb8, 4, 4);
  EXPECT_EQ(error(rgb.bytes(), 0), "JPEG quality 0 out of range (1..100)");
  EXPECT_EQ(error(rgb.bytes().first(150), 80).substr(0, 6), "JPEG: ");
}

}  // namespace
}  // namespace probeless::foxglove
