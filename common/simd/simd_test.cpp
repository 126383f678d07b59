// The run-time SIMD choice: the environment override, the scoped override and the CPU cap.
#include "probeless/simd/simd.h"

#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdlib>
#include <string>

namespace probeless::simd {
namespace {

TEST(Simd, ActiveNeverExceedsWhatTheCpuSupports) {
  EXPECT_LE(static_cast<int>(Active()), static_cast<int>(Supported()));
  ScopedLevel avx2(Level::kAvx2Fma);
  EXPECT_EQ(Active(), Supported());
}

TEST(Simd, ScopedLevelForcesThePortablePathAndRestores) {
  const Level before = Active();
  {
    ScopedLevel portable(Level::kPortable);
    EXPECT_EQ(Active(), Level::kPortable);
    EXPECT_FALSE(UseAvx2());
    {
      ScopedLevel inner(Level::kAvx2Fma);
      EXPECT_EQ(Active(), Supported());
    }
    EXPECT_EQ(Active(), Level::kPortable);
  }
  EXPECT_EQ(Active(), before);
}

// The variable is read once per process: check it in a child.
TEST(Simd, EnvironmentVariableScalarForcesThePortablePath) {
  const std::string self = PROBELESS_TEST_BIN_DIR "/simd_test";
  const std::string filter = " --gtest_filter=Simd.ReportsActive >/dev/null 2>&1";
  EXPECT_EQ(std::system(("PROBELESS_SIMD=scalar " + self + filter).c_str()), 0);
  const int expected = Supported() == Level::kAvx2Fma ? 1 : 0;
  EXPECT_EQ(WEXITSTATUS(std::system(("PROBELESS_SIMD_EXPECT=" + std::to_string(expected) +
                                     " PROBELESS_SIMD=auto " + self + filter)
                                        .c_str())),
            0);
}

// Run by the test above in a child: Active() against PROBELESS_SIMD_EXPECT (default 0); skipped
// without PROBELESS_SIMD.
TEST(Simd, ReportsActive) {
  if (std::getenv("PROBELESS_SIMD") == nullptr) GTEST_SKIP() << "run by the test above";
  const char* expect = std::getenv("PROBELESS_SIMD_EXPECT");
  EXPECT_EQ(static_cast<int>(Active()), expect != nullptr ? std::atoi(expect) : 0)
      << "PROBELESS_SIMD=" << (std::getenv("PROBELESS_SIMD") ? std::getenv("PROBELESS_SIMD") : "");
}

}  // namespace
}  // namespace probeless::simd
