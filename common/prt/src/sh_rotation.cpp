#include <string>

#include "probeless/prt/prt.h"
#include "probeless/sh/sh.h"

namespace probeless::prt {

std::vector<double> ShRotationMatrix(const raytrace::Mat3& b_to_a, int bands) {
  if (bands < 1 || bands > 5) {
    throw PrtError("ShRotationMatrix: bands " + std::to_string(bands) + " out of range 1..5");
  }
  // M_nm = integral Y_n(w) Y_m(R w) dw; the integrand has degree <= 2 (bands - 1), so a
  // Gauss-Legendre rule with n_z = bands integrates it exactly.
  const sh::QuadratureRule rule = sh::GaussLegendreRule(bands);
  const int count = bands * bands;
  std::vector<double> m(static_cast<size_t>(count * count), 0.0);
  std::vector<double> yn(count), ym(count);
  const auto& r = b_to_a.m;
  for (size_t i = 0; i < rule.directions.size(); ++i) {
    const sh::Vec3& d = rule.directions[i];
    const double rx = r[0][0] * d[0] + r[0][1] * d[1] + r[0][2] * d[2];
    const double ry = r[1][0] * d[0] + r[1][1] * d[1] + r[1][2] * d[2];
    const double rz = r[2][0] * d[0] + r[2][1] * d[1] + r[2][2] * d[2];
    sh::EvaluateBasis<double>(bands, d[0], d[1], d[2], yn.data());
    sh::EvaluateBasis<double>(bands, rx, ry, rz, ym.data());
    for (int n = 0; n < count; ++n) {
      for (int k = 0; k < count; ++k) m[n * count + k] += rule.weights[i] * yn[n] * ym[k];
    }
  }
  return m;
}

}  // namespace probeless::prt
