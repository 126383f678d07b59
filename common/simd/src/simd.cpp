#include "probeless/simd/simd.h"

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <cstring>

namespace probeless::simd {
namespace {

Level Detect() {
#ifdef PROBELESS_SIMD_X86
  __builtin_cpu_init();
  if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) return Level::kAvx2Fma;
#endif
  return Level::kPortable;
}

Level FromEnvironment(Level supported) {
  const char* value = std::getenv("PROBELESS_SIMD");
  if (value == nullptr || *value == '\0' || std::strcmp(value, "auto") == 0) return supported;
  if (std::strcmp(value, "scalar") == 0 || std::strcmp(value, "portable") == 0) {
    return Level::kPortable;
  }
  std::fprintf(stderr, "probeless: PROBELESS_SIMD=%s ignored (expected scalar, portable or auto)\n",
               value);
  return supported;
}

// -1 = not yet read; else the Level.
std::atomic<int> g_active{-1};

int Initial() {
  static const int level = static_cast<int>(FromEnvironment(Supported()));
  return level;
}

}  // namespace

Level Supported() {
  static const Level level = Detect();
  return level;
}

Level Active() {
  int level = g_active.load(std::memory_order_relaxed);
  if (level < 0) {
    level = Initial();
    int expected = -1;
    if (!g_active.compare_exchange_strong(expected, level, std::memory_order_relaxed)) {
      level = expected;
    }
  }
  return static_cast<Level>(level);
}

ScopedLevel::ScopedLevel(Level level) : previous_(static_cast<int>(Active())) {
  const int capped = std::min(static_cast<int>(level), static_cast<int>(Supported()));
  g_active.store(capped, std::memory_order_relaxed);
}

ScopedLevel::~ScopedLevel() { g_active.store(previous_, std::memory_order_relaxed); }

const char* Name(Level level) { return level == Level::kAvx2Fma ? "avx2+fma" : "portable"; }

}  // namespace probeless::simd
