// Private: Extended Yale Face Database B file names, light directions and SH coefficients.
#pragma once

#include <array>
#include <optional>
#include <string_view>

namespace probeless::dataset::internal {

// What a file name "yaleBxx_P00A±aaaE±ee.pgm" says: subject xx, light azimuth and elevation in
// degrees.
struct YaleBName {
  int subject = 0;
  int azimuth_deg = 0;
  int elevation_deg = 0;
};

// The parsed name, or nullopt for any other file name (ambient images, .info, .bad files, ...).
std::optional<YaleBName> ParseYaleBName(std::string_view file_name);

// Unit vector from the face towards the light in the camera frame (x right, y down, z forward,
// the subject facing the camera) for azimuth A (positive = light from the subject's right = image
// left) and elevation E (positive = above): (-sin A cos E, -sin E, -cos A cos E).
std::array<double, 3> YaleBLightDirection(double azimuth_deg, double elevation_deg);

// The 9 real orthonormal SH basis functions (Condon-Shortley phase, index l(l+1)+m) of bands 0..2
// at unit direction (x, y, z): the coefficients of a directional light of radiance integral 1
// arriving from that direction.
std::array<double, 9> ShBasis3(double x, double y, double z);

}  // namespace probeless::dataset::internal
