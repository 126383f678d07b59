// Capture's choice of intrinsics: calibration file > device factory values > field-of-view default,
// scaling a file to another resolution of the same aspect ratio, and calibration file errors as
// CaptureError(kBadInput). The files themselves are tested in common/calib.
#include "probeless/capture/intrinsics.h"

#include <gtest/gtest.h>

#include <cmath>

#include "probeless/capture/capture_error.h"
#include "probeless/testing/testing.h"

namespace {

using namespace probeless;
using namespace probeless::capture;
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

TEST(IntrinsicsTest, ResolveOrderAndScaling) {
  TempDir dir("probeless_capture_k");
  const std::string path = dir.File("cam.yaml");
  calib::WriteCameraInfoYaml(path, Sample(), "webcam");
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
    EXPECT_EQ(e.kind(), ErrorKind::kBadInput);
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

TEST(IntrinsicsTest, CalibrationErrorsAreBadInput) {
  TempDir dir("probeless_capture_k");
  const std::string missing = dir.File("missing.yaml");
  const std::string bad = dir.File("bad.yaml");
  WriteText(bad, "camera_matrix: {rows: 3, cols: 3, data: [1, 2, 3]}\n");
  for (const auto& [path, fov, message] :
       {std::tuple{missing, 60.0, "cannot read calibration file '" + missing + "'"},
        std::tuple{bad, 60.0,
                   "calibration file '" + bad + "': camera matrix has 3 entries, expected 9 (3x3)"},
        std::tuple{std::string(), 200.0,
                   std::string("field of view 200.000000 deg is outside (0, 180)")}}) {
    try {
      ResolveIntrinsics(path, std::nullopt, 640, 480, fov);
      ADD_FAILURE() << message;
    } catch (const CaptureError& e) {
      EXPECT_EQ(e.kind(), ErrorKind::kBadInput);
      EXPECT_EQ(std::string(e.what()), message);
    }
  }
}

}  // namespace
