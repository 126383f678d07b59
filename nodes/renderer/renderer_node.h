// The renderer's state between frames and its handlers: the content and the GL renderer, the latest
// camera image, calibration, light, head and camera pose, G_r and transfer buffers, the objects'
// placement (object_pixel, viewer clicks), the outputs and the counters of the summary lines at
// exit. main.cpp reads the params, constructs it and spins it.
#pragma once

#include <chrono>
#include <cstdint>
#include <optional>
#include <vector>

#include "outputs.h"
#include "params.h"
#include "probeless/bus/bus.h"
#include "probeless/light/transfer.h"
#include "probeless/msgs/msgs.h"
#include "probeless/node/node.h"
#include "probeless/render/content.h"
#include "probeless/render/differential.h"
#include "probeless/render/output.h"
#include "probeless/render/renderer.h"
#include "probeless/render/viewer.h"
#include "probeless/render/viewer_click.h"

namespace probeless::renderer_node {

class RendererNode {
 public:
  // Loads the content (render::LoadContent), creates the GL renderer and, with
  // params.gbuffer_differential, the differential renderer (RenderError for bad options), uploads
  // the objects and the receiver, logs the "GL ... ready in ... s" line, opens the video / PNG
  // writer, then subscribes, in this order, camera/image, camera/camera_info, light,
  // face/observation, scene/pose, scene/gbuffer, scene/transfer, scene/transfer_virtual and
  // creates render/composite. `params` come from ReadParams (checked there).
  RendererNode(node::Node& node, const RendererParams& params);
  RendererNode(const RendererNode&) = delete;  // the handlers hold `this`
  RendererNode& operator=(const RendererNode&) = delete;

  // node::Node::Spin over the handlers (the light last) until shutdown or max_frames, with the
  // window back-end a watcher of the X display; then the summary lines (info). Returns the exit
  // code: 0, or 1 when the window back-end's display went away (one error line).
  int Spin();

 private:
  // Handlers (a bad sample throws msgs::MessageError or render::RenderError, rejected by Spin).
  void HoldImage(bus::Sample&& s);  // renders a frame with trigger image
  void HoldCameraInfo(bus::Sample&& s);
  void HoldFace(bus::Sample&& s);
  void HoldPose(bus::Sample&& s);
  void HoldGeometry(bus::Sample&& s);
  void HoldTransfer(bus::Sample&& s);
  void HoldTransferVirtual(bus::Sample&& s);
  void HoldLight(bus::Sample&& s);  // renders a frame with trigger light
  // One composite from the latest inputs (none before an image and a light): published, written,
  // shown; counts the frame and requests shutdown at max_frames.
  void RenderFrame();
  // The window's clicks since the last frame into pending_clicks_ (face mode: dropped, one info
  // line the first time; at most render::ClickQueue::kCapacity, the newest).
  void QueueClicks();
  // object_pixel (once) and then each pending click in order, as a hit test on G_r `g`.
  void PlaceObjects(const light::GeometryView& g, const raytrace::Transform& camera_to_world);
  // The ARKit-style hit test shared by object_pixel and clicks (render::PlaceOnSurface): all
  // objects rest on the surface seen at (u, v); returns the group's new centre (world frame), or
  // nullopt when there is no surface there (the objects stay).
  std::optional<raytrace::Vec3> PlaceAt(const light::GeometryView& g, double u, double v,
                                        const raytrace::Transform& to_world);
  // Gruber §5.4 on `in`: G_r' -> R_d, R'_d (R_i, R'_i) -> eq. 13-15 from the reconstruction (scene
  // mode, once placed) or the head at its pose (face mode); without a usable G_r one warning.
  void ApplyDifferential(bool have_gbuffer, render::FrameInputs& in);
  // The viewer panels and keys (window back-end); a quit key or a closed window ends the node.
  void Present();

  node::Node& node_;
  const RendererParams params_;
  // Scene mode with the window back-end: a click places the objects.
  const bool click_placement_;
  // Declared in their construction order (the constructor's contract).
  const std::chrono::steady_clock::time_point load_start_;
  const render::Content content_;
  render::Renderer renderer_;
  std::optional<render::DifferentialRenderer> differential_;
  const raytrace::Mesh
      head_mesh_;  // face mode's G_r: the proxy head the objects were baked against
  std::optional<render::FrameWriter> writer_;
  bus::Subscriber image_sub_;
  bus::Subscriber info_sub_;
  bus::Subscriber light_sub_;
  bus::Subscriber face_sub_;
  bus::Subscriber pose_sub_;
  bus::Subscriber gbuffer_sub_;
  bus::Subscriber transfer_sub_;
  bus::Subscriber transfer_virtual_sub_;
  CompositePublisher composite_pub_;

  // Uploads the objects and the receiver; returns head_mesh_'s value (empty but in face mode with
  // the G_r differential).
  raytrace::Mesh AddContent();
  // Logs the ready line; returns writer_'s value (none without video and png_dir).
  std::optional<render::FrameWriter> ReportReadyAndOpenWriter();

  // Latest state.
  std::vector<uint8_t> camera_rgb_;
  msgs::Header camera_header_;
  int width_ = 0, height_ = 0;
  std::optional<render::Intrinsics> intrinsics_;
  render::ShLightRgb light_;
  bool have_light_ = false;
  msgs::FaceObservation face_;
  bool have_face_ = false;
  raytrace::Transform camera_to_world_;
  std::vector<float> real_depth_, real_normals_, transfer_real_, transfer_virtual_;
  std::vector<uint8_t> real_colour_, camera_diff_;
  msgs::ShLight light_msg_;
  int transfer_count_ = 0;
  // The objects' placement (object_pixel moves them once, at the first frame with G_r; in scene
  // mode each click in the viewer window moves them again).
  std::vector<raytrace::Transform> placement_;
  bool placed_;
  std::vector<render::ViewerClick> pending_clicks_;  // taken from the window, waiting for G_r
  bool told_click_mode_ = false;
  std::vector<const raytrace::Mesh*> object_meshes_;
  // Scratch of the differential, kept between frames.
  render::VirtualGeometry with_virtual_, head_geometry_;
  render::DifferentialResult diff_result_;
  render::Composite composite_;
  render::ViewerState viewer_;
  // Counters and once-only warnings.
  double diff_ms_sum_ = 0, diff_changed_sum_ = 0;
  int64_t diff_frames_ = 0;
  bool warned_size_ = false, warned_hit_ = false;
  std::optional<msgs::ShLightUnits> warned_units_;  // one warning per change of units
  int64_t frames_ = 0;
};

}  // namespace probeless::renderer_node
