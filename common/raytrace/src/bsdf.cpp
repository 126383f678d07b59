#include "bsdf.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>

namespace probeless::raytrace::internal {
namespace {

constexpr float kPi = static_cast<float>(std::numbers::pi);
constexpr int kTableSize = 32;          // nodes along mu and along roughness
constexpr int kTableStrata = 32;        // stratified VNDF samples per axis per table node
constexpr float kMinMu = 1e-3f;         // the mu = 0 node is evaluated here (VNDF needs mu > 0)
constexpr float kMinRoughness = 0.01f;  // the r = 0 node (roughness must be > 0 in materials)

float Luminance(Vec3 c) { return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z; }

float SchlickWeight(float cos_theta) {
  const float m = std::clamp(1 - cos_theta, 0.0f, 1.0f);
  const float m2 = m * m;
  return m2 * m2 * m;
}

// GGX normal distribution D(h) for local h (z = normal).
float GgxD(float cos_h, float alpha) {
  const float a2 = alpha * alpha;
  const float d = cos_h * cos_h * (a2 - 1) + 1;
  return a2 / (kPi * d * d);
}

// Smith Lambda of GGX for a local direction w.
float SmithLambda(Vec3 w, float alpha) {
  const float z2 = w.z * w.z;
  if (z2 <= 0) return 1e30f;
  const float tan2 = std::max(0.0f, 1 - z2) / z2;
  return 0.5f * (-1 + std::sqrt(1 + alpha * alpha * tan2));
}

// v / |v| with one division (hot path).
Vec3 Unit(Vec3 v) {
  const float n2 = Dot(v, v);
  return n2 > 0 ? v * (1 / std::sqrt(n2)) : Vec3{};
}

// Visible-normal sample of GGX (Heitz 2018) for local wo with wo.z > 0: the microfacet normal.
Vec3 SampleVisibleNormal(Vec3 wo, float alpha, float u1, float u2) {
  const Vec3 v = Normalize({alpha * wo.x, alpha * wo.y, wo.z});
  const float len2 = v.x * v.x + v.y * v.y;
  const Vec3 t1 = len2 > 0 ? Vec3{-v.y, v.x, 0} / std::sqrt(len2) : Vec3{1, 0, 0};
  const Vec3 t2 = Cross(v, t1);
  const float r = std::sqrt(u1);
  float sin_phi, cos_phi;
  SinCos2Pi(u2, &sin_phi, &cos_phi);
  const float p1 = r * cos_phi;
  float p2 = r * sin_phi;
  const float s = 0.5f * (1 + v.z);
  p2 = (1 - s) * std::sqrt(std::max(0.0f, 1 - p1 * p1)) + s * p2;
  const Vec3 nh = t1 * p1 + t2 * p2 + v * std::sqrt(std::max(0.0f, 1 - p1 * p1 - p2 * p2));
  return Unit({alpha * nh.x, alpha * nh.y, std::max(1e-7f, nh.z)});
}

Vec3 Reflect(Vec3 w, Vec3 h) { return h * (2 * Dot(w, h)) - w; }

// The directional-albedo tables: E = f0 * a + b at (mu node, roughness node), and their means.
struct AlbedoTables {
  std::array<std::array<float, kTableSize>, kTableSize> a{};  // [roughness][mu]
  std::array<std::array<float, kTableSize>, kTableSize> b{};
  std::array<float, kTableSize> a_avg{};  // [roughness]
  std::array<float, kTableSize> b_avg{};

  AlbedoTables() {
    for (int j = 0; j < kTableSize; ++j) {
      const float r = std::max(kMinRoughness, static_cast<float>(j) / (kTableSize - 1));
      const float alpha = r * r;
      for (int i = 0; i < kTableSize; ++i) {
        const float mu = std::max(kMinMu, static_cast<float>(i) / (kTableSize - 1));
        const Vec3 wo{std::sqrt(1 - mu * mu), 0, mu};
        const float lambda_o = SmithLambda(wo, alpha);
        double sum_a = 0, sum_b = 0;
        // Deterministic stratified quadrature of E = E_h~VNDF[F G2 / G1(wo)].
        for (int sy = 0; sy < kTableStrata; ++sy) {
          for (int sx = 0; sx < kTableStrata; ++sx) {
            const Vec3 h = SampleVisibleNormal(wo, alpha, (sx + 0.5f) / kTableStrata,
                                               (sy + 0.5f) / kTableStrata);
            const Vec3 wi = Reflect(wo, h);
            if (wi.z <= 0) continue;
            const float g = (1 + lambda_o) / (1 + lambda_o + SmithLambda(wi, alpha));
            const float fw = SchlickWeight(Dot(wo, h));
            sum_a += (1 - fw) * g;
            sum_b += fw * g;
          }
        }
        a[j][i] = static_cast<float>(sum_a / (kTableStrata * kTableStrata));
        b[j][i] = static_cast<float>(sum_b / (kTableStrata * kTableStrata));
      }
      // 2 int E(mu) mu dmu of the piecewise-linear E, exactly (segment by segment).
      const double h = 1.0 / (kTableSize - 1);
      double sa = 0, sb = 0;
      for (int i = 0; i + 1 < kTableSize; ++i) {
        const double m0 = i * h, m1 = (i + 1) * h;
        sa += h * (a[j][i] * (2 * m0 + m1) + a[j][i + 1] * (m0 + 2 * m1)) / 6;
        sb += h * (b[j][i] * (2 * m0 + m1) + b[j][i + 1] * (m0 + 2 * m1)) / 6;
      }
      a_avg[j] = static_cast<float>(2 * sa);
      b_avg[j] = static_cast<float>(2 * sb);
    }
  }
};

const AlbedoTables& Tables() {
  static const AlbedoTables tables;  // built once (thread-safe static), ~50 ms
  return tables;
}

// Index and weight of x in [0, 1] on the table grid.
void GridPosition(float x, int* i, float* w) {
  const float f = std::clamp(x, 0.0f, 1.0f) * (kTableSize - 1);
  *i = std::min(kTableSize - 2, static_cast<int>(f));
  *w = f - *i;
}

}  // namespace

float GgxAlbedo(float mu, float roughness, float f0) {
  const AlbedoTables& tab = Tables();
  int i, j;
  float wi, wj;
  GridPosition(mu, &i, &wi);
  GridPosition(roughness, &j, &wj);
  auto at = [&](const auto& t) {
    return (t[j][i] * (1 - wi) + t[j][i + 1] * wi) * (1 - wj) +
           (t[j + 1][i] * (1 - wi) + t[j + 1][i + 1] * wi) * wj;
  };
  return f0 * at(tab.a) + at(tab.b);
}

float GgxAverageAlbedo(float roughness, float f0) {
  const AlbedoTables& tab = Tables();
  int j;
  float wj;
  GridPosition(roughness, &j, &wj);
  const float a = tab.a_avg[j] * (1 - wj) + tab.a_avg[j + 1] * wj;
  const float b = tab.b_avg[j] * (1 - wj) + tab.b_avg[j + 1] * wj;
  return f0 * a + b;
}

Bsdf::Bsdf(Vec3 albedo, float f0, float roughness, Vec3 n, Vec3 wo)
    : frame_(n), albedo_(albedo), f0_(f0) {
  wo_local_ = frame_.ToLocal(wo);
  wo_local_.z = std::max(wo_local_.z, 1e-6f);
  if (f0_ > 0) {
    alpha_ = std::max(roughness * roughness, 1e-4f);
    lambda_o_ = SmithLambda(wo_local_, alpha_);
    const float e_o = GgxAlbedo(wo_local_.z, roughness, f0_);
    const float e_avg = GgxAverageAlbedo(roughness, f0_);
    // A lobe reflecting everything leaves nothing to the diffuse part.
    diffuse_scale_ = e_avg < 1 - 1e-4f ? std::max(0.0f, 1 - e_o) / (1 - e_avg) : 0.0f;
    roughness_ = roughness;
    const float diffuse_weight = Luminance(albedo_) * std::max(0.0f, 1 - e_o);
    p_specular_ = e_o + diffuse_weight > 0 ? e_o / (e_o + diffuse_weight) : 1.0f;
  }
}

Vec3 Bsdf::EvalLocal(Vec3 wi, float* pdf) const {
  *pdf = 0;
  if (wi.z <= 0) return {};
  const Vec3 wo = wo_local_;
  const float diffuse_pdf = wi.z * (1 / kPi);
  if (f0_ <= 0) {
    *pdf = diffuse_pdf;
    return albedo_ * diffuse_pdf;
  }
  const Vec3 diffuse =
      albedo_ * (diffuse_scale_ * (1 - GgxAlbedo(wi.z, roughness_, f0_)) * diffuse_pdf);
  const Vec3 h = Unit(wo + wi);
  const float o_h = std::max(0.0f, Dot(wo, h));
  const float d = GgxD(h.z, alpha_);
  const float g2 = 1 / (1 + lambda_o_ + SmithLambda(wi, alpha_));
  const float fresnel = f0_ + (1 - f0_) * SchlickWeight(o_h);
  const float quarter_over_mu_o = 0.25f / wo.z;
  const float spec = fresnel * d * g2 * quarter_over_mu_o;
  const float spec_pdf = d * quarter_over_mu_o / (1 + lambda_o_);
  *pdf = p_specular_ * spec_pdf + (1 - p_specular_) * diffuse_pdf;
  return diffuse + Vec3{spec, spec, spec};
}

bool Bsdf::Sample(float u_lobe, float u1, float u2, Vec3* wi_world, Vec3* weight,
                  float* pdf) const {
  Vec3 wi;
  if (u_lobe < p_specular_) {
    wi = Reflect(wo_local_, SampleVisibleNormal(wo_local_, alpha_, u1, u2));
  } else {
    // Cosine-weighted hemisphere (concentric-free polar map: fine for a path tracer).
    const float r = std::sqrt(u1);
    float sin_phi, cos_phi;
    SinCos2Pi(u2, &sin_phi, &cos_phi);
    wi = {r * cos_phi, r * sin_phi, std::sqrt(std::max(0.0f, 1 - u1))};
  }
  if (wi.z <= 0) return false;
  if (f0_ <= 0) {
    // Pure Lambert: f cos / pdf is the albedo itself.
    *pdf = wi.z * (1 / kPi);
    if (!(*pdf > 0)) return false;
    *wi_world = Unit(frame_.ToWorld(wi));
    *weight = albedo_;
    return true;
  }
  const Vec3 f = EvalLocal(wi, pdf);
  if (!(*pdf > 0)) return false;
  *wi_world = Unit(frame_.ToWorld(wi));
  *weight = f * (1 / *pdf);
  return true;
}

}  // namespace probeless::raytrace::internal
