#!/bin/bash
# Runs binaries on an emulated x86-64 CPU without AVX (qemu-x86_64 -cpu Nehalem): none may die with
# SIGILL, and the run-time choice must say "portable" there (docs/ARCHITECTURE.md "SIMD kernels").
# The canary (sigill_probe, an unconditional FMA instruction) must die, or the check proves nothing.
# usage: check_no_avx2.sh BIN_DIR TEST_BIN_DIR SOURCE_DIR. Exit 77 (skipped) without qemu-x86_64
# (Debian qemu-user, installed by tools/setup).
set -u
bin=$1 tests=$2 src=$3
qemu=$(command -v qemu-x86_64) || { echo "SKIP: qemu-x86_64 not installed (apt-get install qemu-user)"; exit 77; }
[ "$(uname -m)" = x86_64 ] || { echo "SKIP: not an x86-64 host"; exit 77; }
run() { "$qemu" -cpu Nehalem "$@"; }
fail=0
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT

run "$tests/simd_sigill_probe" >/dev/null 2>&1
rc=$?
if [ $rc -ne 132 ] && [ $rc -ne 4 ]; then
  echo "FAIL: the canary (an FMA instruction) exited $rc under -cpu Nehalem, not SIGILL: the check cannot fail"
  exit 1
fi
echo "ok: canary dies with SIGILL"

check() {  # name, command...
  local name=$1; shift
  if run "$@" >"$out/log" 2>&1; then
    echo "ok: $name"
  else
    echo "FAIL: $name exited $? under -cpu Nehalem:"; tail -5 "$out/log"; fail=1
  fi
}
PROBELESS_SIMD=auto PROBELESS_SIMD_EXPECT=0 \
  check "simd_test: portable chosen" "$tests/simd_test" --gtest_filter=Simd.ReportsActive
check "light_kernel_test" "$tests/light_kernel_test"
check "scene_light_eval (2 frames: transfer, estimate, shadows, point lamps)" \
  "$bin/scene_light_eval" --frames 2 --json "$out/scene.json"
check "fusion_eval (simulated room, 3 frames: preprocess, ICP, integrate, raycast, merge)" \
  "$bin/fusion_eval" --sim "$src/data/scenarios/room_dynamic.yaml" --frames 0-2 --json "$out/fusion.json"
exit $fail
