// Every executable in build/bin answers -h/--help with a usage on stdout and exit code 0 without
// doing its work (issue #22): nodes through node::Node, tools through their own option parsing.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <string>

#include "probeless/testing/testing.h"

namespace {

namespace fs = std::filesystem;

TEST(Help, EveryExecutableAnswersHelp) {
  const fs::path scratch =
      fs::temp_directory_path() / ("probeless_help_" + std::to_string(getpid()));
  fs::create_directories(scratch);
  int checked = 0;
  for (const auto& entry : fs::directory_iterator(PROBELESS_BIN_DIR)) {
    if (!entry.is_regular_file() || ::access(entry.path().c_str(), X_OK) != 0) continue;
    for (const char* flag : {"--help", "-h"}) {
      // timeout: a binary that ignores --help would start its work (a node runs until stopped).
      const auto r = probeless::testing::RunCommand(
          "timeout 20 " + entry.path().string() + " " + flag, scratch);
      EXPECT_EQ(r.code, 0) << entry.path() << " " << flag << ": " << r.err;
      EXPECT_EQ(r.out.rfind("usage: ", 0), 0u) << entry.path() << " " << flag << ": " << r.out;
    }
    ++checked;
  }
  EXPECT_GT(checked, 20);
  fs::remove_all(scratch);
}

}  // namespace
