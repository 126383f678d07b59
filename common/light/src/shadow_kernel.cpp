#include "shadow_kernel.h"

#include "probeless/simd/simd.h"

#ifdef PROBELESS_SIMD_X86
#include <immintrin.h>
#endif

namespace probeless::light::internal {

float ShadowRayScalar(const ShadowRayParams& r, float px, float py, float pz,
                      const std::array<float, 3>& l) {
  bool hidden = false;
  // u(t) = (au + t bu) / (p.z + t l_z): the projection of p + t l (pixel centres at integers;
  // the + 0.5 makes the truncation below a rounding).
  const float au = r.fx * px + r.cx * pz + 0.5f, bu = r.fx * l[0] + r.cx * l[2];
  const float av = r.fy * py + r.cy * pz + 0.5f, bv = r.fy * l[1] + r.cy * l[2];
  for (int k = 0; k < r.step_count; ++k) {
    const float t = r.steps[k];
    const float sz = pz + t * l[2];
    if (sz < 0.05f) break;
    const float inv = 1.0f / sz;
    const float u = (au + t * bu) * inv, v = (av + t * bv) * inv;
    if (!(u >= 0 && v >= 0 && u < r.width && v < r.height)) break;
    const float d = r.depth[static_cast<int>(v) * r.width + static_cast<int>(u)];
    if (d > 0 && sz - d > r.bias + r.bias_rel * sz) {
      if (sz - d < r.thickness[k]) return 0;
      hidden = true;
    }
  }
  return hidden && r.unknown_behind ? -1.0f : 1.0f;
}

void ShadowRay8Scalar(const ShadowRayParams& r, const float* px, const float* py, const float* pz,
                      const std::array<float, 3>& l, float out[8]) {
  for (int i = 0; i < 8; ++i) out[i] = pz[i] > 0 ? ShadowRayScalar(r, px[i], py[i], pz[i], l) : 1;
}

ShadowRay8Fn ShadowRay8Kernel() {
#ifdef PROBELESS_SIMD_X86
  if (simd::UseAvx2()) return ShadowRay8Avx2;
#endif
  return ShadowRay8Scalar;
}

void ShadowRay8(const ShadowRayParams& r, const float* px, const float* py, const float* pz,
                const std::array<float, 3>& l, float out[8]) {
  ShadowRay8Kernel()(r, px, py, pz, l, out);
}

#ifdef PROBELESS_SIMD_X86
PROBELESS_SIMD_AVX2 void ShadowRay8Avx2(const ShadowRayParams& r, const float* px, const float* py,
                                        const float* pz, const std::array<float, 3>& l,
                                        float out[8]) {
  const __m256 x = _mm256_loadu_ps(px), y = _mm256_loadu_ps(py), z = _mm256_loadu_ps(pz);
  const __m256 half = _mm256_set1_ps(0.5f), zero = _mm256_setzero_ps();
  const __m256 fx = _mm256_set1_ps(r.fx), fy = _mm256_set1_ps(r.fy);
  const __m256 cx = _mm256_set1_ps(r.cx), cy = _mm256_set1_ps(r.cy);
  const __m256 au = _mm256_add_ps(_mm256_fmadd_ps(fx, x, _mm256_mul_ps(cx, z)), half);
  const __m256 av = _mm256_add_ps(_mm256_fmadd_ps(fy, y, _mm256_mul_ps(cy, z)), half);
  const __m256 bu = _mm256_set1_ps(r.fx * l[0] + r.cx * l[2]);
  const __m256 bv = _mm256_set1_ps(r.fy * l[1] + r.cy * l[2]);
  const __m256 lz = _mm256_set1_ps(l[2]), min_z = _mm256_set1_ps(0.05f);
  const __m256 w = _mm256_set1_ps(static_cast<float>(r.width));
  const __m256 h = _mm256_set1_ps(static_cast<float>(r.height));
  const __m256 bias = _mm256_set1_ps(r.bias), bias_rel = _mm256_set1_ps(r.bias_rel);
  const __m256i width = _mm256_set1_epi32(r.width);
  __m256 active = _mm256_cmp_ps(z, zero, _CMP_GT_OQ);  // lanes still marching
  __m256 occluded = zero, hidden = zero;               // all-ones masks
  for (int k = 0; k < r.step_count; ++k) {
    const __m256 t = _mm256_set1_ps(r.steps[k]);
    const __m256 sz = _mm256_fmadd_ps(t, lz, z);
    active = _mm256_and_ps(active, _mm256_cmp_ps(sz, min_z, _CMP_GE_OQ));
    const __m256 inv = _mm256_div_ps(_mm256_set1_ps(1.0f), sz);
    const __m256 u = _mm256_mul_ps(_mm256_fmadd_ps(t, bu, au), inv);
    const __m256 v = _mm256_mul_ps(_mm256_fmadd_ps(t, bv, av), inv);
    active = _mm256_and_ps(active, _mm256_and_ps(_mm256_cmp_ps(u, zero, _CMP_GE_OQ),
                                                 _mm256_cmp_ps(v, zero, _CMP_GE_OQ)));
    active = _mm256_and_ps(
        active, _mm256_and_ps(_mm256_cmp_ps(u, w, _CMP_LT_OQ), _mm256_cmp_ps(v, h, _CMP_LT_OQ)));
    if (_mm256_movemask_ps(active) == 0) break;
    const __m256i index =
        _mm256_add_epi32(_mm256_mullo_epi32(_mm256_cvttps_epi32(v), width), _mm256_cvttps_epi32(u));
    const __m256 d = _mm256_mask_i32gather_ps(zero, r.depth, index, active, 4);
    const __m256 gap = _mm256_sub_ps(sz, d);
    const __m256 behind =
        _mm256_and_ps(_mm256_and_ps(active, _mm256_cmp_ps(d, zero, _CMP_GT_OQ)),
                      _mm256_cmp_ps(gap, _mm256_fmadd_ps(bias_rel, sz, bias), _CMP_GT_OQ));
    const __m256 hit =
        _mm256_and_ps(behind, _mm256_cmp_ps(gap, _mm256_set1_ps(r.thickness[k]), _CMP_LT_OQ));
    occluded = _mm256_or_ps(occluded, hit);
    hidden = _mm256_or_ps(hidden, _mm256_andnot_ps(hit, behind));
    active = _mm256_andnot_ps(hit, active);
  }
  const __m256 one = _mm256_set1_ps(1.0f);
  const __m256 unknown =
      r.unknown_behind ? _mm256_andnot_ps(occluded, hidden) : _mm256_setzero_ps();
  __m256 result = _mm256_blendv_ps(one, _mm256_set1_ps(-1.0f), unknown);
  result = _mm256_blendv_ps(result, zero, occluded);
  _mm256_storeu_ps(out, result);
}
#endif

}  // namespace probeless::light::internal
