// libFuzzer target: sim::ParseScenario (the simulator's scenario YAML, docs/sim.md) on arbitrary
// text, with relative file names resolved in an empty scratch folder (so every mesh or image a
// scenario names is missing unless it is a built-in). Only ScenarioError may escape.
#include <cstring>

#include "fuzz_file.h"
#include "probeless/sim/scenario.h"

namespace {

using probeless::fuzz::Check;
constexpr size_t kMaxInputBytes = 16 * 1024;

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size > kMaxInputBytes) return 0;
  // "data:" names must not reach the shared data set (large meshes would make inputs slow).
  static const bool no_data = [] {
    setenv("PROBELESS_DATA", probeless::fuzz::ScratchDir("scenario").c_str(), 1);
    return true;
  }();
  (void)no_data;
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    probeless::sim::ParseScenario(text, "fuzz/scenario.yaml",
                                  probeless::fuzz::ScratchDir("scenario"));
  } catch (const probeless::sim::ScenarioError& e) {
    Check(std::strncmp(e.what(), "fuzz/scenario.yaml", 18) == 0);
  }
  return 0;
}
