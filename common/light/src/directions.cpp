#include "probeless/light/directions.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <string>

#include "probeless/sh/sh.h"

namespace probeless::light {
namespace {

double Uniform(std::mt19937_64& rng) {  // [0, 1) from the raw 64-bit output (portable)
  return static_cast<double>(rng() >> 11) * (1.0 / 9007199254740992.0);
}

}  // namespace

std::vector<std::array<int, 2>> SphericalDelaunayEdges(const std::vector<Vec3f>& points) {
  const int n = static_cast<int>(points.size());
  if (n < 4) {
    throw LightError("light::SphericalDelaunayEdges: need >= 4 directions, got " +
                     std::to_string(n));
  }
  std::vector<uint8_t> edge(static_cast<size_t>(n) * n, 0);
  auto sub = [](const Vec3f& a, const Vec3f& b) {
    return std::array<double, 3>{double(a[0]) - b[0], double(a[1]) - b[1], double(a[2]) - b[2]};
  };
  int faces = 0;
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n; ++j) {
      const auto e1 = sub(points[j], points[i]);
      for (int k = j + 1; k < n; ++k) {
        const auto e2 = sub(points[k], points[i]);
        const std::array<double, 3> c{e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                                      e1[0] * e2[1] - e1[1] * e2[0]};
        const double len = std::sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
        if (len < 1e-12) continue;
        // A hull face iff every other point lies on one side of the plane through i, j, k.
        int above = 0, below = 0;
        for (int m = 0; m < n && !(above && below); ++m) {
          if (m == i || m == j || m == k) continue;
          const auto d = sub(points[m], points[i]);
          const double s = (c[0] * d[0] + c[1] * d[1] + c[2] * d[2]) / len;
          if (s > 1e-9) ++above;
          if (s < -1e-9) ++below;
        }
        if (above && below) continue;
        ++faces;
        edge[i * n + j] = edge[i * n + k] = edge[j * n + k] = 1;
      }
    }
  }
  if (faces < 4) {
    throw LightError("light::SphericalDelaunayEdges: degenerate (coplanar) direction set");
  }
  std::vector<std::array<int, 2>> edges;
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n; ++j) {
      if (edge[i * n + j]) edges.push_back({i, j});
    }
  }
  return edges;
}

DirectionSet::DirectionSet(int count, int bands, uint64_t seed) : bands_(bands) {
  if (count < 8 || count > kMaxDirections) {
    throw LightError("light::DirectionSet: directions must be 8.." +
                     std::to_string(kMaxDirections) + ", got " + std::to_string(count));
  }
  if (bands < 1 || bands > sh::kMaxBands) {
    throw LightError("light::DirectionSet: bands must be 1..5, got " + std::to_string(bands));
  }
  // Jittered Fibonacci spiral: stratum i covers z in [1 - 2(i+1)/N, 1 - 2i/N] (equal areas).
  std::mt19937_64 rng(seed);
  const double golden = std::numbers::pi * (3.0 - std::sqrt(5.0));
  directions_.resize(count);
  for (int i = 0; i < count; ++i) {
    const double jz = Uniform(rng) - 0.5, jphi = Uniform(rng) - 0.5;
    const double z = 1.0 - (2.0 * i + 1.0 + 0.5 * jz) / count;
    const double phi = golden * (i + 0.5 * jphi);
    const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
    directions_[i] = {static_cast<float>(r * std::cos(phi)), static_cast<float>(r * std::sin(phi)),
                      static_cast<float>(z)};
  }
  // eq. 6 with d omega_j = 4 pi / N, divided by pi (Lambertian BRDF, msgs::TransferBuffer).
  const int cc = bands * bands;
  weights_.resize(static_cast<size_t>(count) * cc);
  std::vector<double> y(cc);
  for (int j = 0; j < count; ++j) {
    const auto& d = directions_[j];
    sh::EvaluateBasis<double>(bands, d[0], d[1], d[2], y.data());
    for (int n = 0; n < cc; ++n) weights_[j * cc + n] = static_cast<float>(y[n] * 4.0 / count);
  }
  // eq. 9: chi = cos(median(alpha_ij in Psi) / 2).
  edges_ = SphericalDelaunayEdges(directions_);
  std::vector<double> angles;
  angles.reserve(edges_.size());
  for (const auto& [i, j] : edges_) {
    const auto& a = directions_[i];
    const auto& b = directions_[j];
    const double dot = double(a[0]) * b[0] + double(a[1]) * b[1] + double(a[2]) * b[2];
    angles.push_back(std::acos(std::clamp(dot, -1.0, 1.0)));
  }
  std::sort(angles.begin(), angles.end());
  const size_t m = angles.size();
  median_angle_ = m % 2 ? angles[m / 2] : 0.5 * (angles[m / 2 - 1] + angles[m / 2]);
  chi_ = std::cos(median_angle_ / 2);
}

}  // namespace probeless::light
