// Cholesky factorisation and solve against a hand-made SPD system and a non-SPD matrix.
#include "probeless/linalg/cholesky.h"

#include <gtest/gtest.h>

namespace probeless::linalg {
namespace {

TEST(CholeskyTest, SolvesASymmetricPositiveDefiniteSystem) {
  // A = M M^T + I for M = [[1,2,0],[0,1,3],[2,0,1]]; x = (1, -2, 3); b = A x.
  double a[9] = {6, 2, 2, 2, 11, 3, 2, 3, 6};
  const double x[3] = {1, -2, 3};
  double b[3];
  for (int i = 0; i < 3; ++i) b[i] = a[i * 3] * x[0] + a[i * 3 + 1] * x[1] + a[i * 3 + 2] * x[2];
  ASSERT_TRUE(CholeskyFactor(a, 3));
  EXPECT_DOUBLE_EQ(a[0], std::sqrt(6.0));
  CholeskySolveFactored(a, 3, b);
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(b[i], x[i], 1e-12);
}

TEST(CholeskyTest, RejectsIndefiniteMatrices) {
  double a[4] = {1, 2, 2, 1};  // eigenvalues 3 and -1
  EXPECT_FALSE(CholeskyFactor(a, 2));
  double zero[4] = {0, 0, 0, 0};
  EXPECT_FALSE(CholeskyFactor(zero, 2));
}

}  // namespace
}  // namespace probeless::linalg
