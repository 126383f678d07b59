// Tests of the renderer (label render), headless under OSMesa: golden images of a sphere lit by a
// known SH light against the analytic shading computed on the CPU (clamp and Reinhard tone
// mapping), the real depth hiding virtual fragments, differential rendering (shadow receivers and
// per-pixel transfer buffers) leaving pixels outside the virtual object's influence bit-exact, the
// viewer panels, input errors, and the GLFW window under xvfb-run (the test re-runs itself there).
#include "probeless/raytrace/render.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <string>

#include "probeless/prt/demo_objects.h"
#include "probeless/prt/prt.h"
#include "probeless/render/content.h"
#include "probeless/render/output.h"
#include "probeless/render/renderer.h"
#include "probeless/render/viewer.h"
#include "probeless/sh/sh.h"

namespace probeless::render {
namespace {

using raytrace::Mat3;
using raytrace::Transform;
using raytrace::Vec3;

constexpr int kW = 320, kH = 240;
constexpr float kRadius = 0.1f;
constexpr Vec3 kCentre{0.02f, -0.01f, 0.6f};
constexpr uint8_t kBackground = 60;

Intrinsics Camera() {
  Intrinsics k;
  k.width = kW;
  k.height = kH;
  k.fx = k.fy = 300;
  k.cx = 159.5;
  k.cy = 119.5;
  return k;
}

// A light with ambient, a strong key from upper left front and colour (camera frame).
ShLightRgb TestLight() {
  ShLightRgb light;
  light.bands = 3;
  const std::vector<double> key = sh::DirectionalLight({-0.5, -0.6, -0.62}, 2.2, 3);
  const std::vector<double> fill = sh::DirectionalLight({0.7, 0.2, -0.68}, 0.8, 3);
  for (int k = 0; k < 9; ++k) {
    light.coefficients[k] = {static_cast<float>(key[k] + 0.6 * fill[k]),
                             static_cast<float>(0.9 * key[k] + 0.8 * fill[k]),
                             static_cast<float>(0.7 * key[k] + fill[k])};
  }
  light.coefficients[0][0] += 0.6f;
  light.coefficients[0][1] += 0.6f;
  light.coefficients[0][2] += 0.7f;
  return light;
}

// A sphere with the analytic unshadowed transfer (bands 3), centred at the origin.
prt::TransferMesh AnalyticSphere(int segments) {
  prt::TransferMesh m;
  m.mesh = raytrace::MakeSphere(kRadius, segments);
  m.bands = 3;
  for (const Vec3& n : m.mesh.normals) {
    const std::vector<float> t = prt::UnshadowedTransfer(n, 3);
    m.transfer.insert(m.transfer.end(), t.begin(), t.end());
  }
  return m;
}

struct AnalyticImage {
  std::vector<uint8_t> rgb;
  std::vector<uint8_t> mask;
};

// Per pixel: ray-sphere hit, normal, radiance albedo * sum_k A_l L_k Y_k(n) / pi, tone map, sRGB.
AnalyticImage Analytic(const ShLightRgb& light, const ToneMapping& tone, float albedo) {
  AnalyticImage out;
  out.rgb.assign(kW * kH * 3, kBackground);
  out.mask.assign(kW * kH, 0);
  const Intrinsics k = Camera();
  for (int v = 0; v < kH; ++v) {
    for (int u = 0; u < kW; ++u) {
      const Vec3 d = raytrace::Normalize(
          {static_cast<float>((u - k.cx) / k.fx), static_cast<float>((v - k.cy) / k.fy), 1.0f});
      const float b = raytrace::Dot(d, kCentre);
      const float c = raytrace::Dot(kCentre, kCentre) - kRadius * kRadius;
      const float disc = b * b - c;
      if (disc < 0) continue;
      const Vec3 p = d * (b - std::sqrt(disc));
      const Vec3 n = raytrace::Normalize(p - kCentre);
      const std::vector<float> t = prt::UnshadowedTransfer(n, 3);
      const auto radiance = ShadeTransfer(t, light);
      out.mask[v * kW + u] = 1;
      for (int ch = 0; ch < 3; ++ch) {
        out.rgb[(v * kW + u) * 3 + ch] = raytrace::LinearToSrgb8(tone.Apply(albedo * radiance[ch]));
      }
    }
  }
  return out;
}

FrameInputs BaseFrame(const std::vector<uint8_t>& camera_rgb, const ShLightRgb& light) {
  FrameInputs in;
  in.camera = Camera();
  in.camera_rgb = camera_rgb;
  in.light = light;
  in.face_valid = false;
  return in;  // world = camera frame (camera_to_world identity)
}

// Mean absolute error (0..1 units) over pixels covered in both images; IoU of the masks.
void Compare(const Composite& got, const AnalyticImage& want, double* mean_error, double* iou) {
  double sum = 0;
  size_t both = 0, either = 0;
  for (int i = 0; i < kW * kH; ++i) {
    const bool a = got.coverage[i], b = want.mask[i];
    either += a || b;
    if (!(a && b)) continue;
    ++both;
    for (int c = 0; c < 3; ++c) sum += std::abs(got.rgb[i * 3 + c] - want.rgb[i * 3 + c]) / 255.0;
  }
  *mean_error = both ? sum / (3.0 * both) : 1.0;
  *iou = either ? static_cast<double>(both) / either : 0.0;
}

TEST(RenderTest, OffscreenContextIsCore) {
  Renderer renderer({});
  EXPECT_EQ(renderer.backend(), Backend::kOffscreen);
  const std::string version = renderer.gl_version();
  ASSERT_FALSE(version.empty());
  EXPECT_TRUE(version.rfind("4.5", 0) == 0 || version.rfind("3.3", 0) == 0) << version;
  std::printf("GL %s on %s\n", version.c_str(), renderer.gl_renderer().c_str());
}

class GoldenTest : public ::testing::TestWithParam<ToneOperator> {};

TEST_P(GoldenTest, SphereMatchesAnalyticShading) {
  ToneMapping tone;
  tone.op = GetParam();
  tone.exposure = GetParam() == ToneOperator::kReinhard ? 1.5f : 1.0f;
  RendererOptions options;
  options.width = kW;
  options.height = kH;
  options.tone = tone;
  Renderer renderer(options);
  VirtualObject sphere;
  sphere.mesh = AnalyticSphere(128);
  sphere.anchor = Anchor::kWorld;
  sphere.object_to_anchor = Transform{Mat3::Identity(), {kCentre.x, kCentre.y, kCentre.z}};
  sphere.albedo = {0.8f, 0.8f, 0.8f};
  renderer.AddObject(sphere);
  const std::vector<uint8_t> camera(kW * kH * 3, kBackground);
  const ShLightRgb light = TestLight();
  Composite out;
  renderer.Render(BaseFrame(camera, light), out);
  const AnalyticImage want = Analytic(light, tone, 0.8f);
  double error = 0, iou = 0;
  Compare(out, want, &error, &iou);
  EXPECT_LT(error, 1.0 / 255.0);
  EXPECT_GT(iou, 0.97);
  // Background untouched.
  EXPECT_EQ(out.rgb[0], kBackground);
  EXPECT_EQ(out.coverage[0], 0);
  if (::testing::Test::HasFailure()) {
    WritePng("/tmp/render_golden_got.png", kW, kH, out.rgb);
    WritePng("/tmp/render_golden_want.png", kW, kH, want.rgb);
  }
  std::printf("mean error %.5f (%.3f / 255), IoU %.4f\n", error, error * 255, iou);
}

INSTANTIATE_TEST_SUITE_P(ToneOperators, GoldenTest,
                         ::testing::Values(ToneOperator::kClamp, ToneOperator::kReinhard));

TEST(RenderTest, AlbedoTextureModulatesShading) {
  // A constant linear albedo texture of 0.5 on a white sphere equals the analytic image of albedo
  // 0.5 (the texture path: uvs, linear RGB float texture, v up).
  RendererOptions options;
  options.width = kW;
  options.height = kH;
  Renderer renderer(options);
  VirtualObject sphere;
  sphere.mesh = AnalyticSphere(128);
  ASSERT_EQ(sphere.mesh.mesh.uvs.size(), sphere.mesh.mesh.positions.size());
  sphere.anchor = Anchor::kWorld;
  sphere.object_to_anchor = Transform{Mat3::Identity(), {kCentre.x, kCentre.y, kCentre.z}};
  auto texture = std::make_shared<raytrace::Texture>();
  texture->width = 4;
  texture->height = 2;
  texture->linear_rgb.assign(4 * 2 * 3, 0.5f);
  sphere.texture = texture;
  renderer.AddObject(sphere);
  const std::vector<uint8_t> camera(kW * kH * 3, kBackground);
  Composite out;
  renderer.Render(BaseFrame(camera, TestLight()), out);
  double error = 0, iou = 0;
  Compare(out, Analytic(TestLight(), ToneMapping{}, 0.5f), &error, &iou);
  EXPECT_LT(error, 1.0 / 255.0);
  // A texture without uvs is refused.
  sphere.mesh.mesh.uvs.clear();
  EXPECT_THROW(renderer.AddObject(sphere), RenderError);
}

TEST(RenderTest, FaceAnchoredObjectUsesRotatedLight) {
  // The same sphere, face-anchored under a rotated head pose: the light is rotated into the face
  // frame, so the image equals the world-anchored one.
  RendererOptions options;
  options.width = kW;
  options.height = kH;
  Renderer renderer(options);
  const Mat3 r = Mat3::FromEulerZyx(0.4, -0.3, 0.2);
  VirtualObject sphere;
  sphere.mesh = AnalyticSphere(128);
  // The transfer is in the face (object) frame; the renderer rotates the camera-frame light into
  // it, so a vertex with face normal n shows the camera-frame shading of normal r n.
  sphere.anchor = Anchor::kFace;
  // Face frame at kCentre rotated by r; the sphere at the face origin.
  renderer.AddObject(sphere);
  const std::vector<uint8_t> camera(kW * kH * 3, kBackground);
  FrameInputs in = BaseFrame(camera, TestLight());
  in.face_to_camera = Transform{r, {kCentre.x, kCentre.y, kCentre.z}};
  in.face_valid = true;
  Composite out;
  renderer.Render(in, out);
  double error = 0, iou = 0;
  Compare(out, Analytic(TestLight(), ToneMapping{}, 1.0f), &error, &iou);
  EXPECT_LT(error, 1.0 / 255.0);
  EXPECT_GT(iou, 0.97);
  // Without a face the face-anchored content is hidden.
  in.face_valid = false;
  renderer.Render(in, out);
  for (uint8_t c : out.coverage) ASSERT_EQ(c, 0);
}

TEST(RenderTest, RealDepthHidesVirtualFragments) {
  RendererOptions options;
  options.width = kW;
  options.height = kH;
  Renderer renderer(options);
  VirtualObject sphere;
  sphere.mesh = AnalyticSphere(64);
  sphere.anchor = Anchor::kWorld;
  sphere.object_to_anchor = Transform{Mat3::Identity(), {kCentre.x, kCentre.y, kCentre.z}};
  renderer.AddObject(sphere);
  const std::vector<uint8_t> camera(kW * kH * 3, kBackground);
  // A real wall at 0.45 m covering the left half of the image (in front of the sphere at 0.5..0.7).
  std::vector<float> depth(kW * kH, 0.0f);
  for (int v = 0; v < kH; ++v)
    for (int u = 0; u < kW / 2; ++u) depth[v * kW + u] = 0.45f;
  FrameInputs in = BaseFrame(camera, TestLight());
  in.real_depth = depth;
  Composite out;
  renderer.Render(in, out);
  int left = 0, right = 0;
  for (int v = 0; v < kH; ++v) {
    for (int u = 0; u < kW; ++u) (u < kW / 2 ? left : right) += out.coverage[v * kW + u];
  }
  EXPECT_EQ(left, 0);
  EXPECT_GT(right, 1000);
  // A wall behind the sphere (0.8 m) hides nothing.
  for (float& z : depth) z = z > 0 ? 0.8f : 0.0f;
  renderer.Render(in, out);
  int all = 0;
  for (uint8_t c : out.coverage) all += c;
  EXPECT_EQ(
      all, left + right + [&] {
        int l = 0;
        for (int v = 0; v < kH; ++v)
          for (int u = 0; u < kW / 2; ++u) l += out.coverage[v * kW + u];
        return l;
      }());
  EXPECT_GT(all, right + 1000);
}

// A grid in the camera frame's x-z plane at height y (a floor, normal -y = up), n x n quads.
raytrace::Mesh Floor(float y, float half, int n) {
  raytrace::Mesh m;
  for (int j = 0; j <= n; ++j) {
    for (int i = 0; i <= n; ++i) {
      m.positions.push_back(
          {kCentre.x - half + 2 * half * i / n, y, kCentre.z - half + 2 * half * j / n});
      m.normals.push_back({0, -1, 0});
    }
  }
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      const uint32_t a = j * (n + 1) + i;
      // Counter-clockwise seen from above (-y).
      m.triangles.push_back({a, a + 1, a + n + 1});
      m.triangles.push_back({a + 1, a + n + 2, a + n + 1});
    }
  }
  return m;
}

TEST(RenderTest, DifferentialRenderingLeavesPixelsOutsideInfluenceUnchanged) {
  // Real floor 0.15 m below the sphere's centre; the sphere casts a shadow on it (Gruber eq. 13).
  const raytrace::Mesh floor = Floor(kCentre.y + 0.15f, 0.4f, 80);
  prt::BakeOptions options;
  options.samples = 256;
  options.self_occlusion = false;
  const prt::TransferMesh real = prt::Bake(floor, {}, options);
  raytrace::Mesh occluder_mesh = raytrace::MakeSphere(kRadius, 48);
  const prt::Occluder occluder{occluder_mesh,
                               Transform{Mat3::Identity(), {kCentre.x, kCentre.y, kCentre.z}}};
  const prt::TransferMesh with = prt::Bake(floor, {&occluder, 1}, options);

  RendererOptions ro;
  ro.width = kW;
  ro.height = kH;
  Renderer renderer(ro);
  VirtualObject sphere;
  sphere.mesh = AnalyticSphere(64);
  sphere.anchor = Anchor::kWorld;
  sphere.object_to_anchor = occluder.placement;
  renderer.AddObject(sphere);
  ShadowReceiver receiver;
  receiver.mesh = floor;
  receiver.bands = 3;
  receiver.transfer_real = real.transfer;
  receiver.transfer_with_virtual = with.transfer;
  receiver.anchor = Anchor::kWorld;
  renderer.AddReceiver(receiver);

  // A textured camera image: every pixel a different value.
  std::vector<uint8_t> camera(kW * kH * 3);
  for (size_t i = 0; i < camera.size(); ++i) camera[i] = static_cast<uint8_t>(40 + (i * 7) % 180);
  FrameInputs in = BaseFrame(camera, TestLight());
  Composite out;
  renderer.Render(in, out);

  // Influence: pixels whose floor vertex transfer changed (projected), plus the virtual object.
  // Check: every changed pixel is covered or lies on the floor in the shadow region; pixels far
  // from both (image corners, the sky above the sphere) are bit-exact.
  int changed = 0, darker = 0, unchanged_far = 0, far = 0;
  long change_sum = 0;
  for (int v = 0; v < kH; ++v) {
    for (int u = 0; u < kW; ++u) {
      const int i = v * kW + u;
      const bool diff = out.rgb[i * 3] != camera[i * 3] ||
                        out.rgb[i * 3 + 1] != camera[i * 3 + 1] ||
                        out.rgb[i * 3 + 2] != camera[i * 3 + 2];
      if (out.coverage[i]) continue;
      changed += diff;
      darker += out.rgb[i * 3 + 1] < camera[i * 3 + 1];
      change_sum += static_cast<int>(out.rgb[i * 3 + 1]) - camera[i * 3 + 1];
      // Outside the influence: not on the floor (whose far edge at z = 1 m projects to row 161)
      // and not covered by the sphere. Every floor point sees the sphere, so the whole floor may
      // change (its ambient occlusion).
      if (v < 155) {
        ++far;
        unchanged_far += !diff;
      }
    }
  }
  EXPECT_EQ(unchanged_far, far);
  EXPECT_GT(changed, 200);
  // Mostly darker: the virtual sphere occludes the floor's sky (a few pixels brighten where the
  // band-2 light's negative lobes are occluded).
  EXPECT_GT(darker, changed / 2);
  EXPECT_LT(change_sum, 0);

  // Without the receiver's shadow (both transfer sets equal) nothing but the object changes.
  renderer.SetReceiverTransfer(0, real.transfer, real.transfer);
  renderer.Render(in, out);
  for (int i = 0; i < kW * kH; ++i) {
    if (out.coverage[i]) continue;
    for (int c = 0; c < 3; ++c) ASSERT_EQ(out.rgb[i * 3 + c], camera[i * 3 + c]) << "pixel " << i;
  }
}

TEST(RenderTest, PerPixelTransferBuffersAndIndirect) {
  RendererOptions ro;
  ro.width = kW;
  ro.height = kH;
  Renderer renderer(ro);
  std::vector<uint8_t> camera(kW * kH * 3, 128);
  const ShLightRgb light = TestLight();
  // Real transfer: an up-facing unshadowed surface everywhere; with virtual: half of it in a
  // block [100, 140) x [60, 100) (the virtual shadow).
  const std::vector<float> t = prt::UnshadowedTransfer({0, -1, 0}, 3);
  std::vector<float> real(kW * kH * 9), with(kW * kH * 9);
  std::vector<float> indirect(kW * kH * 3, 0.0f);
  for (int v = 0; v < kH; ++v) {
    for (int u = 0; u < kW; ++u) {
      const int i = v * kW + u;
      const bool shadow = u >= 100 && u < 140 && v >= 60 && v < 100;
      for (int k = 0; k < 9; ++k) {
        real[i * 9 + k] = t[k];
        with[i * 9 + k] = shadow ? 0.5f * t[k] : t[k];
      }
      if (u >= 200 && u < 210 && v >= 10 && v < 20) indirect[i * 3] = 0.1f;  // a red bleed
    }
  }
  FrameInputs in = BaseFrame(camera, light);
  in.transfer_real = real;
  in.transfer_with_virtual = with;
  in.transfer_count = 9;
  in.indirect_rgb = indirect;
  Composite out;
  renderer.Render(in, out);
  for (int v = 0; v < kH; ++v) {
    for (int u = 0; u < kW; ++u) {
      const int i = v * kW + u;
      const bool shadow = u >= 100 && u < 140 && v >= 60 && v < 100;
      const bool bleed = u >= 200 && u < 210 && v >= 10 && v < 20;
      if (shadow) {
        ASSERT_LT(out.rgb[i * 3 + 1], 128) << u << "," << v;
      } else if (bleed) {
        ASSERT_GT(out.rgb[i * 3], 128);
        ASSERT_EQ(out.rgb[i * 3 + 1], 128);
      } else {
        for (int c = 0; c < 3; ++c) ASSERT_EQ(out.rgb[i * 3 + c], 128) << u << "," << v;
      }
    }
  }
  // The shadow equals eq. 13 computed on the CPU (within rounding).
  const int i = 80 * kW + 120;
  const auto r = ShadeTransfer({real.data() + i * 9, 9}, light);
  const auto rv = ShadeTransfer({with.data() + i * 9, 9}, light);
  const ToneMapping tone;
  const float ic = raytrace::Srgb8ToLinear(128);
  const float expected = ic * (1 + tone.Apply(rv[1]) - tone.Apply(r[1]));
  EXPECT_NEAR(out.rgb[i * 3 + 1], raytrace::LinearToSrgb8(expected), 1.0);
}

TEST(RenderTest, ErrorsAreClear) {
  Renderer renderer({});
  VirtualObject bad;
  bad.mesh.mesh = raytrace::MakeSphere(0.1f, 8);
  bad.mesh.bands = 3;  // no transfer
  try {
    renderer.AddObject(bad);
    FAIL();
  } catch (const RenderError& e) {
    EXPECT_NE(std::string(e.what()).find("renderer object: 0 transfer values"), std::string::npos)
        << e.what();
  }
  FrameInputs in;
  std::vector<uint8_t> small(10);
  in.camera_rgb = small;
  Composite out;
  try {
    renderer.Render(in, out);
    FAIL();
  } catch (const RenderError& e) {
    EXPECT_EQ(std::string(e.what()),
              "frame: camera image has 10 values, expected 921600 for 640x480");
  }
  in.camera_rgb = {};
  in.camera.width = 0;
  EXPECT_THROW(renderer.Render(in, out), RenderError);
  EXPECT_THROW(BackendFromName("vulkan"), RenderError);
  try {
    raytrace::LoadMesh("/nonexistent/object.obj");
    FAIL();
  } catch (const raytrace::RaytraceError& e) {
    EXPECT_EQ(std::string(e.what()), "/nonexistent/object.obj: cannot open OBJ file");
  }
}

TEST(RenderTest, ViewerPanelsAndKeys) {
  ViewerState state;
  state.ApplyKeys({'F', 'G', 'P'});
  EXPECT_TRUE(state.face_samples && state.geometry && state.pose);
  const ShLightRgb light = TestLight();
  msgs::FaceObservation face;
  face.face_detected = 1;
  face.sample_count = 2;
  face.SetSampleValid(0, true);
  face.SetSampleValid(1, true);
  face.sample_normals[0][2] = -1;
  face.sample_rgb[0][0] = 1;
  face.head_pose.rotation.w = 1;
  ViewerInputs in;
  in.light = &light;
  in.face = &face;
  const std::vector<Panel> panels = MakePanels(state, in, 640, 480);
  ASSERT_EQ(panels.size(), 5u);
  // The light sphere is brightest towards the key light (upper left).
  const Panel& sphere = panels[0];
  const auto at = [&](int u, int v) { return sphere.rgb[(v * sphere.width + u) * 3 + 1]; };
  EXPECT_GT(at(30, 30), at(66, 66));
  state.ApplyKeys({256});
  EXPECT_TRUE(state.quit);
}

TEST(RenderTest, FrameWriterWritesPngSequence) {
  const std::string dir = (std::filesystem::temp_directory_path() / "render_test_png").string();
  std::filesystem::remove_all(dir);
  FrameWriter writer("", 30, dir);
  Composite frame;
  frame.width = 4;
  frame.height = 2;
  frame.rgb.assign(24, 200);
  writer.Write(frame);
  writer.Write(frame);
  EXPECT_EQ(writer.frames_written(), 2u);
  int w = 0, h = 0;
  const auto rgb = ReadImageRgb(dir + "/frame_000002.png", w, h);
  EXPECT_EQ(w, 4);
  EXPECT_EQ(rgb[0], 200);
  // Video (OpenCV VideoWriter, MJPG in AVI).
  const std::string video = dir + "/out.avi";
  {
    FrameWriter video_writer(video, 10, "");
    Composite big;
    big.width = 64;
    big.height = 48;
    big.rgb.assign(64 * 48 * 3, 120);
    for (int i = 0; i < 3; ++i) video_writer.Write(big);
    EXPECT_EQ(video_writer.frames_written(), 3u);
  }
  EXPECT_GT(std::filesystem::file_size(video), 0u);
}

// The GLFW window: run under xvfb-run by re-executing this binary with a filter.
TEST(WindowTest, OpensAndRendersUnderXvfb) {
  if (std::getenv("PROBELESS_RENDER_WINDOW_CHILD") == nullptr) {
    if (std::system("command -v xvfb-run > /dev/null 2>&1") != 0) {
      GTEST_SKIP() << "xvfb-run is missing (apt-get install xvfb): window test skipped";
    }
    char self[4096] = {};
    const ssize_t n = readlink("/proc/self/exe", self, sizeof(self) - 1);
    ASSERT_GT(n, 0);
    const std::string command =
        "PROBELESS_RENDER_WINDOW_CHILD=1 xvfb-run -a -s '-screen 0 800x600x24' '" +
        std::string(self) + "' --gtest_filter=WindowTest.*";
    EXPECT_EQ(std::system(command.c_str()), 0) << command;
    return;
  }
  RendererOptions options;
  options.backend = Backend::kWindow;
  options.width = kW;
  options.height = kH;
  Renderer renderer(options);
  std::printf("window GL %s on %s\n", renderer.gl_version().c_str(),
              renderer.gl_renderer().c_str());
  VirtualObject sphere;
  sphere.mesh = AnalyticSphere(64);
  sphere.anchor = Anchor::kWorld;
  sphere.object_to_anchor = Transform{Mat3::Identity(), {kCentre.x, kCentre.y, kCentre.z}};
  renderer.AddObject(sphere);
  const std::vector<uint8_t> camera(kW * kH * 3, kBackground);
  Composite out;
  renderer.Render(BaseFrame(camera, TestLight()), out);
  double error = 0, iou = 0;
  Compare(out, Analytic(TestLight(), ToneMapping{}, 1.0f), &error, &iou);
  EXPECT_LT(error, 1.0 / 255.0);
  ViewerState state;
  const ShLightRgb light = TestLight();
  ViewerInputs vin;
  vin.light = &light;
  const auto [ww, wh] = renderer.WindowSize();
  ASSERT_GT(ww, 0);
  Composite window;
  renderer.Present(MakePanels(state, vin, ww, wh), &window);
  ASSERT_EQ(window.width, ww);
  // The window shows the composite: the sphere's centre pixel is lit, a corner is background.
  const int cx = ww / 2 + static_cast<int>(kCentre.x / kCentre.z * 300 * ww / kW);
  const int cy = wh / 2 + static_cast<int>(kCentre.y / kCentre.z * 300 * wh / kH);
  EXPECT_GT(window.rgb[(cy * ww + cx) * 3 + 1], kBackground + 20);
  EXPECT_NEAR(window.rgb[((wh - 2) * ww + 2) * 3], kBackground, 1);
  (void)renderer.TakeKeys();
  EXPECT_FALSE(renderer.WindowClosed());
}

}  // namespace
}  // namespace probeless::render

namespace probeless::render {
namespace {

// The whole face pipeline: the procedural head ray-traced as the camera image, the demo objects
// (nose, glasses, cap) baked with the proxy head, and the proxy head as shadow receiver.
TEST(RenderTest, DemoFaceComposite) {
  const Transform face_to_camera{Mat3::FromEulerZyx(0.0, 0.25, 0.0), {0.0, 0.0, 0.5}};
  const ShLightRgb light = TestLight();
  raytrace::Scene scene;
  scene.AddObject(raytrace::MakeHead().mesh, raytrace::Material{}, face_to_camera, 1);
  for (int k = 0; k < 9; ++k) {
    scene.environment().sh[k] = {light.coefficients[k][0], light.coefficients[k][1],
                                 light.coefficients[k][2]};
  }
  scene.Commit();
  raytrace::Camera camera;
  const raytrace::Frame frame = raytrace::Render(scene, camera, raytrace::RenderOptions{});

  ContentOptions options;
  options.objects = {"nose", "glasses", "cap"};
  options.bake.samples = 64;
  options.head_resolution = 40;
  const Content content = LoadContent(options);
  ASSERT_EQ(content.objects.size(), 3u);
  ASSERT_TRUE(content.receiver.has_value());

  Renderer renderer({});
  for (const VirtualObject& o : content.objects) renderer.AddObject(o);
  renderer.AddReceiver(*content.receiver);
  FrameInputs in;
  in.camera_rgb = frame.srgb;
  in.light = light;
  in.face_to_camera = face_to_camera;
  in.face_valid = true;
  Composite out;
  renderer.Render(in, out);
  size_t covered = 0, changed = 0;
  for (size_t i = 0; i < out.coverage.size(); ++i) {
    covered += out.coverage[i];
    if (!out.coverage[i] &&
        (out.rgb[i * 3] != frame.srgb[i * 3] || out.rgb[i * 3 + 1] != frame.srgb[i * 3 + 1]))
      ++changed;
  }
  EXPECT_GT(covered, 5000u);
  EXPECT_GT(changed, 500u);  // virtual shadows on the face
  // The clown nose covers the projected nose tip.
  const Vec3 tip = face_to_camera.Apply(raytrace::MakeHead().landmarks[30]);
  const int u = static_cast<int>(std::lround(525 * tip.x / tip.z + 319.5));
  const int v = static_cast<int>(std::lround(525 * tip.y / tip.z + 239.5));
  EXPECT_EQ(out.coverage[v * 640 + u], 1);
  EXPECT_GT(out.rgb[(v * 640 + u) * 3], out.rgb[(v * 640 + u) * 3 + 1] + 30);  // red
  WritePng((std::filesystem::temp_directory_path() / "render_demo_face.png").string(), 640, 480,
           out.rgb);
  // Missing and malformed content: clear errors.
  options.objects = {"missing.obj"};
  try {
    LoadContent(options);
    FAIL();
  } catch (const RenderError& e) {
    EXPECT_EQ(std::string(e.what()), "objects[0] 'missing.obj': missing.obj: cannot open OBJ file");
  }
  const std::string bad = (std::filesystem::temp_directory_path() / "render_bad.ply").string();
  {
    std::ofstream(bad)
        << "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n0\n";
  }
  options.objects = {bad};
  try {
    LoadContent(options);
    FAIL();
  } catch (const RenderError& e) {
    EXPECT_EQ(std::string(e.what()).rfind("objects[0] '" + bad + "': ", 0), 0u) << e.what();
  }
  options.objects = {"hat"};
  EXPECT_THROW(LoadContent(options), RenderError);
}

// object_scale / object_position place each object before its bake: a 0.11 m sphere (the nose
// scaled by 5) lands where asked, and the real-scene mesh it rests on (a plane touching it) gets
// its shadow in the receiver's transfer there, while far from it nothing changes.
TEST(RenderTest, ObjectPlacementHappensBeforeTheBake) {
  const Vec3 target{0.2f, -0.1f, 2.0f};
  const auto modelled = prt::MakeClownNose().Bounds();
  const float radius = 5 * (modelled[1].x - modelled[0].x) / 2;
  // A 1 m plane grid (5 cm) tangent to the placed sphere below it (+y is down), facing it.
  const std::string plane = (std::filesystem::temp_directory_path() / "render_plane.obj").string();
  {
    std::ofstream obj(plane);
    for (int j = 0; j <= 20; ++j) {
      for (int i = 0; i <= 20; ++i) {
        obj << "v " << target.x - 0.5f + 0.05f * i << " " << target.y + radius << " "
            << target.z - 0.5f + 0.05f * j << "\n";
      }
    }
    obj << "vn 0 -1 0\n";
    for (int j = 0; j < 20; ++j) {
      for (int i = 0; i < 20; ++i) {
        const int a = j * 21 + i + 1, b = a + 21;
        obj << "f " << a << "//1 " << a + 1 << "//1 " << b << "//1\n";
        obj << "f " << a + 1 << "//1 " << b + 1 << "//1 " << b << "//1\n";
      }
    }
  }
  ContentOptions options;
  options.anchor = Anchor::kWorld;
  options.objects = {"nose"};
  options.object_scale = 5;
  options.object_position = std::array<double, 3>{target.x, target.y, target.z};
  options.scene_mesh = plane;
  options.bake.samples = 64;
  const Content content = LoadContent(options);
  ASSERT_EQ(content.objects.size(), 1u);
  const auto placed = content.objects[0].mesh.mesh.Bounds();
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR((placed[0][k] + placed[1][k]) / 2, target[k], 1e-4) << k;
    EXPECT_NEAR(placed[1][k] - placed[0][k], 5 * (modelled[1][k] - modelled[0][k]), 1e-4) << k;
  }
  ASSERT_TRUE(content.receiver.has_value());
  const ShadowReceiver& r = *content.receiver;
  const int n = r.bands * r.bands;
  // The receiver vertex under the sphere and the one farthest from it (0.7 m).
  const Vec3 touch{target.x, target.y + radius, target.z};
  size_t contact = 0, corner = 0;
  float nearest = 1e9f, farthest = 0;
  for (size_t v = 0; v < r.mesh.positions.size(); ++v) {
    const Vec3 d = r.mesh.positions[v] - touch;
    const float distance = raytrace::Length(d);
    if (distance < nearest) nearest = distance, contact = v;
    if (distance > farthest) farthest = distance, corner = v;
  }
  ASSERT_LT(nearest, 1e-3f);
  EXPECT_LT(r.transfer_with_virtual[contact * n], 0.5f * r.transfer_real[contact * n]);
  EXPECT_NEAR(r.transfer_with_virtual[corner * n], r.transfer_real[corner * n],
              0.05f * r.transfer_real[corner * n]);
  options.object_scale = 0;
  try {
    LoadContent(options);
    FAIL();
  } catch (const RenderError& e) {
    EXPECT_EQ(std::string(e.what()).rfind("object_scale must be > 0", 0), 0u) << e.what();
  }
}

}  // namespace
}  // namespace probeless::render
