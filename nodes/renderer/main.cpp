// renderer: composites virtual objects (baked PRT, Knorr & Kurz 2014 §4.3) over the camera image
// with differential rendering (Gruber et al. 2015 §5.4) and publishes the result.
//
//   renderer [--ros-args -p mode:=face -p objects:="[nose, glasses]" -p backend:=window ...]
//
// Subscribes (relative names, remap in launch files): camera/image (Image rgb8/bgr8/mono8),
// camera/camera_info (CameraInfo), light (ShLight, camera frame; /face/light or /scene/light),
// face/observation (FaceObservation: head pose, samples for the viewer), scene/pose (Pose, camera
// -> world), scene/gbuffer (GeometryBuffer: the real depth G_r hides virtual fragments),
// scene/transfer and scene/transfer_virtual (TransferBuffer: per-pixel real-only and real+virtual
// transfer of the scene-light node, both or neither).
// Publishes render/composite (Image rgb8, the camera image's header).
//
// Params: mode (face | scene), objects (list: nose, cap, glasses, *.prt, *.obj, *.ply),
// object_scale (1: scale about each object's bounding-box centre), object_position ([] = as
// modelled, else [x, y, z] m in the anchor frame, where that centre goes; scene mode: the world
// frame of scene/pose), scene_mesh, shadows (bool: virtual shadows on the proxy head / scene mesh),
// samples, bands, backend (offscreen | window), trigger (light | image: what starts a frame), tone
// (clamp | reinhard), exposure, white, video (file), video_fps, png_dir, max_frames (0 =
// unlimited). Exit: 0 on shutdown or after max_frames, 2 on bad params or content, 1 when the
// window back-end's X display goes away (one line on stderr).
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <exception>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "probeless/msgs/msgs.h"
#include "probeless/node/node.h"
#include "probeless/render/content.h"
#include "probeless/render/msgs_io.h"
#include "probeless/render/output.h"
#include "probeless/render/renderer.h"
#include "probeless/render/viewer.h"

namespace {

using namespace probeless;

int Run(int argc, char** argv) {
  node::Node node(argc, argv, "renderer");
  render::ContentOptions content_options;
  const std::string mode = node.Param("mode", "face");
  if (mode != "face" && mode != "scene") {
    throw render::RenderError("param mode: expected face or scene, got '" + mode + "'");
  }
  content_options.anchor = mode == "face" ? render::Anchor::kFace : render::Anchor::kWorld;
  content_options.objects = node.Param<std::vector<std::string>>("objects", {"nose"});
  content_options.object_scale = node.Param("object_scale", 1.0);
  const std::vector<double> position = node.Param("object_position", std::vector<double>{});
  if (!position.empty()) {
    if (position.size() != 3) {
      throw render::RenderError("param object_position: expected [x, y, z] (metres), got " +
                                std::to_string(position.size()) + " values");
    }
    content_options.object_position = {position[0], position[1], position[2]};
  }
  content_options.scene_mesh = node.Param("scene_mesh", "");
  content_options.receiver = node.Param("shadows", true);
  content_options.bake.samples = node.Param("samples", 256);
  content_options.bake.bands = node.Param("bands", 3);
  const render::Backend backend = render::BackendFromName(node.Param("backend", "offscreen"));
  const std::string trigger = node.Param("trigger", "light");
  if (trigger != "light" && trigger != "image") {
    throw render::RenderError("param trigger: expected light or image, got '" + trigger + "'");
  }
  render::RendererOptions renderer_options;
  renderer_options.backend = backend;
  const std::string tone = node.Param("tone", "reinhard");
  if (tone != "clamp" && tone != "reinhard") {
    throw render::RenderError("param tone: expected clamp or reinhard, got '" + tone + "'");
  }
  renderer_options.tone.op =
      tone == "reinhard" ? render::ToneOperator::kReinhard : render::ToneOperator::kClamp;
  renderer_options.tone.exposure = static_cast<float>(node.Param("exposure", 1.0));
  renderer_options.tone.white = static_cast<float>(node.Param("white", 4.0));
  const std::string video = node.Param("video", "");
  const double video_fps = node.Param("video_fps", 30.0);
  const std::string png_dir = node.Param("png_dir", "");
  const int64_t max_frames = node.Param<int64_t>("max_frames", 0);

  const auto load_start = std::chrono::steady_clock::now();
  const render::Content content = render::LoadContent(content_options);
  render::Renderer renderer(renderer_options);
  for (size_t i = 0; i < content.objects.size(); ++i) renderer.AddObject(content.objects[i]);
  if (content.receiver) renderer.AddReceiver(*content.receiver);
  node.Info()
      << "GL " << renderer.gl_version() << " (" << renderer.gl_renderer() << "), "
      << content.objects.size() << " objects" << (content.receiver ? " + shadow receiver" : "")
      << " ready in "
      << std::chrono::duration<double>(std::chrono::steady_clock::now() - load_start).count()
      << " s";
  std::optional<render::FrameWriter> writer;
  if (!video.empty() || !png_dir.empty()) writer.emplace(video, video_fps, png_dir);

  bus::Subscriber image_sub = node.CreateSubscriber<msgs::Image>("camera/image");
  bus::Subscriber info_sub = node.CreateSubscriber<msgs::CameraInfo>("camera/camera_info");
  bus::Subscriber light_sub = node.CreateSubscriber<msgs::ShLight>("light");
  bus::Subscriber face_sub = node.CreateSubscriber<msgs::FaceObservation>("face/observation");
  bus::Subscriber pose_sub = node.CreateSubscriber<msgs::Pose>("scene/pose");
  bus::Subscriber gbuffer_sub = node.CreateSubscriber<msgs::GeometryBuffer>("scene/gbuffer");
  bus::Subscriber transfer_sub = node.CreateSubscriber<msgs::TransferBuffer>("scene/transfer");
  bus::Subscriber transfer_virtual_sub =
      node.CreateSubscriber<msgs::TransferBuffer>("scene/transfer_virtual");
  std::optional<bus::Publisher> publisher;
  uint32_t publisher_w = 0, publisher_h = 0;

  // Latest state.
  std::vector<uint8_t> camera_rgb;
  msgs::Header camera_header;
  int width = 0, height = 0;
  std::optional<render::Intrinsics> intrinsics;
  render::ShLightRgb light;
  bool have_light = false;
  msgs::FaceObservation face;
  bool have_face = false;
  raytrace::Transform camera_to_world;
  std::vector<float> real_depth, transfer_real, transfer_virtual;
  int transfer_count = 0;
  render::Composite composite;
  render::ViewerState viewer;
  int64_t frames = 0;

  auto render_frame = [&] {
    if (camera_rgb.empty() || !have_light) return;
    render::FrameInputs in;
    in.camera = intrinsics && intrinsics->width == width && intrinsics->height == height
                    ? *intrinsics
                    : render::DefaultIntrinsics(width, height);
    in.camera_rgb = camera_rgb;
    in.light = light;
    in.face_valid = have_face && face.face_detected;
    if (in.face_valid) in.face_to_camera = render::TransformFromMsg(face.head_pose);
    in.camera_to_world = camera_to_world;
    if (real_depth.size() == camera_rgb.size() / 3) in.real_depth = real_depth;
    if (transfer_count > 0 && transfer_real.size() == transfer_virtual.size() &&
        transfer_real.size() == camera_rgb.size() / 3 * transfer_count) {
      in.transfer_real = transfer_real;
      in.transfer_with_virtual = transfer_virtual;
      in.transfer_count = transfer_count;
    }
    renderer.Render(in, composite);
    if (!publisher || publisher_w != static_cast<uint32_t>(width) ||
        publisher_h != static_cast<uint32_t>(height)) {
      bus::PublisherOptions options;
      options.max_message_bytes =
          msgs::Image::MessageBytesFor(width, height, msgs::Encoding::kRgb8);
      options.slot_count = 8;
      // The publisher appears with the first frame (its size is the camera's): keep the last two
      // composites for subscribers that discover the topic a moment later (the recorder polls).
      options.history = 2;
      publisher.reset();
      publisher.emplace(node.CreatePublisher<msgs::Image>("render/composite", options));
      publisher_w = width;
      publisher_h = height;
    }
    bus::Loan loan =
        publisher->Borrow(msgs::Image::MessageBytesFor(width, height, msgs::Encoding::kRgb8));
    auto view = msgs::WriteMessage<msgs::Image>(loan.data());
    view->header = camera_header;
    view->Init(width, height, msgs::Encoding::kRgb8);
    std::memcpy(view.payload.data(), composite.rgb.data(), composite.rgb.size());
    publisher->Publish(std::move(loan));
    if (writer) writer->Write(composite);
    if (backend == render::Backend::kWindow) {
      render::ViewerInputs vin;
      vin.light = &light;
      vin.face = have_face ? &face : nullptr;
      vin.tone = renderer.tone_mapping();
      const auto [ww, wh] = renderer.WindowSize();
      renderer.Present(render::MakePanels(viewer, vin, ww, wh));
      viewer.ApplyKeys(renderer.TakeKeys());
      if (viewer.quit || renderer.WindowClosed()) node::RequestShutdown();
    }
    ++frames;
    if (max_frames > 0 && frames >= max_frames) node::RequestShutdown();
  };

  std::vector<node::Handler> handlers;
  handlers.push_back({&image_sub, [&](bus::Sample&& s) {
                        const auto m = msgs::ReadMessage<msgs::Image>(s.data());
                        render::ImageToRgb(*m, m.payload, camera_rgb);
                        camera_header = m->header;
                        width = static_cast<int>(m->width);
                        height = static_cast<int>(m->height);
                        if (trigger == "image") render_frame();
                      }});
  handlers.push_back({&info_sub, [&](bus::Sample&& s) {
                        intrinsics = render::IntrinsicsFromMsg(
                            *msgs::ReadMessage<msgs::CameraInfo>(s.data()));
                      }});
  handlers.push_back({&face_sub, [&](bus::Sample&& s) {
                        face = *msgs::ReadMessage<msgs::FaceObservation>(s.data());
                        have_face = true;
                      }});
  handlers.push_back({&pose_sub, [&](bus::Sample&& s) {
                        camera_to_world = render::TransformFromMsg(
                            msgs::ReadMessage<msgs::Pose>(s.data())->transform);
                      }});
  handlers.push_back({&gbuffer_sub, [&](bus::Sample&& s) {
                        const auto m = msgs::ReadMessage<msgs::GeometryBuffer>(s.data());
                        render::GeometryDepth(*m, m.payload, real_depth);
                      }});
  handlers.push_back({&transfer_sub, [&](bus::Sample&& s) {
                        const auto m = msgs::ReadMessage<msgs::TransferBuffer>(s.data());
                        render::TransferValues(*m, m.payload, transfer_real);
                        transfer_count = static_cast<int>(m->coefficient_count);
                      }});
  handlers.push_back({&transfer_virtual_sub, [&](bus::Sample&& s) {
                        const auto m = msgs::ReadMessage<msgs::TransferBuffer>(s.data());
                        render::TransferValues(*m, m.payload, transfer_virtual);
                      }});
  // The light comes last: Spin serves ready subscriptions in this order, and a frame's image, head
  // pose, scene pose and G_r are published before the light computed from them, so with
  // trigger=light a frame is drawn with its own inputs even when the node wakes late.
  handlers.push_back({&light_sub, [&](bus::Sample&& s) {
                        light = render::LightFromMsg(*msgs::ReadMessage<msgs::ShLight>(s.data()));
                        have_light = true;
                        if (trigger == "light") render_frame();
                      }});

  // The window back-end idles between frames, so a watcher notices a display that went away
  // (X server killed, ssh -X session closed) instead of the node waiting on it forever.
  std::atomic<bool> display_lost{false};
  std::thread watcher;
  if (backend == render::Backend::kWindow) {
    watcher = std::thread([&] {
      while (node.ok()) {
        if (renderer.DisplayLost()) {
          display_lost = true;
          node::RequestShutdown();
          break;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
      }
    });
  }
  node.Spin(handlers);
  if (watcher.joinable()) watcher.join();
  node.Info() << "rendered " << frames << " frames";
  if (display_lost) {
    node.Error()
        << "window backend: the X display closed the connection; exiting (backend:=offscreen "
           "needs no display)";
    return 1;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return Run(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "[error] [renderer] %s\n", e.what());
    return 2;
  }
}
