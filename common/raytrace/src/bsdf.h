// Private BSDF of the path tracer: Lambert + GGX (Trowbridge-Reitz distribution, Smith
// height-correlated masking-shadowing, Fresnel-Schlick), energy conserving through a tabulated
// directional albedo of the GGX lobe (docs/raytrace.md "Path tracing").
#pragma once

#include <cmath>
#include <numbers>

#include "probeless/raytrace/geometry.h"

namespace probeless::raytrace::internal {

// An orthonormal frame (t, b, n) around a unit normal n.
struct Frame3 {
  Vec3 t, b, n;
  explicit Frame3(Vec3 normal) : n(normal) {
    // Branchless orthonormal basis (Duff et al. 2017): continuous except at n.z = -0.
    const float sign = std::copysign(1.0f, n.z);
    const float a = -1 / (sign + n.z);
    const float c = n.x * n.y * a;
    t = {1 + sign * n.x * n.x * a, sign * c, -sign * n.x};
    b = {c, sign + n.y * n.y * a, -n.y};
  }
  Vec3 ToLocal(Vec3 v) const { return {Dot(v, t), Dot(v, b), Dot(v, n)}; }
  Vec3 ToWorld(Vec3 v) const { return t * v.x + b * v.y + n * v.z; }
};

// sin and cos of 2 pi u for u in [0, 1] (the sampling angles): quadrant reduction and Taylor
// polynomials on [-pi/4, pi/4], error < 1e-7, a third of the instructions of std::sin + std::cos.
inline void SinCos2Pi(float u, float* sin_out, float* cos_out) {
  const float q = u * 4;
  const float k = std::floor(q + 0.5f);  // nearest quarter turn
  const float a = (q - k) * 1.57079632679f;
  const float a2 = a * a;
  const float s =
      a * (1 + a2 * (-1.0f / 6 + a2 * (1.0f / 120 + a2 * (-1.0f / 5040 + a2 * (1.0f / 362880)))));
  const float c = 1 + a2 * (-0.5f + a2 * (1.0f / 24 + a2 * (-1.0f / 720 + a2 * (1.0f / 40320))));
  const int quadrant = static_cast<int>(k) & 3;
  const float sq = (quadrant & 1) ? c : s;
  const float cq = (quadrant & 1) ? s : c;
  *sin_out = (quadrant & 2) ? -sq : sq;
  *cos_out = (quadrant == 1 || quadrant == 2) ? -cq : cq;
}

// The GGX lobe's directional albedo with Fresnel-Schlick: E(mu, r, f0) = f0 A + B, tabulated over
// mu = cos(theta_o) in [0, 1] and roughness r in [0, 1] (bilinear), and its cosine-weighted
// hemispherical mean E_avg(r, f0) = 2 int E(mu) mu dmu, exact for the interpolated table.
float GgxAlbedo(float mu, float roughness, float f0);
float GgxAverageAlbedo(float roughness, float f0);

// One surface's BSDF at a hit, viewed from `wo` (unit, towards the viewer, world frame).
class Bsdf {
 public:
  // albedo: linear RGB diffuse albedo; f0 = 0 turns the GGX lobe off (pure Lambert); roughness in
  // (0, 1]; n: unit shading normal on the side of wo.
  Bsdf(Vec3 albedo, float f0, float roughness, Vec3 n, Vec3 wo);

  // f(wo, wi) * max(0, n.wi) for unit wi (world); *pdf = the solid-angle density with which
  // Sample draws wi.
  Vec3 Eval(Vec3 wi, float* pdf) const {
    if (f0_ > 0) return EvalLocal(frame_.ToLocal(wi), pdf);
    // Pure Lambert, inline (most surfaces): only the cosine is needed.
    const float cos_i = Dot(wi, frame_.n);
    *pdf = 0;
    if (cos_i <= 0) return {};
    *pdf = cos_i * (1 / std::numbers::pi_v<float>);
    return albedo_ * *pdf;
  }
  // Draws wi from the lobe mixture with three uniforms in [0, 1). Returns false (and no
  // direction) when the draw falls below the surface; else wi, weight = f cos / pdf and pdf.
  bool Sample(float u_lobe, float u1, float u2, Vec3* wi, Vec3* weight, float* pdf) const;

  bool specular() const { return f0_ > 0; }

 private:
  Vec3 EvalLocal(Vec3 wi, float* pdf) const;  // Eval for a direction in the local frame

  Frame3 frame_;
  Vec3 albedo_;
  Vec3 wo_local_;
  float f0_ = 0;
  float alpha_ = 1;
  float roughness_ = 1;
  float lambda_o_ = 0;       // Smith Lambda(wo)
  float diffuse_scale_ = 1;  // (1 - E(mu_o)) / (1 - E_avg): the diffuse part's wo factor
  float p_specular_ = 0;     // probability of sampling the GGX lobe
};

}  // namespace probeless::raytrace::internal
