// Test and evaluation inputs of probeless_light from the simulator (target probeless_light_sim,
// depends on probeless_sim / probeless_raytrace): the G-buffer of a SimFrame with or without
// sensor effects, and the auxiliary orthographic views traced from the scene, filled exactly as
// the OrthographicView contract in transfer.h says (recon fills the same struct later).
#pragma once

#include <vector>

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
  std::vector<float> depth;     // metres
  std::vector<float> normals;   // camera frame
  std::vector<uint8_t> colour;  // sRGB
  std::vector<float> grey;      // linear grey intensity of the image (the estimator's I_c)
  GeometryView View() const { return {width, height, intrinsics, depth, normals, colour}; }
};

// sensor_effects = false: the noise-free render (exact depth, rendered normals, noiseless colour,
// linear grey clamped to [0, 1]); true: the sensor's depth16 (quantised, noisy, holes) with normals
// from SmoothDepth (radius width / 80) + NormalsFromDepth (step = width / 160 pixels, at least 2)
// and the noisy rgb8 image.
GeometryStorage GeometryFromSimFrame(const sim::SimFrame& frame, bool sensor_effects);

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
  Vec3f light_direction{0, -1, 0};
};

// Traces the auxiliary views of the committed `scene` for `camera` (orthographic, see
// OrthographicView): left and right look along the camera's +x / -x, top along world -y (down),
// the light view along -light_direction. Each view_to_camera is exact.
AuxiliaryStorage RenderAuxiliaryViews(const raytrace::Scene& scene, const raytrace::Camera& camera,
                                      const AuxiliaryViewOptions& options,
                                      raytrace::ThreadPool* pool = nullptr);

}  // namespace probeless::light
