// Extended Yale Face Database B (cropped) file names and light directions, the one parser of them
// (the dataset source, the face-light training and evaluation, the Yale-B-style simulator use it;
// the SH coefficients of the light are probeless_sh's).
#pragma once

#include <array>
#include <optional>
#include <string_view>

namespace probeless::dataset {

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
// left) and elevation E (positive = above), in degrees: sh::DirectionFromAzimuthElevation,
// (-sin A cos E, -sin E, -cos A cos E).
std::array<double, 3> YaleBLightDirection(double azimuth_deg, double elevation_deg);

}  // namespace probeless::dataset
