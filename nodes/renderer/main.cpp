// renderer: composites virtual objects (baked PRT, Knorr & Kurz 2014 §4.3) over the camera image
// with differential rendering (Gruber et al. 2015 §5.4) and publishes the result.
//
//   renderer [--ros-args -p mode:=face -p objects:="[nose, glasses]" -p backend:=window ...]
//
// Subscribes (relative names, remap in launch files): camera/image (Image rgb8/bgr8/mono8),
// camera/camera_info (CameraInfo), light (ShLight, camera frame; /face/light or /scene/light;
// linear units: face_model lights are refused, unknown / linear_unscaled ones used with a warning),
// face/observation (FaceObservation: head pose, samples for the viewer), scene/pose (Pose, camera
// -> world), scene/gbuffer (GeometryBuffer: the real depth G_r hides virtual fragments),
// scene/transfer and scene/transfer_virtual (TransferBuffer: per-pixel real-only and real+virtual
// transfer of the scene-light node, both or neither).
// Publishes render/composite (Image rgb8, the camera image's header).
//
// Scene mode with shadows (the default): every composite rasterises the objects into the latest G_r
// (-> G_r'), computes the SSDO transfer of both buffers in the objects' window and applies Gruber
// eq. 13-15 to the camera image (render/differential.h), so the objects shadow whatever real
// surface fusion reconstructed and tint it by their bounce light; shadow_source mesh keeps the
// older receiver from scene_mesh instead. Face mode does the same with shadow_source gbuffer, G_r
// being the proxy head rasterised at the head pose (its depth also hides objects behind the head).
//
// Params: mode (face | scene), objects (list: nose, cap, glasses, *.prt, *.obj, *.ply),
// object_scale (1: scale about each object's bounding-box centre), object_position ([] = as
// modelled, else [x, y, z] m in the anchor frame, where that centre goes; scene mode: the world
// frame of scene/pose), scene_mesh, shadows (bool: the objects' shadows on the real scene),
// samples, bands, backend (offscreen | window), trigger (light | image: what starts a frame), tone
// (clamp | reinhard), exposure, white, video (file), video_fps, png_dir, max_frames (0 =
// unlimited), shadow_source (gbuffer: from G_r, the default in scene mode; face mode: the proxy
// head rasterised at the head pose | mesh: the baked receiver, face mode's default), ssdo_radius
// (0.3 m scene, 0.1 m face), ssdo_directions, ssdo_bands, ssdo_seed,
// ssdo_threads, differential_step, differential_smooth, differential_tone (ratio | fixed | key),
// differential_key, indirect, sun_shadow (with differential_tone ratio: the crisp cast shadow of
// the light's directional part, render::DifferentialOptions::sun_shadow),
// object_pixel ([] or [u, v]: the objects rest on the reconstructed surface seen there),
// virtual_occlusion, virtual_bounce, object_uncertainty_blur (0: off; > 0: the objects shaded
// with the light blurred by its confidence's expected error). Read in params.cpp.
//
// Click to place (backend window, scene mode): a left click on the composite in the viewer window
// places the objects like object_pixel at the clicked pixel (render::Renderer::TakeClicks converts
// window coordinates to image pixels), on the next frame with G_r, with the same
// render::PlaceOnSurface; each new click moves them again. One info line per click ("viewer click
// at pixel [u, v]: objects rest on the surface there, centre at (x, y, z) m, world frame"); a pixel
// without surface: one warning, the objects stay. Face mode ignores clicks (one info line).
//
// Exit: 0 on shutdown or after max_frames, 2 on bad params or content, 1 when the window back-end's
// X display goes away (one line on stderr).
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "outputs.h"
#include "params.h"
#include "probeless/light/fusion.h"
#include "probeless/msgs/msgs.h"
#include "probeless/node/node.h"
#include "probeless/prt/demo_objects.h"
#include "probeless/render/content.h"
#include "probeless/render/differential.h"
#include "probeless/render/msgs_io.h"
#include "probeless/render/output.h"
#include "probeless/render/renderer.h"
#include "probeless/render/viewer.h"

namespace {

using namespace probeless;

int Run(int argc, char** argv) {
  node::Node node(argc, argv, "renderer");
  const renderer_node::RendererParams params = renderer_node::ReadParams(node);
  const std::string& mode = params.mode;
  const render::ContentOptions& content_options = params.content_options;
  const bool gbuffer_differential = params.gbuffer_differential;
  const bool face_differential = params.face_differential;
  const render::DifferentialOptions& diff_options = params.diff_options;
  const std::vector<double>& object_pixel = params.object_pixel;
  const render::Backend backend = params.renderer_options.backend;
  const std::string& trigger = params.trigger;
  const render::RendererOptions& renderer_options = params.renderer_options;
  const std::string& video = params.video;
  const double video_fps = params.video_fps;
  const std::string& png_dir = params.png_dir;
  const int64_t max_frames = params.max_frames;

  const auto load_start = std::chrono::steady_clock::now();
  const render::Content content = render::LoadContent(content_options);
  render::Renderer renderer(renderer_options);
  std::optional<render::DifferentialRenderer> differential;
  if (gbuffer_differential) differential.emplace(diff_options);  // throws for bad options
  for (size_t i = 0; i < content.objects.size(); ++i) renderer.AddObject(content.objects[i]);
  if (content.receiver) renderer.AddReceiver(*content.receiver);
  // Face mode G_r: the proxy head the objects were baked against.
  const raytrace::Mesh head_mesh =
      face_differential ? prt::ProxyHead(content_options.head_resolution) : raytrace::Mesh{};
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
  renderer_node::CompositePublisher composite_pub(node);

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
  std::vector<float> real_depth, real_normals, transfer_real, transfer_virtual;
  std::vector<uint8_t> real_colour, camera_diff;
  msgs::ShLight light_msg;
  // The objects' placement (object_pixel moves them once, at the first frame with G_r; in scene
  // mode each click in the viewer window moves them again).
  std::vector<raytrace::Transform> placement(content.objects.size());
  bool placed = object_pixel.empty();
  const bool click_placement = backend == render::Backend::kWindow && mode == "scene";
  std::vector<render::ViewerClick> pending_clicks;  // taken from the window, waiting for G_r
  bool told_click_mode = false;
  std::vector<const raytrace::Mesh*> object_meshes;
  for (const auto& o : content.objects) object_meshes.push_back(&o.mesh.mesh);
  // The ARKit-style hit test shared by object_pixel and clicks (render::PlaceOnSurface): all
  // objects rest on the surface seen at (u, v); returns the group's new centre (world frame), or
  // nullopt when there is no surface there (the objects stay).
  auto place_at = [&](const light::GeometryView& g, double u, double v,
                      const raytrace::Transform& to_world) -> std::optional<raytrace::Vec3> {
    const auto hit = render::PlaceOnSurface(g, u, v, to_world, object_meshes);
    if (!hit) return std::nullopt;
    for (size_t i = 0; i < placement.size(); ++i) {
      placement[i] = *hit;
      renderer.SetObjectPlacement(static_cast<int>(i), *hit);
    }
    placed = true;
    return hit->Apply(render::GroupCentre(object_meshes));
  };
  render::VirtualGeometry with_virtual, head_geometry;
  render::DifferentialResult diff_result;
  double diff_ms_sum = 0, diff_changed_sum = 0;
  int64_t diff_frames = 0;
  bool warned_size = false, warned_hit = false;
  std::optional<msgs::ShLightUnits> warned_units;  // one warning per change of units
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
    // The objects' light as its expected value under the direction uncertainty (params.h).
    if (params.object_uncertainty_blur > 0) {
      for (int k = 1; k < in.light.bands * in.light.bands; ++k) {
        const int band = static_cast<int>(std::sqrt(static_cast<double>(k)));
        const auto f = static_cast<float>(light::UncertaintyBandFactor(
            light_msg.confidence, params.object_uncertainty_blur, band));
        for (float& c : in.light.coefficients[k]) c *= f;
      }
    }
    in.face_valid = have_face && face.face_detected;
    if (in.face_valid) in.face_to_camera = render::TransformFromMsg(face.head_pose);
    in.camera_to_world = camera_to_world;
    if (real_depth.size() == camera_rgb.size() / 3) in.real_depth = real_depth;
    const bool have_gbuffer =
        real_depth.size() == camera_rgb.size() / 3 && real_normals.size() == 3 * real_depth.size();
    // Clicks of the frames shown so far (their pixels are the shown frames'; none offscreen).
    if (backend == render::Backend::kWindow) {
      for (const render::ViewerClick& c : renderer.TakeClicks()) pending_clicks.push_back(c);
      if (!click_placement && !pending_clicks.empty()) {
        if (!told_click_mode) {
          node.Info() << "viewer click: placing objects by click needs mode scene (face mode's "
                         "objects follow the head)";
          told_click_mode = true;
        }
        pending_clicks.clear();
      }
      // Until G_r arrives keep only the newest few (the queue's bound).
      if (pending_clicks.size() > render::ClickQueue::kCapacity) {
        pending_clicks.erase(pending_clicks.begin(),
                             pending_clicks.end() - render::ClickQueue::kCapacity);
      }
    }
    if ((!placed || !pending_clicks.empty()) && have_gbuffer) {
      // An ARKit-style hit test on the reconstruction (render/differential.h): object_pixel once,
      // then each click in order.
      const light::Intrinsics k{in.camera.fx, in.camera.fy, in.camera.cx, in.camera.cy};
      const light::GeometryView g{width, height, k, real_depth, real_normals, {}};
      if (!placed) {
        if (const auto at = place_at(g, object_pixel[0], object_pixel[1], in.camera_to_world)) {
          node.Info() << "object_pixel [" << object_pixel[0] << ", " << object_pixel[1]
                      << "]: objects moved by (" << placement[0].translation[0] << ", "
                      << placement[0].translation[1] << ", " << placement[0].translation[2]
                      << ") m, world frame";
        } else if (!warned_hit) {
          node.Warn() << "object_pixel: no reconstructed surface at that pixel yet";
          warned_hit = true;
        }
      }
      for (const render::ViewerClick& c : pending_clicks) {
        const int u = static_cast<int>(std::floor(c.u + 0.5));
        const int v = static_cast<int>(std::floor(c.v + 0.5));
        if (u >= width || v >= height) {  // the camera image shrank since that frame was shown
          node.Warn() << "viewer click at pixel [" << u << ", " << v << "]: outside the current "
                      << width << "x" << height << " image; the objects stay where they were";
        } else if (const auto at = place_at(g, u, v, in.camera_to_world)) {
          node.Info() << "viewer click at pixel [" << u << ", " << v
                      << "]: objects rest on the surface there, centre at (" << at->x << ", "
                      << at->y << ", " << at->z << ") m, world frame";
        } else {
          node.Warn() << "viewer click at pixel [" << u << ", " << v
                      << "]: no reconstructed surface there; the objects stay where they were";
        }
      }
      pending_clicks.clear();
    }
    // Gruber §5.4: G_r' -> R_d, R'_d (R_i, R'_i) -> eq. 13-15, from the reconstruction (scene
    // mode) or the head at its pose (face mode).
    const light::Intrinsics k{in.camera.fx, in.camera.fy, in.camera.cx, in.camera.cy};
    std::optional<light::GeometryView> real_view;
    raytrace::Transform anchor_to_camera;
    if (differential && face_differential && in.face_valid) {
      render::RasteriseHead(head_mesh, in.face_to_camera, k, width, height, camera_rgb,
                            &head_geometry);
      real_view = head_geometry.View(k);
      anchor_to_camera = in.face_to_camera;
      in.real_depth = head_geometry.depth;  // the head hides the objects behind it
    } else if (differential && !face_differential && placed && have_gbuffer) {
      const std::span<const uint8_t> colour = real_colour.size() == 3 * real_depth.size()
                                                  ? std::span<const uint8_t>(real_colour)
                                                  : std::span<const uint8_t>();
      real_view = light::GeometryView{width, height, k, real_depth, real_normals, colour};
      anchor_to_camera = in.camera_to_world.Inverse();
    }
    if (real_view) {
      const light::GeometryView& g = *real_view;
      std::vector<render::RasterObject> raster;
      for (size_t i = 0; i < content.objects.size(); ++i) {
        const render::VirtualObject& o = content.objects[i];
        raster.push_back({&o.mesh.mesh, anchor_to_camera * placement[i] * o.object_to_anchor,
                          o.albedo, o.cull_back_faces});
      }
      render::RasteriseObjects(g, raster, &with_virtual);
      render::DifferentialFrame df;
      df.real = g;
      df.with_virtual = &with_virtual;
      df.light = light;
      df.dominant = renderer_node::DominantOf(light_msg);
      df.camera_tone = renderer.tone_mapping();
      df.camera_rgb = camera_rgb;
      df.objects = raster;
      differential->Compute(df, &diff_result);
      camera_diff = camera_rgb;
      render::ApplyDifferential(diff_result, width, height, camera_diff);
      in.camera_rgb = camera_diff;
      if (!diff_result.virtual_modulation.empty()) {
        const auto& vr = diff_result.virtual_rect;
        in.virtual_rect = {vr.x0, vr.y0, vr.x1, vr.y1};
        in.virtual_modulation = diff_result.virtual_modulation;
        in.virtual_indirect = diff_result.virtual_indirect;
      }
      diff_ms_sum += diff_result.ms_total;
      diff_changed_sum += diff_result.changed_pixels;
      ++diff_frames;
      node.Debug() << "differential: window " << diff_result.window.width() << "x"
                   << diff_result.window.height() << ", " << diff_result.changed_pixels
                   << " pixels changed, smallest factor " << diff_result.min_factor << ", sun "
                   << diff_result.sun_amplitude[0] << " over " << diff_result.sun_shadow_pixels
                   << " pixels, " << diff_result.ms_total << " ms";
    } else if (differential && !face_differential && !have_gbuffer && !real_depth.empty() &&
               !warned_size) {
      node.Warn() << "scene/gbuffer is not the camera image's size (or has no normals): no "
                     "shadows from G_r for such frames";
      warned_size = true;
    }
    if (transfer_count > 0 && transfer_real.size() == transfer_virtual.size() &&
        transfer_real.size() == camera_rgb.size() / 3 * transfer_count) {
      in.transfer_real = transfer_real;
      in.transfer_with_virtual = transfer_virtual;
      in.transfer_count = transfer_count;
    }
    renderer.Render(in, composite);
    composite_pub.Publish(camera_header, width, height, composite);
    if (writer) {
      try {
        writer->Write(composite);
      } catch (const render::RenderError& e) {
        throw node::NodeError(e.what());  // the output, not this sample: the node ends
      }
    }
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
                        if (differential || !placed || click_placement) {
                          render::GeometryPlanes(*m, m.payload, real_normals, real_colour);
                        }
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
                        const msgs::ShLight m = *msgs::ReadMessage<msgs::ShLight>(s.data());
                        std::string why;
                        const bool usable = render::AcceptLightUnits(m.units, &why);
                        if (!why.empty() && warned_units != m.units) {
                          node.Warn() << why;
                          warned_units = m.units;
                        }
                        if (!usable) return;  // keeps the last linear light, if any
                        light_msg = m;
                        light = render::LightFromMsg(light_msg);
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
  if (diff_frames > 0) {
    node.Info() << "differential rendering from G_r on " << diff_frames << " frames, mean "
                << diff_ms_sum / diff_frames << " ms, " << diff_changed_sum / diff_frames
                << " pixels changed per frame";
  }
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
