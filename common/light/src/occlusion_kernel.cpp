#include "occlusion_kernel.h"

#include <algorithm>
#include <cmath>

#include "probeless/simd/simd.h"

#ifdef PROBELESS_SIMD_X86
#include <immintrin.h>
#endif

namespace probeless::light::internal {

void OcclusionScalar(const OcclusionParams& p, const float* offsets, const float x[3],
                     const float n[3], PixelOcclusion* out) {
  for (int j = 0; j < p.n_padded; ++j) {
    out->k[j] = 1;
    out->occluder[j] = -1;
    const float ox = p.dir_x[j], oy = p.dir_y[j], oz = p.dir_z[j];
    const float cosn = ox * n[0] + oy * n[1] + oz * n[2];  // (omega_j . n(x)), eq. 6
    out->cosn[j] = cosn;
    if (!(cosn > 0)) continue;
    const float len = p.radius * offsets[j];
    const float y0 = x[0] + ox * len, y1 = x[1] + oy * len, y2 = x[2] + oz * len;
    if (!(y2 > 1e-3f)) continue;
    // Project y_j, look up s_j; occluded if s_j is closer than y_j (§5.1).
    const float inv_z = 1.0f / y2;
    const float pu = p.fx * y0 * inv_z + p.cx, pv = p.fy * y1 * inv_z + p.cy;
    if (!(pu > -0.5f && pv > -0.5f && pu < p.width - 0.5f && pv < p.height - 0.5f)) continue;
    const int iu = static_cast<int>(pu + 0.5f), iv = static_cast<int>(pv + 0.5f);
    const int32_t q = iv * p.width + iu;
    const float ds = p.depth[q];
    if (!(ds > 0 && ds < y2 - (p.bias + p.bias_rel * y2))) continue;
    const float s0 = ds * (iu - p.cx) * p.ifx - x[0], s1 = ds * (iv - p.cy) * p.ify - x[1],
                s2 = ds - x[2];
    const float dist2 = s0 * s0 + s1 * s1 + s2 * s2;
    if (!(dist2 <= p.max_occ2 && dist2 > 1e-12f)) continue;
    // eq. 7: the angle between omega_j and the direction to s_j; eq. 8: K = min(chi, 1 - cos)/chi.
    const float cos_a = (s0 * ox + s1 * oy + s2 * oz) / std::sqrt(dist2);
    out->k[j] = std::min(p.chi, 1.0f - cos_a) * p.inv_chi;
    out->occluder[j] = q;
  }
}

OcclusionFn OcclusionKernel() {
#ifdef PROBELESS_SIMD_X86
  if (simd::UseAvx2()) return OcclusionAvx2;
#endif
  return OcclusionScalar;
}

#ifdef PROBELESS_SIMD_X86
PROBELESS_SIMD_AVX2 void OcclusionAvx2(const OcclusionParams& p, const float* offsets,
                                       const float x[3], const float n[3], PixelOcclusion* out) {
  const __m256 x0 = _mm256_set1_ps(x[0]), x1 = _mm256_set1_ps(x[1]), x2 = _mm256_set1_ps(x[2]);
  const __m256 nx = _mm256_set1_ps(n[0]), ny = _mm256_set1_ps(n[1]), nz = _mm256_set1_ps(n[2]);
  const __m256 zero = _mm256_setzero_ps(), one = _mm256_set1_ps(1.0f);
  const __m256 radius = _mm256_set1_ps(p.radius), min_z = _mm256_set1_ps(1e-3f);
  const __m256 fx = _mm256_set1_ps(p.fx), fy = _mm256_set1_ps(p.fy);
  const __m256 cx = _mm256_set1_ps(p.cx), cy = _mm256_set1_ps(p.cy);
  const __m256 ifx = _mm256_set1_ps(p.ifx), ify = _mm256_set1_ps(p.ify);
  const __m256 lo = _mm256_set1_ps(-0.5f), half = _mm256_set1_ps(0.5f);
  const __m256 hi_u = _mm256_set1_ps(p.width - 0.5f), hi_v = _mm256_set1_ps(p.height - 0.5f);
  const __m256 bias = _mm256_set1_ps(p.bias), bias_rel = _mm256_set1_ps(p.bias_rel);
  const __m256 max_occ2 = _mm256_set1_ps(p.max_occ2), min_d2 = _mm256_set1_ps(1e-12f);
  const __m256 chi = _mm256_set1_ps(p.chi), inv_chi = _mm256_set1_ps(p.inv_chi);
  const __m256i width = _mm256_set1_epi32(p.width), none = _mm256_set1_epi32(-1);
  for (int j = 0; j < p.n_padded; j += 8) {
    const __m256 ox = _mm256_loadu_ps(p.dir_x + j), oy = _mm256_loadu_ps(p.dir_y + j),
                 oz = _mm256_loadu_ps(p.dir_z + j);
    const __m256 cosn = _mm256_fmadd_ps(ox, nx, _mm256_fmadd_ps(oy, ny, _mm256_mul_ps(oz, nz)));
    _mm256_store_ps(out->cosn + j, cosn);
    const __m256 len = _mm256_mul_ps(radius, _mm256_loadu_ps(offsets + j));
    const __m256 y0 = _mm256_fmadd_ps(ox, len, x0), y1 = _mm256_fmadd_ps(oy, len, x1),
                 y2 = _mm256_fmadd_ps(oz, len, x2);
    const __m256 inv_z = _mm256_div_ps(one, y2);
    const __m256 pu = _mm256_fmadd_ps(_mm256_mul_ps(fx, y0), inv_z, cx);
    const __m256 pv = _mm256_fmadd_ps(_mm256_mul_ps(fy, y1), inv_z, cy);
    __m256 m =
        _mm256_and_ps(_mm256_cmp_ps(cosn, zero, _CMP_GT_OQ), _mm256_cmp_ps(y2, min_z, _CMP_GT_OQ));
    m = _mm256_and_ps(
        m, _mm256_and_ps(_mm256_cmp_ps(pu, lo, _CMP_GT_OQ), _mm256_cmp_ps(pv, lo, _CMP_GT_OQ)));
    m = _mm256_and_ps(
        m, _mm256_and_ps(_mm256_cmp_ps(pu, hi_u, _CMP_LT_OQ), _mm256_cmp_ps(pv, hi_v, _CMP_LT_OQ)));
    if (_mm256_movemask_ps(m) == 0) {
      _mm256_store_ps(out->k + j, one);
      _mm256_store_si256(reinterpret_cast<__m256i*>(out->occluder + j), none);
      continue;
    }
    // Lanes outside the image are masked out of the gather (nothing is read for them).
    const __m256i iu = _mm256_cvttps_epi32(_mm256_add_ps(pu, half));
    const __m256i iv = _mm256_cvttps_epi32(_mm256_add_ps(pv, half));
    const __m256i q = _mm256_add_epi32(_mm256_mullo_epi32(iv, width), iu);
    const __m256 ds = _mm256_mask_i32gather_ps(zero, p.depth, q, m, 4);
    const __m256 limit = _mm256_sub_ps(y2, _mm256_fmadd_ps(bias_rel, y2, bias));
    __m256 occ = _mm256_and_ps(m, _mm256_and_ps(_mm256_cmp_ps(ds, zero, _CMP_GT_OQ),
                                                _mm256_cmp_ps(ds, limit, _CMP_LT_OQ)));
    if (_mm256_movemask_ps(occ) == 0) {
      _mm256_store_ps(out->k + j, one);
      _mm256_store_si256(reinterpret_cast<__m256i*>(out->occluder + j), none);
      continue;
    }
    const __m256 fu = _mm256_sub_ps(_mm256_cvtepi32_ps(iu), cx);
    const __m256 fv = _mm256_sub_ps(_mm256_cvtepi32_ps(iv), cy);
    const __m256 s0 = _mm256_fmsub_ps(_mm256_mul_ps(ds, fu), ifx, x0);
    const __m256 s1 = _mm256_fmsub_ps(_mm256_mul_ps(ds, fv), ify, x1);
    const __m256 s2 = _mm256_sub_ps(ds, x2);
    const __m256 dist2 = _mm256_fmadd_ps(s0, s0, _mm256_fmadd_ps(s1, s1, _mm256_mul_ps(s2, s2)));
    occ = _mm256_and_ps(occ, _mm256_and_ps(_mm256_cmp_ps(dist2, max_occ2, _CMP_LE_OQ),
                                           _mm256_cmp_ps(dist2, min_d2, _CMP_GT_OQ)));
    // eq. 7-8 as in OcclusionScalar.
    const __m256 dot = _mm256_fmadd_ps(s0, ox, _mm256_fmadd_ps(s1, oy, _mm256_mul_ps(s2, oz)));
    const __m256 cos_a = _mm256_div_ps(dot, _mm256_sqrt_ps(dist2));
    const __m256 k = _mm256_mul_ps(_mm256_min_ps(chi, _mm256_sub_ps(one, cos_a)), inv_chi);
    _mm256_store_ps(out->k + j, _mm256_blendv_ps(one, k, occ));
    _mm256_store_si256(reinterpret_cast<__m256i*>(out->occluder + j),
                       _mm256_blendv_epi8(none, q, _mm256_castps_si256(occ)));
  }
}
#endif

}  // namespace probeless::light::internal
