#!/usr/bin/env bash
# Every shipped launch file resolves (`probeless launch FILE ARGS --dry-run`): its YAML, includes,
# substitutions and executables are valid. Required arguments get placeholder values here.
#   check_launch_files.sh PROBELESS_BINARY SOURCE_DIR
set -euo pipefail
probeless=$1
cd "$2"
declare -A args=(
  [launch/face_yaleb.yaml]="yaleb:=/tmp"
  [launch/fusion_7scenes.yaml]="source:=/tmp"
  [launch/scene_light.yaml]="log:=/tmp/x.mcap"
  [launch/replay.yaml]="source:=/tmp/x.mcap fuse:=true render:=true record:=true respawn:=true"
  [launch/capture/freenect_fakenect.launch.yaml]="dump:=/tmp"
  [tests/replay/lockstep.launch.yaml]="source:=/tmp probe:=/bin/true output:=/tmp/x"
)
checked=0
failed=0
for file in launch/*.yaml launch/*/*.yaml tests/replay/lockstep.launch.yaml; do
  # shellcheck disable=SC2086
  if out=$("$probeless" launch "$file" ${args[$file]:-} --dry-run 2>&1); then
    checked=$((checked + 1))
  else
    echo "FAILED: $file: $out"
    failed=$((failed + 1))
  fi
done
echo "$checked passed, $failed failed"
[ "$failed" -eq 0 ] && [ "$checked" -gt 10 ]
