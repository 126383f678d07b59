// Private BSDF of the path tracer: Lambert + GGX (Trowbridge-Reitz distribution, Smith
// height-correlated masking-shadowing, Fresnel-Schlick), energy conserving through a tabulated
// directional albedo of the GGX lobe (docs/raytrace.md "Path tracing").
#pragma once

#include "probeless/raytrace/geometry.h"

namespace probeless::raytrace::internal {

// An orthonormal frame (t, b, n) around a unit normal n.
struct Frame3 {
  Vec3 t, b, n;
  explicit Frame3(Vec3 normal);
  Vec3 ToLocal(Vec3 v) const { return {Dot(v, t), Dot(v, b), Dot(v, n)}; }
  Vec3 ToWorld(Vec3 v) const { return t * v.x + b * v.y + n * v.z; }
};

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
  Vec3 Eval(Vec3 wi, float* pdf) const;
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
