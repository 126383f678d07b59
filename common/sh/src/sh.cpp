// Spherical harmonics helpers (see probeless/sh/sh.h).
#include "probeless/sh/sh.h"

#include <algorithm>
#include <random>

namespace probeless::sh {
namespace {

void CheckBands(const char* function, int bands) {
  if (bands < 1 || bands > kMaxBands) {
    throw ShError(std::string("sh::") + function + ": bands " + std::to_string(bands) +
                  " out of range 1..5");
  }
}

int BandsOfSize(const char* function, size_t size, int min_bands) {
  for (int bands = min_bands; bands <= kMaxBands; ++bands) {
    if (static_cast<size_t>(CoefficientCount(bands)) == size) return bands;
  }
  throw ShError(std::string("sh::") + function + ": " + std::to_string(size) +
                " coefficients is not a square " + std::to_string(min_bands * min_bands) + "..25");
}

// Uniform double in [0, 1) from the top 53 bits of one 64-bit draw.
double Uniform(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

}  // namespace

std::vector<double> Basis(int bands, const Vec3& d) {
  CheckBands("Basis", bands);
  std::vector<double> y(CoefficientCount(bands));
  EvaluateBasis<double>(bands, d[0], d[1], d[2], y.data());
  return y;
}

std::array<double, 25> BasisNormalisation() {
  std::array<double, 25> k{};
  for (int l = 0; l < 5; ++l) {
    double ratio = 1;  // (l - m)! / (l + m)!
    for (int m = 0; m <= l; ++m) {
      if (m > 0) ratio /= static_cast<double>((l + m) * (l - m + 1));
      const double k_lm = std::sqrt((2 * l + 1) / (4 * std::numbers::pi) * ratio);
      k[l * (l + 1) + m] = m == 0 ? k_lm : std::numbers::sqrt2 * k_lm;
    }
  }
  return k;
}

double ClampedCosineCoefficient(int l) {
  constexpr double kPi = std::numbers::pi;
  if (l == 0) return kPi;
  if (l == 1) return 2 * kPi / 3;
  if (l % 2 == 1) return 0;
  // 2 pi (-1)^(l/2-1) / ((l+2)(l-1)) * l! / (2^l (l/2)!^2)  (Ramamoorthi & Hanrahan 2001, eq. 8)
  double ratio = 1;  // l! / (2^l (l/2)!^2) = C(l, l/2) / 2^l
  for (int k = 1; k <= l / 2; ++k) ratio *= static_cast<double>(l / 2 + k) / (4.0 * k);
  const double sign = ((l / 2 - 1) % 2 == 0) ? 1.0 : -1.0;
  return 2 * kPi * sign / ((l + 2) * (l - 1)) * ratio;
}

void ConvolveClampedCosine(std::span<double> coefficients, int bands) {
  CheckBands("ConvolveClampedCosine", bands);
  if (coefficients.size() != static_cast<size_t>(CoefficientCount(bands))) {
    throw ShError("sh::ConvolveClampedCosine: " + std::to_string(coefficients.size()) +
                  " coefficients, expected " + std::to_string(CoefficientCount(bands)));
  }
  for (int n = 0; n < CoefficientCount(bands); ++n) {
    coefficients[n] *= ClampedCosineCoefficient(DegreeOf(n));
  }
}

std::vector<double> DirectionalLight(const Vec3& d, double power, int bands) {
  CheckBands("DirectionalLight", bands);
  std::vector<double> y(CoefficientCount(bands));
  EvaluateBasis<double>(bands, d[0], d[1], d[2], y.data());
  for (double& v : y) v *= power;
  return y;
}

double Evaluate(std::span<const double> coefficients, const Vec3& d) {
  const int bands = BandsOfSize("Evaluate", coefficients.size(), 1);
  double y[kMaxCoefficients];
  EvaluateBasis<double>(bands, d[0], d[1], d[2], y);
  double sum = 0;
  for (size_t n = 0; n < coefficients.size(); ++n) sum += coefficients[n] * y[n];
  return sum;
}

double DirectionalPower(std::span<const double> coefficients, const Vec3& d) {
  const int bands = BandsOfSize("DirectionalPower", coefficients.size(), 2);
  double y[kMaxCoefficients];
  EvaluateBasis<double>(bands, d[0], d[1], d[2], y);
  double dot = 0;
  for (size_t n = 1; n < coefficients.size(); ++n) dot += coefficients[n] * y[n];
  return dot / ((CoefficientCount(bands) - 1) / (4 * std::numbers::pi));
}

QuadratureRule GaussLegendreRule(int n_z) {
  if (n_z < 1 || n_z > 512) {
    throw ShError("sh::GaussLegendreRule: n_z " + std::to_string(n_z) + " out of range 1..512");
  }
  // Gauss-Legendre nodes and weights on [-1, 1] by Newton iteration on P_n.
  std::vector<double> nodes(n_z), node_weights(n_z);
  for (int i = 0; i < n_z; ++i) {
    double z = std::cos(std::numbers::pi * (i + 0.75) / (n_z + 0.5));
    double dp = 1;
    for (int iteration = 0; iteration < 100; ++iteration) {
      double p0 = 1, p1 = z;
      for (int k = 2; k <= n_z; ++k) {
        const double p2 = ((2 * k - 1) * z * p1 - (k - 1) * p0) / k;
        p0 = p1;
        p1 = p2;
      }
      dp = n_z * (z * p1 - p0) / (z * z - 1);
      const double step = p1 / dp;
      z -= step;
      if (std::abs(step) < 1e-16) break;
    }
    nodes[i] = z;
    node_weights[i] = 2 / ((1 - z * z) * dp * dp);
  }
  QuadratureRule rule;
  const int n_phi = 2 * n_z;
  for (int i = 0; i < n_z; ++i) {
    const double z = nodes[i], r = std::sqrt(std::max(0.0, 1 - z * z));
    for (int j = 0; j < n_phi; ++j) {
      const double phi = 2 * std::numbers::pi * (j + 0.5) / n_phi;
      rule.directions.push_back({r * std::cos(phi), r * std::sin(phi), z});
      rule.weights.push_back(node_weights[i] * 2 * std::numbers::pi / n_phi);
    }
  }
  return rule;
}

std::vector<double> Project(const std::function<double(const Vec3&)>& f, int bands,
                            const QuadratureRule& rule) {
  CheckBands("Project", bands);
  std::vector<double> out(CoefficientCount(bands), 0.0);
  double y[kMaxCoefficients];
  for (size_t i = 0; i < rule.directions.size(); ++i) {
    const Vec3& d = rule.directions[i];
    const double value = f(d) * rule.weights[i];
    EvaluateBasis<double>(bands, d[0], d[1], d[2], y);
    for (size_t n = 0; n < out.size(); ++n) out[n] += value * y[n];
  }
  return out;
}

std::vector<double> ProjectMonteCarlo(const std::function<double(const Vec3&)>& f, int bands,
                                      int samples, uint64_t seed) {
  CheckBands("ProjectMonteCarlo", bands);
  if (samples < 1) {
    throw ShError("sh::ProjectMonteCarlo: samples " + std::to_string(samples) + " must be >= 1");
  }
  std::mt19937_64 rng(seed);
  std::vector<double> out(CoefficientCount(bands), 0.0);
  double y[kMaxCoefficients];
  const double weight = 4 * std::numbers::pi / samples;
  for (int i = 0; i < samples; ++i) {
    const double z = 1 - 2 * Uniform(rng);
    const double phi = 2 * std::numbers::pi * Uniform(rng);
    const double r = std::sqrt(std::max(0.0, 1 - z * z));
    const Vec3 d{r * std::cos(phi), r * std::sin(phi), z};
    const double value = f(d) * weight;
    EvaluateBasis<double>(bands, d[0], d[1], d[2], y);
    for (size_t n = 0; n < out.size(); ++n) out[n] += value * y[n];
  }
  return out;
}

std::vector<Vec3> FibonacciSphere(int n) {
  if (n < 1) throw ShError("sh::FibonacciSphere: n " + std::to_string(n) + " must be >= 1");
  std::vector<Vec3> out(n);
  const double golden_angle = std::numbers::pi * (3 - std::sqrt(5.0));
  for (int i = 0; i < n; ++i) {
    const double z = 1 - (2 * i + 1.0) / n;
    const double r = std::sqrt(std::max(0.0, 1 - z * z));
    const double phi = golden_angle * i;
    out[i] = {r * std::cos(phi), r * std::sin(phi), z};
  }
  return out;
}

Vec3 DirectionFromAzimuthElevation(double azimuth, double elevation) {
  return {-std::sin(azimuth) * std::cos(elevation), -std::sin(elevation),
          -std::cos(azimuth) * std::cos(elevation)};
}

std::array<double, 2> AzimuthElevation(const Vec3& d) {
  return {std::atan2(-d[0], -d[2]), std::asin(std::clamp(-d[1], -1.0, 1.0))};
}

Vec3 LatLongDirection(int u, int v, int width, int height) {
  const double azimuth = std::numbers::pi - 2 * std::numbers::pi * (u + 0.5) / width;
  const double elevation = std::numbers::pi / 2 - std::numbers::pi * (v + 0.5) / height;
  return DirectionFromAzimuthElevation(azimuth, elevation);
}

void RenderLatLong(std::span<const float> coefficients, int bands, int channels, int width,
                   int height, std::span<float> out) {
  CheckBands("RenderLatLong", bands);
  if (channels < 1 || channels > 4) {
    throw ShError("sh::RenderLatLong: channels " + std::to_string(channels) + " out of range 1..4");
  }
  if (width < 1 || height < 1) {
    throw ShError("sh::RenderLatLong: image size " + std::to_string(width) + "x" +
                  std::to_string(height) + " must be at least 1x1");
  }
  const size_t count = CoefficientCount(bands);
  if (coefficients.size() != count * channels) {
    throw ShError("sh::RenderLatLong: " + std::to_string(coefficients.size()) +
                  " coefficients, expected " + std::to_string(count * channels));
  }
  if (out.size() != static_cast<size_t>(width) * height * channels) {
    throw ShError("sh::RenderLatLong: output holds " + std::to_string(out.size()) +
                  " floats, expected " +
                  std::to_string(static_cast<size_t>(width) * height * channels));
  }
  double y[kMaxCoefficients];
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      const Vec3 d = LatLongDirection(u, v, width, height);
      EvaluateBasis<double>(bands, d[0], d[1], d[2], y);
      float* pixel = &out[(static_cast<size_t>(v) * width + u) * channels];
      for (int c = 0; c < channels; ++c) {
        double sum = 0;
        for (size_t n = 0; n < count; ++n) sum += coefficients[n * channels + c] * y[n];
        pixel[c] = static_cast<float>(sum);
      }
    }
  }
}

}  // namespace probeless::sh
