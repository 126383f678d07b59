// V4L2 without a camera: control mapping (what locking exposure / white balance / gain writes),
// format negotiation, lookup by name in a /dev/v4l/by-id folder made here, and the real open path
// against a missing device and a file that is not a V4L2 device. libcamera: a missing camera.
#include "probeless/capture/v4l2.h"

#include <gtest/gtest.h>
#include <linux/videodev2.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "probeless/capture/capture_error.h"

namespace {

namespace fs = std::filesystem;
using namespace probeless::capture;

TEST(V4l2ControlsTest, ExplicitValuesTurnTheirAutoModeOffFirst) {
  V4l2Controls c;
  c.exposure_time_us = 10000;
  c.white_balance_temperature_k = 4500;
  c.gain = 64;
  const std::vector<ControlWrite> w = MapControls(c);
  ASSERT_EQ(w.size(), 7u);
  EXPECT_EQ(w[0].id, V4L2_CID_EXPOSURE_AUTO);
  EXPECT_EQ(w[0].value, V4L2_EXPOSURE_MANUAL);
  EXPECT_EQ(w[1].id, V4L2_CID_EXPOSURE_AUTO_PRIORITY);
  EXPECT_EQ(w[2].id, V4L2_CID_AUTO_WHITE_BALANCE);
  EXPECT_EQ(w[2].value, 0);
  EXPECT_EQ(w[3].id, V4L2_CID_AUTOGAIN);
  EXPECT_EQ(w[3].value, 0);
  EXPECT_EQ(w[4].id, V4L2_CID_EXPOSURE_ABSOLUTE);
  EXPECT_EQ(w[4].value, 100);  // 10 ms in 100 us units
  EXPECT_EQ(w[5].id, V4L2_CID_WHITE_BALANCE_TEMPERATURE);
  EXPECT_EQ(w[6].id, V4L2_CID_GAIN);
  // Those were explicit, so nothing is left to lock later.
  EXPECT_TRUE(LockControls(c).empty());
}

TEST(V4l2ControlsTest, DefaultLocksAutoModesAfterSettling) {
  V4l2Controls c;
  EXPECT_TRUE(MapControls(c).empty());
  const std::vector<ControlWrite> lock = LockControls(c);
  ASSERT_EQ(lock.size(), 4u);
  EXPECT_EQ(lock[0].id, V4L2_CID_EXPOSURE_AUTO);
  EXPECT_EQ(lock[0].value, V4L2_EXPOSURE_MANUAL);
  EXPECT_EQ(lock[2].id, V4L2_CID_AUTO_WHITE_BALANCE);
  EXPECT_EQ(lock[3].id, V4L2_CID_AUTOGAIN);
  c.auto_exposure = true;  // explicitly automatic: kept
  c.lock_auto = true;
  const std::vector<ControlWrite> w = MapControls(c);
  ASSERT_EQ(w.size(), 1u);
  EXPECT_EQ(w[0].value, V4L2_EXPOSURE_APERTURE_PRIORITY);
  EXPECT_EQ(LockControls(c).size(), 2u);
  c.lock_auto = false;
  EXPECT_TRUE(LockControls(c).empty());
}

TEST(V4l2FormatTest, Negotiation) {
  const std::vector<FormatOption> offers = {
      {PixelFormat::kYuyv, 640, 480, 30},   {PixelFormat::kYuyv, 1280, 720, 10},
      {PixelFormat::kMjpeg, 640, 480, 30},  {PixelFormat::kMjpeg, 1280, 720, 30},
      {PixelFormat::kMjpeg, 1280, 720, 60}, {PixelFormat::kYuyv, 320, 240, 30}};
  FormatOption f = ChooseFormat(offers, "auto", 640, 480, 30, "/dev/video0");
  EXPECT_EQ(f.format, PixelFormat::kYuyv);
  f = ChooseFormat(offers, "auto", 1280, 720, 60, "/dev/video0");
  EXPECT_EQ(f.format, PixelFormat::kMjpeg);
  EXPECT_EQ(f.fps, 60);
  f = ChooseFormat(offers, "yuyv", 800, 600, 30, "/dev/video0");  // closest size
  EXPECT_EQ(f.width, 640u);
  try {
    ChooseFormat({{PixelFormat::kYuyv, 640, 480, 30}}, "grey", 640, 480, 30, "/dev/video0");
    FAIL();
  } catch (const CaptureError& e) {
    EXPECT_STREQ(e.what(),
                 "V4L2 device '/dev/video0' offers no grey format (offers: yuyv 640x480@30): set "
                 "param pixel_format to one of them");
  }
}

TEST(V4l2DeviceTest, LookupByNameInByIdFolder) {
  const fs::path dir = fs::temp_directory_path() / ("probeless_byid_" + std::to_string(getpid()));
  fs::create_directories(dir);
  for (const char* name :
       {"usb-Logitech_HD_Pro_Webcam_C920_ABC123-video-index0",
        "usb-Logitech_HD_Pro_Webcam_C920_ABC123-video-index1", "usb-Other_Cam_XYZ-video-index0"}) {
    std::ofstream(dir / name) << "";
  }
  EXPECT_EQ(ResolveV4l2Device("c920", dir.string()),
            (dir / "usb-Logitech_HD_Pro_Webcam_C920_ABC123-video-index0").string());
  EXPECT_EQ(ResolveV4l2Device("XYZ", dir.string()),
            (dir / "usb-Other_Cam_XYZ-video-index0").string());
  EXPECT_EQ(ResolveV4l2Device("/dev/video7", dir.string()), "/dev/video7");
  try {
    ResolveV4l2Device("usb", dir.string());
    FAIL();
  } catch (const CaptureError& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kBadInput);
    EXPECT_NE(std::string(e.what()).find("matches 2 cameras"), std::string::npos);
  }
  try {
    ResolveV4l2Device("brio", dir.string());
    FAIL();
  } catch (const CaptureError& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kNoDevice);
    EXPECT_EQ(std::string(e.what()).substr(0, 27), "no V4L2 camera named 'brio'");
  }
  fs::remove_all(dir);
  try {
    ResolveV4l2Device("c920", dir.string());
    FAIL();
  } catch (const CaptureError& e) {
    EXPECT_EQ(std::string(e.what()), "no V4L2 camera named 'c920' in " + dir.string() +
                                         " (no camera connected): plug it in or fix param device");
  }
}

TEST(V4l2DeviceTest, RealOpenPathErrors) {
  V4l2Options options;
  options.device = "/dev/video_probeless_missing";
  try {
    OpenV4l2(options, [](const std::string&) {});
    FAIL();
  } catch (const CaptureError& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kNoDevice);
    EXPECT_STREQ(e.what(),
                 "V4L2 device '/dev/video_probeless_missing' does not exist: plug the camera in or "
                 "pick another with param device (ls /dev/v4l/by-id)");
    EXPECT_TRUE(e.retryable());
  }
  options.device = "/dev/null";  // a character device that is not V4L2
  try {
    OpenV4l2(options, [](const std::string&) {});
    FAIL();
  } catch (const CaptureError& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kBadInput);
    EXPECT_EQ(std::string(e.what()).substr(0, 48),
              "V4L2 device '/dev/null' is not a V4L2 video devi");
    EXPECT_FALSE(e.retryable());
  }
}

TEST(LibcameraTest, MissingCameraIsAClearError) {
  LibcameraOptions options;
  options.camera_id = "/base/soc/i2c0mux/i2c@1/imx219@10";
  try {
    OpenLibcamera(options, [](const std::string&) {});
    FAIL() << "a camera was found";
  } catch (const CaptureError& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kNoDevice) << e.what();
    EXPECT_EQ(std::string(e.what()),
              "libcamera camera '/base/soc/i2c0mux/i2c@1/imx219@10' not found (libcamera finds no "
              "camera): connect it, or set param camera_id (cam --list)");
  }
}

}  // namespace
