// Calibration files: ROS camera_info YAML and OpenCV FileStorage YAML/XML, written and read back,
// the field-of-view guess, scaling to another resolution, CameraInfo fields, and one-line errors.
#include "probeless/calib/calibration.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <opencv2/core.hpp>
#include <string>

#include "probeless/testing/expect.h"
#include "probeless/testing/testing.h"

namespace {

using namespace probeless;
using namespace probeless::calib;
using probeless::testing::TempDir;
using probeless::testing::WriteText;

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

TEST(CalibrationTest, RosYamlRoundTrip) {
  TempDir dir("probeless_calib");
  const std::string path = dir.File("cam.yaml");
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
  EXPECT_NE(CameraInfoYaml(Sample(), "webcam").find("camera_name: webcam\n"), std::string::npos);
}

TEST(CalibrationTest, RosYamlDistortionCounts) {
  TempDir dir("probeless_calib");
  const std::string path = dir.File("cam.yaml");
  const std::string k = "camera_matrix: {rows: 3, cols: 3, data: [1, 0, 2, 0, 1, 2, 0, 0, 1]}\n";
  WriteText(path, k + "distortion_coefficients: {rows: 1, cols: 4, data: [1, 2, 3, 4]}\n");
  Intrinsics read = ReadCalibrationFile(path);
  EXPECT_EQ(read.model, msgs::DistortionModel::kPlumbBob);
  ASSERT_EQ(read.distortion.size(), 5u);  // k3 = 0 added
  EXPECT_EQ(read.distortion[4], 0);
  WriteText(path, k);
  EXPECT_EQ(ReadCalibrationFile(path).model, msgs::DistortionModel::kNone);
  WriteText(path,
            k + "distortion_model: rational_polynomial\n"
                "distortion_coefficients: {rows: 1, cols: 8, data: [1, 2, 3, 4, 5, 6, 7, 8]}\n");
  EXPECT_EQ(ReadCalibrationFile(path).model, msgs::DistortionModel::kRationalPolynomial);
  WriteText(path, k + "distortion_model: rational_polynomial\n"
                      "distortion_coefficients: {rows: 1, cols: 5, data: [1, 2, 3, 4, 5]}\n");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      ReadCalibrationFile(path), CalibrationError,
      "calibration file '" + path + "': rational_polynomial needs 8 distortion coefficients");
  WriteText(path, k + "distortion_coefficients: {rows: 1, cols: 3, data: [1, 2, 3]}\n");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      ReadCalibrationFile(path), CalibrationError,
      "calibration file '" + path +
          "' has 3 distortion coefficients: expected 0, 4, 5 (plumb_bob) or 8 "
          "(rational_polynomial)");
}

TEST(CalibrationTest, OpenCvFileStorageYamlAndXml) {
  TempDir dir("probeless_calib");
  for (const char* name : {"cv.yml", "cv.xml"}) {
    const std::string path = dir.File(name);
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
  // OpenCV's own key names (cv::calibrateCamera samples).
  const std::string path = dir.File("opencv.yml");
  {
    cv::FileStorage fs(path, cv::FileStorage::WRITE);
    fs << "width" << 320 << "height" << 240;
    fs << "cameraMatrix" << (cv::Mat_<float>(3, 3) << 300, 0, 160, 0, 301, 120, 0, 0, 1);
    fs << "distCoeffs" << (cv::Mat_<double>(8, 1) << 1, 2, 3, 4, 5, 6, 7, 8);
  }
  const Intrinsics k = ReadCalibrationFile(path);
  EXPECT_DOUBLE_EQ(k.fy, 301);
  EXPECT_EQ(k.height, 240u);
  EXPECT_EQ(k.model, msgs::DistortionModel::kRationalPolynomial);
}

TEST(CalibrationTest, BadFilesGiveOneLine) {
  TempDir dir("probeless_calib");
  const std::string missing = dir.File("missing.yaml");
  PROBELESS_EXPECT_THROWS_MESSAGE(ReadCalibrationFile(missing), CalibrationError,
                                  "cannot read calibration file '" + missing + "'");
  const std::string path = dir.File("bad.yaml");
  WriteText(path, "camera_matrix: {rows: 3, cols: 3, data: [1, 2, 3]}\n");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      ReadCalibrationFile(path), CalibrationError,
      "calibration file '" + path + "': camera matrix has 3 entries, expected 9 (3x3)");
  WriteText(path, "camera_matrix: {rows: 3, cols: 3, data: [0, 0, 2, 0, 1, 2, 0, 0, 1]}\n");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      ReadCalibrationFile(path), CalibrationError,
      "calibration file '" + path + "': camera matrix must have positive focal lengths fx, fy");
  WriteText(path, "- 1\n- 2\n");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      ReadCalibrationFile(path), CalibrationError,
      "calibration file '" + path +
          "': expected a ROS camera_info YAML mapping (camera_matrix, ...)");
  WriteText(path, "image_width: 40\n");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      ReadCalibrationFile(path), CalibrationError,
      "calibration file '" + path +
          "': missing camera_matrix (expected a ROS camera_info YAML file)");
  WriteText(path,
            "image_width: 40.5\n"
            "camera_matrix: {rows: 3, cols: 3, data: [1, 0, 2, 0, 1, 2, 0, 0, 1]}\n");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      ReadCalibrationFile(path), CalibrationError,
      "calibration file '" + path + "': image_width must be a non-negative whole number of pixels");
  WriteText(path, "camera_matrix: [1, 2]\n");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      ReadCalibrationFile(path), CalibrationError,
      "calibration file '" + path + "': camera_matrix needs a data list");
  const std::string xml = dir.File("bad.xml");
  WriteText(xml,
            "<?xml version=\"1.0\"?>\n<opencv_storage>\n"
            "<image_width>20</image_width></opencv_storage>\n");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      ReadCalibrationFile(xml), CalibrationError,
      "calibration file '" + xml +
          "': missing camera_matrix (or cameraMatrix, K) in OpenCV FileStorage file");
  const std::string unwritable = dir.File("no/such/folder") + "/cam.yaml";
  std::filesystem::remove_all(dir.File("no"));
  PROBELESS_EXPECT_THROWS_MESSAGE(
      WriteCameraInfoYaml(unwritable, Sample(), "x"), CalibrationError,
      "calibration file '" + unwritable +
          "' cannot be written (check the folder exists and is writable)");
}

TEST(CalibrationTest, FieldOfViewGuessScalingAndCameraInfo) {
  const Intrinsics guess = IntrinsicsFromFieldOfView(640, 480);
  EXPECT_NEAR(guess.fx, 640 / (2 * std::tan(std::numbers::pi / 6)), 1e-9);
  EXPECT_EQ(guess.fy, guess.fx);
  EXPECT_EQ(guess.cx, 319.5);
  EXPECT_EQ(guess.cy, 239.5);
  EXPECT_EQ(guess.model, msgs::DistortionModel::kNone);
  PROBELESS_EXPECT_THROWS_MESSAGE(IntrinsicsFromFieldOfView(640, 480, 180), CalibrationError,
                                  "field of view 180.000000 deg is outside (0, 180)");

  const Intrinsics half = ScaleIntrinsics(Sample(), 320, 240);
  EXPECT_DOUBLE_EQ(half.fx, 525.5 / 2);
  EXPECT_DOUBLE_EQ(half.cx, (319.75 + 0.5) / 2 - 0.5);
  EXPECT_EQ(half.width, 320u);
  Intrinsics unsized = Sample();
  unsized.width = 0;
  EXPECT_DOUBLE_EQ(ScaleIntrinsics(unsized, 320, 240).fx, 525.5);

  msgs::CameraInfo info;
  FillCameraInfo(Sample(), 0.001, info);
  EXPECT_EQ(info.width, 640u);
  EXPECT_EQ(info.fy, 524.25);
  EXPECT_EQ(info.distortion_model, msgs::DistortionModel::kPlumbBob);
  EXPECT_EQ(info.distortion_count, 5u);
  EXPECT_EQ(info.distortion[4], 0.05);
  EXPECT_EQ(info.depth_scale, 0.001);

  // Without distortion: plumb_bob with five zeros, as ROS writes an undistorted camera.
  msgs::CameraInfo plain;
  FillCameraInfo(guess, 0, plain);
  EXPECT_EQ(plain.distortion_model, msgs::DistortionModel::kPlumbBob);
  EXPECT_EQ(plain.distortion_count, 5u);
  for (int i = 0; i < 5; ++i) EXPECT_EQ(plain.distortion[i], 0.0);
}

}  // namespace
