// Conversions into bus-slot images: YUYV -> RGB against the BT.601 formula, MJPEG decode of
// recorded frames (written here with OpenCV, also without Huffman tables as webcams send them),
// the Kinect depth model both ways, software registration, and clear errors for bad frames.
#include "probeless/capture/convert.h"

#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "probeless/capture/capture_error.h"
#include "probeless/capture/registration.h"

namespace {

using namespace probeless;
using namespace probeless::capture;

std::vector<std::byte> Slot(size_t bytes) { return std::vector<std::byte>(bytes); }

TEST(ConvertTest, YuyvMatchesBt601LimitedRange) {
  // 4x2: white, black, mid grey, saturated red-ish pairs.
  const std::vector<uint8_t> yuyv = {235, 128, 16, 128, 126, 128, 126, 128,
                                     82,  90,  82, 240, 145, 54,  145, 34};
  RawFrame frame{PixelFormat::kYuyv, 4, 2, 0, yuyv};
  msgs::Image image;
  std::vector<std::byte> payload = Slot(4 * 2 * 3);
  ConvertFrame(frame, image, payload);
  EXPECT_EQ(image.encoding, msgs::Encoding::kRgb8);
  EXPECT_EQ(image.step, 12u);
  auto* rgb = reinterpret_cast<const uint8_t*>(payload.data());
  EXPECT_EQ(rgb[0], 255);  // Y 235 = white
  EXPECT_EQ(rgb[1], 255);
  EXPECT_EQ(rgb[3], 0);  // Y 16 = black
  EXPECT_NEAR(rgb[6], 128, 1);
  // Row 1: Y 82, U 90, V 240 is BT.601 red (255, 0, 0) within rounding.
  EXPECT_NEAR(rgb[12], 255, 2);
  EXPECT_NEAR(rgb[13], 0, 2);
  EXPECT_NEAR(rgb[14], 0, 2);
  // Against the floating-point formula everywhere.
  for (int p = 0; p < 8; ++p) {
    const int pair = p / 2;
    const double y = yuyv[pair * 4 + (p % 2) * 2] - 16.0;
    const double u = yuyv[pair * 4 + 1] - 128.0;
    const double v = yuyv[pair * 4 + 3] - 128.0;
    auto clamp = [](double x) { return std::min(255.0, std::max(0.0, x)); };
    EXPECT_NEAR(rgb[p * 3 + 0], clamp(1.164 * y + 1.596 * v), 1.5) << p;
    EXPECT_NEAR(rgb[p * 3 + 1], clamp(1.164 * y - 0.392 * u - 0.813 * v), 1.5) << p;
    EXPECT_NEAR(rgb[p * 3 + 2], clamp(1.164 * y + 2.017 * u), 1.5) << p;
  }
}

TEST(ConvertTest, YuyvWithPaddedRowsAndErrors) {
  std::vector<uint8_t> yuyv(2 * 16, 128);  // 2x2, 16-byte rows
  RawFrame frame{PixelFormat::kYuyv, 2, 2, 16, yuyv};
  msgs::Image image;
  std::vector<std::byte> payload = Slot(12);
  ConvertFrame(frame, image, payload);
  frame.data = std::span<const uint8_t>(yuyv).first(10);
  try {
    ConvertFrame(frame, image, payload);
    FAIL();
  } catch (const CaptureError& e) {
    EXPECT_STREQ(e.what(), "yuyv frame 2x2 needs 20 bytes, the device gave 10");
    EXPECT_EQ(e.kind(), ErrorKind::kBadInput);
  }
  std::vector<std::byte> small = Slot(5);
  frame.data = yuyv;
  try {
    ConvertFrame(frame, image, small);
    FAIL();
  } catch (const CaptureError& e) {
    EXPECT_STREQ(e.what(), "image 2x2 rgb8 (step 6) needs 12 bytes, the bus slot has 5");
  }
}

cv::Mat TestPattern(int w, int h) {
  cv::Mat bgr(h, w, CV_8UC3);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      bgr.at<cv::Vec3b>(y, x) =
          cv::Vec3b(static_cast<uint8_t>(x * 255 / w), static_cast<uint8_t>(y * 255 / h), 128);
    }
  }
  return bgr;
}

// Removes the DHT segments of a JPEG, as many UVC cameras send MJPEG frames.
std::vector<uint8_t> StripHuffmanTables(const std::vector<uint8_t>& jpeg) {
  std::vector<uint8_t> out(jpeg.begin(), jpeg.begin() + 2);
  size_t i = 2;
  while (i + 4 <= jpeg.size() && jpeg[i] == 0xFF && jpeg[i + 1] != 0xDA) {
    const size_t length = (jpeg[i + 2] << 8) | jpeg[i + 3];
    if (jpeg[i + 1] != 0xC4) out.insert(out.end(), jpeg.begin() + i, jpeg.begin() + i + 2 + length);
    i += 2 + length;
  }
  out.insert(out.end(), jpeg.begin() + i, jpeg.end());
  return out;
}

TEST(ConvertTest, MjpegDecodesIntoTheSlotWithAndWithoutHuffmanTables) {
  const cv::Mat bgr = TestPattern(64, 48);
  std::vector<uint8_t> jpeg;
  cv::imencode(".jpg", bgr, jpeg, {cv::IMWRITE_JPEG_QUALITY, 95});
  for (const std::vector<uint8_t>& data : {jpeg, StripHuffmanTables(jpeg)}) {
    RawFrame frame{PixelFormat::kMjpeg, 64, 48, 0, data};
    msgs::Image image;
    std::vector<std::byte> payload = Slot(64 * 48 * 3);
    ConvertFrame(frame, image, payload);
    const auto* rgb = reinterpret_cast<const uint8_t*>(payload.data());
    double error = 0;
    for (int y = 0; y < 48; ++y) {
      for (int x = 0; x < 64; ++x) {
        const cv::Vec3b b = bgr.at<cv::Vec3b>(y, x);
        const uint8_t* p = rgb + (y * 64 + x) * 3;
        error += std::abs(p[0] - b[2]) + std::abs(p[1] - b[1]) + std::abs(p[2] - b[0]);
      }
    }
    EXPECT_LT(error / (64 * 48 * 3), 3.0) << "mean absolute error per channel";
  }
  EXPECT_LT(StripHuffmanTables(jpeg).size(), jpeg.size());
}

TEST(ConvertTest, MjpegErrorsNameTheProblem) {
  const cv::Mat bgr = TestPattern(32, 16);
  std::vector<uint8_t> jpeg;
  cv::imencode(".jpg", bgr, jpeg);
  msgs::Image image;
  std::vector<std::byte> payload = Slot(64 * 48 * 3);
  RawFrame frame{PixelFormat::kMjpeg, 64, 48, 0, jpeg};
  try {
    ConvertFrame(frame, image, payload);
    FAIL();
  } catch (const CaptureError& e) {
    EXPECT_STREQ(e.what(), "MJPEG frame is 32x16, expected 64x48");
  }
  std::vector<uint8_t> junk(100, 7);
  frame.data = junk;
  try {
    ConvertFrame(frame, image, payload);
    FAIL();
  } catch (const CaptureError& e) {
    EXPECT_STREQ(e.what(), "MJPEG frame (100 bytes) does not start with a JPEG SOI marker");
  }
  std::vector<uint8_t> cut(jpeg.begin(), jpeg.begin() + jpeg.size() / 3);
  frame.data = cut;
  frame.width = 32;
  frame.height = 16;
  // A truncated frame decodes (libjpeg pads it) or fails with one line; it never crashes.
  try {
    ConvertFrame(frame, image, payload);
  } catch (const CaptureError& e) {
    EXPECT_NE(std::string(e.what()).find("MJPEG frame"), std::string::npos);
  }
}

TEST(ConvertTest, KinectModelMatchesLibfreenectAndRoundTrips) {
  const KinectDepthModel& model = KinectDepthModel::Default();
  // Values of libfreenect's freenect_raw_to_mm with the default zero-plane parameters.
  EXPECT_EQ(model.ToMm(0), 317);
  EXPECT_EQ(model.ToMm(2047), 0);
  EXPECT_GT(model.ToMm(1000), 3800);
  EXPECT_LT(model.ToMm(1000), 3900);
  // Monotonic over the valid range.
  int raw = 1;
  for (; raw < 2047 && model.ToMm(raw) != 0; ++raw) ASSERT_GE(model.ToMm(raw), model.ToMm(raw - 1));
  EXPECT_GT(model.ToMm(raw - 1), 9000);  // valid up to the 10 m cut-off, 0 beyond
  for (; raw < 2048; ++raw) ASSERT_EQ(model.ToMm(raw), 0) << raw;
  for (int mm = 500; mm <= 8000; mm += 7) {
    const uint16_t raw = model.ToRaw(mm);
    ASSERT_NE(raw, KinectDepthModel::kNoData) << mm;
    const int back = model.ToMm(raw);
    ASSERT_LE(std::abs(back - mm), model.QuantisationErrorMm(mm)) << mm;
  }
  EXPECT_EQ(model.ToRaw(0), KinectDepthModel::kNoData);
  EXPECT_EQ(model.ToRaw(60000), KinectDepthModel::kNoData);
  EXPECT_EQ(model.ToRaw(100), KinectDepthModel::kNoData);  // nearer than the Kinect sees
  EXPECT_LE(model.QuantisationErrorMm(1000), 3);
  EXPECT_GE(model.QuantisationErrorMm(4000), 10);

  std::vector<uint16_t> raws = {0, 600, 1000, 2047};
  RawFrame frame{PixelFormat::kKinectRaw11,
                 2,
                 2,
                 0,
                 {reinterpret_cast<const uint8_t*>(raws.data()), raws.size() * 2}};
  msgs::Image image;
  std::vector<std::byte> payload = Slot(8);
  ConvertFrame(frame, image, payload);
  EXPECT_EQ(image.encoding, msgs::Encoding::kDepth16);
  const auto* mm = reinterpret_cast<const uint16_t*>(payload.data());
  EXPECT_EQ(mm[0], model.ToMm(0));
  EXPECT_EQ(mm[1], model.ToMm(600));
  EXPECT_EQ(mm[3], 0);
}

TEST(RegistrationTest, IdentityKeepsDepthAndATranslationShiftsIt) {
  Intrinsics k = {8, 6, 10, 10, 3.5, 2.5, msgs::DistortionModel::kNone, {}};
  std::vector<uint16_t> depth(8 * 6, 1000);
  depth[0] = 0;
  std::vector<uint16_t> out(8 * 6, 7);
  RegisterDepthToColour(depth.data(), 16, k, k, {}, out.data(), 16);
  EXPECT_EQ(out[0], 0);
  for (size_t i = 1; i < out.size(); ++i) EXPECT_EQ(out[i], 1000) << i;
  // Colour camera 0.1 m to the left of the depth camera (p_colour = p_depth + (0.1, 0, 0)):
  // at 1 m, x shifts by fx * 0.1 = 1 pixel right.
  DepthToColour shift;
  shift.translation_m = {0.1, 0, 0};
  depth.assign(8 * 6, 0);
  depth[2 * 8 + 3] = 1000;
  RegisterDepthToColour(depth.data(), 16, k, k, shift, out.data(), 16);
  EXPECT_EQ(out[2 * 8 + 4], 1000);
  EXPECT_EQ(out[2 * 8 + 3], 0);
}

TEST(ConvertTest, PixelFormatNames) {
  EXPECT_EQ(PixelFormatFromName("mjpg"), PixelFormat::kMjpeg);
  EXPECT_EQ(PixelFormatFromName("yuyv"), PixelFormat::kYuyv);
  try {
    PixelFormatFromName("nv12");
    FAIL();
  } catch (const CaptureError& e) {
    EXPECT_STREQ(e.what(),
                 "unknown pixel format 'nv12' (expected mjpeg, yuyv, rgb24, bgr24 or grey)");
  }
}

}  // namespace
