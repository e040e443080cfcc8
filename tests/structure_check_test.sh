#!/usr/bin/env bash
# scripts/check_structure.py on a made-up tree: it fails on a new long file, a long function and a
# method named outside its folder methods/<name>/ and the registry, passes once they are recorded,
# and fails when a recorded one grows or a failure reason has no catalog entry.
set -euo pipefail
check=$1/scripts/check_structure.py
tree=$(mktemp -d)
trap 'rm -rf "$tree"' EXIT
mkdir -p "$tree/core" "$tree/server" "$tree/methods/pca"
expect() {  # expect STATUS TEXT: the check exits STATUS and prints TEXT
  local status=0 out
  out=$(python3 "$check" --root "$tree" --baseline "$tree/baseline.json" 2>&1) || status=$?
  if [ "$status" != "$1" ] || ! grep -qF -- "$2" <<<"$out"; then
    echo "expected exit $1 and '$2', got exit $status:"; echo "$out"; exit 1
  fi
}
echo '{"files": {}, "functions": {}, "method_mentions": {}}' >"$tree/baseline.json"
{ echo 'int Long() {'; for i in $(seq 160); do echo "  int x$i = $i;"; done; echo '}'; } >"$tree/core/f.cc"
expect 1 "function core/f.cc:Long has 162 lines, over the limit of 150: split it"
for i in $(seq 700); do echo "// $i"; done >>"$tree/core/f.cc"
expect 1 "core/f.cc has 863 lines, over the limit of 800: split it"
echo 'const char* k = "imu";' >"$tree/server/s.cc"
echo 'const char* k = "imu";' >"$tree/methods/pca/m.cc"  # inside a method's folder: allowed
echo 'const char* k = "imu";' >"$tree/methods/registry.cc"  # the registry: allowed
echo 'j = {{"type", "array"}};' >"$tree/server/openapi.cc"   # JSON Schema's type: not the method
expect 1 '"imu" is named outside methods/ in 1 files, recorded 0: server/s.cc'
echo '// the "imu" method' >"$tree/methods/method.h"  # methods/ but not a method's folder
expect 1 '"imu" is named outside methods/ in 2 files, recorded 0: methods/method.h server/s.cc'
python3 "$check" --root "$tree" --baseline "$tree/baseline.json" --update >/dev/null
expect 0 "no rule broken beyond the recorded offenders (1 files, 1 functions)"
echo '// one more line' >>"$tree/core/f.cc"
expect 1 "core/f.cc has 864 lines, over the limit of 800 and its recorded 863: split it"
# A method's own failure reason needs a catalog entry (its FailureReasons()).
mkdir -p "$tree/methods/imu"
printf 'namespace imu_reason {\ninline constexpr Reason kSpin{"spin"};\n}\n' >"$tree/core/imu.h"
expect 1 "failure reason imu_reason::kSpin (core/imu.h) has no catalog entry"
echo 'CatalogEntry(core::imu_reason::kSpin, "Spin", "Hold it.")' >"$tree/methods/imu/imu_method.cc"
python3 "$check" --root "$tree" --baseline "$tree/baseline.json" --update >/dev/null
expect 0 "no rule broken beyond the recorded offenders"
echo "structure_check_test: ok"
