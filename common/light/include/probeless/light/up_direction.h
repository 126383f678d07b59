// The up direction (against gravity) in the camera frame from the geometry alone (beyond the
// paper): hand-held cameras are held roughly upright and rooms are built of horizontal floors,
// tables and shelves, so the densest cluster of surface normals near the image's up (-y) is the
// up direction. The light prior (LightPrior) is set about it.
#pragma once

#include "probeless/light/directions.h"
#include "probeless/light/transfer.h"

namespace probeless::light {

struct UpDirectionOptions {
  int stride = 4;             // every stride-th pixel in x and y (>= 1)
  float search_deg = 60;      // normals within this angle of the image's up (-y) are candidates
  float kernel_deg = 12;      // final mean-shift window (a floor's normals spread a few degrees)
  float min_support = 0.03f;  // fraction of the sampled valid pixels the cluster needs
};

struct UpDirection {
  bool valid = false;  // false: no horizontal surface in view (the result is the image's up)
  Vec3f up{0, -1, 0};  // unit, camera frame (x right, y down, z forward)
  float support = 0;   // fraction of the sampled valid pixels within kernel_deg of `up`
};

// Mean shift on the unit normals of `geometry` from the image's up, with a window narrowing from
// search_deg to kernel_deg. Throws LightError for options out of range or a geometry whose sizes
// do not match (as ValidateGeometryView).
UpDirection EstimateUpDirection(const GeometryView& geometry,
                                const UpDirectionOptions& options = {});

}  // namespace probeless::light
