// Private: strict parsing of the dataset text files (matrices, TUM lists, timestamps).
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "probeless/msgs/geometry.h"

namespace probeless::dataset::internal {

// The whole file as text. Throws DatasetError "cannot read <what> '<path>'" if it cannot be read.
std::string ReadTextFile(const std::string& path, std::string_view what);

// The whitespace-separated tokens of `text` (spaces, tabs, newlines, carriage returns).
std::vector<std::string_view> SplitWhitespace(std::string_view text);

// `token` as a finite double (the whole token must be a number), or false.
bool ParseDouble(std::string_view token, double& value);

// The numbers of file `path`, which must hold exactly `count` whitespace-separated finite numbers.
// Throws DatasetError "malformed <what> '<path>': expected <expectation>, ..." otherwise.
std::vector<double> ReadNumberFile(const std::string& path, size_t count, std::string_view what,
                                   std::string_view expectation);

// A decimal time in seconds ("1305031102.175304") as nanoseconds, exactly (digits beyond the
// ninth decimal are rounded half up). False if `token` is not a non-negative decimal number.
bool ParseSecondsToNs(std::string_view token, uint64_t& ns);

// Unit quaternion (w >= 0) of the rotation matrix `r` (row-major 3x3).
msgs::Quaternion QuaternionFromRotation(const std::array<double, 9>& r);

// The child -> parent transform of a row-major 4x4 matrix [R t; 0 0 0 1] read from `path`. Throws
// DatasetError naming the file unless the last row is 0 0 0 1 and R is a rotation (orthonormal
// within 1e-3, determinant +1).
msgs::RigidTransform TransformFromMatrix(const std::vector<double>& m, const std::string& path);

// Spherical linear interpolation between unit quaternions a (t = 0) and b (t = 1) along the
// shorter arc; the result is unit length with w >= 0.
msgs::Quaternion Slerp(msgs::Quaternion a, msgs::Quaternion b, double t);

}  // namespace probeless::dataset::internal
