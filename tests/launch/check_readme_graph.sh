#!/usr/bin/env bash
# The README's "Looking at a running graph" block works as printed: its launch line starts the graph
# (in a domain of its own), `topic list -v` lists every topic a later line names, `topic hz` reports
# a rate for each, and `clean` succeeds after the graph stops. Lines that cannot run here are listed
# in `not_here` with the reason; any other line fails the check, so a new README line is either
# executed or named below.
#   check_readme_graph.sh SOURCE_DIR BIN_DIR
set -euo pipefail
src=${1:?usage: check_readme_graph.sh SOURCE_DIR BIN_DIR}
bin=${2:?usage: check_readme_graph.sh SOURCE_DIR BIN_DIR}
cd "$src"
export PROBELESS_DOMAIN="readme_graph_$$"
log=$(mktemp)

block=$(awk '
  $0 == "## Looking at a running graph" { inside = 1; next }
  inside && /^```/ { if (open) exit; open = 1; next }
  inside && open { print }' README.md)
[ -n "$block" ] || { echo "README.md: no code block under '## Looking at a running graph'"; exit 1; }

# Lines this check does not run, by the command they start with, and why.
not_here() {
  case "$1" in
    "probeless launch launch/foxglove_bridge.launch.yaml"*) echo "a WebSocket server on a fixed port: tests/foxglove" ;;
    "bus_bench "*) echo "a 45-s benchmark: docs/benchmarks/bus.md" ;;
    "probeless bag info redkitchen.mcap"*) echo "needs the converted 7-Scenes log: tests/log" ;;
    *) return 1 ;;
  esac
}

launch_pid=""
stop_graph() {
  [ -n "$launch_pid" ] || return 0
  kill -INT "$launch_pid" 2>/dev/null || true
  wait "$launch_pid" 2>/dev/null || true
  launch_pid=""
}
trap 'stop_graph; "$bin/probeless" clean >/dev/null 2>&1 || true; rm -f "$log"' EXIT

failures=0
fail() { echo "FAIL: $*"; failures=$((failures + 1)); }
topics=""
while IFS= read -r line; do
  cmd=${line%%#*}                        # drop the trailing comment
  cmd=$(sed -E 's/[[:space:]]+$//' <<< "$cmd")
  [ -n "$cmd" ] || continue
  case "$cmd" in build/bin/*) cmd=${cmd#build/bin/} ;; *) fail "'$line' does not run a build/bin tool"; continue ;; esac
  if why=$(not_here "$cmd"); then echo "skip: $cmd ($why)"; continue; fi
  read -r -a argv <<< "$cmd"
  exe="$bin/${argv[0]}"
  case "$cmd" in
    "probeless launch "*)
      "$exe" "${argv[@]:1}" > "$log" 2>&1 &
      launch_pid=$!
      sleep 2
      kill -0 "$launch_pid" 2>/dev/null || { fail "'$cmd' exited: $(tail -n 3 "$log")"; launch_pid=""; }
      echo "ran: $cmd (in the background)"
      ;;
    "probeless topic list"*)
      topics=$("$exe" "${argv[@]:1}") || fail "'$cmd' exited with $?"
      echo "ran: $cmd"
      ;;
    "probeless topic hz "*)
      topic=${argv[3]}
      grep -qE "^$topic[[:space:]]" <<< "$topics" || fail "'$cmd': $topic is not in the topic list the README printed before it"
      out=$("$exe" "${argv[@]:1}" --duration 2 --timeout 2 2>&1) || fail "'$cmd' exited with $?: $out"
      grep -qE "^average rate: [0-9.]+ Hz" <<< "$out" || fail "'$cmd' printed no rate: $out"
      echo "ran: $cmd -> $(head -n 1 <<< "$out")"
      ;;
    "probeless clean"*)
      stop_graph
      "$exe" "${argv[@]:1}" > /dev/null || fail "'$cmd' exited with $?"
      echo "ran: $cmd"
      ;;
    *) fail "'$cmd': neither run by this check nor listed in not_here" ;;
  esac
done <<< "$block"
[ "$failures" -eq 0 ] || { echo "$failures README command(s) failed"; exit 1; }
echo "README graph commands: ok"
