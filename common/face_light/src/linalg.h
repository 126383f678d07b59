// Private: the fixed-size 9 x 9 and runtime-size Cholesky calls of the face light estimator, on top
// of the shared implementation in probeless/linalg/cholesky.h.
#pragma once

#include <array>

#include "probeless/linalg/cholesky.h"

namespace probeless::face_light::internal {

// In place Cholesky factorisation of the symmetric positive definite N x N matrix a (row-major,
// lower triangle used and overwritten with L). Returns false if a is not positive definite.
template <int N>
bool Cholesky(std::array<double, N * N>& a) {
  return linalg::CholeskyFactor(a.data(), N);
}

// Solves L L^T x = b in place (l from Cholesky).
template <int N>
void CholeskySolve(const std::array<double, N * N>& l, double* b) {
  linalg::CholeskySolveFactored(l.data(), N, b);
}

// Runtime-size variants (row stride n).
inline bool CholeskyN(double* a, int n) { return linalg::CholeskyFactor(a, n); }
inline void CholeskySolveN(const double* l, int n, double* b) {
  linalg::CholeskySolveFactored(l, n, b);
}

}  // namespace probeless::face_light::internal
