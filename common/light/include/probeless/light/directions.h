// The sampling directions of the screen-space directional occlusion (Gruber et al. 2015, §5.1):
// N jittered unit directions over the whole sphere with precomputed SH weights, and the
// visibility threshold chi of eq. 9 from a spherical Delaunay triangulation of the directions.
#pragma once

#include <array>
#include <cstdint>
#include <stdexcept>
#include <vector>

#include "probeless/error/error.h"

namespace probeless::light {

// Bad input at the public boundary of probeless_light: one line "light::<Function>: <problem>".
class LightError : public InputError {
 public:
  using InputError::InputError;
};

using Vec3f = std::array<float, 3>;

// Largest supported direction count (the O(N^4) hull below is built once per set).
inline constexpr int kMaxDirections = 256;

// A fixed set of unit directions omega_j (in whatever frame the caller uses — probeless_light uses
// the camera optical frame: x right, y down, z forward) with per-direction SH weights.
class DirectionSet {
 public:
  // `count` (8..kMaxDirections) directions: a Fibonacci spiral whose z and azimuth are jittered by
  // up to half a stratum with a std::mt19937_64 seeded with `seed` (deterministic, portable: the
  // uniforms come from the raw 64-bit output), SH of `bands` (1..5) bands. Throws LightError.
  DirectionSet(int count, int bands, uint64_t seed);

  int count() const { return static_cast<int>(directions_.size()); }
  int bands() const { return bands_; }
  int coefficient_count() const { return bands_ * bands_; }
  const std::vector<Vec3f>& directions() const { return directions_; }
  // weights()[j * coefficient_count() + n] = Y_n(omega_j) * (4 pi / N) / pi: the quadrature weight
  // of direction j for coefficient n, including the Lambertian 1/pi of msgs::TransferBuffer
  // (eq. 6 with d omega_j = 4 pi / N). Steradians / pi, i.e. dimensionless.
  const std::vector<float>& weights() const { return weights_; }
  // Edges (i < j) of the spherical Delaunay triangulation Psi = the convex hull of the unit
  // directions (a point set on a sphere: its hull faces are exactly the spherical Delaunay
  // triangles). Built by brute force: a triple is a face iff no other direction lies strictly
  // outside its plane (O(N^4), once per set; N <= 256).
  const std::vector<std::array<int, 2>>& delaunay_edges() const { return edges_; }
  // Median angle alpha_ij over delaunay_edges(), radians.
  double median_neighbour_angle() const { return median_angle_; }
  // chi = cos(median(alpha_ij) / 2) (eq. 9).
  double chi() const { return chi_; }

 private:
  int bands_ = 0;
  std::vector<Vec3f> directions_;
  std::vector<float> weights_;
  std::vector<std::array<int, 2>> edges_;
  double median_angle_ = 0;
  double chi_ = 1;
};

// Edges (i < j, sorted) of the convex hull of unit vectors `points` (>= 4, not all coplanar) =
// their spherical Delaunay triangulation. Throws LightError for fewer than 4 points or a
// degenerate (coplanar) set.
std::vector<std::array<int, 2>> SphericalDelaunayEdges(const std::vector<Vec3f>& points);

}  // namespace probeless::light
