#include "text_io.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <sstream>

#include "probeless/dataset/source.h"

namespace probeless::dataset::internal {

std::string ReadTextFile(const std::string& path, std::string_view what) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw DatasetError("cannot read " + std::string(what) + " '" + path + "'");
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) throw DatasetError("cannot read " + std::string(what) + " '" + path + "'");
  return text.str();
}

std::vector<std::string_view> SplitWhitespace(std::string_view text) {
  std::vector<std::string_view> tokens;
  size_t i = 0;
  auto is_space = [](char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r'; };
  while (i < text.size()) {
    while (i < text.size() && is_space(text[i])) ++i;
    const size_t start = i;
    while (i < text.size() && !is_space(text[i])) ++i;
    if (i > start) tokens.push_back(text.substr(start, i - start));
  }
  return tokens;
}

bool ParseDouble(std::string_view token, double& value) {
  if (!token.empty() && token.front() == '+') token.remove_prefix(1);
  if (token.empty()) return false;
  double parsed = 0;
  const auto [end, error] = std::from_chars(token.data(), token.data() + token.size(), parsed);
  if (error != std::errc() || end != token.data() + token.size() || !std::isfinite(parsed)) {
    return false;
  }
  value = parsed;
  return true;
}

std::vector<double> ReadNumberFile(const std::string& path, size_t count, std::string_view what,
                                   std::string_view expectation) {
  const std::string text = ReadTextFile(path, what);
  const std::vector<std::string_view> tokens = SplitWhitespace(text);
  const std::string prefix =
      "malformed " + std::string(what) + " '" + path + "': expected " + std::string(expectation);
  std::vector<double> numbers;
  for (std::string_view token : tokens) {
    double value = 0;
    if (!ParseDouble(token, value)) {
      throw DatasetError(prefix + ", found '" + std::string(token) + "'");
    }
    numbers.push_back(value);
  }
  if (numbers.size() != count) {
    throw DatasetError(prefix + ", found " + std::to_string(numbers.size()) + " numbers");
  }
  return numbers;
}

bool ParseSecondsToNs(std::string_view token, uint64_t& ns) {
  const size_t dot = token.find('.');
  const std::string_view whole = token.substr(0, dot);
  const std::string_view fraction =
      dot == std::string_view::npos ? std::string_view() : token.substr(dot + 1);
  if (whole.empty() || whole.size() > 10) return false;
  auto all_digits = [](std::string_view s) {
    return std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; });
  };
  if (!all_digits(whole) || !all_digits(fraction)) return false;
  if (dot != std::string_view::npos && fraction.empty()) return false;
  uint64_t seconds = 0;
  for (char c : whole) seconds = seconds * 10 + static_cast<uint64_t>(c - '0');
  uint64_t nanos = 0;
  for (size_t i = 0; i < 9; ++i) {
    nanos = nanos * 10 + (i < fraction.size() ? static_cast<uint64_t>(fraction[i] - '0') : 0);
  }
  if (fraction.size() > 9 && fraction[9] >= '5') ++nanos;
  ns = seconds * 1'000'000'000ull + nanos;
  return true;
}

msgs::Quaternion QuaternionFromRotation(const std::array<double, 9>& r) {
  // Shepperd's method: pick the largest of 4w^2, 4x^2, 4y^2, 4z^2 for numerical stability.
  const double trace = r[0] + r[4] + r[8];
  msgs::Quaternion q;
  if (trace >= r[0] && trace >= r[4] && trace >= r[8]) {
    const double s = std::sqrt(1.0 + trace) * 2;  // 4w
    q.w = 0.25 * s;
    q.x = (r[7] - r[5]) / s;
    q.y = (r[2] - r[6]) / s;
    q.z = (r[3] - r[1]) / s;
  } else if (r[0] >= r[4] && r[0] >= r[8]) {
    const double s = std::sqrt(1.0 + r[0] - r[4] - r[8]) * 2;  // 4x
    q.w = (r[7] - r[5]) / s;
    q.x = 0.25 * s;
    q.y = (r[1] + r[3]) / s;
    q.z = (r[2] + r[6]) / s;
  } else if (r[4] >= r[8]) {
    const double s = std::sqrt(1.0 + r[4] - r[0] - r[8]) * 2;  // 4y
    q.w = (r[2] - r[6]) / s;
    q.x = (r[1] + r[3]) / s;
    q.y = 0.25 * s;
    q.z = (r[5] + r[7]) / s;
  } else {
    const double s = std::sqrt(1.0 + r[8] - r[0] - r[4]) * 2;  // 4z
    q.w = (r[3] - r[1]) / s;
    q.x = (r[2] + r[6]) / s;
    q.y = (r[5] + r[7]) / s;
    q.z = 0.25 * s;
  }
  const double norm = std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
  const double sign = q.w < 0 ? -1.0 : 1.0;
  q.w *= sign / norm;
  q.x *= sign / norm;
  q.y *= sign / norm;
  q.z *= sign / norm;
  return q;
}

msgs::RigidTransform TransformFromMatrix(const std::vector<double>& m, const std::string& path) {
  const std::string prefix = "malformed pose file '" + path + "': ";
  if (m.size() != 16) {
    throw DatasetError(prefix + "expected 16 numbers (a 4x4 matrix), found " +
                       std::to_string(m.size()));
  }
  if (std::abs(m[12]) > 1e-6 || std::abs(m[13]) > 1e-6 || std::abs(m[14]) > 1e-6 ||
      std::abs(m[15] - 1) > 1e-6) {
    throw DatasetError(prefix + "expected the last row 0 0 0 1 of a rigid transform");
  }
  const std::array<double, 9> r = {m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]};
  // R^T R must be the identity and det R = +1.
  double worst = 0;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      double dot = 0;
      for (int k = 0; k < 3; ++k) dot += r[k * 3 + i] * r[k * 3 + j];
      worst = std::max(worst, std::abs(dot - (i == j ? 1.0 : 0.0)));
    }
  }
  const double det = r[0] * (r[4] * r[8] - r[5] * r[7]) - r[1] * (r[3] * r[8] - r[5] * r[6]) +
                     r[2] * (r[3] * r[7] - r[4] * r[6]);
  if (worst > 1e-3 || det < 0) {
    throw DatasetError(prefix +
                       "expected a rotation (orthonormal, determinant +1) in the upper-left 3x3");
  }
  msgs::RigidTransform transform;
  transform.translation = {m[3], m[7], m[11]};
  transform.rotation = QuaternionFromRotation(r);
  return transform;
}

msgs::Quaternion Slerp(msgs::Quaternion a, msgs::Quaternion b, double t) {
  double dot = a.w * b.w + a.x * b.x + a.y * b.y + a.z * b.z;
  if (dot < 0) {
    b = {-b.w, -b.x, -b.y, -b.z};
    dot = -dot;
  }
  double wa = 1 - t;
  double wb = t;
  if (dot < 0.9995) {
    const double theta = std::acos(std::min(dot, 1.0));
    const double sin_theta = std::sin(theta);
    wa = std::sin((1 - t) * theta) / sin_theta;
    wb = std::sin(t * theta) / sin_theta;
  }
  msgs::Quaternion q{wa * a.w + wb * b.w, wa * a.x + wb * b.x, wa * a.y + wb * b.y,
                     wa * a.z + wb * b.z};
  const double norm = std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
  const double sign = q.w < 0 ? -1.0 : 1.0;
  return {q.w * sign / norm, q.x * sign / norm, q.y * sign / norm, q.z * sign / norm};
}

}  // namespace probeless::dataset::internal
