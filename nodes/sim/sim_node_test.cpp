// Process test of bin/sim's command line: each mode's bad options exit 2 with one line, --help
// prints the usage, --preview writes a contact sheet.
#include <gtest/gtest.h>
#include <stdlib.h>

#include <chrono>
#include <filesystem>
#include <string>
#include <vector>

#include "probeless/testing/testing.h"

namespace {

using namespace std::chrono_literals;
using probeless::testing::Process;

[[maybe_unused]] const bool kEnvironmentCleared = (unsetenv("PROBELESS_LOG_LEVEL"), true);

const std::string kScenario = PROBELESS_SOURCE_DIR "/data/scenarios/face_orbit.yaml";

// Runs sim with `args`; expects exit 2, nothing on stdout and exactly `error` on stderr.
void ExpectUsageError(std::vector<std::string> args, const std::string& error) {
  Process sim("sim", args);
  EXPECT_EQ(sim.Wait(20s), 2);
  EXPECT_EQ(sim.Err(), "[error] [sim] " + error + "\n");
  EXPECT_EQ(sim.Out(), "");
}

TEST(SimNodeTest, BadOptionsOfEachModeExitTwoWithOneLine) {
  ExpectUsageError({}, "no scenario given (a YAML file or param 'scenario')");
  ExpectUsageError({kScenario, "b.yaml"}, "unexpected argument 'b.yaml' (see --help)");
  ExpectUsageError({kScenario, "--frames", "-1"},
                   "--frames expects a non-negative integer, got '-1'");
  ExpectUsageError({kScenario, "--threads", "0"}, "--threads must be >= 1");
  ExpectUsageError({kScenario, "--rgb"},
                   "--subjects, --size, --rgb, --behind, --seed and --mesh need --yaleb-style");
  ExpectUsageError({"--yaleb-style", "/tmp/x", "--size", "5"},
                   "--size: expected WIDTHxHEIGHT, got '5'");
  ExpectUsageError({"--yaleb-style", "/tmp/x", kScenario}, "--yaleb-style takes no scenario");
  ExpectUsageError({"--yaleb-style", "/tmp/x", "--mesh", "cube"},
                   "--mesh: expected 'procedural' or 'ict', got 'cube'");
  ExpectUsageError({"--generate", "0"}, "--generate expects a positive integer, got '0'");
  ExpectUsageError({"--generate", "1", "--out", "/tmp/x"},
                   "--generate needs --split train|validation|test");
  ExpectUsageError({"--generate", "1", "--split", "test"}, "--generate needs --out DIR");
  ExpectUsageError({"--bogus"}, "unknown option '--bogus' (see --help)");
}

TEST(SimNodeTest, HelpPrintsTheUsageOfEveryMode) {
  Process sim("sim", {"--help"});
  EXPECT_EQ(sim.Wait(20s), 0);
  const std::string out = sim.Out();
  EXPECT_EQ(out.rfind("usage: sim [options] [SCENARIO]\n", 0), 0u) << out;
  for (const char* flag : {"--preview", "--yaleb-style", "--generate", "--spp", "--lockstep"}) {
    EXPECT_NE(out.find(flag), std::string::npos) << flag;
  }
}

TEST(SimNodeTest, PreviewWritesAContactSheet) {
  const std::filesystem::path png =
      std::filesystem::temp_directory_path() / "probeless_sim_node_test_preview.png";
  std::filesystem::remove(png);
  Process sim("sim", {kScenario, "--frames", "2", "--threads", "1", "--preview", png.string()});
  EXPECT_EQ(sim.Wait(60s), 0) << sim.Err();
  EXPECT_EQ(sim.Out(), "sim: wrote " + png.string() + " (2 frames)\n");
  EXPECT_GT(std::filesystem::file_size(png), 1000u);
  std::filesystem::remove(png);
}

}  // namespace
