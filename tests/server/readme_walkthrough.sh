#!/usr/bin/env bash
# Runs the README's walkthrough block, as written, against a fresh server on a free port, so the
# README cannot drift from what calibd does. Usage: readme_walkthrough.sh CALIBD_BINARY SOURCE_DIR
set -euo pipefail
bin=$(realpath "$1")
src=$(realpath "$2")
tmp=$(mktemp -d)
# shellcheck source=/dev/null
source "$(dirname "$0")/../lib/serve.sh"
cleanup() {
  stop_calibd
  rm -rf "$tmp"
}
trap cleanup EXIT

start_calibd "$bin"

sed -n '/<!-- walkthrough:begin -->/,/<!-- walkthrough:end -->/p' "$src/README.md" |
  grep -v -e '^<!--' -e '^```' |
  sed -e "s|build/calibd|$bin|g" -e "s|127.0.0.1:8080|127.0.0.1:$port|g" \
      -e "s|/tmp/calibd-demo|$tmp/demo|g" >"$tmp/walkthrough.sh"
[ "$(wc -l <"$tmp/walkthrough.sh")" -gt 10 ] || { echo "walkthrough block not found"; exit 1; }

cd "$tmp"
timeout 300 bash -euo pipefail "$tmp/walkthrough.sh" >"$tmp/out.txt" 2>&1 || {
  echo "walkthrough failed:"; cat "$tmp/out.txt"; echo "server log:"; cat "$tmp/server.log"; exit 1; }

# What the walkthrough produced must be what it promises.
grep -q '"status": "succeeded"' "$tmp/demo/job-1.json"
grep -q '"method": "pca"' "$tmp/demo/pca-result.json"
grep -q 'constexpr double kSensitivity\[12\]\[3\]' "$tmp/demo/calibration.h"
grep -q '^name,x,y,z,offset_x' "$tmp/out.txt"
grep -q '^name,scale,scale_std' "$tmp/out.txt"
echo "README walkthrough: 1 passed, 0 failed"
