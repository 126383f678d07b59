// NDEBUG as in the Release and RelWithDebInfo builds, whatever this build defines: assert is then
// compiled out, and PROBELESS_DEMAND must still fire.
#undef NDEBUG
#define NDEBUG 1
#include "probeless/error/error.h"

#include <gtest/gtest.h>

#include <cassert>
#include <stdexcept>
#include <string>

namespace probeless {
namespace {

TEST(InputErrorTest, IsARuntimeErrorWithTheMessage) {
  try {
    throw InputError("player: no file 'x.mcap' (expected an MCAP log)");
  } catch (const std::runtime_error& e) {
    EXPECT_STREQ(e.what(), "player: no file 'x.mcap' (expected an MCAP log)");
    return;
  }
  FAIL() << "InputError was not caught as a std::runtime_error";
}

TEST(DemandTest, PassingCheckDoesNothingAndEvaluatesOnce) {
  int evaluations = 0;
  PROBELESS_DEMAND(++evaluations == 1, "evaluated once");
  EXPECT_EQ(evaluations, 1);
}

TEST(DemandTest, FiresWhereAssertIsCompiledOut) {
  assert(1 + 1 == 3);  // NOLINT: compiled out by NDEBUG, so this line passes
  EXPECT_DEATH(PROBELESS_DEMAND(1 + 1 == 3, "arithmetic broke"),
               "PROBELESS_DEMAND\\(1 \\+ 1 == 3\\) failed: arithmetic broke");
}

TEST(DemandTest, FailureNamesFileAndLine) {
  EXPECT_DEATH(PROBELESS_DEMAND(false, "x"), "error_test\\.cpp:[0-9]+: PROBELESS_DEMAND");
}

TEST(DemandTest, WorksAsTheBodyOfAnUnbracedIf) {
  const bool check = false;
  if (check)
    PROBELESS_DEMAND(false, "never reached");
  else
    SUCCEED();
}

}  // namespace
}  // namespace probeless
