// The canary of check_no_avx2.sh: executes one AVX2/FMA instruction without asking the CPU first,
// so on a CPU (or emulated CPU) without AVX2 it must die with SIGILL — proof that the check can
// fail.
#include <cstdio>

#include "probeless/simd/simd.h"

PROBELESS_SIMD_AVX2 __attribute__((noinline)) float Fma(float a, float b, float c) {
  return __builtin_fmaf(a, b, c);
}

int main(int argc, char** argv) {
  volatile float a = static_cast<float>(argc), b = 2, c = 3;
  std::printf("%g\n", Fma(a, b, c));
  return 0;
}
