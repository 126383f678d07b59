// Private to probeless_light: the inner loop of TransferComputer, the screen-space directional
// occlusion of one pixel's N sample points against the main buffer G_r (Gruber et al. 2015,
// §5.1, eq. 7-8), in a portable reference version and an AVX2/FMA version (8 directions per
// step), chosen at run time (OcclusionKernel, probeless/simd/simd.h).
#pragma once

#include <cstdint>

#include "probeless/light/directions.h"

namespace probeless::light::internal {

// Everything the kernel needs besides the pixel: the depth image (metres, 0 = none), pinhole
// intrinsics, the SSDO radius and range check, the depth bias, chi of eq. 8, and the directions as
// structure-of-arrays padded with zeros to `n_padded` (a multiple of 8 >= the direction count; the
// kernels run over all n_padded, the zero padding gives cosn = 0, k = 1). width * height < 2^31
// (pixel indices are int32 for the gathers).
struct OcclusionParams {
  const float* depth = nullptr;
  int width = 0;
  int height = 0;
  float fx = 0, fy = 0, cx = 0, cy = 0, ifx = 0, ify = 0;
  float radius = 0;    // sample points y_j = x + omega_j * radius * offset_j
  float max_occ2 = 0;  // squared range of an occluder from x (metres^2)
  float bias = 0;      // occluded when depth(s_j) < z(y_j) - (bias + bias_rel * z(y_j))
  float bias_rel = 0;
  float chi = 1;  // eq. 8
  float inv_chi = 1;
  int n_padded = 0;
  const float* dir_x = nullptr;  // n_padded each
  const float* dir_y = nullptr;
  const float* dir_z = nullptr;
};

// Per direction j < n_padded of one pixel: cosn[j] = omega_j . n (eq. 6's cosine); k[j] = the
// continuous visibility K of eq. 8 from the main buffer (1 = unoccluded, also for cosn <= 0);
// occluder[j] = index v * width + u of the pixel that occludes y_j, or -1. Arrays of n_padded.
struct PixelOcclusion {
  alignas(32) float cosn[kMaxDirections];
  alignas(32) float k[kMaxDirections];
  alignas(32) int32_t occluder[kMaxDirections];
};

// The pixel: camera-frame point x (metres), unit normal n, and its row of the 2x2-block offset
// table (n_padded values in [0.1, 1]).
void OcclusionScalar(const OcclusionParams& p, const float* offsets, const float x[3],
                     const float n[3], PixelOcclusion* out);
// Same results as OcclusionScalar up to float rounding (FMA; a sample within rounding of a
// threshold may go either way). Only where simd::Supported() is kAvx2Fma (x86-64 builds).
void OcclusionAvx2(const OcclusionParams& p, const float* offsets, const float x[3],
                   const float n[3], PixelOcclusion* out);

using OcclusionFn = void (*)(const OcclusionParams&, const float*, const float[3], const float[3],
                             PixelOcclusion*);
// OcclusionAvx2 when simd::UseAvx2(), else OcclusionScalar (choose once per loop, not per pixel).
OcclusionFn OcclusionKernel();

}  // namespace probeless::light::internal
