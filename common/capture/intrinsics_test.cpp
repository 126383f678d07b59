// Calibration files: ROS camera_info YAML and OpenCV FileStorage YAML/XML, written and read back,
// scaling to another resolution, the order file > factory > default, and clear errors.
#include "probeless/capture/intrinsics.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <opencv2/core.hpp>

#include "probeless/capture/capture_error.h"

namespace {

namespace fs = std::filesystem;
using namespace probeless;
using namespace probeless::capture;

class IntrinsicsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("probeless_capture_k_" + std::to_string(getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

Intrinsics Sample() {
  return {640,
          480,
          525.5,
          524.25,
          319.75,
          241.5,
          msgs::DistortionModel::kPlumbBob,
          {0.1, -0.2, 0.001, 0.002, 0.05}};
}

TEST_F(IntrinsicsTest, RosYamlRoundTrip) {
  const std::string path = (dir_ / "cam.yaml").string();
  WriteCameraInfoYaml(path, Sample(), "webcam");
  const Intrinsics k = ReadCalibrationFile(path);
  EXPECT_EQ(k.width, 640u);
  EXPECT_EQ(k.height, 480u);
  EXPECT_DOUBLE_EQ(k.fx, 525.5);
  EXPECT_DOUBLE_EQ(k.fy, 524.25);
  EXPECT_DOUBLE_EQ(k.cx, 319.75);
  EXPECT_DOUBLE_EQ(k.cy, 241.5);
  EXPECT_EQ(k.model, msgs::DistortionModel::kPlumbBob);
  ASSERT_EQ(k.distortion.size(), 5u);
  EXPECT_DOUBLE_EQ(k.distortion[1], -0.2);
}

TEST_F(IntrinsicsTest, OpenCvFileStorageYamlAndXml) {
  for (const char* name : {"cv.yml", "cv.xml"}) {
    const std::string path = (dir_ / name).string();
    {
      cv::FileStorage fs(path, cv::FileStorage::WRITE);
      fs << "image_width" << 640 << "image_height" << 480;
      fs << "camera_matrix" << (cv::Mat_<double>(3, 3) << 500, 0, 320, 0, 501, 240, 0, 0, 1);
      fs << "distortion_coefficients" << (cv::Mat_<double>(1, 5) << 0.1, 0.2, 0, 0, 0.3);
    }
    const Intrinsics k = ReadCalibrationFile(path);
    EXPECT_DOUBLE_EQ(k.fx, 500) << name;
    EXPECT_DOUBLE_EQ(k.fy, 501) << name;
    EXPECT_EQ(k.width, 640u) << name;
    EXPECT_EQ(k.model, msgs::DistortionModel::kPlumbBob) << name;
  }
}

TEST_F(IntrinsicsTest, ResolveOrderAndScaling) {
  const std::string path = (dir_ / "cam.yaml").string();
  WriteCameraInfoYaml(path, Sample(), "webcam");
  ResolvedIntrinsics r = ResolveIntrinsics(path, std::nullopt, 640, 480);
  EXPECT_TRUE(r.calibrated);
  EXPECT_EQ(r.source, "calibration file '" + path + "'");
  r = ResolveIntrinsics(path, std::nullopt, 320, 240);  // same aspect: scaled
  EXPECT_DOUBLE_EQ(r.intrinsics.fx, 525.5 / 2);
  EXPECT_DOUBLE_EQ(r.intrinsics.cx, (319.75 + 0.5) / 2 - 0.5);
  try {
    ResolveIntrinsics(path, std::nullopt, 1280, 720);
    FAIL();
  } catch (const CaptureError& e) {
    EXPECT_EQ(std::string(e.what()),
              "calibration file '" + path +
                  "' is for 640x480 images, the camera delivers 1280x720: calibrate at this size "
                  "(tools/calibrate) or change the size");
  }
  Intrinsics factory = Sample();
  r = ResolveIntrinsics("", factory, 640, 480);
  EXPECT_EQ(r.source, "device factory values");
  r = ResolveIntrinsics("", std::nullopt, 640, 480, 60);
  EXPECT_FALSE(r.calibrated);
  EXPECT_NEAR(r.intrinsics.fx, 640 / (2 * std::tan(M_PI / 6)), 1e-9);
  EXPECT_EQ(r.source,
            "default from a 60 deg horizontal field of view (NOT calibrated: set param "
            "camera_info_url)");
}

TEST_F(IntrinsicsTest, BadFilesGiveOneLine) {
  try {
    ReadCalibrationFile((dir_ / "missing.yaml").string());
    FAIL();
  } catch (const CaptureError& e) {
    EXPECT_EQ(std::string(e.what()), "calibration file '" + (dir_ / "missing.yaml").string() +
                                         "' cannot be read (missing or not readable)");
  }
  const std::string path = (dir_ / "bad.yaml").string();
  std::ofstream(path) << "camera_matrix: {rows: 3, cols: 3, data: [1, 2, 3]}\n";
  try {
    ReadCalibrationFile(path);
    FAIL();
  } catch (const CaptureError& e) {
    EXPECT_EQ(std::string(e.what()),
              "calibration file '" + path + "' has a camera matrix of 3 entries, expected 9 (3x3)");
  }
}

}  // namespace
