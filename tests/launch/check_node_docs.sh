#!/usr/bin/env bash
# docs/nodes.md documents every node: each directory nodes/<n>/ (with a main.cpp) has a "## <n>"
# section, and every parameter its sources (nodes/<n>/*.cpp but *_test.cpp) read by a literal
# name (node.Param("name", ...), node.Param<T>("name", ...), HasParamOverride("name"),
# Optional<T>(node, "name", ...)) has a table
# row "| `name` |" in that section. Nodes that run capture::RunCaptureNode must also find the
# params read by common/capture/src/capture_node.cpp in the "### Common capture params" section.
# Rows naming a param the code does not read are reported as warnings (stale documentation).
#   check_node_docs.sh SOURCE_DIR            check; exit 1 naming each node and param missing
#   check_node_docs.sh --self-test          the check passes on a complete synthetic tree and fails,
#                                           naming the node and param, when a row or a section is
#                                           removed from it
set -euo pipefail

# Literal parameter names read in the C++ files "$@", one per line.
params_read() {
  cat "$@" | tr '\n' ' ' |
    grep -oE '(Param(<[^()"]*>)?|HasParamOverride|Optional<[^()"]*>)\( *(node, *)?"[A-Za-z0-9_.]+"' |
    sed -E 's/.*"([A-Za-z0-9_.]+)"$/\1/' | sort -u
}

# The lines of the section starting at the exact heading $2 in file $1, up to the next "## ".
section() {
  awk -v heading="$2" '
    $0 == heading { inside = 1; next }
    inside && /^## / { exit }
    inside { print }' "$1"
}

documented() {  # $1 section text, $2 param
  grep -qF "| \`$2\` |" <<< "$1"
}

check() {
  local root=$1 doc=$1/docs/nodes.md failures=0 nodes=0 params=0
  [ -f "$doc" ] || { echo "FAILED: $doc is missing"; return 1; }
  local common_text common_params
  common_text=$(section "$doc" "### Common capture params")
  common_params=$(params_read "$root/common/capture/src/capture_node.cpp")
  for dir in "$root"/nodes/*/; do
    local node main text
    node=$(basename "$dir")
    main=$dir/main.cpp
    [ -f "$main" ] || continue
    nodes=$((nodes + 1))
    if ! grep -qx "## $node" "$doc"; then
      echo "FAILED: node '$node' (nodes/$node) has no '## $node' section in docs/nodes.md"
      failures=$((failures + 1))
      continue
    fi
    text=$(section "$doc" "## $node")
    local srcs=()  # main.cpp and the node's other sources (its params reading), not its tests
    for f in "$dir"*.cpp; do [[ $f == *_test.cpp ]] || srcs+=("$f"); done
    for p in $(params_read "${srcs[@]}"); do
      params=$((params + 1))
      if ! documented "$text" "$p"; then
        echo "FAILED: node '$node': param '$p' (read in nodes/$node/) is not documented in" \
          "its section of docs/nodes.md"
        failures=$((failures + 1))
      fi
    done
    if grep -q 'RunCaptureNode' "$main"; then
      for p in $common_params; do
        params=$((params + 1))
        if ! documented "$common_text" "$p"; then
          echo "FAILED: node '$node': common capture param '$p' (common/capture/src/capture_node.cpp)" \
            "is not documented under '### Common capture params' in docs/nodes.md"
          failures=$((failures + 1))
        fi
      done
    fi
    # Rows of params the code does not read: stale. A name may be a prefix literal ("image_")
    # plus a literal read with it, or (capture nodes) come from capture_node.cpp.
    local sources=("${srcs[@]}") prefixes
    if grep -q 'RunCaptureNode' "$main"; then
      sources+=("$root/common/capture/src/capture_node.cpp")
    fi
    prefixes=$(grep -ohE '"[a-z0-9]+_"' "${srcs[@]}" | tr -d '"' | sort -u || true)
    for p in $(section "$doc" "## $node" | awk '/^### /{exit} {print}' |
      grep -oE '^\| `[A-Za-z0-9_.]+` \| (string|int|double|bool)' | sed -E 's/^\| `([^`]+)`.*/\1/'); do
      local found=0
      if grep -qF "\"$p\"" "${sources[@]}"; then found=1; fi
      for prefix in $prefixes; do
        if [[ $p == "$prefix"* ]] && grep -qF "\"${p#"$prefix"}\"" "${srcs[@]}"; then found=1; fi
      done
      if [ "$found" -eq 0 ]; then
        echo "warning: node '$node': documented param '$p' is not read by that name in" \
          "nodes/$node/"
      fi
    done
  done
  echo "$nodes nodes, $params params checked, $failures missing"
  [ "$nodes" -gt 0 ] && [ "$failures" -eq 0 ]
}

if [ "${1:-}" = "--self-test" ]; then
  # A synthetic tree: node alpha (params in the call forms the check knows, one split over two
  # lines, one with a ParamDescriptor) and capture node beta (common capture params), fully documented; then one row and one
  # section removed.
  tmp=$(mktemp -d)
  trap 'rm -rf "$tmp"' EXIT
  mkdir -p "$tmp/docs" "$tmp/common/capture/src" "$tmp/nodes/alpha" "$tmp/nodes/beta"
  cat > "$tmp/nodes/alpha/main.cpp" <<'CPP'
const double speed = node.Param("speed", 1.0);
const auto names = node.Param<std::vector<std::string>>("names", {});
const int gap = node.Param(
    "gap", 2);
const std::string mode = node.Param("mode", "a", {.choices = {"a", "b"}});
CPP
  echo 'o.depth = node.Param("depth", 3);' > "$tmp/nodes/alpha/params.cpp"
  cat > "$tmp/nodes/beta/main.cpp" <<'CPP'
if (node.HasParamOverride("gain")) o.gain = node.Param("gain", 1.0);
c.focus = Optional<int64_t>(node, "focus", 0);
return capture::RunCaptureNode(node, open);
CPP
  echo 's.frame_id = node.Param("frame_id", "camera");' > "$tmp/common/capture/src/capture_node.cpp"
  cat > "$tmp/docs/nodes.md" <<'MD'
## alpha

| param | type | default | unit | meaning |
|---|---|---|---|---|
| `speed` | double | 1.0 | m/s | |
| `names` | string list | `[]` | | |
| `gap` | int | 2 | px | |
| `mode` | string | `a` | | a or b |
| `depth` | int | 3 | | read in the node's params.cpp |

## beta

| `gain` | double | unset | | |
| `focus` | int | unset | | |

### Common capture params

| `frame_id` | string | `camera` | | |
MD
  expect_failure() {  # $1 what, $2 expected line
    local out
    if out=$(check "$tmp"); then
      echo "self-test: $1 was not detected"
      exit 1
    fi
    grep -qF "$2" <<< "$out" || { echo "self-test: $1: unexpected report: $out"; exit 1; }
  }
  check "$tmp" > /dev/null || { echo "self-test: the complete fixture fails:"; check "$tmp"; exit 1; }
  cp "$tmp/docs/nodes.md" "$tmp/complete.md"
  grep -vF '| `gap` |' "$tmp/complete.md" > "$tmp/docs/nodes.md"
  expect_failure "a missing row" "node 'alpha': param 'gap'"
  grep -vF '| `mode` |' "$tmp/complete.md" > "$tmp/docs/nodes.md"
  expect_failure "a missing row of a declared param" "node 'alpha': param 'mode'"
  grep -vF '| `depth` |' "$tmp/complete.md" > "$tmp/docs/nodes.md"
  expect_failure "a missing row of a param read outside main.cpp" "node 'alpha': param 'depth'"
  grep -vF '| `frame_id` |' "$tmp/complete.md" > "$tmp/docs/nodes.md"
  expect_failure "a missing common capture row" "node 'beta': common capture param 'frame_id'"
  grep -vF '| `focus` |' "$tmp/complete.md" > "$tmp/docs/nodes.md"
  expect_failure "a missing Optional<T> row" "node 'beta': param 'focus'"
  grep -vx '## beta' "$tmp/complete.md" > "$tmp/docs/nodes.md"
  expect_failure "a missing section" "node 'beta' (nodes/beta) has no '## beta' section"
  echo "self-test passed"
  exit 0
fi
check "${1:?usage: check_node_docs.sh SOURCE_DIR}"
