// render_bench: speed of the AR renderer (docs/benchmarks/render.md).
//
//   render_bench [--json OUT] [--frames N] [--triangles T] [--backend offscreen|window]
//
// 1. Composite frame rate at 640x480: a face-anchored sphere of about T (50k) triangles with baked-
//    style transfer over a camera image, the whole Render() (camera upload, three passes, read-
//    back), without and with differential rendering (the proxy head as shadow receiver).
// 2. Latency from a light message to the published composite: a light publisher thread stamps
//    ShLight messages (CLOCK_MONOTONIC) at 30 Hz; the render loop takes each light, renders and
//    publishes the composite (Image rgb8) with the light's stamp; a receiver thread takes the
//    composites and records now - stamp. Transport is the probeless bus (shared memory).
// 3. Differential rendering from G_r (scene mode's default, render/differential.h): a 0.15 m
//    world-anchored sphere on the floor of a 640x480 G_r (floor 0.4 m below the camera, wall at
//    2 m), per frame RasteriseObjects + DifferentialRenderer (SSDO of G_r and G_r' in the window,
//    ratio tone, bounce light) + ApplyDifferential + Render with the real depth; full (step 1)
//    and OursFast-style (step 2, the node's default), and the light-to-composite latency of step 2.
// Prints the JSON object on stdout and writes it to OUT.
#include "probeless/node/main.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "probeless/bus/bus.h"
#include "probeless/msgs/msgs.h"
#include "probeless/node/flags.h"
#include "probeless/prt/demo_objects.h"
#include "probeless/prt/prt.h"
#include "probeless/render/differential.h"
#include "probeless/render/renderer.h"
#include "probeless/sh/sh.h"

namespace {

using namespace probeless;
using Clock = std::chrono::steady_clock;

int64_t MonoNs() {
  timespec t{};
  clock_gettime(CLOCK_MONOTONIC, &t);
  return static_cast<int64_t>(t.tv_sec) * 1'000'000'000 + t.tv_nsec;
}

double Percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(p * (v.size() - 1) + 0.5))];
}

double Mean(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x;
  return v.empty() ? 0 : s / v.size();
}

prt::TransferMesh Sphere(int triangles) {
  // A UV sphere with s segments has about s^2 triangles.
  const int segments = std::max(8, static_cast<int>(std::lround(std::sqrt(triangles))));
  prt::TransferMesh m;
  m.mesh = raytrace::MakeSphere(0.03f, segments);
  m.bands = 3;
  for (const raytrace::Vec3& n : m.mesh.normals) {
    const std::vector<float> t = prt::UnshadowedTransfer(n, 3);
    m.transfer.insert(m.transfer.end(), t.begin(), t.end());
  }
  return m;
}

render::ShLightRgb Light(double phase) {
  render::ShLightRgb light;
  const std::vector<double> key =
      sh::DirectionalLight({std::sin(phase) * 0.6, -0.6, -std::cos(phase) * 0.6}, 2.0, 3);
  for (int k = 0; k < 9; ++k) light.coefficients[k] = {float(key[k]), float(key[k]), float(key[k])};
  light.coefficients[0] = {light.coefficients[0][0] + 0.5f, light.coefficients[0][1] + 0.5f,
                           light.coefficients[0][2] + 0.5f};
  return light;
}

}  // namespace

int Run(int argc, char** argv) {
  std::string json_path;
  int frames = 300;
  int triangles = 50000;
  std::string backend = "offscreen";
  probeless::node::FlagParser flags(
      "render_bench",
      "speed of the AR renderer (docs/benchmarks/render.md): composite frame rate at 640x480,\n"
      "light-to-composite latency over the bus, differential rendering from G_r; prints the JSON");
  flags.Add("--json", &json_path, "OUT", "also write the JSON object to OUT");
  flags.Add("--frames", &frames, "N", "frames timed", 10);
  flags.Add("--triangles", &triangles, "T", "triangles of the face-anchored sphere", 100);
  flags.Add("--backend", &backend, "offscreen|window", "the renderer's backend");
  if (!flags.Parse(argc, argv)) return 0;
  const std::string domain = "render_bench_" + std::to_string(getpid());
  setenv("PROBELESS_DOMAIN", domain.c_str(), 1);
  constexpr int kW = 640, kH = 480;
  render::RendererOptions options;
  options.backend = render::BackendFromName(backend);
  options.width = kW;
  options.height = kH;
  options.tone.op = render::ToneOperator::kReinhard;
  render::Renderer renderer(options);
  render::VirtualObject object;
  object.mesh = Sphere(triangles);
  object.anchor = render::Anchor::kFace;
  object.object_to_anchor = raytrace::Transform{raytrace::Mat3::Identity(), {0, 0.04, -0.06}};
  const size_t triangle_count = object.mesh.mesh.triangles.size();
  renderer.AddObject(object);
  // The proxy head as receiver (identical transfer sets: the pass runs at full cost).
  render::ShadowReceiver receiver;
  receiver.mesh = prt::ProxyHead(48);
  receiver.mesh.ComputeNormals();
  for (const raytrace::Vec3& n : receiver.mesh.normals) {
    const std::vector<float> t = prt::UnshadowedTransfer(n, 3);
    receiver.transfer_real.insert(receiver.transfer_real.end(), t.begin(), t.end());
  }
  receiver.transfer_with_virtual = receiver.transfer_real;
  receiver.anchor = render::Anchor::kFace;
  const int receiver_index = renderer.AddReceiver(receiver);
  // Scene mode: the world-anchored sphere (camera = world here) and its G_r.
  render::VirtualObject ball;
  ball.mesh = Sphere(triangles);
  for (raytrace::Vec3& p : ball.mesh.mesh.positions) p = {p.x * 5, p.y * 5, p.z * 5};
  ball.anchor = render::Anchor::kWorld;
  ball.object_to_anchor = raytrace::Transform{raytrace::Mat3::Identity(), {0, 0.25, 1.8}};
  ball.visible = false;
  const int ball_index = renderer.AddObject(ball);
  const light::Intrinsics gk{525, 525, 319.5, 239.5};
  std::vector<float> g_depth(kW * kH), g_normals(3 * kW * kH);
  for (int v = 0; v < kH; ++v) {
    for (int u = 0; u < kW; ++u) {
      const size_t p = static_cast<size_t>(v) * kW + u;
      const double dy = (v - gk.cy) / gk.fy;
      const bool floor = dy > 0 && 0.4 / dy < 2.0;
      g_depth[p] = static_cast<float>(floor ? 0.4 / dy : 2.0);
      g_normals[3 * p + 1] = floor ? -1.0f : 0.0f;
      g_normals[3 * p + 2] = floor ? 0.0f : -1.0f;
    }
  }
  const light::GeometryView g_real{kW, kH, gk, g_depth, g_normals, {}};

  std::vector<uint8_t> camera(kW * kH * 3);
  for (size_t i = 0; i < camera.size(); ++i) camera[i] = static_cast<uint8_t>((i * 31) % 251);
  render::FrameInputs in;
  in.camera.width = kW;
  in.camera.height = kH;
  in.camera_rgb = camera;
  in.face_valid = true;
  in.face_to_camera = raytrace::Transform{raytrace::Mat3::FromEulerZyx(0.2, 0.1, 0), {0, 0, 0.5}};
  render::Composite out;

  auto run = [&](bool differential) {
    renderer.SetReceiverVisible(receiver_index, differential);
    std::vector<double> ms;
    for (int f = 0; f < frames + 5; ++f) {
      in.light = Light(f * 0.05);
      const auto t0 = Clock::now();
      renderer.Render(in, out);
      const double dt = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
      if (f >= 5) ms.push_back(dt);  // warm-up frames excluded
    }
    return ms;
  };
  const std::vector<double> plain = run(false);
  const std::vector<double> diff = run(true);
  // Scene mode: G_r' and eq. 13-15 on the CPU, then the GL passes with the real depth.
  render::VirtualGeometry g_virtual;
  render::DifferentialResult g_result;
  std::vector<uint8_t> g_camera;
  double g_transfer_ms = 0, g_raster_ms = 0, g_total_ms = 0;
  int g_changed = 0, g_sun_pixels = 0;
  bool g_sun = false;   // the crisp sun shadow (DifferentialOptions::sun_shadow) on
  bool g_side = false;  // the dominant light from the side (its shadow in view)
  auto coherent_frame = [&](render::DifferentialRenderer& dr) {
    render::RasterObject o{&ball.mesh.mesh, ball.object_to_anchor, {0.8f, 0.1f, 0.1f}, true};
    const auto t_raster = Clock::now();
    render::RasteriseObjects(g_real, {&o, 1}, &g_virtual);
    g_raster_ms = std::chrono::duration<double, std::milli>(Clock::now() - t_raster).count();
    render::DifferentialFrame df;
    df.real = g_real;
    df.with_virtual = &g_virtual;
    df.light = in.light;
    df.dominant = {{0, -0.7f, -0.7f}, 2.0f};
    df.camera_tone = renderer.tone_mapping();
    df.camera_rgb = camera;
    // A lamp from the right, above and behind the ball: its shadow falls on the floor in view.
    if (g_side) df.dominant = {{0.70f, -0.59f, 0.40f}, 2.0f};
    if (g_sun) df.objects = {&o, 1};
    dr.Compute(df, &g_result);
    g_sun_pixels = g_result.sun_shadow_pixels;
    g_camera = camera;
    render::ApplyDifferential(g_result, kW, kH, g_camera);
    render::FrameInputs gin = in;
    gin.camera_rgb = g_camera;
    gin.real_depth = g_depth;
    renderer.Render(gin, out);
    g_transfer_ms = g_result.ms_transfer;
    g_total_ms = g_result.ms_total;
    g_changed = g_result.changed_pixels;
  };
  auto run_coherent = [&](int step, double* transfer_ms, double* raster_ms, double* diff_ms,
                          bool sun = false, bool side = false) {
    render::DifferentialOptions o;
    o.tone = render::DifferentialTone::kRatio;
    o.step = step;
    o.sun_shadow = sun;
    g_sun = sun;
    g_side = side;
    render::DifferentialRenderer dr(o);
    renderer.SetReceiverVisible(receiver_index, false);
    renderer.SetObjectVisible(0, false);
    renderer.SetObjectVisible(ball_index, true);
    std::vector<double> ms, transfer, raster, total;
    for (int f = 0; f < std::min(frames, 60) + 3; ++f) {
      in.light = Light(f * 0.05);
      const auto t0 = Clock::now();
      coherent_frame(dr);
      const double dt = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
      if (f >= 3) {
        ms.push_back(dt);
        transfer.push_back(g_transfer_ms);
        raster.push_back(g_raster_ms);
        total.push_back(g_total_ms);
      }
    }
    renderer.SetObjectVisible(0, true);
    renderer.SetObjectVisible(ball_index, false);
    *transfer_ms = Percentile(transfer, 0.5);
    *raster_ms = Percentile(raster, 0.5);
    *diff_ms = Percentile(total, 0.5);
    return ms;
  };
  double coherent_transfer_ms = 0, coherent_fast_transfer_ms = 0, raster_ms = 0, diff_ms = 0,
         fast_raster_ms = 0, fast_diff_ms = 0;
  const std::vector<double> coherent = run_coherent(1, &coherent_transfer_ms, &raster_ms, &diff_ms);
  const int coherent_window = g_result.window.width() * g_result.window.height();
  const int coherent_changed = g_changed;
  const std::vector<double> coherent_fast =
      run_coherent(2, &coherent_fast_transfer_ms, &fast_raster_ms, &fast_diff_ms);
  // The same side light without and with the crisp sun shadow.
  double side_transfer_ms = 0, side_raster_ms = 0, side_diff_ms = 0;
  const std::vector<double> coherent_side =
      run_coherent(2, &side_transfer_ms, &side_raster_ms, &side_diff_ms, false, /*side=*/true);
  double sun_transfer_ms = 0, sun_raster_ms = 0, sun_diff_ms = 0;
  const std::vector<double> coherent_sun =
      run_coherent(2, &sun_transfer_ms, &sun_raster_ms, &sun_diff_ms, /*sun=*/true, true);
  const int sun_pixels = g_sun_pixels;
  size_t covered = 0;
  for (uint8_t c : out.coverage) covered += c;

  // Latency through the bus.
  bus::PublisherOptions light_options;
  light_options.max_message_bytes = sizeof(msgs::ShLight);
  bus::Publisher light_pub("/bench/light", msgs::TopicTypeOf<msgs::ShLight>(), light_options);
  bus::Subscriber light_sub("/bench/light", msgs::TopicTypeOf<msgs::ShLight>(), {.queue_depth = 4});
  bus::PublisherOptions image_options;
  image_options.max_message_bytes = msgs::Image::MessageBytesFor(kW, kH, msgs::Encoding::kRgb8);
  image_options.slot_count = 8;
  bus::Publisher image_pub("/bench/composite", msgs::TopicTypeOf<msgs::Image>(), image_options);
  bus::Subscriber image_sub("/bench/composite", msgs::TopicTypeOf<msgs::Image>(),
                            {.queue_depth = 4});
  const int latency_frames = std::min(frames, 150);
  render::DifferentialOptions latency_options;
  latency_options.tone = render::DifferentialTone::kRatio;
  latency_options.step = 2;  // the renderer node's default
  render::DifferentialRenderer latency_dr(latency_options);
  auto measure_latency = [&](bool differential, bool coherent) {
    renderer.SetReceiverVisible(receiver_index, differential);
    renderer.SetObjectVisible(0, !coherent);
    renderer.SetObjectVisible(ball_index, coherent);
    std::vector<double> latency;
    std::atomic<bool> done{false};
    std::thread receiver_thread([&] {
      while (!done) {
        auto s = image_sub.Take(std::chrono::milliseconds(50));
        if (!s) continue;
        const auto m = msgs::ReadMessage<msgs::Image>(s->data());
        latency.push_back((MonoNs() - m->header.stamp_mono_ns) / 1e6);
      }
    });
    std::thread light_thread([&] {
      for (int f = 0; f < latency_frames; ++f) {
        bus::Loan loan = light_pub.Borrow(sizeof(msgs::ShLight));
        auto m = msgs::WriteMessage<msgs::ShLight>(loan.data());
        const render::ShLightRgb l = Light(f * 0.05);
        m->bands = 3;
        m->units = msgs::ShLightUnits::kLinear;
        for (int k = 0; k < 9; ++k)
          for (int c = 0; c < 3; ++c) m->coefficients[k][c] = l.coefficients[k][c];
        m->header.StampNow();
        light_pub.Publish(std::move(loan));
        std::this_thread::sleep_for(std::chrono::microseconds(33333));
      }
    });
    for (int f = 0; f < latency_frames; ++f) {
      auto s = light_sub.Take(std::chrono::seconds(2));
      if (!s) break;
      const auto m = msgs::ReadMessage<msgs::ShLight>(s->data());
      in.light.bands = static_cast<int>(m->bands);
      for (int k = 0; k < 9; ++k)
        for (int c = 0; c < 3; ++c) in.light.coefficients[k][c] = m->coefficients[k][c];
      const msgs::Header header = m->header;
      s.reset();
      if (coherent) {
        coherent_frame(latency_dr);
      } else {
        renderer.Render(in, out);
      }
      bus::Loan loan = image_pub.Borrow(image_options.max_message_bytes);
      auto img = msgs::WriteMessage<msgs::Image>(loan.data());
      img->header = header;
      img->Init(kW, kH, msgs::Encoding::kRgb8);
      std::memcpy(img.payload.data(), out.rgb.data(), out.rgb.size());
      image_pub.Publish(std::move(loan));
    }
    light_thread.join();
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    done = true;
    receiver_thread.join();
    return latency;
  };
  const std::vector<double> latency = measure_latency(false, false);
  const std::vector<double> latency_diff = measure_latency(true, false);
  const std::vector<double> latency_coherent = measure_latency(false, true);

  char buffer[8192];
  std::snprintf(
      buffer, sizeof(buffer),
      "{\"backend\": \"%s\", \"gl_version\": \"%s\", \"gl_renderer\": \"%s\", \"width\": %d, "
      "\"height\": %d, \"triangles\": %zu, \"receiver_triangles\": %zu, \"covered_pixels\": %zu, "
      "\"frames\": %d, \"fps\": %.1f, \"frame_ms_mean\": %.3f, \"frame_ms_p50\": %.3f, "
      "\"frame_ms_p95\": %.3f, \"fps_differential\": %.1f, \"frame_ms_differential_p50\": %.3f, "
      "\"frame_ms_differential_p95\": %.3f, \"latency_samples\": %zu, \"latency_ms_p50\": %.3f, "
      "\"latency_ms_p95\": %.3f, \"latency_ms_max\": %.3f, \"latency_differential_ms_p50\": "
      "%.3f, "
      "\"latency_differential_ms_p95\": %.3f, \"gbuffer_window_pixels\": %d, "
      "\"gbuffer_changed_pixels\": %d, \"frame_ms_gbuffer_p50\": %.3f, "
      "\"frame_ms_gbuffer_p95\": %.3f, \"transfer_ms_gbuffer_p50\": %.3f, "
      "\"frame_ms_gbuffer_step2_p50\": %.3f, \"transfer_ms_gbuffer_step2_p50\": %.3f, "
      "\"raster_ms_gbuffer_p50\": %.3f, \"differential_ms_gbuffer_p50\": %.3f, "
      "\"differential_ms_gbuffer_step2_p50\": %.3f, "
      "\"differential_ms_gbuffer_step2_side_p50\": %.3f, "
      "\"frame_ms_gbuffer_step2_sun_p50\": %.3f, \"differential_ms_gbuffer_step2_sun_p50\": "
      "%.3f, \"sun_shadow_pixels\": %d, "
      "\"latency_gbuffer_ms_p50\": %.3f, \"latency_gbuffer_ms_p95\": %.3f, "
      "\"lp_num_threads\": \"%s\"}",
      backend.c_str(), renderer.gl_version().c_str(), renderer.gl_renderer().c_str(), kW, kH,
      triangle_count, receiver.mesh.triangles.size(), covered, frames, 1000.0 / Mean(plain),
      Mean(plain), Percentile(plain, 0.5), Percentile(plain, 0.95), 1000.0 / Mean(diff),
      Percentile(diff, 0.5), Percentile(diff, 0.95), latency.size(), Percentile(latency, 0.5),
      Percentile(latency, 0.95),
      latency.empty() ? 0.0 : *std::max_element(latency.begin(), latency.end()),
      Percentile(latency_diff, 0.5), Percentile(latency_diff, 0.95), coherent_window,
      coherent_changed, Percentile(coherent, 0.5), Percentile(coherent, 0.95), coherent_transfer_ms,
      Percentile(coherent_fast, 0.5), coherent_fast_transfer_ms, fast_raster_ms, diff_ms,
      fast_diff_ms, side_diff_ms, Percentile(coherent_sun, 0.5), sun_diff_ms, sun_pixels,
      Percentile(latency_coherent, 0.5), Percentile(latency_coherent, 0.95),
      std::getenv("LP_NUM_THREADS") ? std::getenv("LP_NUM_THREADS") : "default");
  std::printf("%s\n", buffer);
  if (!json_path.empty()) {
    std::ofstream(json_path) << buffer << "\n";
  }
  return 0;
}

int main(int argc, char** argv) {
  return probeless::node::RunMain("render_bench", [&] { return Run(argc, argv); });
}
