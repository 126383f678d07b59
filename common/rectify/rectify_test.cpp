// probeless_rectify: the maps against OpenCV's projection model, straight lines of a checkerboard
// rendered through the Freiburg 1 lens, depth that never mixes across an edge, every encoding,
// pass-through, the rectified camera_info, calibration-file round trips and the error messages.
#include "probeless/rectify/rectify.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <set>
#include <vector>

#include "probeless/calib/calibration.h"
#include "probeless/testing/testing.h"
#include "test_scenes.h"

namespace probeless::rectify {
namespace {

using probeless::testing::TempDir;
using probeless::testing::ThrownMessage;

msgs::CameraInfo RationalInfo() {
  msgs::CameraInfo info = test::Freiburg1Info();
  info.distortion_model = msgs::DistortionModel::kRationalPolynomial;
  info.distortion_count = 8;
  const double d[8] = {0.31, -0.12, 0.0011, -0.0008, 0.012, 0.62, -0.05, 0.021};
  for (int i = 0; i < 8; ++i) info.distortion[i] = d[i];
  return info;
}

// An image message and its pixels, packed.
struct TestImage {
  msgs::Image header;
  std::vector<std::byte> pixels;
  TestImage(uint32_t w, uint32_t h, msgs::Encoding e) {
    header.Init(w, h, e);
    header.header.stamp_ns = 42;
    header.header.SetFrameId("cam");
    pixels.resize(header.PayloadBytes());
  }
  template <typename T>
  T* As() {
    return reinterpret_cast<T*>(pixels.data());
  }
};

TestImage Rectified(const Rectifier& r, const TestImage& in) {
  TestImage out(in.header.width, in.header.height, in.header.encoding);
  r.Rectify(in.header, in.pixels, out.header, out.pixels);
  return out;
}

TEST(Rectify, SourcePixelsFollowOpenCvsProjectionForBothModels) {
  for (const msgs::CameraInfo& info : {test::Freiburg1Info(), RationalInfo()}) {
    const Rectifier rectifier(info);
    std::vector<cv::Point3d> rays;
    std::vector<cv::Point2i> at;
    for (int y = 0; y < 480; y += 37) {
      for (int x = 0; x < 640; x += 41) {
        rays.emplace_back((x - info.cx) / info.fx, (y - info.cy) / info.fy, 1.0);
        at.emplace_back(x, y);
      }
    }
    std::vector<cv::Point2d> expected;
    cv::projectPoints(rays, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), test::K(info), test::D(info),
                      expected);
    double worst = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
      const auto p =
          rectifier.SourcePixel(static_cast<uint32_t>(at[i].x), static_cast<uint32_t>(at[i].y));
      worst = std::max(worst, std::hypot(p[0] - expected[i].x, p[1] - expected[i].y));
    }
    EXPECT_LT(worst, 1e-3) << msgs::DistortionModelName(info.distortion_model);
  }
}

// Largest distance of `points` from their total-least-squares line, pixels.
double LineDeviation(const std::vector<cv::Point2f>& points) {
  cv::Vec4f line;
  cv::fitLine(points, line, cv::DIST_L2, 0, 1e-6, 1e-6);
  double worst = 0;
  for (const auto& p : points) {
    worst =
        std::max(worst, double(std::abs((p.x - line[2]) * line[1] - (p.y - line[3]) * line[0])));
  }
  return worst;
}

// Rows and columns of a cols x rows corner grid: the largest deviation from a straight line.
double WorstStraightness(const std::vector<cv::Point2f>& corners, cv::Size pattern) {
  double worst = 0;
  for (int r = 0; r < pattern.height; ++r) {
    worst = std::max(worst, LineDeviation({corners.begin() + r * pattern.width,
                                           corners.begin() + (r + 1) * pattern.width}));
  }
  for (int c = 0; c < pattern.width; ++c) {
    std::vector<cv::Point2f> column;
    for (int r = 0; r < pattern.height; ++r) column.push_back(corners[r * pattern.width + c]);
    worst = std::max(worst, LineDeviation(column));
  }
  return worst;
}

std::vector<cv::Point2f> Corners(const cv::Mat& grey, cv::Size pattern) {
  std::vector<cv::Point2f> corners;
  EXPECT_TRUE(cv::findChessboardCorners(
      grey, pattern, corners, cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE));
  if (corners.size() != static_cast<size_t>(pattern.area())) return {};
  cv::cornerSubPix(grey, corners, cv::Size(7, 7), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 50, 1e-4));
  return corners;
}

TEST(Rectify, CheckerboardLinesAreStraightAfterRectification) {
  const msgs::CameraInfo info = test::Freiburg1Info();
  const cv::Size squares(10, 7), pattern(9, 6);
  const double square = 0.06;
  const cv::Vec3d rvec(0.08, -0.12, 0.03), tvec(-0.3, -0.19, 0.50);
  // The board through the Freiburg 1 lens, and through a pinhole with the same K: the reference
  // (the corner detector's own bias, about 0.2 px on these renders, cancels in the comparison).
  const cv::Mat distorted = test::RenderBoard(info, squares, square, rvec, tvec, true);
  const cv::Mat pinhole = test::RenderBoard(info, squares, square, rvec, tvec, false);
  TestImage in(640, 480, msgs::Encoding::kMono8);
  std::memcpy(in.pixels.data(), distorted.data, in.pixels.size());
  const Rectifier rectifier(info);
  TestImage out = Rectified(rectifier, in);
  const cv::Mat rectified(480, 640, CV_8UC1, out.pixels.data());

  const std::vector<cv::Point2f> before = Corners(distorted, pattern);
  const std::vector<cv::Point2f> after = Corners(rectified, pattern);
  const std::vector<cv::Point2f> reference = Corners(pinhole, pattern);
  ASSERT_FALSE(before.empty());
  ASSERT_FALSE(after.empty());
  ASSERT_FALSE(reference.empty());
  const double bent = WorstStraightness(before, pattern);
  const double straight = WorstStraightness(after, pattern);
  const double floor = WorstStraightness(reference, pattern);
  EXPECT_GT(bent, 0.9) << "the lens must bend the lines for the test to mean anything";
  EXPECT_LT(straight, 0.3) << "bent " << bent;
  EXPECT_LT(straight, floor + 0.1) << "pinhole " << floor;
  double worst = 0, worst_before = 0;
  for (size_t i = 0; i < reference.size(); ++i) {
    worst = std::max(worst, double(cv::norm(after[i] - reference[i])));
    worst_before = std::max(worst_before, double(cv::norm(before[i] - reference[i])));
  }
  // 0.3 px: what a float bicubic remap through the exact maps gives too (the render's per-pixel
  // box filter is not invariant under the warp), against up to 7 px before rectification.
  EXPECT_LT(worst, 0.4) << "corners moved by up to " << worst_before << " px before rectification";
  EXPECT_GT(worst_before, 5.0);
  std::printf(
      "lines: %.3f px from straight before, %.3f after (pinhole render %.3f); corners %.3f px "
      "from the pinhole render's before, %.3f after\n",
      bent, straight, floor, worst_before, worst);
}

// Two planes, 1000 mm left of a slanted edge and 2000 mm right, with holes.
TestImage StepDepth() {
  TestImage d(640, 480, msgs::Encoding::kDepth16);
  for (int y = 0; y < 480; ++y) {
    for (int x = 0; x < 640; ++x) {
      uint16_t v = x < 300 + y / 4 ? 1000 : 2000;
      if ((x * 7 + y * 13) % 97 == 0) v = 0;
      d.As<uint16_t>()[y * 640 + x] = v;
    }
  }
  return d;
}

TEST(Rectify, NearestDepthNeverInventsADepth) {
  const Rectifier rectifier(test::Freiburg1Info());
  const TestImage out = Rectified(rectifier, StepDepth());
  std::set<uint16_t> values;
  const auto* p = reinterpret_cast<const uint16_t*>(out.pixels.data());
  for (size_t i = 0; i < 640 * 480; ++i) values.insert(p[i]);
  EXPECT_EQ(values, (std::set<uint16_t>{0, 1000, 2000}));
  EXPECT_EQ(out.header.header.stamp_ns, 42);
  EXPECT_EQ(out.header.header.FrameId(), "cam");
}

TEST(Rectify, EdgeAwareDepthInterpolatesSurfacesButNotAcrossEdges) {
  RectifyOptions options;
  options.depth_interpolation = DepthInterpolation::kEdgeAware;
  const Rectifier rectifier(test::Freiburg1Info(), options);
  // A plane slanted along x (float metres): interpolation recovers its depth at the source
  // position; nearest would be off by up to half a pixel's slope.
  TestImage plane(640, 480, msgs::Encoding::kFloat32);
  for (int y = 0; y < 480; ++y) {
    for (int x = 0; x < 640; ++x) plane.As<float>()[y * 640 + x] = 1.0f + 0.001f * x;
  }
  const TestImage out = Rectified(rectifier, plane);
  double worst = 0;
  for (uint32_t y = 40; y < 440; y += 7) {
    for (uint32_t x = 40; x < 600; x += 7) {
      const float expected = 1.0f + 0.001f * rectifier.SourcePixel(x, y)[0];
      worst = std::max(
          worst, double(std::abs(reinterpret_cast<const float*>(out.pixels.data())[y * 640 + x] -
                                 expected)));
    }
  }
  EXPECT_LT(worst, 1e-5);
  const TestImage step = Rectified(rectifier, StepDepth());
  const auto* p = reinterpret_cast<const uint16_t*>(step.pixels.data());
  for (size_t i = 0; i < 640 * 480; ++i) {
    ASSERT_TRUE(p[i] == 0 || p[i] == 1000 || p[i] == 2000) << "pixel " << i << ": " << p[i];
  }
}

TEST(Rectify, EveryEncodingKeepsItsLayoutAndAConstantImageConstant) {
  const Rectifier rectifier(test::Freiburg1Info());
  for (msgs::Encoding e : {msgs::Encoding::kRgb8, msgs::Encoding::kBgr8, msgs::Encoding::kMono8,
                           msgs::Encoding::kMono16, msgs::Encoding::kRgb32f}) {
    TestImage in(640, 480, e);
    for (size_t i = 0; i < in.pixels.size(); ++i) in.pixels[i] = std::byte{0x40};
    const TestImage out = Rectified(rectifier, in);
    EXPECT_EQ(out.header.Describe(), in.header.Describe());
    // The centre samples inside the source: unchanged by bilinear interpolation of a constant.
    const size_t centre = (240 * 640 + 320) * msgs::BytesPerPixel(e);
    for (size_t b = 0; b < msgs::BytesPerPixel(e); ++b) {
      EXPECT_EQ(out.pixels[centre + b], std::byte{0x40}) << msgs::EncodingName(e);
    }
    // A corner of the rectified Freiburg 1 image samples outside the source: 0.
    EXPECT_EQ(out.pixels[0], std::byte{0}) << msgs::EncodingName(e);
  }
}

TEST(Rectify, UndistortedCamerasPassThroughAndPublishPlumbBobZeros) {
  msgs::CameraInfo none = test::Freiburg1Info();
  none.distortion_model = msgs::DistortionModel::kNone;
  none.distortion_count = 0;
  std::fill(std::begin(none.distortion), std::end(none.distortion), 0.0);
  msgs::CameraInfo zeros = none;
  zeros.distortion_model = msgs::DistortionModel::kPlumbBob;
  zeros.distortion_count = 5;
  for (const msgs::CameraInfo& info : {none, zeros}) {
    const Rectifier rectifier(info);
    EXPECT_TRUE(rectifier.passthrough());
    EXPECT_TRUE(rectifier.Matches(none));
    EXPECT_TRUE(rectifier.Matches(zeros));
    EXPECT_FALSE(rectifier.Matches(test::Freiburg1Info()));
    // A padded source row (step 1936) comes out packed and byte-identical.
    msgs::Image in;
    in.Init(640, 480, msgs::Encoding::kRgb8);
    in.step = 1936;
    std::vector<std::byte> pixels(in.PayloadBytes());
    for (size_t i = 0; i < pixels.size(); ++i) pixels[i] = std::byte(static_cast<uint8_t>(i * 31));
    TestImage out(640, 480, msgs::Encoding::kRgb8);
    rectifier.Rectify(in, pixels, out.header, out.pixels);
    EXPECT_EQ(out.header.step, 1920u);
    for (uint32_t y = 0; y < 480; y += 53) {
      EXPECT_EQ(std::memcmp(out.pixels.data() + y * 1920, pixels.data() + y * 1936, 1920), 0);
    }
    const msgs::CameraInfo& r = rectifier.rectified_info();
    EXPECT_EQ(r.distortion_model, msgs::DistortionModel::kPlumbBob);
    EXPECT_EQ(r.distortion_count, 5u);
    EXPECT_EQ(r.fx, info.fx);
    EXPECT_EQ(r.cy, info.cy);
  }
}

// Without any calibration the node copies frames through CopyImage: packed, byte-identical, the
// header kept, and the same one-line errors as Rectify.
TEST(Rectify, CopyImagePacksRowsKeepsTheHeaderAndNamesTheTopic) {
  msgs::Image in;
  in.Init(64, 8, msgs::Encoding::kMono16);
  in.step = 144;
  in.header.stamp_ns = 1234;
  std::vector<std::byte> pixels(in.PayloadBytes());
  for (size_t i = 0; i < pixels.size(); ++i) pixels[i] = std::byte(static_cast<uint8_t>(i * 7));
  TestImage out(64, 8, msgs::Encoding::kMono16);
  CopyImage(in, pixels, out.header, out.pixels, "/camera/depth");
  EXPECT_EQ(out.header.step, 128u);
  EXPECT_EQ(out.header.header.stamp_ns, 1234);
  for (uint32_t y = 0; y < 8; ++y) {
    EXPECT_EQ(std::memcmp(out.pixels.data() + y * 128, pixels.data() + y * 144, 128), 0);
  }
  std::vector<std::byte> tiny(100);
  EXPECT_EQ(ThrownMessage<RectifyError>(
                [&] { CopyImage(in, pixels, out.header, tiny, "/camera/depth"); }),
            "/camera/depth: output buffer of 100 bytes, 1024 needed");
  in.encoding = msgs::Encoding::kInvalid;
  EXPECT_EQ(ThrownMessage<RectifyError>(
                [&] { CopyImage(in, pixels, out.header, out.pixels, "/camera/depth"); }),
            "/camera/depth: invalid image encoding 0");
}

TEST(Rectify, RectifiedCameraInfoIsTheRosProjection) {
  msgs::CameraInfo info = test::Freiburg1Info();
  info.header.SetFrameId("kinect_rgb");
  info.header.stamp_ns = 7;
  const msgs::CameraInfo kept = RectifiedCameraInfo(info, {}, "info");
  EXPECT_EQ(kept.header.FrameId(), "kinect_rgb");
  EXPECT_EQ(kept.header.stamp_ns, 7);
  EXPECT_EQ(kept.fx, info.fx);
  EXPECT_EQ(kept.cx, info.cx);
  EXPECT_EQ(kept.distortion_model, msgs::DistortionModel::kPlumbBob);
  EXPECT_EQ(kept.distortion_count, 5u);
  for (double d : kept.distortion) EXPECT_EQ(d, 0.0);
  EXPECT_EQ(kept.depth_scale, 0.001);
  EXPECT_FALSE(HasDistortion(kept));
  EXPECT_NO_THROW(kept.Validate());
  // alpha = 0: the new camera sees only valid pixels (fr1's lens compresses the periphery, so the
  // valid region's camera has a longer focal length than K... or shorter: only its validity is
  // checked): every rectified corner pixel samples inside the source.
  RectifyOptions zero;
  zero.alpha = 0;
  const Rectifier cropped(info, zero);
  EXPECT_NE(cropped.rectified_info().fx, info.fx);
  for (auto [x, y] : {std::pair<uint32_t, uint32_t>{0, 0}, {639, 0}, {0, 479}, {639, 479}}) {
    const auto p = cropped.SourcePixel(x, y);
    EXPECT_GE(p[0], -1.0f);
    EXPECT_LE(p[0], 640.0f);
    EXPECT_GE(p[1], -1.0f);
    EXPECT_LE(p[1], 480.0f);
  }
}

// A calibration written as ROS YAML (tools/calibrate writes through calib::WriteCameraInfoYaml) and
// read back gives the same maps, for both models.
TEST(Rectify, CalibrationFilesRoundTripToTheSameMaps) {
  TempDir dir("rectify");
  for (const msgs::CameraInfo& info : {test::Freiburg1Info(), RationalInfo()}) {
    calib::Intrinsics k;
    k.width = info.width;
    k.height = info.height;
    k.fx = info.fx;
    k.fy = info.fy;
    k.cx = info.cx;
    k.cy = info.cy;
    k.model = info.distortion_model;
    k.distortion = test::D(info);
    const std::string path = dir.File("cam.yaml");
    calib::WriteCameraInfoYaml(path, k, "cam");
    msgs::CameraInfo read;
    calib::FillCameraInfo(calib::ReadCalibrationFile(path), 0.001, read);
    const Rectifier a(info), b(read, {}, path);
    EXPECT_TRUE(a.Matches(read));
    for (uint32_t y = 0; y < 480; y += 5) {
      for (uint32_t x = 0; x < 640; x += 5) ASSERT_EQ(a.SourcePixel(x, y), b.SourcePixel(x, y));
    }
  }
}

TEST(Rectify, MalformedCalibrationsNameTheirSource) {
  TempDir dir("rectify");
  const std::string six = dir.File("six.yaml");
  probeless::testing::WriteText(six,
                                "image_width: 640\nimage_height: 480\ncamera_matrix:\n  rows: 3\n"
                                "  cols: 3\n  data: [517.3, 0, 318.6, 0, 516.5, 255.3, 0, 0, 1]\n"
                                "distortion_model: plumb_bob\ndistortion_coefficients:\n  rows: 1\n"
                                "  cols: 6\n  data: [0.26, -0.95, 0, 0, 1.16, 0.1]\n");
  EXPECT_NE(ThrownMessage<calib::CalibrationError>([&] {
              calib::ReadCalibrationFile(six);
            }).find("'" + six + "'"),
            std::string::npos);
  const std::string nan = dir.File("nan.yaml");
  probeless::testing::WriteText(nan,
                                "image_width: 640\nimage_height: 480\ncamera_matrix:\n  rows: 3\n"
                                "  cols: 3\n  data: [517.3, 0, 318.6, 0, 516.5, 255.3, 0, 0, 1]\n"
                                "distortion_model: plumb_bob\ndistortion_coefficients:\n  rows: 1\n"
                                "  cols: 5\n  data: [0.26, .nan, 0, 0, 1.16]\n");
  const std::string error = ThrownMessage<RectifyError>([&] {
    msgs::CameraInfo info;
    calib::FillCameraInfo(calib::ReadCalibrationFile(nan), 0.001, info);
    Rectifier r(info, {}, "calibration file '" + nan + "'");
  });
  EXPECT_NE(error.find("'" + nan + "'"), std::string::npos) << error;
  EXPECT_NE(error.find("NaN"), std::string::npos) << error;
}

TEST(Rectify, BadInputIsOneLineNamingTheTopic) {
  const std::string topic = "/camera/camera_info";
  msgs::CameraInfo info = test::Freiburg1Info();
  info.distortion_count = 4;
  EXPECT_EQ(ThrownMessage<RectifyError>([&] { Rectifier r(info, {}, topic); }),
            "/camera/camera_info: distortion model plumb_bob has 5 coefficients, "
            "distortion_count is 4");
  info = test::Freiburg1Info();
  info.distortion[2] = std::nan("");
  EXPECT_EQ(ThrownMessage<RectifyError>([&] { Rectifier r(info, {}, topic); }),
            "/camera/camera_info: distortion coefficient 2 (p1) is NaN");
  info.distortion[2] = INFINITY;
  EXPECT_EQ(ThrownMessage<RectifyError>([&] { Rectifier r(info, {}, topic); }),
            "/camera/camera_info: distortion coefficient 2 (p1) is infinite");
  info = test::Freiburg1Info();
  info.distortion_model = static_cast<msgs::DistortionModel>(9);
  EXPECT_EQ(ThrownMessage<RectifyError>([&] { Rectifier r(info, {}, topic); }),
            "/camera/camera_info: invalid distortion model 9 (expected none, plumb_bob or "
            "rational_polynomial)");
  info = test::Freiburg1Info();
  info.width = 0;
  EXPECT_EQ(ThrownMessage<RectifyError>([&] { Rectifier r(info, {}, topic); }),
            "/camera/camera_info: image size 0x480 (width and height must be > 0)");
  info = test::Freiburg1Info();
  info.fx = -1;
  EXPECT_EQ(ThrownMessage<RectifyError>([&] { Rectifier r(info, {}, topic); }),
            "/camera/camera_info: fx and fy must be finite and > 0");
  RectifyOptions alpha;
  alpha.alpha = 2;
  EXPECT_EQ(ThrownMessage<RectifyError>([&] { Rectifier r(test::Freiburg1Info(), alpha, topic); }),
            "/camera/camera_info: alpha 2.000000 is outside [0, 1] (or < 0 to keep the camera "
            "matrix)");

  const Rectifier rectifier(test::Freiburg1Info(), {}, topic);
  TestImage small(320, 240, msgs::Encoding::kRgb8), out(640, 480, msgs::Encoding::kRgb8);
  EXPECT_EQ(ThrownMessage<RectifyError>([&] {
              rectifier.Rectify(small.header, small.pixels, out.header, out.pixels,
                                "/camera/image");
            }),
            "/camera/image: image 320x240 does not match the calibration (640x480 from "
            "/camera/camera_info)");
  TestImage in(640, 480, msgs::Encoding::kRgb8);
  std::vector<std::byte> tiny(100);
  EXPECT_EQ(ThrownMessage<RectifyError>([&] {
              rectifier.Rectify(in.header, in.pixels, out.header, tiny, "/camera/image");
            }),
            "/camera/image: output buffer of 100 bytes, 921600 needed");
  EXPECT_EQ(ThrownMessage<RectifyError>([&] {
              rectifier.Rectify(in.header, std::span(in.pixels).first(10), out.header, out.pixels,
                                "/camera/image");
            }),
            "/camera/image: Image 640x480 rgb8 (step 1920) needs 921600 payload bytes, got 10");
  in.header.encoding = msgs::Encoding::kInvalid;
  EXPECT_EQ(ThrownMessage<RectifyError>([&] {
              rectifier.Rectify(in.header, in.pixels, out.header, out.pixels, "/camera/image");
            }),
            "/camera/image: invalid image encoding 0");
}

}  // namespace
}  // namespace probeless::rectify
