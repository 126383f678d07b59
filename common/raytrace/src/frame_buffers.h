// Private to probeless_raytrace: the zeroed output images of a Frame, shared by Render and
// PathTrace so both fill the same layout.
#pragma once

#include <cstddef>

#include "probeless/raytrace/render.h"

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
  return frame;
}

}  // namespace probeless::raytrace::internal
