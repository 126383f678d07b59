// Private to probeless_light: the screen-space shadow ray of the cast-shadow search (shadow.cpp,
// docs/light.md "Cast shadows"), in a scalar reference version and an AVX2 version (8 points per
// call).
#pragma once

#include <array>

namespace probeless::light::internal {

// The depth image (metres, 0 = none) with pinhole intrinsics, the march (ray lengths `steps`,
// metres, increasing, and the occluder thickness assumed at each), the depth bias and whether a
// ray that passed behind a surface by more than its thickness without a hit is unknown.
// width * height < 2^31 (pixel indices are int32 for the gathers).
struct ShadowRayParams {
  const float* depth = nullptr;
  int width = 0;
  int height = 0;
  float fx = 0, fy = 0, cx = 0, cy = 0;
  const float* steps = nullptr;
  const float* thickness = nullptr;
  int step_count = 0;
  float bias = 0;      // occluded when z(sample) - depth > bias + bias_rel * z(sample) ...
  float bias_rel = 0;  // ... and less than thickness[k] (else "behind")
  bool unknown_behind = true;
};

// 1 if camera-frame point p (metres) sees the light along unit l, 0 if a surface occludes it, -1
// if unknown (unknown_behind and the ray passed behind a surface without a hit). The ray ends
// where it leaves the image or comes within 5 cm of the camera plane.
float ShadowRayScalar(const ShadowRayParams& r, float px, float py, float pz,
                      const std::array<float, 3>& l);

// The same for 8 points (x, y, z of each), results in out[8]; up to float rounding identical to
// ShadowRayScalar (falls back to it without AVX2). A point with z <= 0 gives 1.
void ShadowRay8(const ShadowRayParams& r, const float* px, const float* py, const float* pz,
                const std::array<float, 3>& l, float out[8]);

}  // namespace probeless::light::internal
