// Small dense symmetric positive definite systems (normal equations of least-squares fits, n up to
// a few dozen) by Cholesky factorisation: the one implementation the estimators share. Row-major,
// row stride n; only the lower triangle of A is read.
#pragma once

#include <cmath>

namespace probeless::linalg {

// Factorises the n x n matrix `a` in place into L (lower triangle, A = L L^T). Returns false, with
// `a` partly overwritten, if A is not (numerically) positive definite.
inline bool CholeskyFactor(double* a, int n) {
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

// Solves L L^T x = b in place (`l` from CholeskyFactor).
inline void CholeskySolveFactored(const double* l, int n, double* b) {
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

}  // namespace probeless::linalg
