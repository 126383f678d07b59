// Unit tests of probeless_face_track on synthetic input: bad model paths, the generic 3-D model
// and head pose, sampling validity cases, SH rotation, the light smoother following an on/off step
// within 3 frames, the JSON layouts, the ARKit / WebXR exports of a known linear light (directly
// and through the face model and the linear conversion), and the hold of the last confident light
// for a backlit face.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <numbers>
#include <optional>
#include <string>
#include <vector>

#include "probeless/face_light/estimator.h"
#include "probeless/face_light/linear_light.h"
#include "probeless/face_light/model.h"
#include "probeless/face_track/face_light_pipeline.h"
#include "probeless/face_track/face_tracker.h"
#include "probeless/face_track/head_model.h"
#include "probeless/face_track/light_output.h"
#include "probeless/face_track/sampling.h"
#include "probeless/msgs/image.h"
#include "probeless/sh/sh.h"
#include "probeless/testing/expect.h"

namespace {

using namespace probeless;
using namespace probeless::face_track;
namespace fl = probeless::face_light;

TEST(FaceTracker, BadModelPathsAreClearErrors) {
  TrackerOptions o;
  o.shape_predictor_path = "/nonexistent/sp.dat";
  PROBELESS_EXPECT_THROWS_MESSAGE(
      FaceTracker t(o), FaceTrackError,
      "shape predictor model '/nonexistent/sp.dat' not found (install the Debian package "
      "libdlib-data, or set shape_predictor_path)");
  o = {};
  o.backend = DetectorBackend::kHaar;
  o.haar_cascade_path = "/nonexistent/haar.xml";
  PROBELESS_EXPECT_THROWS_MESSAGE(
      FaceTracker t(o), FaceTrackError,
      "Haar cascade model '/nonexistent/haar.xml' not found (install the Debian package "
      "opencv-data, or set haar_cascade_path)");
  o = {};
  o.backend = DetectorBackend::kYuNet;
  o.yunet_model_path = "/nonexistent/yunet.onnx";
  PROBELESS_EXPECT_THROWS_MESSAGE(
      FaceTracker t(o), FaceTrackError,
      "YuNet model '/nonexistent/yunet.onnx' not found (set yunet_model_path to an ONNX "
      "YuNet model)");
  PROBELESS_EXPECT_THROWS_MESSAGE(
      BackendFromName("mtcnn"), FaceTrackError,
      "unknown face detector backend 'mtcnn' (expected dlib, yunet or haar)");
  o = {};
  o.redetect_period = 0;
  PROBELESS_EXPECT_THROWS_MESSAGE(FaceTracker t(o), FaceTrackError, "redetect_period must be >= 1");
  o = {};
  o.flow_min_points = 2;
  PROBELESS_EXPECT_THROWS_MESSAGE(FaceTracker t(o), FaceTrackError,
                                  "flow_min_points must be in 3..51");
  o = {};
  o.flow_agreement = 0;
  PROBELESS_EXPECT_THROWS_MESSAGE(FaceTracker t(o), FaceTrackError, "flow_agreement must be > 0");
  o = {};
  o.max_undetected_frames = 0;
  PROBELESS_EXPECT_THROWS_MESSAGE(FaceTracker t(o), FaceTrackError,
                                  "max_undetected_frames must be >= 1");
  o = {};
  o.clahe_clip_limit = -1;
  PROBELESS_EXPECT_THROWS_MESSAGE(FaceTracker t(o), FaceTrackError,
                                  "clahe_clip_limit must be >= 0");
}

// Projects the generic model with a known pose; EstimateHeadPose recovers it.
TEST(HeadModel, PoseFromProjectedGenericModel) {
  const double angle = 0.3;  // yaw about y
  HeadPose truth;
  truth.rotation = {std::cos(angle),  0, std::sin(angle), 0, 1, 0,
                    -std::sin(angle), 0, std::cos(angle)};
  truth.translation = {0.05, -0.02, 0.6};
  std::vector<Point2f> pixels(kLandmarkCount);
  for (int i = 0; i < kLandmarkCount; ++i) {
    const auto& p = kGenericLandmarksMm[i];
    double c[3];
    for (int a = 0; a < 3; ++a) {
      c[a] = truth.rotation[3 * a] * p[0] * 1e-3 + truth.rotation[3 * a + 1] * p[1] * 1e-3 +
             truth.rotation[3 * a + 2] * p[2] * 1e-3 + truth.translation[a];
    }
    pixels[i] = {static_cast<float>(500 * c[0] / c[2] + 320),
                 static_cast<float>(500 * c[1] / c[2] + 240)};
  }
  double rms = 1;
  const HeadPose pose = EstimateHeadPose(pixels, 500, 500, 320, 240, {}, &rms);
  ASSERT_TRUE(pose.valid);
  EXPECT_LT(rms, 0.01);
  for (int i = 0; i < 9; ++i) EXPECT_NEAR(pose.rotation[i], truth.rotation[i], 1e-3);
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(pose.translation[i], truth.translation[i], 1e-3);
  // Eye centres of the table are at x = +-32 mm, y = 1 mm (the crop's proportions).
  double rx = 0, lx = 0;
  for (int i = 0; i < 6; ++i) {
    rx += kGenericLandmarksMm[36 + i][0] / 6;
    lx += kGenericLandmarksMm[42 + i][0] / 6;
  }
  EXPECT_NEAR(rx, -32, 0.01);
  EXPECT_NEAR(lx, 32, 0.01);
  // Quaternion round trip.
  const auto q = QuaternionFromMatrix(truth.rotation);
  const auto m = MatrixFromQuaternion(q);
  for (int i = 0; i < 9; ++i) EXPECT_NEAR(m[i], truth.rotation[i], 1e-12);
}

// A model with a few samples over the face, a frontal track whose landmarks put the canonical crop
// at 2x scale, offset (100, 50).
struct Fixture {
  fl::FaceLightModel model;
  FaceTrack track;
  Fixture() {
    for (double v : {0.3, 0.5, 0.7}) {
      for (double u : {0.3, 0.4, 0.5, 0.6, 0.7}) {
        model.positions.push_back({u, v});
        model.rtf.push_back({0.5f, 0, 0, -0.3f, 0, 0, 0, 0, 0});
        model.residual_rms.push_back(0.01f);
      }
    }
    model.patch_radius_px = 2;
    model.intensity_exponent = 1;
    track.found = true;
    // Landmarks whose CanonicalLandmarks combos are kTrackerCanonical mapped by 2x + (100, 50).
    for (auto& p : track.landmarks) p = {0, 0};
    auto map = [](fl::Point2 c) { return Point2f{float(2 * c.x + 100), float(2 * c.y + 50)}; };
    for (int i = 36; i < 42; ++i) track.landmarks[i] = map(kTrackerCanonical[0]);
    for (int i = 42; i < 48; ++i) track.landmarks[i] = map(kTrackerCanonical[1]);
    track.landmarks[30] = map(kTrackerCanonical[2]);
    for (int i = 60; i < 68; ++i) track.landmarks[i] = map(kTrackerCanonical[3]);
    track.pose.valid = true;
    track.pose.translation = {0, 0, 0.5};
  }
};

TEST(Sampling, ValidityCases) {
  Fixture f;
  const int w = 600, h = 500;
  std::vector<uint8_t> image(static_cast<size_t>(w) * h, 120);
  SamplerOptions o;
  FaceSampler sampler(f.model, o);
  const ImageView view{image.data(), w, h, static_cast<size_t>(w), PixelFormat::kGray};
  FaceSamples s = sampler.Sample(view, f.track);
  ASSERT_EQ(s.count, 15);
  EXPECT_EQ(s.ValidCount(), 15);
  EXPECT_NEAR(s.crop_to_image.Scale(), 2, 1e-6);
  EXPECT_NEAR(s.rgb[0], 120 / 255.0, 1e-6);
  EXPECT_NEAR(s.quality, 1, 1e-6);
  // Sample 7 (centre): saturated pixel; sample 0: a bright outlier among its neighbours; sample 14:
  // dark.
  auto paint = [&](int i, uint8_t value, int radius) {
    const int x = static_cast<int>(std::lround(s.image_points[2 * i]));
    const int y = static_cast<int>(std::lround(s.image_points[2 * i + 1]));
    for (int dy = -radius; dy <= radius; ++dy) {
      for (int dx = -radius; dx <= radius; ++dx) image[(y + dy) * w + x + dx] = value;
    }
  };
  paint(7, 255, 0);
  paint(0, 250, 4);
  paint(14, 1, 4);
  s = sampler.Sample(view, f.track);
  EXPECT_EQ(s.flags[7], kSaturated);
  EXPECT_EQ(s.flags[0], kInconsistent);
  EXPECT_EQ(s.flags[14], kTooDark);
  EXPECT_EQ(s.ValidCount(), 12);
  // Off the image: shift the face left by 250 px.
  FaceTrack shifted = f.track;
  for (auto& p : shifted.landmarks) p.x -= 250;
  s = sampler.Sample(view, shifted);
  EXPECT_TRUE(s.flags[0] & kOutsideImage);
  // Turned away: yaw 90 degrees -> samples on the face's right side face away.
  FaceTrack turned = f.track;
  turned.pose.rotation = {0, 0, 1, 0, 1, 0, -1, 0, 0};
  s = sampler.Sample(view, turned);
  int away = 0;
  for (int i = 0; i < s.count; ++i) away += (s.flags[i] & kFacingAway) != 0;
  EXPECT_GT(away, 0);
  // Frontal normals point towards the camera (-z).
  s = sampler.Sample(view, f.track);
  EXPECT_LT(s.normals[3 * 7 + 2], -0.8);
}

// A bus image as the tracker sees it: the encodings it reads, the row stride of the message, and
// one error line for the others or for a payload too small.
TEST(Sampling, ViewOfImageMapsEncodingsAndRefusesTheRest) {
  msgs::Image image;
  image.Init(5, 3, msgs::Encoding::kRgb8);
  image.step = 16;  // padded rows: the view keeps the message's stride
  std::vector<std::byte> payload(image.step * image.height);
  ImageView view = ViewOfImage(image, payload);
  EXPECT_EQ(view.format, PixelFormat::kRgb);
  EXPECT_EQ(view.width, 5);
  EXPECT_EQ(view.height, 3);
  EXPECT_EQ(view.stride, 16u);
  EXPECT_EQ(static_cast<const void*>(view.data), static_cast<const void*>(payload.data()));
  image.Init(5, 3, msgs::Encoding::kBgr8);
  EXPECT_EQ(ViewOfImage(image, payload).format, PixelFormat::kBgr);
  image.Init(5, 3, msgs::Encoding::kMono8);
  EXPECT_EQ(ViewOfImage(image, payload).format, PixelFormat::kGray);
  image.Init(5, 3, msgs::Encoding::kMono16);
  PROBELESS_EXPECT_THROWS_MESSAGE(
      ViewOfImage(image, payload), msgs::MessageError,
      "face_tracker: image encoding mono16 not supported (expected rgb8, bgr8 or mono8)");
  image.Init(5, 3, msgs::Encoding::kRgb8);
  EXPECT_THROW(ViewOfImage(image, std::span(payload).first(10)), msgs::MessageError);
}

TEST(LightOutput, RotateSh9MatchesRotatedDirectionalLight) {
  const sh::Vec3 d{0.3, -0.5, std::sqrt(1 - 0.34)};
  const auto y = sh::Basis9(d);
  Sh9Rgb c{};
  for (int n = 0; n < 9; ++n) c[n] = {float(y[n]), float(2 * y[n]), float(3 * y[n])};
  const std::array<double, 9> r{0, -1, 0, 1, 0, 0, 0, 0, 1};  // 90 deg about z
  const Sh9Rgb rotated = RotateSh9(c, r);
  const sh::Vec3 rd{-d[1], d[0], d[2]};
  const auto yr = sh::Basis9(rd);
  for (int n = 0; n < 9; ++n) {
    EXPECT_NEAR(rotated[n][0], yr[n], 1e-5);
    EXPECT_NEAR(rotated[n][2], 3 * yr[n], 1e-5);
  }
}

fl::LightEstimate Light(double power, const sh::Vec3& d) {
  fl::LightEstimate e;
  e.channels = 3;
  e.confidence = 0.8f;
  const auto y = sh::Basis9(d);
  for (int n = 0; n < 9; ++n) {
    const float v = static_cast<float>(power * y[n] + (n == 0 ? 0.2 : 0));
    e.coefficients[n] = {v, v, v};
  }
  const sh::Vec3 od = sh::OptimalLinearDirection(&y[0]);
  e.dominant_direction = {float(od[0]), float(od[1]), float(od[2])};
  e.intensity = static_cast<float>(power);
  return e;
}

// A lamp switched on (frames 10..19) then off: the smoothed light is within 10 % of the new
// steady state within 3 frames of each switch, and it smooths frame-to-frame noise.
TEST(LightSmoother, FollowsAnOnOffStepWithin3Frames) {
  LightSmoother smoother;
  const sh::Vec3 up{0, -1, 0}, side{0.8, 0, -0.6};
  auto scene = [&](int frame, double noise) {
    fl::LightEstimate e = Light(1.0, up);
    if (frame >= 10 && frame < 20) {
      const fl::LightEstimate lamp = Light(2.0, side);
      for (int n = 0; n < 9; ++n) {
        for (int c = 0; c < 3; ++c)
          e.coefficients[n][c] += lamp.coefficients[n][c] - (n == 0 ? 0.2f : 0);
      }
    }
    for (int c = 0; c < 3; ++c) e.coefficients[2][c] += static_cast<float>(noise);
    return e;
  };
  auto error = [&](const fl::LightEstimate& a, const fl::LightEstimate& b) {
    double num = 0, den = 0;
    for (int n = 0; n < 9; ++n) {
      num += (a.coefficients[n][0] - b.coefficients[n][0]) *
             (a.coefficients[n][0] - b.coefficients[n][0]);
      den += b.coefficients[n][0] * b.coefficients[n][0];
    }
    return std::sqrt(num / den);
  };
  for (int frame = 0; frame < 30; ++frame) {
    const double noise = (frame % 2 ? 0.02 : -0.02);
    const fl::LightEstimate out = smoother.Update(scene(frame, noise));
    const fl::LightEstimate clean = scene(frame, 0);
    const int since_switch = frame < 10 ? frame : (frame < 20 ? frame - 10 : frame - 20);
    if (since_switch >= 2) {  // the 3rd frame after the switch (0-based 2) at the latest
      EXPECT_LT(error(out, clean), 0.1) << "frame " << frame;
    }
    if (since_switch >= 5) {  // steady state: the noise is attenuated
      EXPECT_LT(std::abs(out.coefficients[2][0] - clean.coefficients[2][0]), 0.015) << frame;
    }
  }
  // Switched off: plain exponential smoothing would need ~7 frames to get within 10 %.
  SmootherOptions plain;
  plain.change_threshold = 1e9;
  LightSmoother slow(plain);
  fl::LightEstimate out;
  for (int frame = 0; frame < 23; ++frame) out = slow.Update(scene(frame, 0));
  EXPECT_GT(error(out, scene(22, 0)), 0.1);
}

TEST(LightOutput, JsonLayouts) {
  Sh9Rgb c{};
  for (int n = 0; n < 9; ++n) c[n] = {float(n + 1), float(10 * (n + 1)), float(100 * (n + 1))};
  const Sh9Rgb y = ToYUpFrame(c);
  // diag(1, -1, -1) then no Condon-Shortley phase: n = 0 (1), 1 (y: -1 then -1 -> +),
  // 2 (z: -1), 3 (x: +1 then -1 -> -).
  EXPECT_NEAR(y[0][0], 1, 1e-5);
  EXPECT_NEAR(y[1][0], 2, 1e-4);
  EXPECT_NEAR(y[2][0], -3, 1e-4);
  EXPECT_NEAR(y[3][0], -4, 1e-4);
  const std::string json = LightJson(c, {0, 0, -1}, 2.5f, 0.75f, LightColour(c), 42, "camera",
                                     msgs::ShLightUnits::kLinear);
  EXPECT_EQ(json.rfind("{\"stamp_ns\":42,\"frame_id\":\"camera\",\"units\":\"linear\","
                       "\"confidence\":0.75,"
                       "\"intensity\":2.5,\"dominant_direction\":[0,0,-1],",
                       0),
            0u)
      << json;
  // ARKit: planar, R plane first: [[R0..R8],[G0..G8],[B0..B8]].
  EXPECT_NE(json.find("\"arkit\":{\"sphericalHarmonicsCoefficients\":[[1,2,-3,-4,"),
            std::string::npos)
      << json;
  EXPECT_NE(json.find("],[10,20,-30,-40,"), std::string::npos) << json;
  // WebXR: interleaved R0 G0 B0 R1 G1 B1 ...
  EXPECT_NE(
      json.find("\"webxr\":{\"sphericalHarmonicsCoefficients\":[1,10,100,2,20,200,-3,-30,-300,"),
      std::string::npos)
      << json;
  const auto colour = LightColour(c);
  EXPECT_NEAR(colour[0] + colour[1] + colour[2], 3, 1e-5);
  // A light in the face model's compressed units is not exported as radiance.
  PROBELESS_EXPECT_THROWS_MESSAGE(
      LightJson(c, (std::array<float, 3>{0, 0, -1}), 2.5f, 0.75f, colour, 42, "camera",
                msgs::ShLightUnits::kFaceModel),
      InputError,
      "LightJson: the ARKit and WebXR exports take linear radiance, got face_model units");
}

// The numbers after `key` in json: the arrays' values in order (nested brackets flattened).
std::vector<double> NumbersAfter(const std::string& json, const std::string& key, size_t count) {
  std::vector<double> out;
  size_t at = json.find(key);
  if (at == std::string::npos) return out;
  at += key.size();
  while (out.size() < count && at < json.size()) {
    const char ch = json[at];
    if (ch == '-' || (ch >= '0' && ch <= '9')) {
      char* end = nullptr;
      out.push_back(std::strtod(json.c_str() + at, &end));
      at = static_cast<size_t>(end - json.c_str());
    } else {
      ++at;
    }
  }
  return out;
}

// Real SH without the Condon-Shortley phase (ARKit / WebXR), order l(l+1)+m.
std::array<double, 9> BasisWithoutPhase(double x, double y, double z) {
  return {0.282095,
          0.488603 * y,
          0.488603 * z,
          0.488603 * x,
          1.092548 * x * y,
          1.092548 * y * z,
          0.315392 * (3 * z * z - 1),
          1.092548 * x * z,
          0.546274 * (x * x - y * y)};
}

// A directional light of power P_c from camera-frame direction d plus ambient radiance r_c
// (msgs::ShLight units) in the camera frame.
Sh9Rgb KnownLight(const sh::Vec3& d, const std::array<double, 3>& power,
                  const std::array<double, 3>& ambient) {
  const auto y = sh::Basis9(d);
  Sh9Rgb c{};
  for (int n = 0; n < 9; ++n) {
    for (int ch = 0; ch < 3; ++ch) {
      c[n][ch] = static_cast<float>(power[ch] * y[n] +
                                    (n == 0 ? ambient[ch] * 2 * std::sqrt(std::numbers::pi) : 0));
    }
  }
  return c;
}

// Checks the ARKit (planar) and WebXR (interleaved) arrays of `json` against the known light in
// the y-up frame (x, -y, -z), relative L2 error per channel below `tolerance`.
void ExpectExportsOf(const std::string& json, const sh::Vec3& d, const std::array<double, 3>& power,
                     const std::array<double, 3>& ambient, double tolerance) {
  const auto basis = BasisWithoutPhase(d[0], -d[1], -d[2]);
  const std::vector<double> arkit = NumbersAfter(json, "\"arkit\":", 27);
  const std::vector<double> webxr = NumbersAfter(json, "\"webxr\":", 27);
  ASSERT_EQ(arkit.size(), 27u) << json;
  ASSERT_EQ(webxr.size(), 27u) << json;
  for (int ch = 0; ch < 3; ++ch) {
    double diff_a = 0, diff_w = 0, norm = 0;
    for (int n = 0; n < 9; ++n) {
      const double truth =
          power[ch] * basis[n] + (n == 0 ? ambient[ch] * 2 * std::sqrt(std::numbers::pi) : 0);
      diff_a += (arkit[9 * ch + n] - truth) * (arkit[9 * ch + n] - truth);
      diff_w += (webxr[3 * n + ch] - truth) * (webxr[3 * n + ch] - truth);
      norm += truth * truth;
    }
    EXPECT_LT(std::sqrt(diff_a / norm), tolerance) << "ARKit channel " << ch << ": " << json;
    EXPECT_LT(std::sqrt(diff_w / norm), tolerance) << "WebXR channel " << ch << ": " << json;
  }
}

TEST(LightOutput, LinearExportsOfAKnownLight) {
  const sh::Vec3 d{0.48, -0.36, -0.8};  // unit: up-right of the camera, in front of the face
  const std::array<double, 3> power{2.4, 1.9, 1.3};
  const std::array<double, 3> ambient{0.06, 0.05, 0.07};
  // The export itself: exact to the printed precision.
  const Sh9Rgb known = KnownLight(d, power, ambient);
  ExpectExportsOf(LightJson(known, {0.48f, -0.36f, -0.8f}, 1.87f, 0.6f, LightColour(known), 1,
                            "camera", msgs::ShLightUnits::kLinear),
                  d, power, ambient, 1e-5);
  // Through the face model and the linear conversion (frontal head: face frame = camera frame),
  // the direction refined for the linear residual: within 3 %.
  const fl::FaceLightModel model =
      fl::LoadModel(std::string(PROBELESS_SOURCE_DIR) + "/data/face_light/default_model.txt");
  fl::EstimatorOptions eo;
  eo.back_prior = 0.1;
  const fl::FaceLightEstimator estimator(model, eo);
  fl::LinearLightOptions lo;
  lo.refine_direction = true;
  const fl::LinearLightConverter converter(model, lo);
  const std::vector<float> rgb = converter.Predict(d, power, ambient);
  const fl::LinearLight light = converter.Convert(rgb, {}, estimator.EstimateRgb(rgb));
  ASSERT_TRUE(light.valid);
  const Sh9Rgb camera = RotateSh9(light.coefficients, {1, 0, 0, 0, 1, 0, 0, 0, 1});
  ExpectExportsOf(LightJson(camera, light.direction, light.intensity, 0.6f, LightColour(camera), 1,
                            "camera", msgs::ShLightUnits::kLinear),
                  d, power, ambient, 0.03);
}

// Irradiance (Lambertian, K&K eq. 20 / Ramamoorthi-Hanrahan) of channel-mean light at normal n.
double Irradiance(const Sh9Rgb& c, const sh::Vec3& n) {
  const auto y = sh::Basis9(n);
  double e = 0;
  for (int k = 0; k < 9; ++k) {
    const int l = k == 0 ? 0 : k < 4 ? 1 : 2;
    e += sh::ClampedCosineCoefficient(l) * y[k] * (c[k][0] + c[k][1] + c[k][2]) / 3;
  }
  return e;
}

// The node's chain on one observation: no face -> nothing; a model mismatch -> one error; a face
// under a known light -> a linear, confident light from that direction, rotated into the camera
// frame by the head pose.
TEST(FaceLightPipeline, PublishesTheLightOfAFaceInTheCameraFrame) {
  const fl::FaceLightModel model =
      fl::LoadModel(std::string(PROBELESS_SOURCE_DIR) + "/data/face_light/default_model.txt");
  const std::array<double, 3> d{0.6, -0.3, -0.74};  // face frame, towards the light
  const double norm = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  const std::array<double, 3> u{d[0] / norm, d[1] / norm, d[2] / norm};
  const fl::LinearLightConverter converter(model);
  const std::vector<float> rgb = converter.Predict(u, {2.0, 1.8, 1.5}, {0.08, 0.08, 0.08});
  msgs::FaceObservation obs;
  obs.header.stamp_ns = 1'000'000'000;
  obs.face_detected = 1;
  obs.quality = 1;
  obs.sample_count = static_cast<uint32_t>(rgb.size() / 3);
  for (uint32_t i = 0; i < obs.sample_count; ++i) {
    for (int c = 0; c < 3; ++c) obs.sample_rgb[i][c] = rgb[3 * i + c];
    obs.sample_valid[i / 64] |= uint64_t{1} << (i % 64);
  }
  obs.head_pose.rotation = {1, 0, 0, 0};
  auto angle = [](const float* a, const std::array<double, 3>& b) {
    return std::acos(std::clamp(a[0] * b[0] + a[1] * b[1] + a[2] * b[2], -1.0, 1.0)) * 180 /
           std::numbers::pi;
  };

  FaceLightPipeline frontal(model, {});
  msgs::FaceObservation none = obs;
  none.face_detected = 0;
  EXPECT_FALSE(frontal.Process(none).has_value());
  const std::optional<msgs::ShLight> a = frontal.Process(obs);
  ASSERT_TRUE(a.has_value());
  EXPECT_EQ(a->units, msgs::ShLightUnits::kLinear);
  EXPECT_EQ(a->bands, 3u);
  EXPECT_EQ(a->header.stamp_ns, obs.header.stamp_ns);
  EXPECT_GT(a->confidence, 0.1f);  // above the hold's threshold: the light itself is published
  EXPECT_LE(a->confidence, 1.f);
  EXPECT_LT(angle(a->dominant_direction, u), 10);

  // The head turned 90 degrees about the camera's y axis: the light turns with it.
  const double h = std::sqrt(0.5);
  msgs::FaceObservation turned = obs;
  turned.head_pose.rotation = {h, 0, h, 0};
  FaceLightPipeline rotated(model, {});
  const std::optional<msgs::ShLight> b = rotated.Process(turned);
  ASSERT_TRUE(b.has_value());
  const std::array<double, 9> r = MatrixFromQuaternion({h, 0, h, 0});
  const std::array<float, 3> expected = RotateVector(r, std::to_array(a->dominant_direction));
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(b->dominant_direction[k], expected[k], 1e-4);

  msgs::FaceObservation other = obs;
  other.sample_count = 7;
  PROBELESS_EXPECT_THROWS_MESSAGE(
      frontal.Process(other), fl::FaceLightError,
      "observation has 7 samples, the model " + std::to_string(frontal.SampleCount()));
}

TEST(LightHold, BacklitFaceDoesNotBrightenTheVirtualObject) {
  LightHold hold;
  const int64_t second = 1'000'000'000;
  // Confident: a light from the side (camera +x), passed through and held.
  const Sh9Rgb side = KnownLight({1, 0, 0}, {2, 2, 2}, {0.05, 0.05, 0.05});
  const LightHold::Output a = hold.Update(side, {1, 0, 0}, 2, 0.6f, 10 * second);
  EXPECT_FALSE(a.held);
  EXPECT_EQ(a.coefficients, side);
  // The light goes behind the head: the fit wrongly puts a bright light in front (towards the
  // camera, -z) with a low confidence (expected error 120 deg).
  const Sh9Rgb wrong = KnownLight({0, 0, -1}, {1.5, 1.5, 1.5}, {0.02, 0.02, 0.02});
  // Normals of the virtual object facing the camera and the wrongly estimated light; the held
  // light's ambient term alone.
  const sh::Vec3 front{0, 0, -1};
  Sh9Rgb side_ambient{};
  side_ambient[0] = side[0];
  double last = 1e9;
  for (int k = 1; k <= 40; ++k) {
    const LightHold::Output b =
        hold.Update(wrong, {0, 0, -1}, 1.5, 0.007f, 10 * second + k * second / 10);
    EXPECT_TRUE(b.held);
    const double e = Irradiance(b.coefficients, front);
    // Never brighter from the front than the held light or its ambient term, far below the wrong
    // estimate, and fading monotonically towards that ambient term.
    EXPECT_LE(e, std::max(Irradiance(side, front), Irradiance(side_ambient, front)) + 1e-6);
    EXPECT_LT(e, 0.5 * Irradiance(wrong, front));
    EXPECT_LE(b.coefficients[3][0] * b.coefficients[3][0], side[3][0] * side[3][0] + 1e-9);
    EXPECT_LE(std::abs(b.coefficients[3][0]), last + 1e-9);
    last = std::abs(b.coefficients[3][0]);
    EXPECT_FLOAT_EQ(b.coefficients[0][0], side[0][0]);
    if (k == 20) {
      EXPECT_NEAR(b.weight, std::exp(-1.0), 1e-6);  // 2 s = blend_time_s
    }
    for (int ch = 0; ch < 3; ++ch) EXPECT_EQ(b.direction[ch], ch == 0 ? 1.f : 0.f);
  }
  // Without a held light: only the unreliable light's ambient term.
  LightHold fresh;
  const LightHold::Output c = fresh.Update(wrong, {0, 0, -1}, 1.5, 0.007f, second);
  EXPECT_TRUE(c.held);
  EXPECT_FLOAT_EQ(c.coefficients[0][1], wrong[0][1]);
  for (int n = 1; n < 9; ++n) EXPECT_EQ(c.coefficients[n][0], 0.f);
  PROBELESS_EXPECT_THROWS_MESSAGE(
      LightHold bad(HoldOptions{.min_confidence = 0.1, .blend_time_s = 0}), InputError,
      "LightHold: min_confidence must be in [0, 1] and blend_time_s > 0");
}

}  // namespace
