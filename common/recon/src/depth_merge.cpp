#include "probeless/recon/depth_merge.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <utility>
#include <vector>

#include "probeless/simd/simd.h"

#ifdef PROBELESS_SIMD_X86
#include <immintrin.h>
#endif

namespace probeless::recon {

// The kernels twice, chosen at run time by MergeDepth (docs/ARCHITECTURE.md "SIMD kernels"): the
// AVX2 version is the code a global -mavx2 -mfma build made (same values).
// (-Wpsabi: the portable version passes 8-float vectors between its own functions in memory.)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpsabi"
namespace portable {
#include "depth_merge_kernels.inc"
}  // namespace portable
#pragma GCC diagnostic pop
#ifdef PROBELESS_SIMD_X86
#pragma GCC push_options
#pragma GCC target("avx2,fma")
namespace avx2 {
#include "depth_merge_kernels.inc"
}  // namespace avx2
#pragma GCC pop_options
#endif

void MergeOptions::Validate() const {
  if (merge_k < 1 || smooth_k < 1 || denoise_k < 1) {
    throw ReconError("merge: window sizes k must be >= 1");
  }
  if (!(merge_lambda_i >= 0) || !(smooth_lambda_i >= 0) || !(lambda_d_m >= 0) ||
      !(lambda_d_sigmas >= 0)) {
    throw ReconError("merge: thresholds must be >= 0");
  }
  if (!(noise_a_m >= 0) || !(noise_b_per_m >= 0) || !std::isfinite(noise_z0_m) ||
      !(noise_quantisation_per_m >= 0) || !(noise_a_m + noise_quantisation_per_m > 0)) {
    throw ReconError(
        "merge: noise model needs noise_a_m, noise_b_per_m, noise_quantisation_per_m >= 0 and "
        "noise_a_m or noise_quantisation_per_m > 0");
  }
}

float DepthNoiseSigma(float z, const MergeOptions& options) {
  const float dz = z - options.noise_z0_m;
  const float axial = options.noise_a_m + options.noise_b_per_m * dz * dz;  // Nguyen et al. 2012
  if (!(options.noise_quantisation_per_m > 0)) return axial;
  const float step = options.noise_quantisation_per_m * z * z;
  return std::sqrt(axial * axial + step * step * (1.0f / 12.0f));
}

float AgreementThreshold(float z, const MergeOptions& options) {
  if (!(options.lambda_d_sigmas > 0) || !(z > 0)) return options.lambda_d_m;
  return std::min(options.lambda_d_m, options.lambda_d_sigmas * DepthNoiseSigma(z, options));
}

void GreyFromRgb(const uint8_t* rgb, int width, int height, size_t stride, GreyImage& out) {
  out.Resize(width, height);
  for (int y = 0; y < height; ++y) {
    const uint8_t* row = rgb + y * stride;
    for (int x = 0; x < width; ++x) {
      out.At(x, y) =
          static_cast<uint8_t>((77 * row[3 * x] + 150 * row[3 * x + 1] + 29 * row[3 * x + 2]) >> 8);
    }
  }
}

void MergeDepth(const DepthImage& raw, const DepthImage& volume, const GreyImage& intensity,
                const MergeOptions& options, MergedDepth& out, ThreadPool* pool) {
  options.Validate();
  if (raw.Empty()) throw ReconError("merge: empty raw depth");
  if (volume.width != raw.width || volume.height != raw.height || intensity.width != raw.width ||
      intensity.height != raw.height) {
    throw ReconError("merge: raw depth " + std::to_string(raw.width) + "x" +
                     std::to_string(raw.height) + ", volume depth " + std::to_string(volume.width) +
                     "x" + std::to_string(volume.height) + " and intensity " +
                     std::to_string(intensity.width) + "x" + std::to_string(intensity.height) +
                     " must have the same size");
  }
#ifdef PROBELESS_SIMD_X86
  if (simd::UseAvx2()) {
    avx2::MergeDepthKernel(raw, volume, intensity, options, out, pool);
    return;
  }
#endif
  portable::MergeDepthKernel(raw, volume, intensity, options, out, pool);
}

}  // namespace probeless::recon
