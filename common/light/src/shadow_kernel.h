// Private to probeless_light: the screen-space shadow ray of the cast-shadow search (shadow.cpp,
// docs/light.md "Cast shadows"), in a portable reference version and an AVX2/FMA version (8 points
// per call), chosen at run time (probeless/simd/simd.h).
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

// The same for 8 points (x, y, z of each), results in out[8]; a point with z <= 0 gives 1.
// ShadowRay8Scalar: ShadowRayScalar per point. ShadowRay8Avx2: up to float rounding identical
// (FMA; a sample within rounding of a pixel border or the bias may go either way), only where
// simd::Supported() is kAvx2Fma (x86-64 builds). ShadowRay8: the one ShadowRay8Kernel() picks.
void ShadowRay8Scalar(const ShadowRayParams& r, const float* px, const float* py, const float* pz,
                      const std::array<float, 3>& l, float out[8]);
void ShadowRay8Avx2(const ShadowRayParams& r, const float* px, const float* py, const float* pz,
                    const std::array<float, 3>& l, float out[8]);
void ShadowRay8(const ShadowRayParams& r, const float* px, const float* py, const float* pz,
                const std::array<float, 3>& l, float out[8]);

using ShadowRay8Fn = void (*)(const ShadowRayParams&, const float*, const float*, const float*,
                              const std::array<float, 3>&, float*);
// ShadowRay8Avx2 when simd::UseAvx2(), else ShadowRay8Scalar (choose once per loop).
ShadowRay8Fn ShadowRay8Kernel();

}  // namespace probeless::light::internal
