// Software depth-to-colour registration: reprojects a depth image (millimetres, depth camera's
// optical frame) into the colour camera's image, for devices without hardware registration.
#pragma once

#include <array>
#include <cstdint>

#include "probeless/capture/intrinsics.h"

namespace probeless::capture {

// Rigid transform from the depth camera's optical frame to the colour camera's (p_colour =
// rotation * p_depth + translation_m); rotation row-major, translation in metres.
struct DepthToColour {
  std::array<double, 9> rotation = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  std::array<double, 3> translation_m = {0, 0, 0};
};

// For every valid depth pixel (mm > 0) of `depth` (depth_k.width x depth_k.height, `depth_step`
// bytes per row) back-projects with depth_k, transforms with `extrinsics`, projects with colour_k
// (distortion ignored) and writes the z in mm of the nearest surface into `out` (colour_k.width x
// colour_k.height, `out_step` bytes per row; 0 where nothing lands). Each source pixel fills the
// target pixels its footprint covers (up to 2x2) so upsampling leaves no holes.
void RegisterDepthToColour(const uint16_t* depth, uint32_t depth_step, const Intrinsics& depth_k,
                           const Intrinsics& colour_k, const DepthToColour& extrinsics,
                           uint16_t* out, uint32_t out_step);

}  // namespace probeless::capture
