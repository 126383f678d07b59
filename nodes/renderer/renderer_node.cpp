#include "renderer_node.h"

#include <atomic>
#include <cmath>
#include <span>
#include <string>
#include <thread>
#include <utility>

#include "probeless/light/fusion.h"
#include "probeless/prt/demo_objects.h"
#include "probeless/render/msgs_io.h"

namespace probeless::renderer_node {

RendererNode::RendererNode(node::Node& node, const RendererParams& params)
    : node_(node),
      params_(params),
      click_placement_(params.renderer_options.backend == render::Backend::kWindow &&
                       params.mode == "scene"),
      load_start_(std::chrono::steady_clock::now()),
      content_(render::LoadContent(params.content_options)),
      renderer_(params.renderer_options),
      differential_(
          params.gbuffer_differential  // throws for bad options
              ? std::optional<render::DifferentialRenderer>(std::in_place, params.diff_options)
              : std::nullopt),
      head_mesh_(AddContent()),
      writer_(ReportReadyAndOpenWriter()),
      image_sub_(node.CreateSubscriber<msgs::Image>("camera/image")),
      info_sub_(node.CreateSubscriber<msgs::CameraInfo>("camera/camera_info")),
      light_sub_(node.CreateSubscriber<msgs::ShLight>("light")),
      face_sub_(node.CreateSubscriber<msgs::FaceObservation>("face/observation")),
      pose_sub_(node.CreateSubscriber<msgs::Pose>("scene/pose")),
      gbuffer_sub_(node.CreateSubscriber<msgs::GeometryBuffer>("scene/gbuffer")),
      transfer_sub_(node.CreateSubscriber<msgs::TransferBuffer>("scene/transfer")),
      transfer_virtual_sub_(node.CreateSubscriber<msgs::TransferBuffer>("scene/transfer_virtual")),
      composite_pub_(node),
      placement_(content_.objects.size()),
      placed_(params.object_pixel.empty()) {
  for (const auto& o : content_.objects) object_meshes_.push_back(&o.mesh.mesh);
}

raytrace::Mesh RendererNode::AddContent() {
  for (size_t i = 0; i < content_.objects.size(); ++i) renderer_.AddObject(content_.objects[i]);
  if (content_.receiver) renderer_.AddReceiver(*content_.receiver);
  return params_.face_differential ? prt::ProxyHead(params_.content_options.head_resolution)
                                   : raytrace::Mesh{};
}

std::optional<render::FrameWriter> RendererNode::ReportReadyAndOpenWriter() {
  node_.Info()
      << "GL " << renderer_.gl_version() << " (" << renderer_.gl_renderer() << "), "
      << content_.objects.size() << " objects" << (content_.receiver ? " + shadow receiver" : "")
      << " ready in "
      << std::chrono::duration<double>(std::chrono::steady_clock::now() - load_start_).count()
      << " s";
  if (params_.video.empty() && params_.png_dir.empty()) return std::nullopt;
  return std::optional<render::FrameWriter>(std::in_place, params_.video, params_.video_fps,
                                            params_.png_dir);
}

int RendererNode::Spin() {
  std::vector<node::Handler> handlers{
      {&image_sub_, [this](bus::Sample&& s) { HoldImage(std::move(s)); }},
      {&info_sub_, [this](bus::Sample&& s) { HoldCameraInfo(std::move(s)); }},
      {&face_sub_, [this](bus::Sample&& s) { HoldFace(std::move(s)); }},
      {&pose_sub_, [this](bus::Sample&& s) { HoldPose(std::move(s)); }},
      {&gbuffer_sub_, [this](bus::Sample&& s) { HoldGeometry(std::move(s)); }},
      {&transfer_sub_, [this](bus::Sample&& s) { HoldTransfer(std::move(s)); }},
      {&transfer_virtual_sub_, [this](bus::Sample&& s) { HoldTransferVirtual(std::move(s)); }},
      // The light comes last: Spin serves ready subscriptions in this order, and a frame's image,
      // head pose, scene pose and G_r are published before the light computed from them, so with
      // trigger=light a frame is drawn with its own inputs even when the node wakes late.
      {&light_sub_, [this](bus::Sample&& s) { HoldLight(std::move(s)); }}};

  // The window back-end idles between frames, so a watcher notices a display that went away
  // (X server killed, ssh -X session closed) instead of the node waiting on it forever.
  std::atomic<bool> display_lost{false};
  std::thread watcher;
  if (params_.renderer_options.backend == render::Backend::kWindow) {
    watcher = std::thread([&] {
      while (node_.ok()) {
        if (renderer_.DisplayLost()) {
          display_lost = true;
          node::RequestShutdown();
          break;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
      }
    });
  }
  node_.Spin(handlers);
  if (watcher.joinable()) watcher.join();
  node_.Info() << "rendered " << frames_ << " frames";
  if (diff_frames_ > 0) {
    node_.Info() << "differential rendering from G_r on " << diff_frames_ << " frames, mean "
                 << diff_ms_sum_ / diff_frames_ << " ms, " << diff_changed_sum_ / diff_frames_
                 << " pixels changed per frame";
  }
  if (display_lost) {
    node_.Error()
        << "window backend: the X display closed the connection; exiting (backend:=offscreen "
           "needs no display)";
    return 1;
  }
  return 0;
}

void RendererNode::HoldImage(bus::Sample&& s) {
  const auto m = msgs::ReadMessage<msgs::Image>(s.data());
  render::ImageToRgb(*m, m.payload, camera_rgb_);
  camera_header_ = m->header;
  width_ = static_cast<int>(m->width);
  height_ = static_cast<int>(m->height);
  if (params_.trigger == "image") RenderFrame();
}

void RendererNode::HoldCameraInfo(bus::Sample&& s) {
  intrinsics_ = render::IntrinsicsFromMsg(*msgs::ReadMessage<msgs::CameraInfo>(s.data()));
}

void RendererNode::HoldFace(bus::Sample&& s) {
  face_ = *msgs::ReadMessage<msgs::FaceObservation>(s.data());
  have_face_ = true;
}

void RendererNode::HoldPose(bus::Sample&& s) {
  camera_to_world_ = render::TransformFromMsg(msgs::ReadMessage<msgs::Pose>(s.data())->transform);
}

void RendererNode::HoldGeometry(bus::Sample&& s) {
  const auto m = msgs::ReadMessage<msgs::GeometryBuffer>(s.data());
  render::GeometryDepth(*m, m.payload, real_depth_);
  if (differential_ || !placed_ || click_placement_) {
    render::GeometryPlanes(*m, m.payload, real_normals_, real_colour_);
  }
}

void RendererNode::HoldTransfer(bus::Sample&& s) {
  const auto m = msgs::ReadMessage<msgs::TransferBuffer>(s.data());
  render::TransferValues(*m, m.payload, transfer_real_);
  transfer_count_ = static_cast<int>(m->coefficient_count);
}

void RendererNode::HoldTransferVirtual(bus::Sample&& s) {
  const auto m = msgs::ReadMessage<msgs::TransferBuffer>(s.data());
  render::TransferValues(*m, m.payload, transfer_virtual_);
}

void RendererNode::HoldLight(bus::Sample&& s) {
  const msgs::ShLight m = *msgs::ReadMessage<msgs::ShLight>(s.data());
  std::string why;
  const bool usable = render::AcceptLightUnits(m.units, &why);
  if (!why.empty() && warned_units_ != m.units) {
    node_.Warn() << why;
    warned_units_ = m.units;
  }
  if (!usable) return;  // keeps the last linear light, if any
  light_msg_ = m;
  light_ = render::LightFromMsg(light_msg_);
  have_light_ = true;
  if (params_.trigger == "light") RenderFrame();
}

void RendererNode::RenderFrame() {
  if (camera_rgb_.empty() || !have_light_) return;
  render::FrameInputs in;
  in.camera = intrinsics_ && intrinsics_->width == width_ && intrinsics_->height == height_
                  ? *intrinsics_
                  : render::DefaultIntrinsics(width_, height_);
  in.camera_rgb = camera_rgb_;
  in.light = light_;
  // The objects' light as its expected value under the direction uncertainty (params.h).
  if (params_.object_uncertainty_blur > 0) {
    light::BlurByUncertainty(std::span(in.light.coefficients)
                                 .first(static_cast<size_t>(in.light.bands * in.light.bands)),
                             light_msg_.confidence, params_.object_uncertainty_blur);
  }
  in.face_valid = have_face_ && face_.face_detected;
  if (in.face_valid) in.face_to_camera = render::TransformFromMsg(face_.head_pose);
  in.camera_to_world = camera_to_world_;
  if (real_depth_.size() == camera_rgb_.size() / 3) in.real_depth = real_depth_;
  const bool have_gbuffer = real_depth_.size() == camera_rgb_.size() / 3 &&
                            real_normals_.size() == 3 * real_depth_.size();
  // Clicks of the frames shown so far (their pixels are the shown frames'; none offscreen).
  if (params_.renderer_options.backend == render::Backend::kWindow) QueueClicks();
  if ((!placed_ || !pending_clicks_.empty()) && have_gbuffer) {
    // An ARKit-style hit test on the reconstruction (render/differential.h): object_pixel once,
    // then each click in order.
    const light::Intrinsics k{in.camera.fx, in.camera.fy, in.camera.cx, in.camera.cy};
    PlaceObjects(light::GeometryView{width_, height_, k, real_depth_, real_normals_, {}},
                 in.camera_to_world);
  }
  ApplyDifferential(have_gbuffer, in);
  if (transfer_count_ > 0 && transfer_real_.size() == transfer_virtual_.size() &&
      transfer_real_.size() == camera_rgb_.size() / 3 * transfer_count_) {
    in.transfer_real = transfer_real_;
    in.transfer_with_virtual = transfer_virtual_;
    in.transfer_count = transfer_count_;
  }
  renderer_.Render(in, composite_);
  composite_pub_.Publish(camera_header_, width_, height_, composite_);
  if (writer_) {
    try {
      writer_->Write(composite_);
    } catch (const render::RenderError& e) {
      throw node::NodeError(e.what());  // the output, not this sample: the node ends
    }
  }
  if (params_.renderer_options.backend == render::Backend::kWindow) Present();
  ++frames_;
  if (params_.max_frames > 0 && frames_ >= params_.max_frames) node::RequestShutdown();
}

void RendererNode::QueueClicks() {
  for (const render::ViewerClick& c : renderer_.TakeClicks()) pending_clicks_.push_back(c);
  if (!click_placement_ && !pending_clicks_.empty()) {
    if (!told_click_mode_) {
      node_.Info() << "viewer click: placing objects by click needs mode scene (face mode's "
                      "objects follow the head)";
      told_click_mode_ = true;
    }
    pending_clicks_.clear();
  }
  // Until G_r arrives keep only the newest few (the queue's bound).
  if (pending_clicks_.size() > render::ClickQueue::kCapacity) {
    pending_clicks_.erase(pending_clicks_.begin(),
                          pending_clicks_.end() - render::ClickQueue::kCapacity);
  }
}

void RendererNode::PlaceObjects(const light::GeometryView& g,
                                const raytrace::Transform& camera_to_world) {
  const std::vector<double>& object_pixel = params_.object_pixel;
  if (!placed_) {
    if (const auto at = PlaceAt(g, object_pixel[0], object_pixel[1], camera_to_world)) {
      node_.Info() << "object_pixel [" << object_pixel[0] << ", " << object_pixel[1]
                   << "]: objects moved by (" << placement_[0].translation[0] << ", "
                   << placement_[0].translation[1] << ", " << placement_[0].translation[2]
                   << ") m, world frame";
    } else if (!warned_hit_) {
      node_.Warn() << "object_pixel: no reconstructed surface at that pixel yet";
      warned_hit_ = true;
    }
  }
  for (const render::ViewerClick& c : pending_clicks_) {
    const int u = static_cast<int>(std::floor(c.u + 0.5));
    const int v = static_cast<int>(std::floor(c.v + 0.5));
    if (u >= width_ || v >= height_) {  // the camera image shrank since that frame was shown
      node_.Warn() << "viewer click at pixel [" << u << ", " << v << "]: outside the current "
                   << width_ << "x" << height_ << " image; the objects stay where they were";
    } else if (const auto at = PlaceAt(g, u, v, camera_to_world)) {
      node_.Info() << "viewer click at pixel [" << u << ", " << v
                   << "]: objects rest on the surface there, centre at (" << at->x << ", " << at->y
                   << ", " << at->z << ") m, world frame";
    } else {
      node_.Warn() << "viewer click at pixel [" << u << ", " << v
                   << "]: no reconstructed surface there; the objects stay where they were";
    }
  }
  pending_clicks_.clear();
}

std::optional<raytrace::Vec3> RendererNode::PlaceAt(const light::GeometryView& g, double u,
                                                    double v, const raytrace::Transform& to_world) {
  const auto hit = render::PlaceOnSurface(g, u, v, to_world, object_meshes_);
  if (!hit) return std::nullopt;
  for (size_t i = 0; i < placement_.size(); ++i) {
    placement_[i] = *hit;
    renderer_.SetObjectPlacement(static_cast<int>(i), *hit);
  }
  placed_ = true;
  return hit->Apply(render::GroupCentre(object_meshes_));
}

void RendererNode::ApplyDifferential(bool have_gbuffer, render::FrameInputs& in) {
  const bool face_differential = params_.face_differential;
  const light::Intrinsics k{in.camera.fx, in.camera.fy, in.camera.cx, in.camera.cy};
  std::optional<light::GeometryView> real_view;
  raytrace::Transform anchor_to_camera;
  if (differential_ && face_differential && in.face_valid) {
    render::RasteriseHead(head_mesh_, in.face_to_camera, k, width_, height_, camera_rgb_,
                          &head_geometry_);
    real_view = head_geometry_.View(k);
    anchor_to_camera = in.face_to_camera;
    in.real_depth = head_geometry_.depth;  // the head hides the objects behind it
  } else if (differential_ && !face_differential && placed_ && have_gbuffer) {
    const std::span<const uint8_t> colour = real_colour_.size() == 3 * real_depth_.size()
                                                ? std::span<const uint8_t>(real_colour_)
                                                : std::span<const uint8_t>();
    real_view = light::GeometryView{width_, height_, k, real_depth_, real_normals_, colour};
    anchor_to_camera = in.camera_to_world.Inverse();
  }
  if (!real_view) {
    if (differential_ && !face_differential && !have_gbuffer && !real_depth_.empty() &&
        !warned_size_) {
      node_.Warn() << "scene/gbuffer is not the camera image's size (or has no normals): no "
                      "shadows from G_r for such frames";
      warned_size_ = true;
    }
    return;
  }
  const light::GeometryView& g = *real_view;
  std::vector<render::RasterObject> raster;
  for (size_t i = 0; i < content_.objects.size(); ++i) {
    const render::VirtualObject& o = content_.objects[i];
    raster.push_back({&o.mesh.mesh, anchor_to_camera * placement_[i] * o.object_to_anchor, o.albedo,
                      o.cull_back_faces});
  }
  render::RasteriseObjects(g, raster, &with_virtual_);
  render::DifferentialFrame df;
  df.real = g;
  df.with_virtual = &with_virtual_;
  df.light = light_;
  df.dominant = render::DominantLightFromMsg(light_msg_);
  df.camera_tone = renderer_.tone_mapping();
  df.camera_rgb = camera_rgb_;
  df.objects = raster;
  differential_->Compute(df, &diff_result_);
  camera_diff_ = camera_rgb_;
  render::ApplyDifferential(diff_result_, width_, height_, camera_diff_);
  in.camera_rgb = camera_diff_;
  if (!diff_result_.virtual_modulation.empty()) {
    const auto& vr = diff_result_.virtual_rect;
    in.virtual_rect = {vr.x0, vr.y0, vr.x1, vr.y1};
    in.virtual_modulation = diff_result_.virtual_modulation;
    in.virtual_indirect = diff_result_.virtual_indirect;
  }
  diff_ms_sum_ += diff_result_.ms_total;
  diff_changed_sum_ += diff_result_.changed_pixels;
  ++diff_frames_;
  node_.Debug() << "differential: window " << diff_result_.window.width() << "x"
                << diff_result_.window.height() << ", " << diff_result_.changed_pixels
                << " pixels changed, smallest factor " << diff_result_.min_factor << ", sun "
                << diff_result_.sun_amplitude[0] << " over " << diff_result_.sun_shadow_pixels
                << " pixels, " << diff_result_.ms_total << " ms";
}

void RendererNode::Present() {
  render::ViewerInputs vin;
  vin.light = &light_;
  vin.face = have_face_ ? &face_ : nullptr;
  vin.tone = renderer_.tone_mapping();
  const auto [ww, wh] = renderer_.WindowSize();
  renderer_.Present(render::MakePanels(viewer_, vin, ww, wh));
  viewer_.ApplyKeys(renderer_.TakeKeys());
  if (viewer_.quit || renderer_.WindowClosed()) node::RequestShutdown();
}

}  // namespace probeless::renderer_node
