// Test and evaluation inputs of probeless_light from the simulator (target probeless_light_sim,
// depends on probeless_sim / probeless_raytrace): the G-buffer of a SimFrame with or without
// sensor effects, and the auxiliary orthographic views traced from the scene, filled exactly as
// the OrthographicView contract in transfer.h says (recon fills the same struct later).
#pragma once

#include <vector>

#include "probeless/light/reliability.h"
#include "probeless/light/transfer.h"
#include "probeless/raytrace/render.h"
#include "probeless/raytrace/scene.h"
#include "probeless/sim/simulator.h"

namespace probeless::light {

// Owns the planes a GeometryView borrows.
struct GeometryStorage {
  int width = 0;
  int height = 0;
  Intrinsics intrinsics;
  std::vector<float> depth;        // metres
  std::vector<float> normals;      // camera frame
  std::vector<uint8_t> colour;     // sRGB
  std::vector<float> grey;         // linear grey intensity of the image (the estimator's I_c)
  std::vector<float> reliability;  // optional per-pixel normal reliability (NormalReliability)
  GeometryView View() const { return {width, height, intrinsics, depth, normals, colour}; }
};

// sensor_effects = false: the noise-free render (exact depth, rendered normals, noiseless colour,
// linear grey clamped to [0, 1]); true: the sensor's depth16 (quantised, noisy, holes) with normals
// and their reliability as the node's depth mode computes them (DepthGeometry with
// `depth_options`) and the noisy rgb8 image; `measured_noise` (optional) gets DepthGeometry's
// measured noise k.
GeometryStorage GeometryFromSimFrame(const sim::SimFrame& frame, bool sensor_effects,
                                     const DepthGeometryOptions& depth_options = {},
                                     float* measured_noise = nullptr);

// Owns the depth planes of auxiliary views.
struct AuxiliaryStorage {
  std::vector<std::vector<float>> depth;
  AuxiliaryBuffers buffers;  // views borrow `depth`
};

struct AuxiliaryViewOptions {
  int resolution = 128;         // pixels per side
  float extent_m = 4.0f;        // side length covered, metres
  float centre_distance_m = 2;  // the views look at camera position + forward * this
  float standoff_m = 1.2f;      // view origin plane: centre - view direction * this (near plane)
  bool left_right_top = true;   // the paper's three views
  bool light_view = false;      // plus one looking along -light_direction (camera frame)
  // false: the top view looks along world -y (down); true: along the camera's +y (downwards in
  // the image), the convention of recon::TsdfVolume::AuxiliaryViewsFor and msgs::AuxiliaryViews,
  // which know no gravity (they differ when the camera is pitched or rolled).
  bool top_along_camera_y = false;
  Vec3f light_direction{0, -1, 0};
};

// Traces the auxiliary views of the committed `scene` for `camera` (orthographic, see
// OrthographicView): left and right look along the camera's +x / -x, top along world -y (down;
// or the camera's +y with top_along_camera_y),
// the light view along -light_direction. Each view_to_camera is exact.
AuxiliaryStorage RenderAuxiliaryViews(const raytrace::Scene& scene, const raytrace::Camera& camera,
                                      const AuxiliaryViewOptions& options,
                                      raytrace::ThreadPool* pool = nullptr);

// The reference for a distant-light estimator in a scene lit by near (point) lights: the light
// averaged over the surface points the camera sees, in the camera frame. Gruber et al. 2015 fit
// one distant light to the visible surfaces (§5.2) and measure it against a light probe at the
// centre of the scene (§6), not at the camera; a lamp inside a room is seen from different
// directions by different surfaces, so the only direction an image of them determines is the
// lamp's direction as seen from those surfaces. Visible points = every `stride`-th pixel of the
// frame's noise-free depth; per point the incident light is raytrace::LightingAt's (unshadowed).
// sh = the mean of the per-point SH (environment + lights); the dominant light is the enabled
// light of largest mean irradiance over the points, its direction the normalised mean of
// irradiance x unit direction (exactly the light direction for a directional light). Falls back
// to LightingAt at the camera if no pixel has depth. Throws LightError if stride < 1.
raytrace::LightingGroundTruth SurfaceLightingTruth(const raytrace::Scene& scene,
                                                   const sim::SimFrame& frame, int stride = 8);

}  // namespace probeless::light
