// Private band 0..2 SH helpers (msgs/sh_light.h convention): the basis is probeless_sh's
// (sh::EvaluateBasis); raytrace_test checks it against the analytic constants.
#pragma once

#include <array>
#include <functional>

#include "probeless/raytrace/geometry.h"

namespace probeless::raytrace::internal {

// Clamped-cosine convolution constants A_0..A_2 (Ramamoorthi & Hanrahan 2001): pi, 2 pi / 3,
// pi / 4, per coefficient index 0..8.
extern const std::array<float, 9> kClampedCosine;

// sum_i sh[i] Y_i(d) per channel.
Vec3 EvaluateSh9(const std::array<Vec3, 9>& sh, Vec3 d);

// Irradiance E(n) = integral L(w) max(0, n.w) dw of the SH radiance `sh` at unit normal n.
Vec3 ShIrradiance(const std::array<Vec3, 9>& sh, Vec3 n);

// Projection of f (world-frame radiance) onto the basis of a rotated frame:
// out_i = integral f(R w) Y_i(w) dw, R = frame_to_world, exact for f of band <= 2.
std::array<Vec3, 9> ProjectRotated(const std::function<Vec3(Vec3)>& f, const Mat3& frame_to_world);

}  // namespace probeless::raytrace::internal
