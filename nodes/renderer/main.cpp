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
// with the light blurred by its confidence's expected error, light::BlurByUncertainty). Read in
// params.cpp.
//
// A thin node: params (params.cpp) -> renderer_node::RendererNode (renderer_node.h: the state
// between frames and the handlers) over render::Renderer and render::DifferentialRenderer; the
// message conversions are render/msgs_io.h's.
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
#include <cstdio>
#include <exception>

#include "params.h"
#include "probeless/node/node.h"
#include "renderer_node.h"

namespace {

using namespace probeless;

int Run(int argc, char** argv) {
  node::Node node(argc, argv, "renderer");
  const renderer_node::RendererParams params = renderer_node::ReadParams(node);
  renderer_node::RendererNode renderer(node, params);
  return renderer.Spin();
}

}  // namespace

// Every exception is exit code 2 (bad params or content), unlike node::RunMain's 1 for non-input
// errors.
int main(int argc, char** argv) {
  try {
    return Run(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "[error] [renderer] %s\n", e.what());
    return 2;
  }
}
