// Private to probeless_raytrace: the zeroed output images of a Frame, shared by Render and
// PathTrace so both fill the same layout.
#pragma once

#include <cstddef>
#include <vector>

#include "probeless/raytrace/render.h"
#include "probeless/raytrace/scene.h"

namespace probeless::raytrace::internal {

// A width x height Frame with every image allocated and zero (background, no hit).
inline Frame EmptyFrame(int width, int height) {
  Frame frame;
  frame.width = width;
  frame.height = height;
  const size_t pixels = static_cast<size_t>(width) * height;
  frame.linear_rgb.assign(pixels * 3, 0);
  frame.srgb.assign(pixels * 3, 0);
  frame.depth_m.assign(pixels, 0);
  frame.depth_mm.assign(pixels, 0);
  frame.normals.assign(pixels * 3, 0);
  frame.object_ids.assign(pixels, 0);
  frame.albedo.assign(pixels * 3, 0);
  return frame;
}

// The rays through the pixel centres of rows [y0, y1) of `camera` into `out` (row-major, resized),
// from `eye` (the camera position, world) with unnormalised directions of optical-axis z = 1, so
// a hit's t is its depth.
inline void PixelCentreRays(const Camera& camera, Vec3 eye, int y0, int y1, std::vector<Ray>& out) {
  const Mat3& rot = camera.camera_to_world.rotation;
  out.resize(static_cast<size_t>(y1 - y0) * camera.width);
  for (int y = y0; y < y1; ++y) {
    for (int x = 0; x < camera.width; ++x) {
      const Vec3 d_cam{static_cast<float>((x - camera.cx) / camera.fx),
                       static_cast<float>((y - camera.cy) / camera.fy), 1.0f};
      out[static_cast<size_t>(y - y0) * camera.width + x] = Ray{eye, rot * d_cam, 0, 1e30f};
    }
  }
}

}  // namespace probeless::raytrace::internal
