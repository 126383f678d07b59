// Spherical harmonics: THE convention of the project (docs/sh.md, msgs/sh_light.h).
//
// Real, orthonormal SH basis Y_lm over the unit sphere, Condon-Shortley phase included, single
// index n = l(l+1)+m (l = 0..4, m = -l..l), e.g. for a unit direction (x, y, z):
//   Y_00 = 1/(2 sqrt(pi)),  Y_1,-1 = -sqrt(3/(4 pi)) y,  Y_10 = sqrt(3/(4 pi)) z,
//   Y_11 = -sqrt(3/(4 pi)) x,  Y_2,-2 = sqrt(15/(4 pi)) xy, ...
// Generally, with P_l^m the associated Legendre function including (-1)^m and
// K_lm = sqrt((2l+1)/(4 pi) (l-|m|)!/(l+|m|)!):
//   Y_l0 = K_l0 P_l^0(z),  Y_lm = sqrt(2) K_lm cos(m phi) P_l^m(z),
//   Y_l,-m = sqrt(2) K_lm sin(m phi) P_l^m(z)  (m > 0, phi = atan2(y, x)).
// The basis is frame-agnostic: directions are unit vectors in whatever frame the caller uses (in
// probeless usually a camera-style frame, x right, y down, z forward). A function on the sphere is
// f(w) ~ sum_n f_n Y_n(w) with f_n = integral f Y_n dw (Knorr & Kurz 2014, eq. 10-11).
//
// Lights: coefficients describe incident radiance L(w) from direction w (pointing from the lit
// point towards the light). A directional light of power P (radiance integral over the sphere,
// i.e. P delta(w - d)) has coefficients P Y_n(d) (Knorr & Kurz 2014, eq. 14).
//
// Errors: invalid arguments at the public boundary (band counts, buffer sizes) throw ShError with
// a one-line message naming the function and the expectation.
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <numbers>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "probeless/error/error.h"

namespace probeless::sh {

// Bad argument to an SH function (one-line message "sh::<Function>: <problem>").
class ShError : public InputError {
 public:
  using InputError::InputError;
};

// Highest supported number of bands (degrees 0..4) and the matching coefficient count.
inline constexpr int kMaxBands = 5;
inline constexpr int kMaxCoefficients = kMaxBands * kMaxBands;  // 25

// Identifies this convention in files (e.g. face_light model files); change it if the basis
// ever changes.
inline constexpr std::string_view kConventionName =
    "real-orthonormal;condon-shortley;index=l(l+1)+m";

// Coefficients of `bands` bands (degrees 0..bands-1): bands^2.
constexpr int CoefficientCount(int bands) { return bands * bands; }

// Single index of degree l and order m (-l <= m <= l): l(l+1)+m.
constexpr int Index(int l, int m) { return l * (l + 1) + m; }

// Degree l of single index n: floor(sqrt(n)).
constexpr int DegreeOf(int n) {
  int l = 0;
  while ((l + 1) * (l + 1) <= n) ++l;
  return l;
}

using Vec3 = std::array<double, 3>;

// The normalisation EvaluateBasis applies, per band l and order m >= 0 at index l (l + 1) + m:
// K_l^m = sqrt((2l + 1) / (4 pi) (l - m)! / (l + m)!), times sqrt(2) for m > 0 (real basis).
// Entries for l >= 5 are 0. Multiply it by per-band factors (e.g. A_l, ClampedCosineCoefficient)
// to get the `weight` of EvaluateWeightedBasis.
std::array<double, 25> BasisNormalisation();

// The hot-path form of EvaluateBasis for a compile-time band count (1..5; the loops unroll): the
// same recurrence and convention, with the normalisation (and any per-(l, |m|) factor) taken from
// weight[l (l + 1) + m], m >= 0. With Accumulate, adds to out instead of writing:
//   out[Index(l, 0)] (+)= w_l0 Q_l^0,  out[Index(l, +-m)] (+)= w_lm Q_l^m (Re, Im of (x + i y)^m).
// weight = BasisNormalisation() gives EvaluateBasis (which is this, with that table).
template <int Bands, bool Accumulate, typename T>
inline void EvaluateWeightedBasis(const T* weight, T x, T y, T z, T* out) {
  static_assert(Bands >= 1 && Bands <= 5, "EvaluateWeightedBasis: 1..5 bands");
  T c = 1, s = 0;  // Re and Im of (x + i y)^m
  T q_mm = 1;      // Q_m^m = (-1)^m (2m-1)!!
  for (int m = 0; m < Bands; ++m) {
    if (m > 0) {
      const T c_next = c * x - s * y;
      s = c * y + s * x;
      c = c_next;
      q_mm *= -static_cast<T>(2 * m - 1);
    }
    T q_prev2 = 0, q_prev = 0;
    for (int l = m; l < Bands; ++l) {
      T q;
      if (l == m) {
        q = q_mm;
      } else if (l == m + 1) {
        q = z * static_cast<T>(2 * m + 1) * q_prev;
      } else {
        q = (static_cast<T>(2 * l - 1) * z * q_prev - static_cast<T>(l + m - 1) * q_prev2) *
            (T(1) / static_cast<T>(l - m));
      }
      const T v = weight[l * (l + 1) + m] * q;
      if (m == 0) {
        if constexpr (Accumulate) {
          out[l * (l + 1)] += v;
        } else {
          out[l * (l + 1)] = v;
        }
      } else if constexpr (Accumulate) {
        out[l * (l + 1) + m] += v * c;
        out[l * (l + 1) - m] += v * s;
      } else {
        out[l * (l + 1) + m] = v * c;
        out[l * (l + 1) - m] = v * s;
      }
      q_prev2 = q_prev;
      q_prev = q;
    }
  }
}

namespace internal {
// BasisNormalisation() converted to T, computed once.
template <typename T>
const T* BasisNormalisationTable() {
  static const std::array<T, 25> table = [] {
    const std::array<double, 25> k = BasisNormalisation();
    std::array<T, 25> t{};
    for (size_t i = 0; i < t.size(); ++i) t[i] = static_cast<T>(k[i]);
    return t;
  }();
  return table.data();
}
}  // namespace internal

// Writes Y_0..Y_{bands^2-1} at the unit direction (x, y, z) to out[0..bands^2): the recurrence in z
// on Q_l^m = P_l^m(z) / sin^m(theta) (Condon-Shortley phase in Q_m^m), with sin^m(theta) cos(m phi)
// = Re((x + i y)^m) and sin^m(theta) sin(m phi) = Im((x + i y)^m) (EvaluateWeightedBasis with
// BasisNormalisation). The direction is not normalised here (non-unit input gives the homogeneous
// polynomials, scaled). bands must be 1..5 (a broken-invariant abort, not an exception: this is the
// hot path; use Basis() for a call that throws ShError).
template <typename T>
inline void EvaluateBasis(int bands, T x, T y, T z, T* out) {
  PROBELESS_DEMAND(bands >= 1 && bands <= 5, "sh::EvaluateBasis: bands must be 1..5");
  const T* k = internal::BasisNormalisationTable<T>();
  switch (bands) {
    case 1:
      return EvaluateWeightedBasis<1, false>(k, x, y, z, out);
    case 2:
      return EvaluateWeightedBasis<2, false>(k, x, y, z, out);
    case 3:
      return EvaluateWeightedBasis<3, false>(k, x, y, z, out);
    case 4:
      return EvaluateWeightedBasis<4, false>(k, x, y, z, out);
    case 5:
      return EvaluateWeightedBasis<5, false>(k, x, y, z, out);
    default:
      return;
  }
}

// Y_0..Y_{bands^2-1} at unit direction d. Throws ShError unless 1 <= bands <= 5.
std::vector<double> Basis(int bands, const Vec3& d);

// The 9 band-0..2 basis values at unit direction d (the paper's L = 2, Knorr & Kurz eq. 12-13).
inline std::array<double, 9> Basis9(const Vec3& d) {
  std::array<double, 9> y{};
  EvaluateBasis<double>(3, d[0], d[1], d[2], y.data());
  return y;
}

// Ramamoorthi & Hanrahan (2001) clamped-cosine convolution constant A_l: the irradiance
// E(n) = integral L(w) max(0, n.w) dw has coefficients E_lm = A_l L_lm. A_0 = pi, A_1 = 2 pi/3,
// A_2 = pi/4, A_l = 0 for odd l > 1, A_l = 2 pi (-1)^(l/2-1) / ((l+2)(l-1)) l! / (2^l (l/2)!^2)
// for even l (A_4 = -pi/24). Valid for any l >= 0.
double ClampedCosineCoefficient(int l);

// In place: radiance coefficients L (bands^2 values) -> irradiance coefficients E_lm = A_l L_lm.
// Throws ShError unless coefficients.size() == bands^2 with 1 <= bands <= 5.
void ConvolveClampedCosine(std::span<double> coefficients, int bands);

// Coefficients (bands^2) of a directional light of power `power` (radiance integral) arriving from
// unit direction d (from the lit point towards the light): power * Y_n(d) (Knorr & Kurz eq. 14).
// Throws ShError unless 1 <= bands <= 5.
std::vector<double> DirectionalLight(const Vec3& d, double power, int bands);

// sum_n coefficients[n] Y_n(d) for bands = DegreeOf(size)+1. Throws ShError unless the size is a
// square 1..25.
double Evaluate(std::span<const double> coefficients, const Vec3& d);

// Sloan's "optimal linear direction" (Sloan 2008, "Stupid SH tricks"): the unit direction d that
// maximises the band-1 part of the light, sum_m L_1m Y_1m(d). With the Condon-Shortley phase
// (Y_1,-1 = -c y, Y_10 = c z, Y_11 = -c x) this is d ~ (-L_11, -L_1,-1, L_10); note the minus
// signs: forgetting the phase mirrors x and y. d points from the lit point towards the light.
// Reads coefficients[1..3] only (the caller's array has >= 4 entries); returns (0, 0, 0) if the
// band-1 coefficients are all zero.
template <typename T>
inline Vec3 OptimalLinearDirection(const T* coefficients) {
  const double x = -static_cast<double>(coefficients[3]);
  const double y = -static_cast<double>(coefficients[1]);
  const double z = static_cast<double>(coefficients[2]);
  const double norm = std::sqrt(x * x + y * y + z * z);
  if (!(norm > 0)) return {0, 0, 0};
  return {x / norm, y / norm, z / norm};
}

// Power P of the directional light P delta(w - d) whose bands 1..bands-1 best match the light in
// the least-squares sense: P = sum_{l>=1,m} L_lm Y_lm(d) / sum_{l>=1,m} Y_lm(d)^2, where the
// denominator is (bands^2 - 1)/(4 pi) by the addition theorem. Band 0 (the ambient part) is left
// out so a uniform ambient term does not inflate it. Throws ShError unless the size is a square
// 4..25 (bands >= 2).
double DirectionalPower(std::span<const double> coefficients, const Vec3& d);

// A quadrature rule over the unit sphere: sum_i weights[i] f(directions[i]) ~ integral f dw.
struct QuadratureRule {
  std::vector<Vec3> directions;  // unit vectors
  std::vector<double> weights;   // steradians; they sum to 4 pi
};

// Gauss-Legendre in z (n_z nodes) times 2 n_z equally spaced azimuths: integrates every spherical
// polynomial of degree <= 2 n_z - 1 exactly (so products Y_a Y_b of bands <= n_z). Throws ShError
// unless 1 <= n_z <= 512.
QuadratureRule GaussLegendreRule(int n_z);

// Projection f_n = integral f Y_n dw (Knorr & Kurz eq. 11) for n < bands^2 with a quadrature rule.
// Throws ShError unless 1 <= bands <= 5.
std::vector<double> Project(const std::function<double(const Vec3&)>& f, int bands,
                            const QuadratureRule& rule);

// The same projection by Monte-Carlo over `samples` uniformly distributed directions drawn from a
// std::mt19937_64 seeded with `seed` (deterministic: uniforms are built from the raw 64-bit output,
// not from std::uniform_real_distribution). Error ~ 1/sqrt(samples). Throws ShError unless
// 1 <= bands <= 5 and samples >= 1.
std::vector<double> ProjectMonteCarlo(const std::function<double(const Vec3&)>& f, int bands,
                                      int samples, uint64_t seed);

// n nearly uniformly spread unit directions (Fibonacci spiral, deterministic; z from +1 to -1).
// Throws ShError unless n >= 1.
std::vector<Vec3> FibonacciSphere(int n);

// Lat-long (equirectangular) images of a light, for a camera-style frame (x right, y down,
// z forward) with "up" = -y. Pixel (u, v) (u = column 0..width-1, v = row 0..height-1, sampled at
// pixel centres) shows the direction of azimuth a = pi - 2 pi (u + 0.5)/width and elevation
// e = pi/2 - pi (v + 0.5)/height, d = (-sin a cos e, -sin e, -cos a cos e): the image centre is the
// direction towards the camera (-z), the left half is light from the camera's left (-x, the
// subject's right for a face looking into the camera: Yale B's positive azimuth), the top row is
// straight up. This is the azimuth/elevation convention of Yale B file names.
Vec3 LatLongDirection(int u, int v, int width, int height);

// Inverse of LatLongDirection's angles: azimuth and elevation in radians of unit direction d,
// a = atan2(-x, -z) in (-pi, pi], e = asin(-y) in [-pi/2, pi/2].
std::array<double, 2> AzimuthElevation(const Vec3& d);

// Unit direction of azimuth a and elevation e (radians), as in LatLongDirection.
Vec3 DirectionFromAzimuthElevation(double azimuth, double elevation);

// Renders L_c(w) = sum_n coefficients[n * channels + c] Y_n(w) into out[(v * width + u) * channels
// + c] for every lat-long pixel (see LatLongDirection). coefficients holds bands^2 * channels
// values (coefficient-major, channels interleaved, as msgs::ShLight::coefficients). Throws ShError
// unless 1 <= bands <= 5, 1 <= channels <= 4, width, height >= 1, and the spans have exactly those
// sizes.
void RenderLatLong(std::span<const float> coefficients, int bands, int channels, int width,
                   int height, std::span<float> out);

}  // namespace probeless::sh
