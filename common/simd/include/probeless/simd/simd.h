// Run-time choice of SIMD kernels (docs/ARCHITECTURE.md "SIMD kernels"). Everything is compiled for
// the portable x86-64 baseline; a kernel's AVX2/FMA version is compiled with PROBELESS_SIMD_AVX2
// (a per-function target attribute, never a global -mavx2) and called only when Active() says so,
// so a binary runs on any x86-64 CPU.
#pragma once

namespace probeless::simd {

// The instruction sets a kernel can be compiled for, portable first.
enum class Level { kPortable = 0, kAvx2Fma = 1 };

// The best level this CPU supports (cpuid through __builtin_cpu_supports: AVX2 and FMA both).
// kPortable on a non-x86 target.
Level Supported();

// The level kernels use: Supported(), lowered to kPortable when the environment variable
// PROBELESS_SIMD is "scalar" or "portable" (read once, at the first call; any other value but ""
// and "auto" is an error on stderr and ignored), or the level of the innermost live ScopedLevel.
// Never above Supported(). Cheap (one atomic load); thread-safe.
Level Active();

// True when Active() is kAvx2Fma.
inline bool UseAvx2() { return Active() == Level::kAvx2Fma; }

// For tests and benchmarks: Active() is min(level, Supported()) while this object lives (process-
// wide, not per thread: do not run kernels on other threads concurrently with a change). Nests.
class ScopedLevel {
 public:
  explicit ScopedLevel(Level level);
  ~ScopedLevel();
  ScopedLevel(const ScopedLevel&) = delete;
  ScopedLevel& operator=(const ScopedLevel&) = delete;

 private:
  int previous_;
};

// "portable" or "avx2+fma".
const char* Name(Level level);

}  // namespace probeless::simd

// Marks a function whose body is compiled for AVX2 + FMA (intrinsics allowed inside, and code
// inlined into it vectorised 8-wide). Call it only when probeless::simd::UseAvx2().
#if defined(__x86_64__) || defined(__i386__)
#define PROBELESS_SIMD_X86 1
#define PROBELESS_SIMD_AVX2 __attribute__((target("avx2,fma")))
#else
#define PROBELESS_SIMD_AVX2
#endif
