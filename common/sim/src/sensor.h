// Private to probeless_sim: the deterministic random stream and the Kinect-like depth sensor
// model shared by the scenario simulator and the scene generator (docs/sim.md, "Sensor").
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>

#include "probeless/sim/scenario.h"

namespace probeless::sim::internal {

inline uint64_t SplitMix64(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// Deterministic uniform and normal variates from a splitmix64 stream.
class Rng {
 public:
  explicit Rng(uint64_t seed) : state_(seed) {}
  double Uniform() {
    state_ = SplitMix64(state_);
    return static_cast<double>(state_ >> 11) * (1.0 / 9007199254740992.0);
  }
  // Uniform in [lo, hi).
  double Uniform(double lo, double hi) { return lo + (hi - lo) * Uniform(); }
  // Box-Muller; the second value of each pair is kept for the next call.
  double Normal() {
    if (has_spare_) {
      has_spare_ = false;
      return spare_;
    }
    const double u1 = std::max(Uniform(), 1e-300);
    const double u2 = Uniform();
    const double r = std::sqrt(-2 * std::log(u1));
    spare_ = r * std::sin(2 * std::numbers::pi * u2);
    has_spare_ = true;
    return r * std::cos(2 * std::numbers::pi * u2);
  }

 private:
  uint64_t state_;
  double spare_ = 0;
  bool has_spare_ = false;
};

// Row `y` of a Kinect-like depth image in millimetres (0 = invalid) from the noiseless optical-
// axis depth `z0` (metres, width x height, 0 = no hit): edge holes, disparity quantisation, axial
// Gaussian noise sigma = a + b (z - 0.4)^2, random dropout and the valid range, drawing from `rng`.
inline void SensorDepthRow(const float* z0, int width, int height, int y, const SensorSpec& sensor,
                           Rng& rng, uint16_t* out_mm) {
  const size_t first = static_cast<size_t>(y) * width;
  for (int x = 0; x < width; ++x) {
    const size_t p = first + x;
    double z = z0[p];
    out_mm[x] = 0;
    if (z <= 0) continue;
    if (sensor.depth_holes) {
      bool edge = false;
      const int dx[4] = {-1, 1, 0, 0};
      const int dy[4] = {0, 0, -1, 1};
      for (int k = 0; k < 4 && !edge; ++k) {
        const int nx = x + dx[k];
        const int ny = y + dy[k];
        if (nx < 0 || ny < 0 || nx >= width || ny >= height) continue;
        const float zn = z0[static_cast<size_t>(ny) * width + nx];
        edge = zn <= 0 || std::abs(zn - z) > sensor.edge_ratio * z;
      }
      if (edge) continue;
    }
    if (sensor.quantisation > 0) {
      const double step = sensor.quantisation * z * z;
      z = std::round(z / step) * step;
    }
    if (sensor.depth_noise) {
      const double sigma = sensor.depth_noise_a + sensor.depth_noise_b * (z - 0.4) * (z - 0.4);
      z += sigma * rng.Normal();
    }
    if (sensor.dropout > 0 && rng.Uniform() < sensor.dropout) continue;
    if (z < sensor.depth_min_m || z > sensor.depth_max_m) continue;
    const double mm = std::round(z * 1000);
    out_mm[x] = mm >= 1 && mm <= 65535 ? static_cast<uint16_t>(mm) : 0;
  }
}

}  // namespace probeless::sim::internal
