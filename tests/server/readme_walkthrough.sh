#!/usr/bin/env bash
# Runs the README's walkthrough block, as written, against a fresh server on a free port, so the
# README cannot drift from what calibd does. Usage: readme_walkthrough.sh CALIBD_BINARY SOURCE_DIR
set -euo pipefail
bin=$(realpath "$1")
src=$(realpath "$2")
tmp=$(mktemp -d)
server_pid=
cleanup() {
  [ -n "$server_pid" ] && kill "$server_pid" 2>/dev/null && wait "$server_pid" 2>/dev/null
  rm -rf "$tmp"
}
trap cleanup EXIT

"$bin" serve --db "$tmp/calibd.db" --listen 127.0.0.1:0 --no-access-log 2>"$tmp/server.log" &
server_pid=$!
port=
for _ in $(seq 1 100); do
  port=$(sed -n 's|.*listening on http://127.0.0.1:\([0-9]*\).*|\1|p' "$tmp/server.log" 2>/dev/null || true)
  [ -n "$port" ] && break
  sleep 0.1
done
[ -n "$port" ] || { echo "server did not start:"; cat "$tmp/server.log"; exit 1; }

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
