// Private: small dense linear algebra for 9 x 9 normal equations (no third-party dependency).
#pragma once

#include <array>
#include <cmath>

namespace probeless::face_light::internal {

// In place Cholesky factorisation of the symmetric positive definite n x n matrix a (row-major,
// lower triangle used and overwritten with L). Returns false if a is not positive definite.
template <int N>
bool Cholesky(std::array<double, N * N>& a) {
  for (int j = 0; j < N; ++j) {
    double d = a[j * N + j];
    for (int k = 0; k < j; ++k) d -= a[j * N + k] * a[j * N + k];
    if (!(d > 0)) return false;
    d = std::sqrt(d);
    a[j * N + j] = d;
    for (int i = j + 1; i < N; ++i) {
      double s = a[i * N + j];
      for (int k = 0; k < j; ++k) s -= a[i * N + k] * a[j * N + k];
      a[i * N + j] = s / d;
    }
  }
  return true;
}

// Solves L L^T x = b in place (l from Cholesky).
template <int N>
void CholeskySolve(const std::array<double, N * N>& l, double* b) {
  for (int i = 0; i < N; ++i) {
    double s = b[i];
    for (int k = 0; k < i; ++k) s -= l[i * N + k] * b[k];
    b[i] = s / l[i * N + i];
  }
  for (int i = N - 1; i >= 0; --i) {
    double s = b[i];
    for (int k = i + 1; k < N; ++k) s -= l[k * N + i] * b[k];
    b[i] = s / l[i * N + i];
  }
}

// Runtime-size variants for n <= 32 (row stride n): the same factorisation and solve.
inline bool CholeskyN(double* a, int n) {
  for (int j = 0; j < n; ++j) {
    double d = a[j * n + j];
    for (int k = 0; k < j; ++k) d -= a[j * n + k] * a[j * n + k];
    if (!(d > 0)) return false;
    d = std::sqrt(d);
    a[j * n + j] = d;
    for (int i = j + 1; i < n; ++i) {
      double s = a[i * n + j];
      for (int k = 0; k < j; ++k) s -= a[i * n + k] * a[j * n + k];
      a[i * n + j] = s / d;
    }
  }
  return true;
}

inline void CholeskySolveN(const double* l, int n, double* b) {
  for (int i = 0; i < n; ++i) {
    double s = b[i];
    for (int k = 0; k < i; ++k) s -= l[i * n + k] * b[k];
    b[i] = s / l[i * n + i];
  }
  for (int i = n - 1; i >= 0; --i) {
    double s = b[i];
    for (int k = i + 1; k < n; ++k) s -= l[k * n + i] * b[k];
    b[i] = s / l[i * n + i];
  }
}

}  // namespace probeless::face_light::internal
