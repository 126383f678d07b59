// The live viewer: the composite in a GLFW window plus switchable inset panels (the estimated
// light as a shaded sphere and as a lat-long map, the face samples, the geometry buffer, the head
// pose). Panels are drawn on the CPU (testable without GL) and shown by Renderer::Present.
//
// Keys: L light sphere, M lat-long map, F face samples, G geometry buffer, P pose, H all off/on,
// Escape or Q closes. Mouse: left clicks on the composite come from Renderer::TakeClicks in image
// pixels (viewer_click.h); the renderer node places the objects there (scene mode).
#pragma once

#include <span>
#include <vector>

#include "probeless/msgs/face_observation.h"
#include "probeless/render/renderer.h"

namespace probeless::render {

struct ViewerState {
  bool light_sphere = true;
  bool latlong = true;
  bool face_samples = false;
  bool geometry = false;
  bool pose = false;
  bool quit = false;
  // Applies GLFW key codes (letters 'A'..'Z', Escape 256) as described above.
  void ApplyKeys(const std::vector<int>& keys);
};

// What the panels show; null / empty = that panel shows a blank "no data" image.
struct ViewerInputs {
  const ShLightRgb* light = nullptr;            // camera frame
  const msgs::FaceObservation* face = nullptr;  // samples and head pose
  int geometry_width = 0;                       // geometry buffer (msgs::GeometryBuffer)
  int geometry_height = 0;
  std::span<const float> geometry_depth;    // metres, 0 = none
  std::span<const float> geometry_normals;  // 3 per pixel, camera frame
  ToneMapping tone;
};

// The light seen on a white Lambertian sphere (unshadowed, albedo 1) from the camera: size x size.
Panel LightSpherePanel(const ShLightRgb& light, const ToneMapping& tone, int size);
// The incident radiance as a lat-long map (sh::LatLongDirection convention), width x width/2.
Panel LatLongPanel(const ShLightRgb& light, const ToneMapping& tone, int width);
// The valid face samples at the screen position of their normal, in their observed colour.
Panel FaceSamplesPanel(const msgs::FaceObservation& face, int size);
// Geometry buffer normals ((n + 1) / 2 as colour; black where depth is 0), scaled to width.
Panel GeometryPanel(int width, int height, std::span<const float> depth,
                    std::span<const float> normals, int panel_width);
// The head pose as the face frame's axes (x red, y green, z blue) seen from the camera.
Panel PosePanel(const msgs::FaceObservation& face, int size);

// The enabled panels laid out along the right edge of a window of window_width x window_height.
std::vector<Panel> MakePanels(const ViewerState& state, const ViewerInputs& inputs,
                              int window_width, int window_height);

}  // namespace probeless::render
