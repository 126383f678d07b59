// The renderer's window back-end when its X display dies (a defect found with issue #25): the
// node exits with code 1 and one line naming the cause, idle or drawing, instead of running on.
// Needs Xvfb (skipped without it).
#include <gtest/gtest.h>
#include <signal.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>

#include "probeless/testing/testing.h"

namespace probeless {
namespace {

TEST(RendererDisplay, ExitsWithOneLineWhenTheXServerDies) {
  if (std::system("command -v Xvfb > /dev/null 2>&1") != 0) GTEST_SKIP() << "no Xvfb";
  testing::TempDir dir("renderer_display");
  const std::string display = ":" + std::to_string(40 + ::getpid() % 50);
  const std::string pid_file = dir.File("xvfb.pid");
  ASSERT_EQ(std::system(("Xvfb " + display + " -screen 0 640x480x24 > /dev/null 2>&1 & echo $! > " +
                         pid_file)
                            .c_str()),
            0);
  std::this_thread::sleep_for(std::chrono::seconds(1));
  const pid_t xvfb = std::stoi(testing::ReadText(pid_file));
  ::setenv("DISPLAY", display.c_str(), 1);
  testing::Process renderer("renderer", {"--ros-args", "-p", "backend:=window", "-p", "mode:=face",
                                         "-r", "__ns:=/display_test"});
  // Until the window is up (the GL line), then the server goes.
  for (int i = 0; i < 300 && renderer.Err().find(" ready in ") == std::string::npos; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ASSERT_NE(renderer.Err().find(" ready in "), std::string::npos) << renderer.Err();
  ::kill(xvfb, SIGTERM);
  const int code = renderer.Wait(std::chrono::seconds(10));
  const std::string err = renderer.Err();
  EXPECT_EQ(code, 1) << err;
  EXPECT_NE(err.find("[error] [/display_test/renderer] window backend: the X display closed the "
                     "connection; exiting (backend:=offscreen needs no display)"),
            std::string::npos)
      << err;
  std::system((std::string(PROBELESS_BIN_DIR) + "/probeless clean > /dev/null 2>&1").c_str());
}

}  // namespace
}  // namespace probeless
