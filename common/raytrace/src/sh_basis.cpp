#include "sh_basis.h"

#include <cmath>
#include <numbers>

#include "probeless/raytrace/render.h"
#include "probeless/sh/sh.h"

namespace probeless::raytrace {

std::array<float, 9> ShBasis9(Vec3 d) {
  std::array<float, 9> y{};
  sh::EvaluateBasis<float>(3, d.x, d.y, d.z, y.data());
  return y;
}

namespace internal {

const std::array<float, 9> kClampedCosine = {
    static_cast<float>(std::numbers::pi),         static_cast<float>(2 * std::numbers::pi / 3),
    static_cast<float>(2 * std::numbers::pi / 3), static_cast<float>(2 * std::numbers::pi / 3),
    static_cast<float>(std::numbers::pi / 4),     static_cast<float>(std::numbers::pi / 4),
    static_cast<float>(std::numbers::pi / 4),     static_cast<float>(std::numbers::pi / 4),
    static_cast<float>(std::numbers::pi / 4)};

Vec3 EvaluateSh9(const std::array<Vec3, 9>& sh, Vec3 d) {
  const std::array<float, 9> y = ShBasis9(d);
  Vec3 out;
  for (int i = 0; i < 9; ++i) out += sh[i] * y[i];
  return out;
}

Vec3 ShIrradiance(const std::array<Vec3, 9>& sh, Vec3 n) {
  const std::array<float, 9> y = ShBasis9(n);
  Vec3 out;
  for (int i = 0; i < 9; ++i) out += sh[i] * (kClampedCosine[i] * y[i]);
  return out;
}

std::array<Vec3, 9> ProjectRotated(const std::function<Vec3(Vec3)>& f, const Mat3& frame_to_world) {
  // Gauss-Legendre in z (4 nodes) x 8 azimuths: exact for spherical polynomials of degree <= 7.
  constexpr double kNodes[4] = {-0.8611363115940526, -0.3399810435848563, 0.3399810435848563,
                                0.8611363115940526};
  constexpr double kWeights[4] = {0.3478548451374538, 0.6521451548625461, 0.6521451548625461,
                                  0.3478548451374538};
  constexpr int kAzimuths = 8;
  std::array<Vec3, 9> out{};
  for (int i = 0; i < 4; ++i) {
    const double z = kNodes[i];
    const double s = std::sqrt(1 - z * z);
    for (int k = 0; k < kAzimuths; ++k) {
      const double phi = 2 * std::numbers::pi * (k + 0.5) / kAzimuths;
      const Vec3 w{static_cast<float>(s * std::cos(phi)), static_cast<float>(s * std::sin(phi)),
                   static_cast<float>(z)};
      const float weight = static_cast<float>(kWeights[i] * 2 * std::numbers::pi / kAzimuths);
      const Vec3 value = f(frame_to_world * w) * weight;
      const std::array<float, 9> y = ShBasis9(w);
      for (int n = 0; n < 9; ++n) out[n] += value * y[n];
    }
  }
  return out;
}

}  // namespace internal
}  // namespace probeless::raytrace
